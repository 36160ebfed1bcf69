"""Projection matrix from marker/pixel pairs: the normalised DLT and its covariance.

See :mod:`irdic.camera.model` for the camera convention.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibrationError
from .model import (MATRIX_PARAMETERS, CameraModel, normalise_matrix, pair_weights, point_array, point_pairs,
                    project_matrix)

__all__ = ["dlt", "fit_dlt", "planarity", "degeneracy", "residual_info"]


def _hartley(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Similarity T moving the centroid to 0 and the mean distance to sqrt(dim)."""
    dim = p.shape[1]
    c = p.mean(axis=0)
    d = np.sqrt(((p - c) ** 2).sum(axis=1)).mean()
    s = np.sqrt(dim) / d if d > 0 else 1.0
    T = np.eye(dim + 1)
    T[:dim, :dim] *= s
    T[:dim, dim] = -s * c
    return T, (p - c) * s


def planarity(x) -> float:
    """Thickness of a point cloud: smallest / largest singular value of the centred points.

    0 for coplanar points; about 0.3 to 0.6 for an open-book target.
    """
    x = point_array(x, "x", 3)
    s = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
    return float(s[2] / s[0]) if s[0] > 0 else 0.0


def degeneracy(x, what: str = "markers", tol: float = 1e-3) -> str | None:
    """Say how a point cloud falls short of spanning 3-D (or 2-D) space; None if it does not.

    Parameters
    ----------
    x : array_like, shape (N, d), d = 2 or 3
        Points (mm or px).
    what : str
        Plural noun for the message (``"markers"``, ``"seed markers"``, ...).
    tol : float
        Smallest accepted ratio of a singular value to the largest one.

    Returns
    -------
    str or None
        ``"the N markers are (nearly) collinear (...)"``, ``"... coplanar ..."``
        or ``"all N markers are at one position"``.

    Notes
    -----
    With singular values :math:`s_1 \\ge s_2 \\ge s_3` of the centred points,
    :math:`s_1 = 0` means one position, :math:`s_2 / s_1 <` ``tol`` a line and
    (in 3-D) :math:`s_3 / s_1 <` ``tol`` a plane.
    """
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    s = np.linalg.svd(x - x.mean(axis=0), compute_uv=False) if n else np.zeros(1)
    if n == 0 or s[0] == 0 or not np.isfinite(s[0]):
        return f"all {n} {what} are at one position"
    if len(s) > 1 and s[1] / s[0] < tol:
        return f"the {n} {what} are (nearly) collinear (singular value ratio s2/s1 = {s[1] / s[0]:.2e})"
    if x.shape[1] == 3 and len(s) > 2 and s[2] / s[0] < tol:
        return f"the {n} {what} are coplanar or nearly so (thickness ratio s3/s1 = {s[2] / s[0]:.2e})"
    return None


def _check_in_front(M: np.ndarray, x: np.ndarray, what: str = "markers") -> None:
    depth = x @ M[2, :3] + M[2, 3]
    if (depth > 0).all():
        return
    if (depth < 0).all():
        err = CalibrationError(
            f"the fitted camera sees all {what} from behind (depth < 0): the pixel positions are mirrored "
            "with respect to the DIC frame. Check that the IR image is not flipped (u = column from the "
            "left, v = row from the top), that u and v are not swapped, and that the DIC frame is right-handed"
        )
        err.reason = "mirrored"
        raise err
    err = CalibrationError(
        f"the fitted camera plane passes through the {what}: {(depth <= 0).sum()} of {len(depth)} lie behind "
        "the camera. The marker/pixel pairs are inconsistent (wrong correspondence?)"
    )
    err.reason = "inconsistent"
    raise err


