"""The exact global IMQ interpolant over all masked pixels: the reference for tests."""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from ..numerics.imq import imq_matrix, imq_scaled_inverse
from ..numerics.saddle import SaddleFactor
from ..validation import as_int, float_array
from .interpolant import Evaluation, MaskedGridInterpolant

__all__ = ["exact_global_interpolant"]


def exact_global_interpolant(mask, fields, points, *, c=2.0, R0=1.0, max_pixels=12000):
    """The exact global IMQ interpolant over all masked pixels (dense solve).

    The reference for :class:`MaskedGridInterpolant` (``method="rbf"``); cost
    O(n_mask^3) time and O(n_mask^2) memory, so for small cases only.

    Parameters
    ----------
    mask : array_like of bool, shape (H, W)
    fields : array_like
        Shape (n_mask,) or (H, W), optionally with a leading n_fields axis.
    points : array_like, shape (M, 2)
        (u, v) in px.
    c, R0 : float
        Kernel shape parameter and distance normalisation (px).
    max_pixels : int
        Refuse larger masks (memory 8 n_mask^2 bytes).

    Returns
    -------
    Evaluation
        value, du, dv with shape (n_fields, M) or (M,); NaN for points outside
        the mask; edge_distance (M,).
    """
    interp = MaskedGridInterpolant(mask, method="bilinear", c=c, R0=R0)
    max_pixels = as_int(max_pixels, "max_pixels", 3)
    if interp.n_mask > max_pixels:
        raise ConfigError(
            f"exact_global_interpolant: the mask has {interp.n_mask} pixels, more than "
            f"max_pixels = {max_pixels} (the dense system needs 8 n^2 bytes)"
        )
    vals, single = interp.field_values(fields)
    p = float_array(points, "points")
    if p.ndim != 2 or p.shape[1] != 2:
        raise ConfigError(f"points must have shape (M, 2) with columns (u, v), got {p.shape}")
    ce = interp.c * interp.R0
    cen = interp.pixels.astype(float)
    origin = cen.mean(axis=0)
    cen = cen - origin
    fac = SaddleFactor(imq_matrix(cen, cen, ce), np.c_[np.ones(len(cen)), cen])
    alpha, beta = fac.solve(vals.T)  # (n, nf), (3, nf)
    loc = interp.locate(p[:, 0], p[:, 1])
    inside = loc[1]
    nf, M = vals.shape[0], p.shape[0]
    val = np.full((nf, M), np.nan)
    gu = np.full((nf, M), np.nan)
    gv = np.full((nf, M), np.nan)
    q = p[inside] - origin
    out = np.flatnonzero(inside)
    for b0 in range(0, q.shape[0], 256):
        qb = q[b0:b0 + 256]
        du_ = qb[:, None, 0] - cen[None, :, 0]
        dv_ = qb[:, None, 1] - cen[None, :, 1]
        s = imq_scaled_inverse(du_ * du_ + dv_ * dv_, ce)
        s3 = s**3
        o = out[b0:b0 + 256]
        val[:, o] = (ce * s @ alpha + beta[0] + qb[:, :1] * beta[1] + qb[:, 1:] * beta[2]).T
        gu[:, o] = (-ce * (s3 * du_) @ alpha + beta[1]).T
        gv[:, o] = (-ce * (s3 * dv_) @ alpha + beta[2]).T
    edge = interp.edge_from_location(p[:, 0], p[:, 1], loc)
    if single:
        val, gu, gv = val[0], gu[0], gv[0]
    return Evaluation(val, gu, gv, edge)
