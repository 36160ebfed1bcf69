"""Continuous surface ``x(Psi, t)`` from DIC stages: parameters, interpolation, tangents.

The paper's surface (eq:x_RBFInterp) is a tensor product. In the surface
parameters ``Psi`` an inverse multiquadric ``m(r) = c / sqrt(c^2 + r^2)``,
``r = |Psi - Psi_k| / R0`` (R0 = 1 mm), on every DIC point plus the monomials
{1, Psi1, Psi2}; in time the same kernel on every stage time (R0 = 1 s) plus
{1, t}. The ``Psi_k`` are fixed (Lagrangian): one spatial and one temporal
operator serve all stages and all three components. With the data ``X``
(points x stages) the surface at the points and evaluation times is
``S X W^T``, its time derivative ``S X W'^T`` and its tangents
``D_alpha X W^T``, where ``W``, ``W'`` are the temporal weights (value, d/dt)
and ``S``, ``D_alpha`` the spatial ones (value, d/dPsi^alpha).

Public API
----------
* :func:`surface_parameters`: ``Psi`` from the reference points (best-fit plane
  or cylinder unwrapping, ``"auto"`` picks the one that does not fold).
* :class:`SpatialInterpolant`: the spatial operator (global dense, local tiles
  or regression with fewer centres), missing-point fill, values and
  ``d/dPsi^alpha`` at the points or anywhere.
* :class:`TemporalSmoother`: the temporal operator (interpolation or regression),
  weights for values and ``d/dt`` at any times; :func:`smooth_series` applies it
  to any per-point time series (point temperatures: their derivative at fixed
  ``Psi`` is the material rate).
* :func:`gcv_spatial`, :func:`gcv_temporal`: choice of the smoothing by
  generalised cross-validation.
* :func:`fit_surface`: the whole stage: ``x``, tangents ``a_alpha``, ``dx/dt``,
  reference tangents ``A_alpha``, fill flags and edge distance.
* :func:`surface_geometry`: metric, dual vectors, unit normal.
* :func:`edge_distance`: distance (mm, in ``Psi``) of points to the edge of the cloud.

Units: mm, s. Arrays of points are ``(N, 2)`` (``Psi``) or ``(N, 3)`` (``x``);
stage data ``(M, N, 3)`` (stage, point, component).

Notes
-----
**Spatial solver** (``solver=``). ``"global"``: the paper's interpolant, one
dense Cholesky factorisation of the N x N kernel matrix (plus a 3 x 3 Schur
complement for the monomials), coefficients for all columns, derivatives from
the kernel rows in blocks. ``"local"``: overlapping tiles, a square core of
points plus every point within ``halo`` of the core; one Cholesky per tile
gives the derivative weights of the core points, applied to all columns by
one matrix product per tile (single-threaded BLAS on a thread pool: the
tiles are many small factorisations). The global interpolant's weights decay
exponentially (about one decade per 1.4 c R0) down to an algebraic tail of
relative size ``~exp(-2 pi c R0 / h)`` (h = point spacing), and for points
near the cloud's edge they keep a tail of ~1e-3 all along the edge. So the
tiles (default ``halo = max(9 c R0, 6 h)``) reproduce the global tangents to
~1e-5 of the data's deviation from a plane 8 mm or more inside (h = 0.6 mm),
but nearer the edge they differ from them by about as much as the global
interpolant differs from the truth, and are the more accurate of the two:
on a curved test field (R = 15 mm, h = 0.6 mm) the largest tangent error was
1.4e-2 (tiles) against 7.0e-2 (global) 1.5-3 mm from the edge, 1.3e-3
against 5.3e-3 at 3-5 mm, 4.7e-6 against 1.1e-5 beyond 8 mm; with h = 1 mm
and c = 0.95 both are limited by the tail (~3e-4 in the interior).
``"auto"`` estimates the run time of both for the data at hand and takes the
tiles when they are at least twice as fast (10,000 points on a 0.6 mm grid
of the half-shell: tiles; 10,000 points on a narrow 25 x 40 mm tube patch,
where every tile would span the patch: global). ``info["solver"]`` says which.

**Missing points.** DIC points missing in some stages (NaN) are filled before
the tensor product is built, and flagged (``filled``): per stage, from that
stage's valid points. With ``G`` the map from data to RBF coefficients, the
values ``f_Q`` at the missing points ``Q`` with ``G_QQ f_Q = -G_QV f_V`` give
coefficients ``alpha_Q = 0``, so the all-points interpolant equals the
valid-points interpolant: the stage's surface stays smooth through the gap and
the neighbours' tangents hardly notice it. The rows of ``G`` come from local
tiles (they decay like the cardinal functions), so a stage's fill is one small
``|Q| x |Q|`` solve; 8 mm or more inside the cloud the fill matches the global
valid-points interpolant to ~1e-4 of the data's variation (h = 0.6 mm), and
near the edge it is closer to the truth than that interpolant (as above).
The velocities ``dx/dt`` use a second fill (``fill="both"``, the default):
short gaps filled from the point's own time series, so that a filled value
does not put a bump into its point's series (see :func:`fit_surface`). Points
missing in the reference stage take their parameters ``Psi`` from their first
valid stage (a small approximation: the point has moved by then). Stages with
fewer than ``min_stage_fraction`` valid points are left out of the temporal fit.

**Smoothing** (beyond the paper; its outlook for noisy data). Regression with
fewer centres: centres on a subset of the points (time: of the stage times)
spaced ``k`` times the median spacing, a kernel six centre spacings wide
(``c R0_eff = 6 H``: flat kernels approximate smooth fields well with few
centres), least squares over all data (QR; missing points are filled first as
above). The hat matrix has trace ``p`` = number of parameters, so generalised
cross-validation, ``GCV(k) = n RSS / (n - p)^2`` pooled over all series, is
exact and cheap; ``smoothing="gcv"`` picks ``k`` by it. Measured: the rate of
a 2 Hz, 250 s heating curve with 0.05 K noise errs by 0.14 K/s (RMS)
interpolated and 1.1e-3 K/s smoothed (GCV: centres every 48 stages); the
largest principal strain of a tube with 0.005 mm coordinate noise on a 0.8 mm
grid by 1.1e-2 interpolated and 7.9e-4 smoothed (centres every 5 points). A
ridge ``(A + lam I)`` was measured and rejected: the IMQ spectrum grows only
logarithmically at low frequencies, so any ``lam`` that damps the noise also
shrinks the signal (GCV then chose ``lam`` too small: rate error reduced only
1.3x on the heating curve).
"""

from __future__ import annotations

import contextlib
import logging
import math
import time as _time
import warnings
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np
import scipy.linalg
from scipy import sparse
from scipy.spatial import Delaunay, QhullError, cKDTree

from ._checks import float_array as _float_array
from ._checks import increasing_times as _increasing_times
from ._checks import positive as _positive
from .errors import ConfigError, DataError, GeometryError, IrdicWarning
from .threads import blas_threads, thread_budget

__all__ = [
    "surface_parameters",
    "SpatialInterpolant",
    "TemporalSmoother",
    "SeriesFit",
    "smooth_series",
    "gcv_spatial",
    "gcv_temporal",
    "SurfaceFields",
    "fit_surface",
    "Geometry",
    "surface_geometry",
    "edge_distance",
]

log = logging.getLogger(__name__)

SOLVERS = ("auto", "global", "local")
PARAMETRISATIONS = ("auto", "plane", "cylinder")

# Minimum number of points: the linear monomials need 3 points off a line, and a
# curved patch has no curvature information below the 6 coefficients of a quadric.
MIN_POINTS = 6
# Tangent pairs whose sine of the enclosed angle is below this are degenerate.
MIN_SINE = 1e-6
# A local normal more than this far (deg) from the projection direction makes a
# plane (or cylinder) projection fold or compress the point spacing > 2.9x.
MAX_NORMAL_ANGLE = 70.0
# Temporal evaluation times closer than this (units of R0) to a stage time are
# taken as that stage time.
_TIME_SNAP = 1e-9
# Rough sustained flop rates of the 2-core reference VM (GEMM vs factorisation
# and triangular solves), only used to compare the two spatial solvers.
_GEMM_RATE = 25e9
_FACTOR_RATE = 12e9
# Kernel rows built per block in the global evaluation (rows x N x 8 B ~ 64 MB).
_BLOCK_BYTES = 64 * 2**20


# --------------------------------------------------------------------------
# argument checks
# --------------------------------------------------------------------------


def _choice(name, value, options):
    if not isinstance(value, str) or value not in options:
        raise ConfigError(f"{name} must be one of {', '.join(map(repr, options))}, got {value!r}")
    return value


def _smoothing(name, value, allow_gcv=True):
    """None/0/1 -> 1.0 (interpolation); a number k >= 1; or "gcv"."""
    if value is None:
        return 1.0
    if isinstance(value, str):
        if allow_gcv and value == "gcv":
            return "gcv"
        raise ConfigError(
            f"{name} must be None (interpolation), a centre spacing factor >= 1 or "
            f"{'gcv' if allow_gcv else 'a number'}, got {value!r}"
        )
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be a number >= 1 or 'gcv', got {value!r}")
    try:
        k = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number >= 1 or 'gcv', got {value!r}") from None
    if k == 0:
        return 1.0
    if not (math.isfinite(k) and k >= 1):
        raise ConfigError(
            f"{name} is the centre spacing of the regression in units of the data spacing "
            f"and must be >= 1 (1 = interpolation), got {value!r}"
        )
    return k


def _psi_array(name, psi):
    p = _float_array(name, psi)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ConfigError(f"{name} must have shape (N, 2) (Psi1, Psi2 in mm), got {p.shape}")
    return p


def _check_times(times, name="times"):
    return _increasing_times(name, times, "stages")


# --------------------------------------------------------------------------
# kernel
# --------------------------------------------------------------------------


