"""In-plane temperature gradient and material temperature rate on a curved surface.

At a material point (fixed surface parameters ``Psi``) and time ``t``:

* the pixel gradient of the IR interpolant ``g_pix = dTheta/d(u, v)`` (K/px),
* the local rate at the fixed pixel ``dTheta/dt`` (K/s),
* the projection Jacobian ``J = d(u, v)/dx`` (2 x 3, px/mm; pinhole:
  ``J = (M[:2, :3] - uv (x) M[2, :3]) / (M[2, :3] . x + M[2, 3])``, eq:derivProjection),
* the surface tangents ``a_alpha`` and velocity ``dx/dt`` at fixed ``Psi``,

give the in-plane gradient in the current configuration (eq:tempGrad,
eq:dThetadPsi)

    grad Theta = (dTheta/dPsi^alpha) a^alpha,   dTheta/dPsi^alpha = g_pix^T J a_alpha,

which equals ``(I - n (x) n) J^T g_pix`` (the tangential part of the 3-D
gradient ``J^T g_pix``), and the material rate (eq:tempVeloc)

    Theta_dot = dTheta/dt + (J^T g_pix) . dx/dt     (local + convective).

Alternatively the material rate is the time derivative of a point's
temperature series at fixed ``Psi`` (:func:`rate_from_series`), which also
allows smoothing noisy IR data in time.

All functions broadcast over leading dimensions (time, point, ...); NaN in
gives NaN out. Pure array math: no files, no camera model.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from .errors import ConfigError
from .numerics.series import smooth_series
from .validation import float_array, shaped_array

__all__ = [
    "spatial_gradient",
    "parameter_derivatives",
    "surface_gradient",
    "projected_gradient",
    "Rate",
    "material_rate",
    "rate_from_series",
]

log = logging.getLogger(__name__)


def _dot(x, y):
    """Dot product over the last axis (einsum on equal shapes: fast)."""
    x, y = np.broadcast_arrays(x, y)
    return np.einsum("...i,...i->...", x, y)


def _lead(*pairs):
    """Check that the leading shapes broadcast; name the culprits otherwise."""
    shapes = [(n, a.shape[: a.ndim - k]) for n, a, k in pairs]
    try:
        return np.broadcast_shapes(*(s for _, s in shapes))
    except ValueError:
        desc = ", ".join(f"{n} {s}" for n, s in shapes)
        raise ConfigError(f"leading (time, point) shapes do not broadcast: {desc}") from None


def spatial_gradient(g_pix, J):
    """3-D gradient ``J^T g_pix`` (K/mm) of the image temperature pulled back to space.

    Parameters
    ----------
    g_pix : array_like, shape (..., 2)
        ``(dTheta/du, dTheta/dv)`` in K/px.
    J : array_like, shape (..., 2, 3)
        Projection Jacobian ``d(u, v)/dx`` in px/mm.

    Returns
    -------
    ndarray, shape (..., 3)
        Its component along the viewing ray is meaningless (the image does not
        see it); only the tangential part, :func:`projected_gradient`, is the
        surface gradient.
    """
    g = shaped_array(g_pix, "g_pix", (2,))
    Jm = shaped_array(J, "J", (2, 3))
    _lead(("g_pix", g, 1), ("J", Jm, 2))
    return g[..., 0, None] * Jm[..., 0, :] + g[..., 1, None] * Jm[..., 1, :]


def parameter_derivatives(g_pix, J, tangents):
    """``dTheta/dPsi^alpha = g_pix^T J a_alpha`` (K/mm), shape (..., 2)."""
    t = shaped_array(tangents, "tangents", (2, 3))
    g3 = spatial_gradient(g_pix, J)
    _lead(("g_pix/J", g3, 1), ("tangents", t, 2))
    return np.stack([_dot(g3, t[..., 0, :]), _dot(g3, t[..., 1, :])], -1)


def surface_gradient(g_pix, J, tangents):
    """In-plane temperature gradient ``grad Theta = (dTheta/dPsi^alpha) a^alpha`` (K/mm).

    Parameters
    ----------
    g_pix : array_like, shape (..., 2)
        Pixel gradient of the IR interpolant (K/px).
    J : array_like, shape (..., 2, 3)
        Projection Jacobian (px/mm).
    tangents : array_like, shape (..., 2, 3)
        Current tangents ``a_alpha``.

    Returns
    -------
    ndarray, shape (..., 3)
        Tangent to the current surface; NaN where any input is NaN or the
        tangents are degenerate (parallel or zero).
    """
    t = shaped_array(tangents, "tangents", (2, 3))
    g3 = spatial_gradient(g_pix, J)
    shape = _lead(("g_pix/J", g3, 1), ("tangents", t, 2))
    a1, a2 = t[..., 0, :], t[..., 1, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        # dTheta/dPsi^alpha = g . a_alpha, then grad = a^ab dTheta/dPsi^b a_a (written out: fast on 5e6 points)
        d1, d2 = _dot(g3, a1), _dot(g3, a2)
        g11, g12, g22 = _dot(a1, a1), _dot(a1, a2), _dot(a2, a2)
        det = g11 * g22 - g12 * g12
        det = np.where(det > 1e-12 * g11 * g22, det, np.nan)
        c1 = (g22 * d1 - g12 * d2) / det
        c2 = (g11 * d2 - g12 * d1) / det
        res = c1[..., None] * a1 + c2[..., None] * a2
    return res if res.shape == shape + (3,) else np.broadcast_to(res, shape + (3,)).copy()


def projected_gradient(g_pix, J, normal):
    """``(I - n (x) n) J^T g_pix`` (K/mm): the same in-plane gradient from the unit normal.

    Parameters
    ----------
    g_pix : array_like, shape (..., 2)
    J : array_like, shape (..., 2, 3)
    normal : array_like, shape (..., 3)
        Unit normal of the current surface.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    n = shaped_array(normal, "normal", (3,))
    g3 = spatial_gradient(g_pix, J)
    _lead(("g_pix/J", g3, 1), ("normal", n, 1))
    return g3 - _dot(g3, n)[..., None] * n


