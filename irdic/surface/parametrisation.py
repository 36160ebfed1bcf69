"""Surface parameters ``Psi`` of DIC points: best-fit plane or unwrapped cylinder.

:func:`surface_parameters` projects the reference points onto the best-fit
plane (the paper; PCA) or unwraps them on a least-squares cylinder, and
checks that the parametrisation does not fold (local normals far from the
projection direction, Delaunay triangles flipping orientation).
"""

from __future__ import annotations

import logging
import math
import warnings

import numpy as np
from scipy.spatial import Delaunay, QhullError, cKDTree

from ..errors import ConfigError, DataError, GeometryError, IrdicWarning
from ..pointcloud import local_normals
from ..validation import choice, float_array, positive

__all__ = ["PARAMETRISATIONS", "MIN_POINTS", "MAX_NORMAL_ANGLE", "median_spacing", "surface_parameters"]

log = logging.getLogger(__name__)

PARAMETRISATIONS = ("auto", "plane", "cylinder")
# Minimum number of points: the linear monomials need 3 points off a line, and a
# curved patch has no curvature information below the 6 coefficients of a quadric.
MIN_POINTS = 6
# A local normal more than this far (deg) from the projection direction makes a
# plane (or cylinder) projection fold or compress the point spacing > 2.9x.
MAX_NORMAL_ANGLE = 70.0


def median_spacing(psi):
    """Median distance (mm) from each point to its nearest neighbour; psi (N, d)."""
    d = cKDTree(psi).query(psi, k=2)[0][:, 1]
    return float(np.median(d))


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



def _angle_stats(normals, ref_dirs):
    cosang = np.abs(np.einsum("ni,ni->n", normals, ref_dirs))
    ang = np.degrees(np.arccos(np.clip(cosang, 0.0, 1.0)))
    return float(np.percentile(ang, 99.0)), float(ang.max())


def short_triangles(psi, max_edge_factor):
    """Delaunay triangles of 2-D points without those that bridge gaps or concave outlines.

    Parameters
    ----------
    psi : ndarray, shape (N, 2)
        Finite points (surface parameters, mm).
    max_edge_factor : float
        Triangles whose longest edge exceeds this many median point spacings
        are dropped.

    Returns
    -------
    (simplices, h) or None
        ``simplices`` (K, 3) int of the kept triangles and ``h`` the median
        spacing; None when the points are collinear (no triangulation).
    """
    try:
        tri = Delaunay(psi)
    except QhullError:
        return None
    h = median_spacing(psi)
    c = psi[tri.simplices]
    longest = np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).max(axis=1)
    return tri.simplices[longest <= max_edge_factor * h], h


def _flipped_triangles(psi, x, ref_normal_fn, max_edge_factor=3.0):
    """Delaunay triangles in Psi whose 3-D orientation disagrees with the reference normal."""
    found = short_triangles(psi, max_edge_factor)
    if found is None:
        return -1, 0
    s, _ = found
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


def _plane_candidate(xv, hint, normals):
    """Plane projection of the reference points ``xv``: (psi, diagnostics) with the fold statistics."""
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
    diag.update(normal_angle_p99_deg=p99, normal_angle_max_deg=pmax, flipped_triangles=flipped, n_triangles=ntri)
    return psi_v, diag


def _cylinder_candidate(xv, normals):
    """Cylinder unwrapping of ``xv``: (psi, diagnostics); psi None when no cylinder fits."""
    extent = float(np.ptp(xv, axis=0).max())
    p0, d, R, rms = _fit_cylinder(xv, normals)
    if not (np.isfinite(R) and R < 100 * extent and rms < 0.05 * R):
        return None, dict(
            method="cylinder", radius=R, rms=rms, ok=False,
            reason=f"no cylinder fits (radius {R:.4g} mm, rms residual {rms:.3g} mm, extent {extent:.4g} mm)",
        )
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
    centre = ts[j] + 0.5 * gaps[j] + np.pi
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
            stacklevel=3,
        )
    diag = dict(method="cylinder", axis_point=p0, axis_direction=d, radius=R, theta_direction=e_r0, rms=rms)
    diag.update(normal_angle_p99_deg=p99, normal_angle_max_deg=pmax, flipped_triangles=flipped, n_triangles=ntri)
    return psi_v, diag


def _fold_message(order, candidates, max_normal_angle):
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
    return "every parametrisation folds the surface: " + "; ".join(parts)


def _first_unfolded(order, xv, hint, max_normal_angle):
    """The first parametrisation of ``order`` that does not fold: name, psi, diagnostics, all candidates."""
    normals = local_normals(xv)
    candidates = {}
    for name in order:
        if name == "plane":
            psi_v, diag = _plane_candidate(xv, hint, normals)
        else:
            psi_v, diag = _cylinder_candidate(xv, normals)
            if psi_v is None:
                candidates["cylinder"] = diag
                continue
        diag["ok"] = ok = diag["normal_angle_p99_deg"] <= max_normal_angle and diag["flipped_triangles"] == 0
        candidates[name] = diag
        if ok:
            return name, psi_v, diag, candidates
    raise GeometryError(_fold_message(order, candidates, max_normal_angle))


def _reference_points(x, normal_hint):
    """Reference coordinates (N, 3), which points have data, which take a later stage, the normal hint."""
    X = float_array(x, "x")
    if X.ndim == 2:
        X = X[None]
    if X.ndim != 3 or X.shape[-1] != 3:
        raise ConfigError(f"x must have shape (N, 3) or (stages, N, 3), got {np.shape(x)}")
    if np.isinf(X).any():
        m, n, _ = np.argwhere(np.isinf(X))[0]
        raise DataError(f"x: infinite coordinate at stage {m}, point {n}; missing points must be NaN")
    hint = None
    if normal_hint is not None:
        hint = float_array(normal_hint, "normal_hint")
        if hint.shape != (3,) or not np.isfinite(hint).all() or not np.linalg.norm(hint) > 0:
            raise ConfigError(f"normal_hint must be a non-zero 3-vector, got {normal_hint!r}")
    ref, first, has, later = _first_valid(X)
    if later.any():
        log.info(
            "%d point(s) missing in stage 0 take their surface parameters from their first valid stage",
            int(later.sum()),
        )
    if (~has).any():
        log.info("%d point(s) have no valid stage: Psi is NaN for them", int((~has).sum()))
    return ref, has, later, hint


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
    choice(method, "method", PARAMETRISATIONS)
    max_normal_angle = positive(max_normal_angle, "max_normal_angle")
    ref, has, later, hint = _reference_points(x, normal_hint)
    N = ref.shape[0]
    xv = ref[has]
    if xv.shape[0] < MIN_POINTS:
        raise DataError(
            f"x: {xv.shape[0]} point(s) with valid coordinates; the surface needs at least {MIN_POINTS}"
        )
    order = ["plane", "cylinder"] if method == "auto" else [method]
    name, psi_v, diag, candidates = _first_unfolded(order, xv, hint, max_normal_angle)
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