def dlt(x, uv, weights=None, *, min_planarity: float = 1e-3) -> np.ndarray:
    """Projection matrix from point pairs by the normalised direct linear transformation.

    Both point sets are normalised (Hartley: centroid to the origin, mean
    distance sqrt(3) in 3-D and sqrt(2) in 2-D), the homogeneous system of
    eq. (DLT) is solved by SVD (last right singular vector) and the
    normalisation is undone.

    Parameters
    ----------
    x : array_like, shape (N, 3)
        Marker centres in the DIC frame, mm.
    uv : array_like, shape (N, 2)
        Their pixel positions ``(u, v)``, px.
    weights : array_like, shape (N,), optional
        Non-negative weight of each pair (multiplies both of its equations;
        ``1 / sigma`` of the pixel position is the usual choice).
    min_planarity : float
        Smallest accepted ratio of the smallest to the largest singular value
        of the centred marker cloud (see :func:`planarity`).

    Returns
    -------
    M : ndarray, shape (3, 4)
        ``||M[2, :3]|| = 1``, ``det(M[:, :3]) > 0`` and ``M[2] @ [x, 1] > 0``
        (depth in mm) for every marker.

    Raises
    ------
    CalibrationError
        Fewer than 6 pairs, coplanar or degenerate markers, or a solution
        that puts the markers behind the camera.
    """
    x, uv = point_pairs(x, uv)
    n = len(x)
    if n < 6:
        raise CalibrationError(f"the DLT needs at least 6 marker/pixel pairs (11 unknowns), got {n}")
    w = pair_weights(weights, n)
    ratio = planarity(x)
    if ratio < min_planarity:
        line = degeneracy(x, "markers", min_planarity)
        if line is not None and "coplanar" not in line:
            raise CalibrationError(
                f"{line}: a line of markers does not determine a camera. Use a 3-D target (open book) with "
                "markers spread over both wings"
            )
        raise CalibrationError(
            f"the {n} markers are coplanar or nearly so (thickness ratio s3/s1 = {ratio:.2e} of the centred "
            f"marker cloud, below {min_planarity:g}): the DLT is degenerate for a planar target. Use a 3-D "
            "target (open book) with markers on both wings visible"
        )
    flat = degeneracy(uv, "pixel positions")
    if flat is not None:
        raise CalibrationError(
            f"{flat}: the image of markers spread in 3-D cannot be a line or a point; check the pixel positions "
            "(u = column, v = row) and the correspondence"
        )
    T3, xn = _hartley(x)
    T2, uvn = _hartley(uv)
    Xh = np.hstack([xn, np.ones((n, 1))])
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = Xh
    A[0::2, 8:12] = -uvn[:, :1] * Xh
    A[1::2, 4:8] = Xh
    A[1::2, 8:12] = -uvn[:, 1:] * Xh
    if w is not None:
        A *= np.repeat(w, 2)[:, None]
    _, s, vt = np.linalg.svd(A, full_matrices=False)
    rel = s / s[0]
    deficit = int((rel[:-1] < 1e-9).sum())
    if deficit:
        raise CalibrationError(
            f"the DLT system is rank-deficient: the 12x12 normal matrix has {deficit + 1} near-zero eigenvalues "
            f"(singular values / largest: {', '.join(f'{r:.1e}' for r in rel[-3:])}); the markers are coplanar, "
            "collinear or repeated"
        )
    M = np.linalg.solve(T2, vt[-1].reshape(3, 4)) @ T3
    M = normalise_matrix(M)
    _check_in_front(M, x)
    return M


def _dlt_covariance(M: np.ndarray, x: np.ndarray, uv: np.ndarray, w: np.ndarray | None):
    """Covariance (12, 12) of the entries of M from the reprojection residuals.

    Gauss-Newton linearisation; the scale of M is a gauge direction (the
    projection does not change with it) and is removed by a rank-11
    pseudo-inverse.
    """
    proj, depth = project_matrix(M, x)
    Xh = np.hstack([x, np.ones((len(x), 1))]) / depth[:, None]
    n = len(x)
    J = np.zeros((2 * n, 12))
    J[0::2, 0:4] = Xh
    J[0::2, 8:12] = -proj[:, :1] * Xh
    J[1::2, 4:8] = Xh
    J[1::2, 8:12] = -proj[:, 1:] * Xh
    r = (proj - uv).ravel()
    if w is not None:
        J *= np.repeat(w, 2)[:, None]
        r = r * np.repeat(w, 2)
    dof = max(2 * n - 11, 1)
    s2 = float(r @ r) / dof
    U, s, vt = np.linalg.svd(J, full_matrices=False)
    inv = np.zeros_like(s)
    inv[:11] = 1.0 / s[:11] ** 2
    return s2 * (vt.T * inv) @ vt, np.sqrt(s2)


def fit_dlt(x, uv, weights=None, *, min_planarity: float = 1e-3) -> tuple["CameraModel", dict]:
    """The DLT of :func:`dlt` as a :class:`CameraModel` with the covariance of ``M``.

    Returns
    -------
    model : CameraModel
        Pinhole model with ``covariance`` (12, 12) over :data:`MATRIX_PARAMETERS`.
    info : dict
        ``residuals`` (N, 2) px (projected - measured), ``rms_px``, ``max_px``,
        ``sigma_px`` (residual standard deviation per coordinate, px).
    """
    x, uv = point_pairs(x, uv)
    w = pair_weights(weights, len(x))
    M = dlt(x, uv, w, min_planarity=min_planarity)
    cov, sigma = _dlt_covariance(M, x, uv, w)
    model = CameraModel(M, covariance=cov, parameters=MATRIX_PARAMETERS)
    res = model.project(x) - uv
    return model, residual_info(res, sigma)


def residual_info(res: np.ndarray, sigma: float) -> dict:
    """Summary of reprojection residuals ``res`` (N, 2) px (projected - measured).

    Returns
    -------
    dict
        ``residuals`` (N, 2) px, ``rms_px`` and ``max_px`` of their lengths,
        ``sigma_px`` (= ``sigma``, the residual standard deviation per coordinate).
    """
    norm = np.hypot(res[:, 0], res[:, 1])
    return {
        "residuals": res,
        "rms_px": float(np.sqrt(np.mean(norm**2))),
        "max_px": float(norm.max()),
        "sigma_px": float(sigma),
    }

