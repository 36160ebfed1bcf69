"""The inverse-multiquadric (IMQ) kernel ``m(r) = c / sqrt(c^2 + r^2)`` and its derivatives.

One kernel serves the image interpolant (:mod:`irdic.image_rbf`, pixels),
the surface (:mod:`irdic.surface`, surface parameters) and time
(:mod:`irdic.numerics.temporal`). ``r`` is a distance divided by the
normalisation ``R0``; ``c`` is the dimensionless shape parameter.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.distance import cdist

__all__ = ["imq", "imq_dr", "imq_matrix", "imq_scaled_inverse", "imq_planar", "imq_planar_hessian", "REGRESSION_RATIO", "regression_R0"]

# Kernel width of a regression relative to its centre spacing, c R0_eff / H.
# Flat kernels approximate smooth fields well with few centres: tangents of a
# curved test field (R = 15 mm, 0.7 mm grid, 0.005 mm noise) erred by 3.8e-3
# at a ratio of 2, 1.1e-3 at 4, 4.4e-4 at 6, 2.4e-4 at 8 (GCV-chosen spacing;
# interpolation: 8.4e-3); temporal rates were insensitive. 6 keeps the
# least-squares design comfortably conditioned.
REGRESSION_RATIO = 6.0


def imq(r, c=2.0):
    """Inverse multiquadric ``m(r) = c / sqrt(c^2 + r^2)``.

    Parameters
    ----------
    r : array_like
        Normalised distance ``distance / R0`` (dimensionless; may be signed).
    c : float
        Shape parameter (dimensionless), c > 0.

    Returns
    -------
    ndarray
        ``m(r)``, same shape as ``r``; ``m(0) = 1``.
    """
    r = np.asarray(r, dtype=float)
    return c / np.sqrt(c * c + r * r)


def imq_dr(r, c=2.0):
    """Derivative ``dm/dr = -c r / (c^2 + r^2)^(3/2)`` of :func:`imq`.

    With a signed ``r = (t - t_j) / R0`` this is ``R0 * dm/dt``.

    Parameters
    ----------
    r : array_like
        Normalised (signed) distance.
    c : float
        Shape parameter, c > 0.

    Returns
    -------
    ndarray
        Same shape as ``r``.
    """
    r = np.asarray(r, dtype=float)
    q = c * c + r * r
    return -c * r / (q * np.sqrt(q))


def imq_matrix(xa, xb, ce, out=None):
    """Kernel matrix ``ce / sqrt(ce^2 + |xa_i - xb_j|^2)`` of 2-D points.

    Parameters
    ----------
    xa, xb : ndarray, shape (n, 2), (m, 2)
        Points in units of length (px for the image, mm for the surface).
    ce : float
        ``c * R0`` in the same unit: only the product matters for the value.
    out : ndarray of float64, shape (n, m), optional
        Where to write the matrix (C-contiguous).

    Returns
    -------
    ndarray, shape (n, m)

    Notes
    -----
    The squared distances come from one pass of ``cdist`` and the rest runs in
    place: a surface tile's matrix (thousands of points) built from the
    broadcast offsets ``dx``, ``dy`` took five arrays of its size and about
    14 times as long, mostly page faults on the fresh arrays.
    """
    m = cdist(xa, xb, "sqeuclidean", out=out)
    m += ce * ce
    np.sqrt(m, out=m)
    np.divide(ce, m, out=m)
    return m


def imq_planar(dx, dy, c, R0, derivatives):
    """IMQ value and its gradient for planar offsets ``(dx, dy) = xi - Psi_k``.

    Parameters
    ----------
    dx, dy : ndarray
        Offsets (mm), any broadcastable shapes.
    c : float
        Shape parameter.
    R0 : float
        Distance normalisation (mm).
    derivatives : bool
        Also return the derivatives.

    Returns
    -------
    m, m1, m2 : ndarray
        ``m``, ``dm/dxi1``, ``dm/dxi2`` (1/mm); the latter two None unless
        ``derivatives``.

    Notes
    -----
    ``r = |xi - Psi_k| / R0``, ``m = c / sqrt(c^2 + r^2)``,
    ``dm/dxi_a = -c (dx_a / R0^2) / (c^2 + r^2)^(3/2)``.
    """
    # In place on two work arrays: the surface stages call this on N x N
    # blocks (13k points: 1.3 GB per array), where every temporary costs a
    # fresh allocation and its page faults. Same operations in the same order
    # as ``c / sqrt(c^2 + (dx^2 + dy^2) / R0^2)``, so bitwise the same numbers.
    dx = np.asarray(dx)
    dy = np.asarray(dy)
    shape = np.broadcast_shapes(dx.shape, dy.shape)
    dtype = np.result_type(dx, dy, 1.0)
    q = np.empty(shape, dtype)
    t = np.empty(shape, dtype)
    np.multiply(dx, dx, out=q)
    np.multiply(dy, dy, out=t)
    q += t
    q /= R0 * R0
    q += c * c
    np.sqrt(q, out=q)
    np.divide(1.0, q, out=q)  # s = 1 / sqrt(c^2 + r^2)
    m = np.multiply(c, q)
    if not derivatives:
        return m, None, None
    np.multiply(m, q, out=t)
    t *= q
    np.negative(t, out=t)
    t /= R0 * R0  # g = -c s^3 / R0^2
    m1 = np.multiply(t, dx)
    np.multiply(t, dy, out=q)
    return m, m1, q


def imq_planar_hessian(dx, dy, c, R0):
    """Second derivatives of the IMQ kernel for planar offsets ``(dx, dy) = xi - Psi_k``.

    Parameters
    ----------
    dx, dy : ndarray
        Offsets (mm), broadcastable shapes.
    c : float
        Shape parameter.
    R0 : float
        Distance normalisation (mm).

    Returns
    -------
    m11, m12, m22 : ndarray
        ``d²m/dxi1²``, ``d²m/dxi1 dxi2``, ``d²m/dxi2²`` (1/mm²).

    Notes
    -----
    With ``s = (c² + r²)^(-1/2)``, ``r² = (dx² + dy²) / R0²``:
    ``d²m/dxi_a dxi_b = -c s³ δ_ab / R0² + 3 c s⁵ dx_a dx_b / R0⁴``.
    """
    dx, dy = np.asarray(dx, dtype=float), np.asarray(dy, dtype=float)
    s2 = 1.0 / (c * c + (dx * dx + dy * dy) / (R0 * R0))
    s3 = c * s2 * np.sqrt(s2) / (R0 * R0)
    s5 = 3.0 * s3 * s2 / (R0 * R0)
    return s5 * dx * dx - s3, s5 * dx * dy, s5 * dy * dy - s3


def regression_R0(c, H):
    """Distance normalisation of regression centres spaced ``H``: ``c R0_eff = 6 H``."""
    return REGRESSION_RATIO * H / c


def imq_scaled_inverse(d2, ce, out=None):
    """``1 / sqrt(ce^2 + d2)``: the IMQ kernel divided by ``ce``, from squared distances.

    The form the image interpolant evaluates in its hot loops: the kernel is
    ``ce * s`` and its gradient ``-ce * s**3 * (x - x_j)``.

    Parameters
    ----------
    d2 : ndarray
        Squared distances (px^2); overwritten when ``out is d2``.
    ce : float
        ``c * R0`` (px).
    out : ndarray, optional
        Where to write the result (may be ``d2`` itself, to save memory).

    Returns
    -------
    ndarray
        Same shape as ``d2`` (1/px).
    """
    if out is None:
        out = np.array(d2, dtype=float, copy=True)
    elif out is not d2:
        np.copyto(out, d2)
    out += ce * ce
    np.sqrt(out, out=out)
    np.divide(1.0, out, out=out)
    return out