def _kernels(dx, dy, c, R0, derivatives):
    """IMQ value and d/dPsi^alpha for offsets ``dx = xi - Psi_k`` (mm).

    Returns ``m``, ``dm/dxi1``, ``dm/dxi2`` (the latter None unless asked), with
    ``r = |xi - Psi_k| / R0``, ``m = c / sqrt(c^2 + r^2)``, ``dm/dxi_a = -c
    (dx_a / R0^2) / (c^2 + r^2)^(3/2)``.
    """
    q = c * c + (dx * dx + dy * dy) / (R0 * R0)
    s = 1.0 / np.sqrt(q)
    m = c * s
    if not derivatives:
        return m, None, None
    g = -(m * s * s) / (R0 * R0)
    return m, g * dx, g * dy


def _median_spacing(psi):
    d = cKDTree(psi).query(psi, k=2)[0][:, 1]
    return float(np.median(d))


# --------------------------------------------------------------------------
# surface parameters
# --------------------------------------------------------------------------


def _first_valid(x):
    """Reference coordinates: stage 0, or each point's first valid stage."""
    valid = np.isfinite(x).all(axis=-1)  # (M, N)
    first = np.argmax(valid, axis=0)
    has = valid.any(axis=0)
    ref = x[first, np.arange(x.shape[1])]
    ref[~has] = np.nan
    later = has & (first > 0)
    return ref, first, has, later


def _orient(v, hint):
    """Sign of ``v`` such that ``v . hint >= 0`` (hint or the largest component)."""
    if hint is not None and abs(v @ hint) > 1e-3 * np.linalg.norm(hint):
        return v if v @ hint > 0 else -v
    return v if v[np.argmax(np.abs(v))] > 0 else -v


def _local_normals(x, k=12):
    """Unit normals by PCA of the k nearest neighbours (orientation arbitrary)."""
    k = min(k, x.shape[0])
    _, idx = cKDTree(x).query(x, k=k)
    nb = x[idx] - x[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    return np.linalg.eigh(cov)[1][:, :, 0]


def _angle_stats(normals, ref_dirs):
    cosang = np.abs(np.einsum("ni,ni->n", normals, ref_dirs))
    ang = np.degrees(np.arccos(np.clip(cosang, 0.0, 1.0)))
    return float(np.percentile(ang, 99.0)), float(ang.max())


def _flipped_triangles(psi, x, ref_normal_fn, max_edge_factor=3.0):
    """Delaunay triangles in Psi whose 3-D orientation disagrees with the reference normal."""
    try:
        tri = Delaunay(psi)
    except QhullError:
        return -1, 0
    h = _median_spacing(psi)
    s = tri.simplices
    p = psi[s]
    e = np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max(axis=1)
    s = s[e <= max_edge_factor * h]
    if s.shape[0] == 0:
        return 0, 0
    p = psi[s]
    cross2 = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 1, 1] - p[:, 0, 1]) * (
        p[:, 2, 0] - p[:, 0, 0]
    )
    X = x[s]
    n3 = np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
    ref = ref_normal_fn(X.mean(axis=1))
    orient = np.sign(cross2) * np.sign(np.einsum("ni,ni->n", n3, ref))
    return int(np.count_nonzero(orient < 0)), int(s.shape[0])


def _plane(xv, normal_hint):
    o = xv.mean(axis=0)
    _, sv, vt = np.linalg.svd(xv - o, full_matrices=False)
    n = _orient(vt[2], normal_hint if normal_hint is not None else np.array([0.0, 0.0, 1.0]))
    # Psi1 along the DIC x axis projected into the plane, for readable parameters.
    e1 = np.array([1.0, 0.0, 0.0]) - n[0] * n
    if np.linalg.norm(e1) < 0.1:
        e1 = vt[0] - (vt[0] @ n) * n
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    rms = float(np.sqrt(np.mean(((xv - o) @ n) ** 2)))
    return o, np.stack([e1, e2, n]), rms, sv


def _fit_cylinder(xv, normals):
    """Least-squares cylinder: axis point p0, unit direction d, radius R, rms residual."""
    from scipy.optimize import least_squares

    o = xv.mean(axis=0)
    d0 = np.linalg.eigh(normals.T @ normals)[1][:, 0]
    u = np.cross(d0, [1.0, 0.0, 0.0])
    if np.linalg.norm(u) < 0.1:
        u = np.cross(d0, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(d0, u)
    q = np.c_[(xv - o) @ u, (xv - o) @ w]
    # Kasa algebraic circle fit as the start
    Amat = np.c_[2 * q, np.ones(len(q))]
    sol, *_ = np.linalg.lstsq(Amat, (q**2).sum(axis=1), rcond=None)
    cu, cw = sol[:2]
    R_start = math.sqrt(max(sol[2] + cu * cu + cw * cw, 1e-12))

    def resid(p):
        d = d0 + p[0] * u + p[1] * w
        d = d / np.linalg.norm(d)
        p0 = o + p[2] * u + p[3] * w
        r = xv - p0
        r = r - np.outer(r @ d, d)
        return np.linalg.norm(r, axis=1) - p[4]

    res = least_squares(resid, [0.0, 0.0, cu, cw, R_start], method="lm", x_scale="jac")
    p = res.x
    d = d0 + p[0] * u + p[1] * w
    d /= np.linalg.norm(d)
    p0 = o + p[2] * u + p[3] * w
    R = abs(p[4])
    # axis point nearest to the centroid: Psi2 is then centred
    p0 = p0 + ((o - p0) @ d) * d
    rms = float(np.sqrt(np.mean(res.fun**2)))
    return p0, d, R, rms


def _cylinder_psi(x, p0, d, R, e_r0):
    r = x - p0
    z = r @ d
    radial = r - np.outer(z, d)
    e_t0 = np.cross(d, e_r0)
    theta = np.arctan2(radial @ e_t0, radial @ e_r0)
    return theta, z


def surface_parameters(x, method="auto", *, normal_hint=None, max_normal_angle=MAX_NORMAL_ANGLE):
    """Surface parameters ``Psi`` of DIC points from their reference coordinates.

    Parameters
    ----------
    x : array_like, shape (N, 3) or (M, N, 3)
        Reference coordinates (mm), or all stages: then each point's first
        valid stage is its reference (stage 0 for every point found there).
        NaN rows are missing points.
    method : {"auto", "plane", "cylinder"}
        ``"plane"``: projection onto the best-fit plane (the paper; PCA).
        ``"cylinder"``: least-squares cylinder, ``Psi = (R theta, axial)``.
        ``"auto"``: the plane unless it would fold (a local normal more than
        ``max_normal_angle`` from the plane normal, or Delaunay triangles of
        ``Psi`` flipping orientation in 3-D), then the cylinder unless it folds
        too; GeometryError when both do.
    normal_hint : array_like, shape (3,), optional
        Side the plane normal points to (default: +z of the DIC frame, i.e.
        towards the cameras for ARAMIS/VIC coordinates). The cylinder normal
        points away from the axis.
    max_normal_angle : float
        Largest acceptable angle (deg, 99th percentile over the points) between
        local normals and the projection direction.

    Returns
    -------
    psi : ndarray, shape (N, 2)
        ``(Psi1, Psi2)`` in mm; NaN for points without any valid stage.
        Plane: ``Psi = ((x - o).e1, (x - o).e2)`` with ``e1`` the DIC x axis
        projected into the plane and ``n = e1 x e2``. Cylinder: ``Psi1 = R
        theta`` (theta about the axis ``d``, 0 at the middle of the patch, seam
        in the largest angular gap), ``Psi2 = (x - p0).d``; ``a1 x a2`` points
        outward.
    info : dict
        ``method``; plane: ``origin``, ``axes`` (rows e1, e2, n), ``rms``;
        cylinder: ``axis_point``, ``axis_direction``, ``radius``,
        ``theta_direction`` (the radial direction of theta = 0), ``rms``;
        always ``normal_angle_p99_deg``, ``normal_angle_max_deg``,
        ``flipped_triangles``, ``n_points``, ``n_without_data``,
        ``n_reference_from_later_stage``, and ``candidates`` (the
        diagnostics of each parametrisation tried).
    """
    _choice("method", method, PARAMETRISATIONS)
    max_normal_angle = _positive("max_normal_angle", max_normal_angle)
    X = _float_array("x", x)
    if X.ndim == 2:
        X = X[None]
    if X.ndim != 3 or X.shape[-1] != 3:
        raise ConfigError(f"x must have shape (N, 3) or (stages, N, 3), got {np.shape(x)}")
    if np.isinf(X).any():
        m, n, _ = np.argwhere(np.isinf(X))[0]
        raise DataError(f"x: infinite coordinate at stage {m}, point {n}; missing points must be NaN")
    hint = None
    if normal_hint is not None:
        hint = _float_array("normal_hint", normal_hint)
        if hint.shape != (3,) or not np.isfinite(hint).all() or not np.linalg.norm(hint) > 0:
            raise ConfigError(f"normal_hint must be a non-zero 3-vector, got {normal_hint!r}")
    ref, first, has, later = _first_valid(X)
    N = ref.shape[0]
    if later.any():
        log.info(
            "%d point(s) missing in stage 0 take their surface parameters from their first valid stage",
            int(later.sum()),
        )
    if (~has).any():
        log.info("%d point(s) have no valid stage: Psi is NaN for them", int((~has).sum()))
    xv = ref[has]
    if xv.shape[0] < MIN_POINTS:
        raise DataError(
            f"x: {xv.shape[0]} point(s) with valid coordinates; the surface needs at least {MIN_POINTS}"
        )
    extent = float(np.ptp(xv, axis=0).max())
    normals = _local_normals(xv)
    candidates = {}
    order = ["plane", "cylinder"] if method == "auto" else [method]
    chosen = None
    for name in order:
        if name == "plane":
            o, axes, rms, sv = _plane(xv, hint)
            if sv[1] < 1e-6 * sv[0]:
                raise GeometryError(
                    f"the {xv.shape[0]} reference points lie on a line (singular values "
                    f"{sv[0]:.3g}, {sv[1]:.3g} mm): no surface can be parametrised"
                )
            psi_v = (xv - o) @ axes[:2].T
            p99, pmax = _angle_stats(normals, np.broadcast_to(axes[2], normals.shape))
            flipped, ntri = _flipped_triangles(psi_v, xv, lambda c, n=axes[2]: np.broadcast_to(n, c.shape))
            diag = dict(method="plane", origin=o, axes=axes, rms=rms)
        else:
            p0, d, R, rms = _fit_cylinder(xv, normals)
            if not (np.isfinite(R) and R < 100 * extent and rms < 0.05 * R):
                candidates["cylinder"] = dict(
                    method="cylinder", radius=R, rms=rms, ok=False,
                    reason=f"no cylinder fits (radius {R:.4g} mm, rms residual {rms:.3g} mm, extent {extent:.4g} mm)",
                )
                continue
            d = _orient(d, np.array([0.0, 1.0, 0.0]))
            radial = (xv - p0) - np.outer((xv - p0) @ d, d)
            e_r0 = radial.sum(axis=0)
            e_r0 -= (e_r0 @ d) * d
            if np.linalg.norm(e_r0) < 1e-9 * len(xv):
                e_r0 = radial[0]
            e_r0 /= np.linalg.norm(e_r0)
            theta, z = _cylinder_psi(xv, p0, d, R, e_r0)
            # seam in the middle of the largest angular gap
            ts = np.sort(theta)
            gaps = np.diff(np.r_[ts, ts[0] + 2 * np.pi])
            j = int(np.argmax(gaps))
            seam = ts[j] + 0.5 * gaps[j]
            centre = seam + np.pi
            e_r0 = math.cos(centre) * e_r0 + math.sin(centre) * np.cross(d, e_r0)
            theta, z = _cylinder_psi(xv, p0, d, R, e_r0)
            psi_v = np.c_[R * theta, z]
            radial_u = radial / np.linalg.norm(radial, axis=1, keepdims=True)
            p99, pmax = _angle_stats(normals, radial_u)

            def _radial(cpts, p0=p0, d=d):
                r = cpts - p0
                return r - np.outer(r @ d, d)

            flipped, ntri = _flipped_triangles(psi_v, xv, _radial)
            if gaps[j] < 0.3:
                warnings.warn(
                    f"the points cover {np.degrees(2 * np.pi - gaps[j]):.0f} deg of the cylinder: "
                    "the parameters have a seam where neighbours in 3-D are far apart in Psi",
                    IrdicWarning,
                    stacklevel=2,
                )
            diag = dict(method="cylinder", axis_point=p0, axis_direction=d, radius=R, theta_direction=e_r0, rms=rms)
        ok = p99 <= max_normal_angle and flipped == 0
        diag.update(normal_angle_p99_deg=p99, normal_angle_max_deg=pmax, flipped_triangles=flipped,
                    n_triangles=ntri, ok=ok)
        candidates[name] = diag
        if ok:
            chosen = (name, psi_v, diag)
            break
    if chosen is None:
        parts = []
        for name in order:
            dg = candidates.get(name)
            if dg is None:
                continue
            if "reason" in dg:
                parts.append(f"{name}: {dg['reason']}")
            else:
                parts.append(
                    f"{name}: local normals up to {dg['normal_angle_p99_deg']:.1f} deg (99th percentile) "
                    f"from the projection direction (limit {max_normal_angle:g}), "
                    f"{dg['flipped_triangles']} of {dg['n_triangles']} triangles flipped"
                )
        raise GeometryError("every parametrisation folds the surface: " + "; ".join(parts))
    name, psi_v, diag = chosen
    psi = np.full((N, 2), np.nan)
    psi[has] = psi_v
    info = {k: v for k, v in diag.items() if k != "ok"}
    info.update(
        n_points=int(N),
        n_without_data=int((~has).sum()),
        n_reference_from_later_stage=int(later.sum()),
        candidates=candidates,
    )
    log.info(
        "surface parameters: %s (rms %.3g mm, normals within %.1f deg, %d points)",
        name, diag["rms"], diag["normal_angle_p99_deg"], int(has.sum()),
    )
    return psi, info


# --------------------------------------------------------------------------
# edge distance
# --------------------------------------------------------------------------


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
    p = _psi_array("psi", psi)
    f = _positive("max_edge_factor", max_edge_factor)
    if f <= 1:
        raise ConfigError(f"max_edge_factor must be > 1, got {max_edge_factor!r}")
    ok = np.isfinite(p).all(axis=1)
    out = np.full(p.shape[0], np.nan)
    pv = p[ok]
    if pv.shape[0] < 3:
        out[ok] = 0.0
        return out
    try:
        tri = Delaunay(pv)
    except QhullError:
        out[ok] = 0.0  # all on a line: every point is on the edge
        return out
    h = _median_spacing(pv)
    s = tri.simplices
    c = pv[s]
    longest = np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).max(axis=1)
    s = s[longest <= f * h]
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


