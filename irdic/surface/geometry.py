"""Geometry of the continuous surface: metric, dual vectors, normal; distance to the cloud's edge."""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ConfigError, GeometryError
from ..numerics.threads import parallel_map, worker_slices
from ..validation import float_array, positive, psi_array
from .parametrisation import short_triangles

__all__ = ["MIN_SINE", "Geometry", "surface_geometry", "edge_distance"]

log = logging.getLogger(__name__)

# Tangent pairs whose sine of the enclosed angle is below this are degenerate.
MIN_SINE = 1e-6


def edge_distance(psi, *, max_edge_factor=3.0):
    """Distance (mm, in ``Psi``) from each point to the edge of the point cloud.

    The cloud's outline is the boundary of its Delaunay triangulation without
    the triangles with an edge longer than ``max_edge_factor`` times the median
    point spacing (so concave outlines and holes larger than a few spacings are
    edges too).

    Parameters
    ----------
    psi : array_like, shape (N, 2)
        Surface parameters (mm); NaN rows give NaN.
    max_edge_factor : float
        See above; > 1.

    Returns
    -------
    ndarray, shape (N,)
        0 on the outline, positive inside (accurate to 1/20 of the spacing).
    """
    p = psi_array(psi, "psi")
    f = positive(max_edge_factor, "max_edge_factor")
    if f <= 1:
        raise ConfigError(f"max_edge_factor must be > 1, got {max_edge_factor!r}")
    ok = np.isfinite(p).all(axis=1)
    out = np.full(p.shape[0], np.nan)
    pv = p[ok]
    if pv.shape[0] < 3:
        out[ok] = 0.0
        return out
    found = short_triangles(pv, f)
    if found is None:
        out[ok] = 0.0  # all on a line: every point is on the edge
        return out
    s, h = found
    if s.shape[0] == 0:
        out[ok] = 0.0
        return out
    edges = np.sort(np.concatenate([s[:, [0, 1]], s[:, [1, 2]], s[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    bnd = uniq[count == 1]
    a, b = pv[bnd[:, 0]], pv[bnd[:, 1]]
    step = h / 10.0
    n_sub = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(int))
    samples = [a, b]
    for j in range(1, int(n_sub.max())):
        sel = n_sub > j
        frac = (j / n_sub[sel])[:, None]
        samples.append(a[sel] + frac * (b[sel] - a[sel]))
    tree = cKDTree(np.concatenate(samples))
    out[ok] = tree.query(pv)[0]
    out[ok & (out < step / 2)] = 0.0
    return out



class Geometry(NamedTuple):
    """Result of :func:`surface_geometry`; ``...`` the leading shape of the tangents."""

    metric: np.ndarray
    """(..., 2, 2) covariant metric ``a_ab = a_a . a_b`` (dimensionless)."""
    inverse_metric: np.ndarray
    """(..., 2, 2) contravariant metric ``a^ab``."""
    dual: np.ndarray
    """(..., 2, 3) dual vectors ``a^a = a^ab a_b`` (``a^a . a_b = delta``)."""
    normal: np.ndarray
    """(..., 3) unit normal ``a_1 x a_2 / |a_1 x a_2|``."""
    area_ratio: np.ndarray
    """(...) ``|a_1 x a_2|``: area per unit Psi area."""
    degenerate: np.ndarray
    """(...) bool: finite tangents that are (nearly) parallel or zero."""


def surface_geometry(tangents, *, min_sine=MIN_SINE):
    """Metric, dual vectors and unit normal from the tangent vectors.

    Parameters
    ----------
    tangents : array_like, shape (..., 2, 3)
        ``a_1``, ``a_2``.
    min_sine : float
        Tangent pairs whose enclosed angle has a sine below this (or with a zero
        vector) are degenerate: NaN results, counted in the log.

    Returns
    -------
    Geometry

    Raises
    ------
    GeometryError
        Every finite tangent pair is degenerate.
    """
    a = float_array(tangents, "tangents")
    if a.ndim < 2 or a.shape[-2:] != (2, 3):
        raise ConfigError(f"tangents must have shape (..., 2, 3), got {a.shape}")
    lead = a.shape[:-2]
    metric, inv, dual = (np.empty(lead + (2, n)) for n in (2, 2, 3))
    normal, area = np.empty(lead + (3,)), np.empty(lead)
    finite, degenerate = np.empty(lead, bool), np.empty(lead, bool)
    outs = (metric, inv, dual, normal, area, finite, degenerate)

    def block(sl):
        for out, part in zip(outs, _geometry(a[sl], min_sine)):
            out[sl] = part

    # pointwise: blocks of the leading axis (times) on the stage's threads give the same numbers
    parallel_map(block, worker_slices(lead[0]) if lead else [Ellipsis])
    nd = int(degenerate.sum())
    if nd:
        if nd == int(finite.sum()):
            raise GeometryError(
                f"all {nd} tangent pairs are degenerate (parallel or zero): the surface has no area; "
                "duplicate or collinear points?"
            )
        log.warning("%d of %d tangent pairs are degenerate (sine of their angle < %g): NaN there",
                    nd, int(finite.sum()), min_sine)
    return Geometry(metric, inv, dual, normal, area, degenerate)


def _geometry(a, min_sine):
    """:func:`surface_geometry`'s arrays of tangents ``a`` (..., 2, 3): metric, its inverse, dual vectors, unit
    normal, area ratio (NaN where degenerate or not finite), whether finite and whether degenerate."""
    a1, a2 = a[..., 0, :], a[..., 1, :]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        g11 = np.einsum("...i,...i->...", a1, a1)
        g12 = np.einsum("...i,...i->...", a1, a2)
        g22 = np.einsum("...i,...i->...", a2, a2)
        cross = np.cross(a1, a2)
        area = np.sqrt(np.einsum("...i,...i->...", cross, cross))
        finite = np.isfinite(area) & np.isfinite(g11) & np.isfinite(g22)
        degenerate = finite & ~(area > min_sine * np.sqrt(g11 * g22))
        bad = ~finite | degenerate
        det = np.where(bad, np.nan, g11 * g22 - g12 * g12)
        i11, i12, i22 = g22 / det, -g12 / det, g11 / det
        metric = np.stack([np.stack([g11, g12], -1), np.stack([g12, g22], -1)], -2)
        inv = np.stack([np.stack([i11, i12], -1), np.stack([i12, i22], -1)], -2)
        # a^a = a^ab a_b, written out (a batched 2 x 2 einsum is slow on 5e6 points)
        dual = np.stack([i11[..., None] * a1 + i12[..., None] * a2, i12[..., None] * a1 + i22[..., None] * a2], -2)
        normal = cross / np.where(bad, np.nan, area)[..., None]
    return metric, inv, dual, normal, np.where(bad, np.nan, area), finite, degenerate