class Rate(NamedTuple):
    """Material temperature rate and its parts (K/s), all of the broadcast leading shape."""

    rate: np.ndarray
    """``Theta_dot = local + convective``."""
    local: np.ndarray
    """``dTheta/dt`` at the fixed pixel."""
    convective: np.ndarray
    """``(J^T g_pix) . dx/dt``: the change seen because the point moves across the image."""


def material_rate(dtheta_dt, g_pix, J, velocity):
    """Material temperature rate ``Theta_dot = dTheta/dt + (J^T g_pix) . dx/dt``.

    Parameters
    ----------
    dtheta_dt : array_like, shape (...)
        Local rate of the IR interpolant at the point's pixel position (K/s).
    g_pix : array_like, shape (..., 2)
        Pixel gradient (K/px).
    J : array_like, shape (..., 2, 3)
        Projection Jacobian (px/mm).
    velocity : array_like, shape (..., 3)
        ``dx/dt`` at fixed ``Psi`` (mm/s).

    Returns
    -------
    Rate
    """
    local = float_array(dtheta_dt, "dtheta_dt")
    v = shaped_array(velocity, "velocity", (3,))
    g3 = spatial_gradient(g_pix, J)
    shape = _lead(("dtheta_dt", local, 0), ("g_pix/J", g3, 1), ("velocity", v, 1))
    conv = _dot(g3, v)
    return Rate(np.broadcast_to(local + conv, shape).copy(), np.broadcast_to(local, shape).copy(),
                np.broadcast_to(conv, shape).copy())


def rate_from_series(theta, times, t_eval=None, *, smoothing=None, c=1.0, R0=1.0):
    """Material rate as the time derivative of point temperature series at fixed ``Psi``.

    ``Theta_k(t) = Theta(x(Psi_k, t), t)``, so ``d Theta_k / dt`` is the material
    rate (eq:tempVeloc) without pixel derivatives or velocities. With
    ``smoothing="gcv"`` the series are smoothed by temporal IMQ regression first
    (see :func:`irdic.numerics.series.smooth_series`): the way to a usable rate from
    noisy IR data.

    Parameters
    ----------
    theta : array_like, shape (M, ...)
        Point temperatures at ``times`` (degC); NaN entries are filled from
        the point's own other times.
    times : array_like, shape (M,)
        Times (s), strictly increasing.
    t_eval : array_like, shape (T,), optional
        Evaluation times; default ``times``.
    smoothing : None, float >= 1 or "gcv"
        None: interpolation (the paper's temporal interpolant).
    c, R0 : float
        Temporal kernel (the paper: 1, 1 s).

    Returns
    -------
    rate : ndarray, shape (T, ...)
        K/s.
    value : ndarray, shape (T, ...)
        The (smoothed) temperatures at ``t_eval``.
    """
    fit = smooth_series(theta, times, t_eval, smoothing=smoothing, c=c, R0=R0)
    return fit.rate, fit.value