# --------------------------------------------------------------------------
# spatial operator
# --------------------------------------------------------------------------


class _Saddle:
    """Factorised ``[[A, P], [P^T, 0]]`` (A the IMQ kernel matrix, positive definite).

    Cholesky of ``A`` and the small Schur complement ``P^T A^-1 P``. When
    round-off makes ``A`` numerically indefinite (very flat kernels, c R0 much
    larger than the spacing) an LU factorisation of the whole saddle matrix
    is used instead. ``rebuild`` (a callable returning A again) lets the
    Cholesky overwrite a large ``A`` in place.
    """

    def __init__(self, A, P, rebuild=None):
        self.K = A.shape[0]
        self.P = P
        self.lu = None
        self.cho = None
        try:
            self.cho = scipy.linalg.cho_factor(A, lower=True, overwrite_a=rebuild is not None, check_finite=False)
            self.Y = scipy.linalg.cho_solve(self.cho, P, check_finite=False)
            self.S_inv = np.linalg.inv(P.T @ self.Y)
            return
        except np.linalg.LinAlgError:
            pass
        log.debug("kernel matrix (%d) not numerically positive definite: LU of the saddle system", self.K)
        self.cho = None
        A = rebuild() if rebuild is not None else A
        n, m = self.K, P.shape[1]
        S = np.zeros((n + m, n + m))
        S[:n, :n] = A
        S[:n, n:] = P
        S[n:, :n] = P.T
        self.lu = scipy.linalg.lu_factor(S, overwrite_a=True, check_finite=False)

    def weights(self, B, Q):
        """Weights ``w`` with ``w @ f`` = functional of the interpolant of ``f``.

        ``B`` (n_f, K) kernel part and ``Q`` (n_f, 3) monomial part of the
        functionals; returns (n_f, K).
        """
        if self.lu is not None:
            rhs = np.concatenate([B, Q], axis=1).T
            return scipy.linalg.lu_solve(self.lu, rhs, trans=1, check_finite=False)[: self.K].T
        Z = scipy.linalg.cho_solve(self.cho, B.T, check_finite=False)
        Z -= self.Y @ (self.S_inv @ (self.P.T @ Z - Q.T))
        return Z.T

    def coefficients(self, F):
        """RBF and monomial coefficients of the interpolant of ``F`` (K, ncols)."""
        if self.lu is not None:
            rhs = np.concatenate([F, np.zeros((self.P.shape[1], F.shape[1]))])
            sol = scipy.linalg.lu_solve(self.lu, rhs, check_finite=False)
            return sol[: self.K], sol[self.K:]
        Z = scipy.linalg.cho_solve(self.cho, F, check_finite=False)
        beta = self.S_inv @ (self.Y.T @ F)
        Z -= self.Y @ beta
        return Z, beta


def _monomials(pts, centre, R0, n_funcs, kind):
    """Monomial rows [1, (xi - centre)/R0] and their derivatives."""
    n = pts.shape[0]
    if kind == 0:
        return np.c_[np.ones(n), (pts - centre) / R0]
    out = np.zeros((n, 3))
    out[:, kind] = 1.0 / R0
    return out


class _Tiles:
    """Overlapping tiles: a square core of side ``core`` plus every point within ``halo``."""

    def __init__(self, psi, c, R0, halo, core):
        self.psi = psi
        self.c, self.R0, self.halo, self.core = c, R0, halo, core
        self.tree = cKDTree(psi)
        self.lo = psi.min(axis=0)

    def cells(self, pts):
        return np.floor((pts - self.lo) / self.core).astype(np.int64)

    def tile_nodes(self, cell):
        lo = self.lo + cell * self.core
        hi = lo + self.core
        ctr = 0.5 * (lo + hi)
        cand = np.asarray(self.tree.query_ball_point(ctr, self.core / math.sqrt(2) + self.halo), dtype=np.int64)
        p = self.psi[cand]
        d = np.hypot(np.maximum(0, np.maximum(lo[0] - p[:, 0], p[:, 0] - hi[0])),
                     np.maximum(0, np.maximum(lo[1] - p[:, 1], p[:, 1] - hi[1])))
        return np.sort(cand[d <= self.halo]), ctr

    def factor(self, nodes, ctr):
        p = self.psi[nodes]
        A, _, _ = _kernels(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1], self.c, self.R0, False)
        P = _monomials(p, ctr, self.R0, 3, 0)
        return _Saddle(A, P)

    def functionals(self, nodes, ctr, pts, kinds):
        """Kernel/monomial rows of the functionals ``kinds`` (0 value, 1 d/dPsi1, 2 d/dPsi2) at ``pts``."""
        p = self.psi[nodes]
        dx = pts[:, None, 0] - p[None, :, 0]
        dy = pts[:, None, 1] - p[None, :, 1]
        m, m1, m2 = _kernels(dx, dy, self.c, self.R0, any(k > 0 for k in kinds))
        rows = {0: m, 1: m1, 2: m2}
        return [(rows[k], _monomials(pts, ctr, self.R0, 3, k)) for k in kinds]

    def count(self, pts):
        """Tile sizes for the cells of ``pts``: list of (n_points_in_cell, K)."""
        cells, inv = np.unique(self.cells(pts), axis=0, return_inverse=True)
        per = np.bincount(inv.ravel(), minlength=len(cells))
        lo = self.lo + cells * self.core
        ctr = lo + 0.5 * self.core
        K = self.tree.query_ball_point(ctr, self.core / math.sqrt(2) + self.halo, return_length=True)
        # the ball circumscribes the rounded box: correct by the area ratio
        r = self.core / math.sqrt(2) + self.halo
        ratio = (self.core**2 + 4 * self.core * self.halo + math.pi * self.halo**2) / (math.pi * r * r)
        return per, np.maximum(np.asarray(K) * ratio, per)


class _LocalOperator:
    """Per-tile weights of a set of functionals, and rows of ``G``."""

    def __init__(self, n_eval, kinds, tiles, g_rows, G, at_nodes):
        self.n_eval, self.kinds, self.tiles = n_eval, tuple(kinds), tiles
        self.g_rows, self.G, self.at_nodes = g_rows, G, at_nodes

    def apply(self, F, kinds):
        """Functionals ``kinds`` (a subset of the built ones) of the interpolant of ``F`` (N, ncols)."""
        pos = [self.kinds.index(k) for k in kinds]
        out = [np.empty((self.n_eval, F.shape[1])) for _ in kinds]

        def work(tile):
            idx, nodes, Wk = tile
            Fl = F[nodes]
            for o, j in zip(out, pos):
                o[idx] = Wk[j] @ Fl

        with blas_threads(1):
            _parallel_map(work, self.tiles)
        return out


def _workers():
    # the stage's thread budget, capped: beyond 8 the tiles are too few to share
    return max(1, min(thread_budget(), 8))


def _parallel_map(fn, items):
    """``list(map(fn, items))`` on a thread pool (LAPACK/BLAS release the GIL)."""
    items = list(items)
    n = _workers()
    if n == 1 or len(items) < 2:
        return [fn(i) for i in items]
    with ThreadPoolExecutor(max_workers=n) as ex:
        return list(ex.map(fn, items))


class SpatialInterpolant:
    """IMQ interpolant (or regression) over fixed surface parameters, for many fields.

    Parameters
    ----------
    psi : array_like, shape (N, 2)
        Surface parameters of the points (mm), all finite and distinct.
    c : float
        Shape factor of the IMQ (the paper: 0.969 half-shell, 0.9328 tube).
    R0 : float
        Distance normalisation (mm); the paper: 1 mm.
    smoothing : None, float >= 1
        None or 1: interpolation (the paper). ``k > 1``: least-squares
        regression with centres spaced ``k`` times the median point spacing
        (see the module Notes); use :func:`gcv_spatial` to choose ``k``.
    solver : {"auto", "global", "local"}
        Interpolation solver (module Notes); regression is always global.
    halo : float, optional
        Halo of the local tiles (mm); default ``max(9 c R0, 6 h)``.
    core : float, optional
        Core side of the local tiles (mm); default: chosen by a cost model.

    Raises
    ------
    DataError
        Fewer than 6 points, or all on a line.
    GeometryError
        Two points with the same ``Psi`` (duplicates: the interpolation is singular).
    """

    def __init__(self, psi, *, c=0.95, R0=1.0, smoothing=None, solver="auto", halo=None, core=None):
        p = _psi_array("psi", psi)
        if not np.isfinite(p).all():
            i = int(np.flatnonzero(~np.isfinite(p).all(axis=1))[0])
            raise ConfigError(f"psi must be finite (drop missing points first); row {i} is {p[i]}")
        self.c = _positive("c", c)
        self.R0 = _positive("R0", R0)
        k = _smoothing("smoothing", smoothing, allow_gcv=False)
        self.k = k
        self.solver = _choice("solver", solver, SOLVERS)
        n = p.shape[0]
        if n < MIN_POINTS:
            raise DataError(f"psi: {n} point(s); the surface interpolant needs at least {MIN_POINTS}")
        q = p - p.mean(axis=0)
        sv = np.linalg.svd(q, compute_uv=False)
        if not sv[1] > 1e-8 * max(sv[0], 1e-300):
            raise DataError(
                f"psi: the {n} points lie on one line; the monomials {{1, Psi1, Psi2}} need points off a line"
            )
        self.psi = p
        self.n = n
        d, j = cKDTree(p).query(p, k=2)
        self.h = float(np.median(d[:, 1]))
        dup = np.flatnonzero(d[:, 1] <= 1e-9 * max(self.h, 1e-300) + 1e-12)
        if dup.size:
            i = int(dup[0])
            other = int(j[i, 1] if j[i, 1] != i else j[i, 0])
            i, other = min(i, other), max(i, other)
            raise GeometryError(
                f"psi: points {i} and {other} have the same surface parameters "
                f"({p[i, 0]:.6g}, {p[i, 1]:.6g}) mm ({max(dup.size // 2, 1)} such pair(s)); duplicate DIC "
                "points make the interpolation singular: remove them"
            )
        ratio = self.c * self.R0 / self.h
        if ratio > 6:
            log.warning(
                "c R0 = %.3g mm is %.1f times the point spacing %.3g mm: the kernel matrix is very "
                "ill-conditioned (derivatives lose digits); consider a smaller R0",
                self.c * self.R0, ratio, self.h,
            )
        self.halo = _positive("halo", halo) if halo is not None else max(9.0 * self.c * self.R0, 6.0 * self.h)
        self.core = _positive("core", core) if core is not None else None
        self._global = None
        self._ls = None
        self._local = None
        self._chosen = None
        self.info = {"spacing": self.h, "halo": self.halo, "smoothing": self.k}

    # ---- cost model -------------------------------------------------------

    def _tiles(self, core):
        return _Tiles(self.psi, self.c, self.R0, self.halo, core)

    def _choose_core(self, pts, n_func, ncols):
        if self.core is not None:
            t = self._tiles(self.core)
            return t, self._tile_cost(t, pts, n_func, ncols)
        best = None
        for f in (0.25, 0.4, 0.6, 0.9, 1.3):
            core = max(f * self.halo, 2 * self.h)
            t = self._tiles(core)
            cost = self._tile_cost(t, pts, n_func, ncols)
            if best is None or cost < best[1]:
                best = (t, cost)
        return best

    @staticmethod
    def _tile_cost(tiles, pts, n_func, ncols):
        per, K = tiles.count(pts)
        return float(
            np.sum(K**3 / 3 + 2 * K * K * n_func * per) / _FACTOR_RATE
            + np.sum(2 * per * K * ncols * n_func) / _GEMM_RATE
        )

    def _global_cost(self, n_eval, ncols, n_func):
        N = self.n
        return N**3 / 3 / _FACTOR_RATE + (2 * N * N * ncols + 2 * n_eval * N * ncols * n_func) / _GEMM_RATE

    def _resolve(self, n_eval, ncols, n_func, pts):
        if self.solver != "auto":
            return self.solver, None
        if self._chosen is not None:
            return self._chosen, None
        tiles, t_cost = self._choose_core(pts, n_func, ncols)
        g_cost = self._global_cost(n_eval, ncols, n_func)
        choice = "local" if 2 * t_cost < g_cost or self.n > 20000 else "global"
        log.info("spatial solver: %s (estimated %.1f s local, %.1f s global)", choice, t_cost, g_cost)
        self._chosen = choice
        return choice, tiles

    # ---- global -------------------------------------------------------------

    def _kernel_matrix(self):
        p = self.psi
        A = np.empty((self.n, self.n))
        # row blocks keep the temporaries small
        step = max(1, _BLOCK_BYTES // (8 * self.n))
        for i in range(0, self.n, step):
            A[i:i + step], _, _ = _kernels(p[i:i + step, None, 0] - p[None, :, 0],
                                           p[i:i + step, None, 1] - p[None, :, 1], self.c, self.R0, False)
        return A

    def _global_factor(self):
        if self._global is None:
            t0 = _time.perf_counter()
            ctr = self.psi.mean(axis=0)
            P = _monomials(self.psi, ctr, self.R0, 3, 0)
            # threaded BLAS only pays for large matrices (and its first call can
            # cost seconds on a loaded machine)
            with blas_threads(1) if self.n < 4000 else contextlib.nullcontext():
                self._global = (_Saddle(self._kernel_matrix(), P, rebuild=self._kernel_matrix), ctr)
            log.info("global factorisation of %d points: %.1f s", self.n, _time.perf_counter() - t0)
        return self._global

    def _eval_global(self, F, pts, kinds):
        fac, ctr = self._global_factor()
        with blas_threads(1) if self.n < 4000 else contextlib.nullcontext():
            alpha, beta = fac.coefficients(F)
        p = self.psi
        out = [np.empty((pts.shape[0], F.shape[1])) for _ in kinds]
        step = max(1, _BLOCK_BYTES // (8 * self.n))
        for i in range(0, pts.shape[0], step):
            q = pts[i:i + step]
            m, m1, m2 = _kernels(q[:, None, 0] - p[None, :, 0], q[:, None, 1] - p[None, :, 1], self.c, self.R0,
                                 any(k > 0 for k in kinds))
            rows = {0: m, 1: m1, 2: m2}
            for o, k in zip(out, kinds):
                o[i:i + step] = rows[k] @ alpha + _monomials(q, ctr, self.R0, 3, k) @ beta
        return out

    # ---- local tiles --------------------------------------------------------

    def local_operator(self, psi_eval=None, kinds=(1, 2), g_rows=None, tiles=None):
        """Tile weights for the functionals ``kinds`` at ``psi_eval`` and the rows ``g_rows`` of ``G``.

        Parameters
        ----------
        psi_eval : array_like, shape (n, 2), optional
            Evaluation points; default the points themselves.
        kinds : sequence of {0, 1, 2}
            Value, d/dPsi1, d/dPsi2.
        g_rows : array_like of int, optional
            Points whose rows of the data-to-coefficient map ``G`` are wanted
            (for :meth:`fill`).

        Returns
        -------
        _LocalOperator
            Cached on the instance: :meth:`evaluate` and :meth:`fill` reuse it.
        """
        pts = self.psi if psi_eval is None else _psi_array("psi_eval", psi_eval)
        kinds = tuple(int(k) for k in kinds)
        rows = np.unique(np.asarray([] if g_rows is None else g_rows, dtype=np.int64))
        if tiles is None:
            if self.core is not None:
                tiles = self._tiles(self.core)
            else:
                probe = pts if kinds else self.psi[rows]
                tiles = self._choose_core(probe, len(kinds) + (rows.size > 0), 3)[0]
        t0 = _time.perf_counter()
        cells_e = tiles.cells(pts) if kinds else np.zeros((0, 2), np.int64)
        cells_g = tiles.cells(self.psi[rows])
        uc, inv = np.unique(np.concatenate([cells_e, cells_g]), axis=0, return_inverse=True)
        inv = inv.ravel()
        inv_e, inv_g = inv[: len(cells_e)], inv[len(cells_e):]
        order_e = np.argsort(inv_e, kind="stable")
        bounds_e = np.searchsorted(inv_e[order_e], np.arange(len(uc) + 1))
        order_g = np.argsort(inv_g, kind="stable")
        bounds_g = np.searchsorted(inv_g[order_g], np.arange(len(uc) + 1))

        def work(t):
            idx = order_e[bounds_e[t]:bounds_e[t + 1]]
            grow = rows[order_g[bounds_g[t]:bounds_g[t + 1]]]
            nodes, ctr = tiles.tile_nodes(uc[t])
            if nodes.size < MIN_POINTS:
                # a cell far from every point (evaluation outside the cloud)
                nodes = np.sort(tiles.tree.query(ctr, k=min(self.n, 4 * MIN_POINTS))[1])
            fac = tiles.factor(nodes, ctr)
            Bs, Qs = [], []
            for B, Q in tiles.functionals(nodes, ctr, pts[idx], kinds) if idx.size else []:
                Bs.append(B)
                Qs.append(Q)
            if grow.size:
                B = np.zeros((grow.size, nodes.size))
                B[np.arange(grow.size), np.searchsorted(nodes, grow)] = 1.0
                Bs.append(B)
                Qs.append(np.zeros((grow.size, 3)))
            W = fac.weights(np.concatenate(Bs), np.concatenate(Qs))
            ne = idx.size
            Wk = [W[i * ne:(i + 1) * ne] for i in range(len(kinds))] if ne else []
            return idx, nodes, Wk, grow, W[len(kinds) * ne:]

        with blas_threads(1):
            results = _parallel_map(work, range(len(uc)))
        G = None
        if rows.size:
            data, ri, ci = [], [], []
            for _, nodes, _, grow, Wg in results:
                if grow.size:
                    data.append(Wg.ravel())
                    ri.append(np.repeat(np.searchsorted(rows, grow), nodes.size))
                    ci.append(np.tile(nodes, grow.size))
            G = sparse.csr_matrix((np.concatenate(data), (np.concatenate(ri), np.concatenate(ci))),
                                  shape=(rows.size, self.n))
        tiles_e = [(idx, nodes, Wk) for idx, nodes, Wk, _, _ in results if idx.size]
        ksum = sum(r[1].size for r in results)
        log.info("local tiles: %d tiles, mean %d points, core %.2f mm, halo %.2f mm: %.1f s",
                 len(uc), ksum // max(len(uc), 1), tiles.core, tiles.halo, _time.perf_counter() - t0)
        op = _LocalOperator(pts.shape[0], kinds, tiles_e, rows, G, psi_eval is None)
        self._local = op
        return op

    def _eval_local(self, F, pts, kinds, tiles, at_nodes):
        op = self._local
        if not (op is not None and op.at_nodes and at_nodes and set(kinds) <= set(op.kinds)):
            op = self.local_operator(None if at_nodes else pts, kinds, tiles=tiles)
        return op.apply(F, kinds)

    def coefficient_rows(self, rows):
        """Rows of the data-to-RBF-coefficient map ``G`` for the points ``rows``.

        Computed from local tiles (the rows decay like the cardinal functions).

        Parameters
        ----------
        rows : array_like of int
            Point indices.

        Returns
        -------
        rows : ndarray of int
            The sorted unique rows.
        G : scipy.sparse.csr_matrix, shape (len(rows), N)
        """
        rows = np.unique(np.asarray(rows, dtype=np.int64))
        op = self._local
        if op is not None and op.G is not None and np.isin(rows, op.g_rows).all():
            return op.g_rows, op.G
        op = self.local_operator(kinds=(), g_rows=rows)
        return op.g_rows, op.G

    # ---- regression ------------------------------------------------------

    def _ls_factor(self):
        if self._ls is None:
            self._ls = _ls_design(self.psi, self.k, self.h, self.c, self.R0)
        return self._ls

    def _eval_ls(self, F, pts, kinds):
        centres, R0k, ctr, Qm, Rm = self._ls_factor()
        coef = scipy.linalg.solve_triangular(Rm, Qm.T @ F, check_finite=False)
        out = []
        step = max(1, _BLOCK_BYTES // (8 * max(len(centres), 1)))
        for k in kinds:
            o = np.empty((pts.shape[0], F.shape[1]))
            for i in range(0, pts.shape[0], step):
                q = pts[i:i + step]
                m, m1, m2 = _kernels(q[:, None, 0] - centres[None, :, 0], q[:, None, 1] - centres[None, :, 1],
                                     self.c, R0k, k > 0)
                E = np.concatenate([{0: m, 1: m1, 2: m2}[k], _monomials(q, ctr, self.R0, 3, k)], axis=1)
                o[i:i + step] = E @ coef
            out.append(o)
        return out

    # ---- public -----------------------------------------------------------

    def evaluate(self, values, psi_eval=None, *, value=True, derivatives=True):
        """Values and ``d/dPsi^alpha`` of the interpolant (regression) of ``values``.

        Parameters
        ----------
        values : array_like, shape (N, ...)
            Data at the points (finite; fill missing values first with :meth:`fill`).
        psi_eval : array_like, shape (n, 2), optional
            Evaluation points (mm); default the points themselves.
        value, derivatives : bool
            Which results to compute.

        Returns
        -------
        val, d1, d2 : ndarray, shape (n, ...) or None
            The interpolant and its derivatives with respect to ``Psi1``,
            ``Psi2`` (units of ``values`` per mm); None where not asked. At the
            points themselves the interpolant's value is the data.
        """
        F = _float_array("values", values)
        if F.ndim < 1 or F.shape[0] != self.n:
            raise ConfigError(f"values must have N = {self.n} rows (one per point), got shape {F.shape}")
        if not np.isfinite(F).all():
            raise DataError("values contain NaN or inf: fill the missing points first (SpatialInterpolant.fill)")
        tail = F.shape[1:]
        F2 = F.reshape(self.n, -1)
        at_nodes = psi_eval is None
        pts = self.psi if at_nodes else _psi_array("psi_eval", psi_eval)
        if not np.isfinite(pts).all():
            raise ConfigError("psi_eval must be finite")
        kinds = []
        exact_value = value and at_nodes and self.k == 1.0
        if value and not exact_value:
            kinds.append(0)
        if derivatives:
            kinds += [1, 2]
        res = {0: None, 1: None, 2: None}
        if kinds:
            if self.k > 1.0:
                solver = "regression"
                outs = self._eval_ls(F2, pts, kinds)
            else:
                solver, tiles = self._resolve(pts.shape[0], F2.shape[1], len(kinds), pts)
                if solver == "global":
                    outs = self._eval_global(F2, pts, kinds)
                else:
                    outs = self._eval_local(F2, pts, kinds, tiles, at_nodes)
            self.info["solver"] = solver
            res.update(dict(zip(kinds, outs)))
        if exact_value:
            res[0] = F2.copy()
        shape = (pts.shape[0],) + tail
        return tuple(None if res[k] is None else res[k].reshape(shape) for k in (0, 1, 2))

    def fill(self, values, valid):
        """Fill missing points per stage from that stage's valid points.

        Parameters
        ----------
        values : array_like, shape (M, N, ...)
            Stage data (NaN where missing).
        valid : array_like of bool, shape (M, N)
            True where a point is valid in a stage.

        Returns
        -------
        filled : ndarray, shape (M, N, ...)
            ``values`` with the missing entries replaced by the value of the
            interpolant of the stage's valid points (module Notes).
        was_filled : ndarray of bool, shape (M, N)

        Raises
        ------
        DataError
            A stage whose valid points are fewer than 6 or on a line.
        """
        X = _float_array("values", values)
        V = np.asarray(valid, dtype=bool)
        if X.ndim < 2 or X.shape[1] != self.n or V.shape != X.shape[:2]:
            raise ConfigError(f"values must be (M, N = {self.n}, ...) and valid (M, N); got {X.shape}, {V.shape}")
        out = X.copy()
        miss = ~V
        rows = np.flatnonzero(miss.any(axis=0))
        if rows.size == 0:
            return out, miss
        for m in np.flatnonzero(miss.any(axis=1)):
            nv = int(V[m].sum())
            if nv < MIN_POINTS:
                raise DataError(f"stage {m}: {nv} valid point(s); filling the others needs at least {MIN_POINTS}")
        t0 = _time.perf_counter()
        rows, G = self.coefficient_rows(rows)
        pos = np.full(self.n, -1)
        pos[rows] = np.arange(rows.size)
        tail = X.shape[2:]
        for m in np.flatnonzero(miss.any(axis=1)):
            Q = np.flatnonzero(miss[m])
            GQ = G[pos[Q]]
            f = np.where(V[m].reshape((-1,) + (1,) * len(tail)), X[m], 0.0).reshape(self.n, -1)
            rhs = -(GQ @ f)
            GQQ = GQ[:, Q].toarray()
            try:
                fq = scipy.linalg.solve(GQQ, rhs, check_finite=False)
            except (np.linalg.LinAlgError, ValueError):
                raise DataError(
                    f"stage {m}: the {V[m].sum()} valid points do not determine the {Q.size} missing ones "
                    "(valid points on a line?)"
                ) from None
            out[m, Q] = fq.reshape((Q.size,) + tail)
        log.info("filled %d missing (stage, point) values in %d stage(s): %.1f s", int(miss.sum()),
                 int(miss.any(axis=1).sum()), _time.perf_counter() - t0)
        return out, miss


# Kernel width of the regression relative to its centre spacing, c R0_eff / H.
# Flat kernels approximate smooth fields well with few centres: tangents of a
# curved test field (R = 15 mm, 0.7 mm grid, 0.005 mm noise) erred by 3.8e-3
# at a ratio of 2, 1.1e-3 at 4, 4.4e-4 at 6, 2.4e-4 at 8 (GCV-chosen spacing;
# interpolation: 8.4e-3); temporal rates were insensitive. 6 keeps the
# least-squares design comfortably conditioned.
_REGRESSION_RATIO = 6.0


def _regression_R0(c, R0, h, H):
    """Distance normalisation of regression centres spaced ``H``: ``c R0_eff = 6 H``."""
    return _REGRESSION_RATIO * H / c


def _grid_subset(psi, H):
    """Indices of a subset of points, about one per square cell of side H (nearest to the cell centre)."""
    lo = psi.min(axis=0)
    cell = np.floor((psi - lo) / H).astype(np.int64)
    d = np.linalg.norm(psi - (lo + (cell + 0.5) * H), axis=1)
    key = cell[:, 0] * (cell[:, 1].max() + 1) + cell[:, 1]
    order = np.lexsort((d, key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return np.sort(order[first])


def _ls_design(psi, k, h, c, R0):
    """QR of the regression design matrix: centres spaced k h, kernel width c R0_eff = 6 k h."""
    idx = _grid_subset(psi, k * h)
    centres = psi[idx]
    R0k = _regression_R0(c, R0, h, k * h)
    ctr = psi.mean(axis=0)
    m, _, _ = _kernels(psi[:, None, 0] - centres[None, :, 0], psi[:, None, 1] - centres[None, :, 1], c, R0k, False)
    E = np.concatenate([m, _monomials(psi, ctr, R0, 3, 0)], axis=1)
    Qm, Rm = scipy.linalg.qr(E, mode="economic", overwrite_a=True, check_finite=False)
    dg = np.abs(np.diag(Rm))
    if dg.min() < 1e-12 * dg.max():
        raise GeometryError(
            f"the regression with centres every {k:g} spacings is rank deficient "
            f"(condition > 1e12); use a larger smoothing factor"
        )
    return centres, R0k, ctr, Qm, Rm


def gcv_spatial(psi, samples, *, c=0.95, R0=1.0, candidates=(2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0)):
    """Choose the spatial regression's centre spacing by generalised cross-validation.

    Parameters
    ----------
    psi : array_like, shape (N, 2)
        Surface parameters (mm).
    samples : array_like, shape (N, n_series)
        Data to judge by (e.g. the three coordinates of a few stages, filled).
    c, R0 : float
        Kernel (as :class:`SpatialInterpolant`).
    candidates : sequence of float
        Centre spacing factors to try (> 1).

    Returns
    -------
    k : float
        The factor with the least ``GCV = n RSS / (n - p)^2`` (pooled over the series).
    table : list of (k, n_parameters, gcv)
    """
    p = _psi_array("psi", psi)
    F = _float_array("samples", samples).reshape(p.shape[0], -1)
    c, R0 = _positive("c", c), _positive("R0", R0)
    h = _median_spacing(p)
    n = p.shape[0]
    table = []
    for k in sorted(set(float(x) for x in candidates)):
        if k <= 1:
            raise ConfigError(f"candidates must be > 1 (1 is interpolation, GCV undefined), got {k}")
        nc = _grid_subset(p, k * h).size
        if nc + 3 > n // 2 or nc < MIN_POINTS:
            continue
        try:
            _, _, _, Qm, _ = _ls_design(p, k, h, c, R0)
        except GeometryError:
            continue
        rss = float(np.sum((F - Qm @ (Qm.T @ F)) ** 2))
        pp = Qm.shape[1]
        table.append((k, pp, n * rss / F.shape[1] / (n - pp) ** 2))
    if not table:
        raise DataError(f"gcv_spatial: no candidate spacing fits {n} points (too few points)")
    best = min(table, key=lambda r: r[2])
    log.info("spatial GCV: centre spacing %.3g x %.3g mm (%d parameters)", best[0], h, best[1])
    return best[0], table


# --------------------------------------------------------------------------
# temporal operator
# --------------------------------------------------------------------------


def _imq1(d, c):
    return c / np.sqrt(c * c + d * d)


def _imq1_dr(d, c):
    q = c * c + d * d
    return -c * d / (q * np.sqrt(q))


class TemporalSmoother:
    """IMQ interpolation (or regression) in time over the stage times, with {1, t}.

    Parameters
    ----------
    times : array_like, shape (M,)
        Stage (or frame) times in s, strictly increasing, at least 2.
    c : float
        Shape factor (the paper: 1).
    R0 : float
        Time normalisation in s (the paper: 1 s).
    smoothing : None or float >= 1
        None / 1: interpolation (the paper). ``k > 1``: least squares with
        centres on about every k-th time (first and last always) and a kernel
        six centre spacings wide (``c R0_eff = 6 H``); see :func:`gcv_temporal`.

    Notes
    -----
    Evaluation times outside ``[times[0], times[-1]]`` give NaN weights: the
    interpolant is not meant to extrapolate.
    """

    def __init__(self, times, *, c=1.0, R0=1.0, smoothing=None):
        t = _check_times(times)
        if t.size < 2:
            raise DataError(
                f"times: {t.size} stage(s); the temporal interpolant with monomials {{1, t}} needs at least 2"
            )
        self.times = t
        self.c = _positive("c", c)
        self.R0 = _positive("R0", R0)
        self.k = _smoothing("smoothing", smoothing, allow_gcv=False)
        self._mid = 0.5 * (t[0] + t[-1])
        M = t.size
        if self.k > 1.0:
            nc = int(math.ceil((M - 1) / self.k)) + 1
            if nc + 2 > M:
                nc = M - 2
            if nc < 2:
                raise DataError(
                    f"smoothing = {self.k:g} leaves fewer than 2 temporal centres for {M} stages"
                )
            self.centre_index = np.unique(np.round(np.linspace(0, M - 1, nc)).astype(int))
            span = t[-1] - t[0]
            dt = float(np.median(np.diff(t)))
            H = span / (self.centre_index.size - 1)
            self.R0_eff = _regression_R0(self.c, self.R0, dt, H)
            cs = (t[self.centre_index] - self._mid) / self.R0_eff
            s = (t - self._mid) / self.R0_eff
            E = np.c_[_imq1(s[:, None] - cs[None, :], self.c), np.ones(M), (t - self._mid) / self.R0]
            self._Q, self._R = scipy.linalg.qr(E, mode="economic", check_finite=False)
            dg = np.abs(np.diag(self._R))
            if dg.min() < 1e-12 * dg.max():
                raise GeometryError(f"temporal regression with smoothing {self.k:g} is rank deficient")
            self._cs = cs
            self.n_parameters = E.shape[1]
        else:
            s = (t - self._mid) / self.R0
            A = _imq1(s[:, None] - s[None, :], self.c)
            P = np.c_[np.ones(M), s]
            self._fac = _Saddle(A, P)
            self._s = s
            self.n_parameters = M

    @property
    def n_times(self):
        return self.times.size

    def in_span(self, t_eval):
        te = _float_array("t_eval", t_eval)
        tol = _TIME_SNAP * self.R0
        with np.errstate(invalid="ignore"):
            return (te >= self.times[0] - tol) & (te <= self.times[-1] + tol)

    def weights(self, t_eval=None, derivative=0):
        """Weights ``W`` with ``f(t_eval) = W @ f(times)`` (or ``df/dt``).

        Parameters
        ----------
        t_eval : array_like, shape (T,), optional
            Evaluation times (s); default the stage times.
        derivative : {0, 1}
            0: value; 1: time derivative (weights in 1/s).

        Returns
        -------
        ndarray, shape (T, M)
            NaN rows for times outside the span. Interpolation at a stage time
            gives exactly the identity row.
        """
        if derivative not in (0, 1) or isinstance(derivative, bool):
            raise ConfigError(f"derivative must be 0 or 1, got {derivative!r}")
        te = self.times if t_eval is None else np.atleast_1d(_float_array("t_eval", t_eval))
        if te.ndim != 1:
            raise ConfigError(f"t_eval must be a scalar or 1-D, got shape {te.shape}")
        ok = self.in_span(te)
        W = np.full((te.size, self.n_times), np.nan)
        if not ok.any():
            return W
        tt = te[ok] - self._mid
        n = tt.size
        if self.k > 1.0:
            s = tt / self.R0_eff
            d = s[:, None] - self._cs[None, :]
            if derivative == 0:
                E = np.c_[_imq1(d, self.c), np.ones(n), tt / self.R0]
            else:
                E = np.c_[_imq1_dr(d, self.c) / self.R0_eff, np.zeros(n), np.full(n, 1.0 / self.R0)]
            W[ok] = scipy.linalg.solve_triangular(self._R, E.T, trans=1, check_finite=False).T @ self._Q.T
            return W
        s = tt / self.R0
        d = s[:, None] - self._s[None, :]
        if derivative == 0:
            B = _imq1(d, self.c)
            Q = np.c_[np.ones(n), s]
        else:
            B = _imq1_dr(d, self.c) / self.R0
            Q = np.c_[np.zeros(n), np.full(n, 1.0 / self.R0)]
        Wok = self._fac.weights(B, Q)
        if derivative == 0:
            j = np.clip(np.searchsorted(self.times, te[ok]), 0, self.n_times - 1)
            for jj in (j, np.clip(j - 1, 0, self.n_times - 1)):
                hit = np.abs(self.times[jj] - te[ok]) <= _TIME_SNAP * self.R0
                if hit.any():
                    Wok[hit] = 0.0
                    Wok[np.flatnonzero(hit), jj[hit]] = 1.0
        W[ok] = Wok
        return W


def gcv_temporal(times, series, *, c=1.0, R0=1.0, candidates=None, max_series=4096):
    """Choose the temporal regression's centre spacing by generalised cross-validation.

    Parameters
    ----------
    times : array_like, shape (M,)
        Stage times (s).
    series : array_like, shape (M, ...)
        Time series (finite) to judge by, pooled: every column counts.
    c, R0 : float
        Kernel (as :class:`TemporalSmoother`).
    candidates : sequence of float, optional
        Centre spacing factors (> 1); default 1.5 ... 64, as many as ``M`` allows.
    max_series : int
        At most this many columns (evenly spaced) enter the pooled GCV.

    Returns
    -------
    k : float
        Factor with the least ``GCV = n RSS / (n - p)^2``; 1.0 (interpolation)
        when no candidate fits (at most M / 2 parameters: fewer than ~10 stages).
    table : list of (k, n_parameters, gcv)
    """
    t = _check_times(times)
    F = _float_array("series", series)
    if F.shape[0] != t.size:
        raise ConfigError(f"series must have M = {t.size} rows, got shape {F.shape}")
    F = F.reshape(t.size, -1)
    if not np.isfinite(F).all():
        raise DataError("series contain NaN or inf; GCV needs complete series")
    if F.shape[1] > max_series:
        F = F[:, np.linspace(0, F.shape[1] - 1, max_series).astype(int)]
    M = t.size
    if candidates is None:
        candidates = (1.5, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64)
    table = []
    seen = set()
    for k in sorted(float(x) for x in candidates):
        if k <= 1:
            raise ConfigError(f"candidates must be > 1 (1 is interpolation, GCV undefined), got {k}")
        try:
            ts = TemporalSmoother(t, c=c, R0=R0, smoothing=k)
        except (DataError, GeometryError):
            continue
        p = ts.n_parameters
        if p in seen or p > M // 2 or ts.centre_index.size < 3:
            continue
        seen.add(p)
        rss = float(np.sum((F - ts._Q @ (ts._Q.T @ F)) ** 2))
        table.append((k, p, M * rss / F.shape[1] / (M - p) ** 2))
    if not table:
        log.warning("temporal GCV: %d stages are too few for a regression; interpolating", M)
        return 1.0, table
    best = min(table, key=lambda r: r[2])
    log.info("temporal GCV: centres every %.3g stages (%d parameters of %d)", best[0], best[1], M)
    return best[0], table


class SeriesFit(NamedTuple):
    """Result of :func:`smooth_series`."""

    value: np.ndarray
    """(T, ...) smoothed (or interpolated) values at the evaluation times."""
    rate: np.ndarray
    """(T, ...) time derivative (units per s)."""
    smoothing: float
    """Centre spacing factor used (1 = interpolation)."""
    gcv: list
    """GCV table ``(k, n_parameters, gcv)`` when chosen by GCV, else empty."""


def smooth_series(values, times, t_eval=None, *, smoothing="gcv", c=1.0, R0=1.0):
    """Value and rate of time series by the temporal IMQ interpolant or regression.

    For point temperatures ``Theta_k(t_n)`` at fixed material points this gives
    the material temperature rate directly (the derivative at fixed ``Psi``).

    Parameters
    ----------
    values : array_like, shape (M, ...)
        Series at ``times``; NaN entries are filled by interpolating each
        series over its own valid times (at least 2 needed, else NaN).
    times : array_like, shape (M,)
        Times (s), strictly increasing.
    t_eval : array_like, shape (T,), optional
        Evaluation times; default ``times``.
    smoothing : None, float >= 1 or "gcv"
        None/1: interpolation; k: regression; "gcv": k by :func:`gcv_temporal`.
    c, R0 : float
        Kernel shape factor and time normalisation (s).

    Returns
    -------
    SeriesFit
    """
    t = _check_times(times)
    F = _float_array("values", values)
    if F.ndim < 1 or F.shape[0] != t.size:
        raise ConfigError(f"values must have M = {t.size} rows (one per time), got shape {F.shape}")
    k = _smoothing("smoothing", smoothing)
    tail = F.shape[1:]
    F2 = F.reshape(t.size, -1).copy()
    bad = ~np.isfinite(F2)
    dead = np.zeros(F2.shape[1], bool)
    if bad.any():
        for j in np.flatnonzero(bad.any(axis=0)):
            ok = ~bad[:, j]
            if ok.sum() < 2:
                dead[j] = True
                F2[:, j] = 0.0
                continue
            w = TemporalSmoother(t[ok], c=c, R0=R0).weights(t[~ok])
            fill = w @ F2[ok, j]
            # outside the valid span: nearest valid value (flat)
            nanf = ~np.isfinite(fill)
            if nanf.any():
                fill[nanf] = np.interp(t[~ok][nanf], t[ok], F2[ok, j])
            F2[~ok, j] = fill
    table = []
    if k == "gcv":
        k, table = gcv_temporal(t, F2[:, ~dead] if (~dead).any() else F2, c=c, R0=R0)
    ts = TemporalSmoother(t, c=c, R0=R0, smoothing=k)
    W0 = ts.weights(t_eval, 0)
    W1 = ts.weights(t_eval, 1)
    with np.errstate(invalid="ignore"):
        val = W0 @ F2
        rate = W1 @ F2
    val[:, dead] = np.nan
    rate[:, dead] = np.nan
    T = W0.shape[0]
    return SeriesFit(val.reshape((T,) + tail), rate.reshape((T,) + tail), float(k), table)


# --------------------------------------------------------------------------
# the surface
# --------------------------------------------------------------------------


def _temporal_fill(X, valid, times, c, R0, max_gap, window=8):
    """Fill short gaps from each point's own valid stages.

    A missing stage is filled when it lies in a run of at most ``max_gap``
    missing stages with valid stages on both sides; the temporal IMQ
    interpolant (with {1, t}) of up to ``window`` valid stages on each side
    gives the value.

    Returns the filled array and the (M, N) mask of entries filled.
    """
    M = X.shape[0]
    idx = np.arange(M)[:, None]
    prev = np.maximum.accumulate(np.where(valid, idx, -1), axis=0)
    nxt = np.minimum.accumulate(np.where(valid, idx, M)[::-1], axis=0)[::-1]
    todo = ~valid & (prev >= 0) & (nxt < M) & (nxt - prev - 1 <= max_gap)
    out = X.copy()
    # the weights depend only on the valid times relative to t_k: with regular
    # stages a handful of patterns serve all gaps
    cache = {}
    valid_of = {}
    for k, i in zip(*np.nonzero(todo)):
        ok = valid_of.get(i)
        if ok is None:
            ok = valid_of[i] = np.flatnonzero(valid[:, i])
        j = np.searchsorted(ok, k)
        sel = ok[max(0, j - window):j + window]
        s = (times[sel] - times[k]) / R0
        key = tuple(np.round(s, 9))
        w = cache.get(key)
        if w is None:
            n = sel.size
            S = np.zeros((n + 2, n + 2))
            S[:n, :n] = _imq1(s[:, None] - s[None, :], c)
            S[:n, n] = S[n, :n] = 1.0
            S[:n, n + 1] = S[n + 1, :n] = s
            rhs = np.zeros(n + 2)
            rhs[:n] = _imq1(-s, c)
            rhs[n] = 1.0
            w = cache[key] = np.linalg.solve(S, rhs)[:n]  # symmetric system: the cardinal weights at t_k
        out[k, i] = w @ X[sel, i]
    return out, todo


def _duplicates(psi):
    """Indices of points closer than 1e-9 of the median spacing to an earlier point."""
    if psi.shape[0] < 2:
        return np.zeros(0, np.int64)
    tree = cKDTree(psi)
    d, _ = tree.query(psi, k=2)
    tol = 1e-9 * max(float(np.median(d[:, 1])), 1e-300) + 1e-12
    pairs = tree.query_pairs(tol, output_type="ndarray")
    return np.unique(pairs.max(axis=1)) if pairs.size else np.zeros(0, np.int64)


class SurfaceFields(NamedTuple):
    """Result of :func:`fit_surface`; ``T`` evaluation times, ``N`` points.

    Points without any valid stage (and duplicates left out) are NaN throughout.
    """

    psi: np.ndarray
    """(N, 2) surface parameters (mm)."""
    times: np.ndarray
    """(T,) evaluation times (s)."""
    x: np.ndarray
    """(T, N, 3) position on the continuous surface (mm)."""
    tangents: np.ndarray
    """(T, N, 2, 3) ``a_alpha = dx/dPsi^alpha`` (dimensionless)."""
    velocity: np.ndarray
    """(T, N, 3) ``dx/dt`` at fixed Psi (mm/s)."""
    ref_x: np.ndarray
    """(N, 3) reference position ``x(Psi, t_0)`` (mm), t_0 the first stage."""
    ref_tangents: np.ndarray
    """(N, 2, 3) reference tangents ``A_alpha``."""
    filled: np.ndarray
    """(M, N) bool: the point was missing in the stage and filled (see ``fill``)."""
    stage_used: np.ndarray
    """(M,) bool: the stage entered the temporal fit."""
    edge_distance: np.ndarray
    """(N,) distance to the edge of the point cloud in Psi (mm)."""
    info: dict
    """Solver, smoothing, GCV tables, parametrisation, timings."""


def fit_surface(
    x,
    times,
    psi=None,
    *,
    t_eval=None,
    c=0.95,
    R0=1.0,
    c_t=1.0,
    R0_t=1.0,
    smoothing=None,
    smoothing_t=None,
    solver="auto",
    halo=None,
    parametrisation="auto",
    min_stage_fraction=0.5,
    fill="both",
    max_gap=3,
):
    """The continuous surface ``x(Psi, t)`` of DIC stages, evaluated at the points.

    Parameters
    ----------
    x : array_like, shape (M, N, 3)
        Point coordinates per stage (mm); NaN rows are missing points.
    times : array_like, shape (M,)
        Stage times (s), strictly increasing; stage 0 is the reference.
    psi : array_like, shape (N, 2), optional
        Surface parameters; default from :func:`surface_parameters`
        (``parametrisation``).
    t_eval : array_like, shape (T,), optional
        Evaluation times (s); default ``times``. Outside the stage span: NaN.
    c, R0 : float
        Spatial IMQ shape factor and distance normalisation (mm). Default c =
        0.95 (the paper: 0.969 half-shell, 0.9328 tube), R0 = 1 mm.
    c_t, R0_t : float
        Temporal shape factor and normalisation (s); the paper: 1, 1 s.
    smoothing, smoothing_t : None, float >= 1 or "gcv"
        Spatial / temporal regression (module Notes); None = interpolation.
    solver : {"auto", "global", "local"}
        Spatial interpolation solver (module Notes).
    halo : float, optional
        Halo of the local tiles (mm).
    parametrisation : {"auto", "plane", "cylinder"}
        Used when ``psi`` is None.
    min_stage_fraction : float
        Stages with fewer valid points than this fraction are left out of the
        temporal fit (and warned about); the reference stage must pass.
    fill : {"both", "space", "time"}
        How a point missing in a stage is filled. In space: from the stage's
        valid points (module Notes), so the stage's surface is the smooth
        interpolant of its valid points and the neighbours' tangents hardly
        notice the gap. In time: from the point's own valid stages (temporal
        interpolant over the nearest 8 valid stages on each side) when the gap
        is at most ``max_gap`` stages with valid stages on both sides (else in
        space), so the point's series stays smooth. ``"both"`` (default):
        positions and tangents from the space-filled data, velocities from the
        time-filled data: each derivative sees the fill that is smooth along
        its direction. Measured on the tube test (1 mm grid, 0.5 s stages,
        1.5 % missing in every other stage): filled in space only, the
        velocity error reached 0.09 mm/s next to filled values (a filled value
        errs by the interpolant's 0.02-0.1 mm between points, a bump in its
        series); filled in time only, the strain error RMS of the synthetic
        tube rose from 5e-4 to 1.4e-3 (bumps in the stage surfaces).
    max_gap : int
        Longest run of missing stages filled in time.

    Returns
    -------
    SurfaceFields

    Points with the same surface parameters as an earlier point (duplicate
    DIC points) are left out with a logged warning: NaN results, listed in
    ``info["duplicates"]``.

    Raises
    ------
    DataError
        Fewer than 2 usable stages, too few points, non-increasing times,
        reference stage unusable.
    GeometryError
        Folded parametrisation.
    """
    t0 = _time.perf_counter()
    X = _float_array("x", x)
    if X.ndim != 3 or X.shape[2] != 3:
        raise ConfigError(f"x must have shape (stages, points, 3), got {X.shape}")
    M, N, _ = X.shape
    t = _check_times(times)
    if t.size != M:
        raise ConfigError(f"times has {t.size} entries but x has {M} stages")
    if M < 2:
        raise DataError(f"x: {M} stage(s); the space-time surface needs at least 2 (monomials {{1, t}})")
    if np.isinf(X).any():
        m, n, _ = np.argwhere(np.isinf(X))[0]
        raise DataError(f"x: infinite coordinate at stage {m}, point {n}; missing points must be NaN")
    _choice("fill", fill, ("both", "space", "time"))
    if isinstance(max_gap, bool) or not isinstance(max_gap, (int, np.integer)) or max_gap < 1:
        raise ConfigError(f"max_gap must be an integer >= 1 (stages), got {max_gap!r}")
    frac = float(min_stage_fraction)
    if not 0 <= frac <= 1:
        raise ConfigError(f"min_stage_fraction must be in [0, 1], got {min_stage_fraction!r}")
    ks = _smoothing("smoothing", smoothing)
    kt = _smoothing("smoothing_t", smoothing_t)
    info = {}
    if psi is None:
        psi, pinfo = surface_parameters(X, parametrisation)
        info["parametrisation"] = pinfo
    else:
        psi = _psi_array("psi", psi)
        if psi.shape[0] != N:
            raise ConfigError(f"psi has {psi.shape[0]} rows but x has {N} points")
    valid = np.isfinite(X).all(axis=2)
    node = np.isfinite(psi).all(axis=1) & valid.any(axis=0)
    nodes = np.flatnonzero(node)
    dup = _duplicates(psi[nodes])
    if dup.size:
        log.warning(
            "%d point(s) have the same surface parameters as an earlier point (duplicate DIC points?) "
            "and are left out (NaN): %s%s", dup.size, nodes[dup][:10].tolist(), " ..." if dup.size > 10 else "",
        )
        info["duplicates"] = nodes[dup].tolist()
        nodes = np.delete(nodes, dup)
    if nodes.size < MIN_POINTS:
        raise DataError(f"x: {nodes.size} point(s) with data and parameters; the surface needs {MIN_POINTS}")
    Xn = X[:, nodes]
    Vn = valid[:, nodes]
    counts = Vn.sum(axis=1)
    used = counts >= max(frac * nodes.size, MIN_POINTS)
    if not used[0]:
        raise DataError(
            f"stage 0 (the reference) has only {counts[0]} of {nodes.size} valid points "
            f"(min_stage_fraction = {frac:g})"
        )
    if not used.all():
        bad = np.flatnonzero(~used)
        warnings.warn(
            f"{bad.size} stage(s) with fewer than {frac:.0%} valid points left out of the temporal fit: "
            f"{bad[:10].tolist()}{' ...' if bad.size > 10 else ''}",
            IrdicWarning,
            stacklevel=2,
        )
    if used.sum() < 2:
        raise DataError("fewer than 2 usable stages")
    sp = SpatialInterpolant(psi[nodes], c=c, R0=R0, solver=solver, halo=halo)
    te = t if t_eval is None else np.atleast_1d(_float_array("t_eval", t_eval))
    tu = t[used]
    ed_nodes = edge_distance(psi[nodes])
    # --- missing points: each derivative sees the fill that is smooth along it
    Xu, Vu = Xn[used], Vn[used]
    miss_rows = np.flatnonzero((~Vu).any(axis=0))
    if ks == 1.0:
        # one pass over the tiles gives the fill rows of G and the derivative weights
        chosen, tiles = sp._resolve(nodes.size, 3 * te.size + 3, 2, sp.psi)
        sp.info["solver"] = chosen
        if chosen == "local":
            sp.local_operator(kinds=(1, 2), g_rows=miss_rows, tiles=tiles)
    Xs = sp.fill(Xu, Vu)[0] if fill != "time" else None
    by_time = np.zeros_like(Vu)
    Xt = Xs
    if fill != "space":
        Xt, by_time = _temporal_fill(Xu, Vu, tu, c_t, R0_t, max_gap)
        if (~(Vu | by_time)).any():
            Xt = sp.fill(Xt, Vu | by_time)[0]
    if fill == "time":
        Xs = Xt
    was_filled = ~Vu
    info["filled_in_time"] = int(by_time.sum())
    info["filled_in_space"] = int(was_filled.sum() - (by_time.sum() if fill == "time" else 0))
    # --- temporal
    if kt == "gcv":
        kt, table = gcv_temporal(tu, Xt.reshape(tu.size, -1), c=c_t, R0=R0_t)
        info["gcv_t"] = table
    ts = TemporalSmoother(tu, c=c_t, R0=R0_t, smoothing=kt)
    W0 = ts.weights(te, 0)
    W1 = ts.weights(te, 1)
    Wr = ts.weights(t[:1], 0)
    T = te.size
    n = nodes.size
    # (stages, points, 3) -> (points, 3 * T): one spatial operator for all columns
    flat = Xs.reshape(tu.size, n * 3)
    with np.errstate(invalid="ignore"):
        Y0 = (W0 @ flat).reshape(T, n, 3).transpose(1, 0, 2).reshape(n, T * 3)
        Y1 = (W1 @ Xt.reshape(tu.size, n * 3)).reshape(T, n, 3).transpose(1, 0, 2).reshape(n, T * 3)
    Yr = (Wr @ flat).reshape(n, 3)
    ok_t = np.isfinite(W0).all(axis=1)
    # --- spatial
    if ks == "gcv":
        pick = np.linspace(0, tu.size - 1, min(tu.size, 8)).astype(int)
        samples = Xs[pick].transpose(1, 0, 2).reshape(n, -1)
        ks, table = gcv_spatial(psi[nodes], samples, c=c, R0=R0)
        info["gcv"] = table
    if ks > 1.0:
        sp = SpatialInterpolant(psi[nodes], c=c, R0=R0, smoothing=ks)
    cols = np.flatnonzero(np.repeat(ok_t, 3))
    tk = np.flatnonzero(ok_t)
    Yall = np.concatenate([Y0[:, cols], Yr], axis=1)
    del Y0
    val, d1, d2 = sp.evaluate(Yall)
    del Yall
    vel = sp.evaluate(Y1[:, cols], derivatives=False)[0]
    del Y1

    def _place(arr, out=None, sub=None):
        """(n, 3 T_ok) -> (T, N, 3) (or into ``out[..., sub, :]`` of (T, N, 2, 3))."""
        block = arr.reshape(n, tk.size, 3).transpose(1, 0, 2)
        if out is None:
            out = np.full((T, N, 3), np.nan)
            out[np.ix_(tk, nodes)] = block
        else:
            out[np.ix_(tk, nodes, [sub])] = block[:, :, None, :]
        return out

    x_out = _place(val[:, :-3])
    v_out = _place(vel)
    del vel
    tang = np.full((T, N, 2, 3), np.nan)
    _place(d1[:, :-3], tang, 0)
    _place(d2[:, :-3], tang, 1)
    ref_x = np.full((N, 3), np.nan)
    ref_x[nodes] = val[:, -3:]
    ref_t = np.full((N, 2, 3), np.nan)
    ref_t[nodes, 0] = d1[:, -3:]
    ref_t[nodes, 1] = d2[:, -3:]
    del val, d1, d2
    filled = np.zeros((M, N), bool)
    filled[np.ix_(np.flatnonzero(used), nodes)] = was_filled
    ed = np.full(N, np.nan)
    ed[nodes] = ed_nodes
    info.update(sp.info)
    info.update(
        smoothing=float(ks), smoothing_t=float(kt), c=float(c), R0=float(R0), c_t=float(c_t), R0_t=float(R0_t),
        n_nodes=int(n), n_filled=int(was_filled.sum()), stages_used=int(used.sum()),
        seconds=_time.perf_counter() - t0,
    )
    log.info("surface: %d points x %d times in %.1f s", n, T, info["seconds"])
    return SurfaceFields(psi, te, x_out, tang, v_out, ref_x, ref_t, filled, used, ed, info)


# --------------------------------------------------------------------------
# geometry
# --------------------------------------------------------------------------


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
    a = _float_array("tangents", tangents)
    if a.ndim < 2 or a.shape[-2:] != (2, 3):
        raise ConfigError(f"tangents must have shape (..., 2, 3), got {a.shape}")
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
    nd = int(degenerate.sum())
    if nd:
        if nd == int(finite.sum()):
            raise GeometryError(
                f"all {nd} tangent pairs are degenerate (parallel or zero): the surface has no area; "
                "duplicate or collinear points?"
            )
        log.warning("%d of %d tangent pairs are degenerate (sine of their angle < %g): NaN there",
                    nd, int(finite.sum()), min_sine)
    return Geometry(metric, inv, dual, normal, np.where(bad, np.nan, area), degenerate)
