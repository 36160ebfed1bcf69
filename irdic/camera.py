"""The IR camera as a projection of DIC points (mm) into IR pixels.

Convention (shared with :mod:`irdic.synthetic`):

- world frame = the DIC frame, mm;
- camera pose: centre ``C`` (3,) and rotation ``R`` (3, 3) whose rows are the
  camera axes in world coordinates (row 0 = image right ``+u``, row 1 = image
  down ``+v``, row 2 = viewing direction); camera coordinates
  ``X_c = R (X - C)``, a point is in front when ``X_c[2] > 0``;
- normalised coordinates ``x_n = X_c[0] / X_c[2]``, ``y_n = X_c[1] / X_c[2]``,
  radial distortion ``d = 1 + k1 r^2 + k2 r^4`` (``r^2 = x_n^2 + y_n^2``),
  ``x_d = d x_n``, ``y_d = d y_n``;
- pixels ``[u, v, 1] ~ K [x_d, y_d, 1]``; for the physical model
  ``K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]`` (square pixels, no skew);
- pinhole projection matrix ``M = K [R | -R C]`` stored normalised so that
  ``||M[2, :3]|| = 1`` and ``M[2] @ [X, 1] > 0`` in front of the camera; then
  ``M[2] @ [X, 1]`` is the depth of ``X`` along the viewing direction in mm.

Pixel convention: ``u`` = column, ``v`` = row, 0-based, pixel centres on
integer coordinates, ``v`` downwards.

This module knows projections and nothing about images, files or RBFs.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import scipy.linalg
import xarray as xr
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from .errors import CalibrationError, ConfigError, DataError

__all__ = [
    "dlt",
    "fit_dlt",
    "CameraModel",
    "CameraGeometry",
    "refine",
    "leave_one_out",
    "planarity",
    "degeneracy",
    "PHYSICAL_PARAMETERS",
    "MATRIX_PARAMETERS",
]

log = logging.getLogger(__name__)

#: Names of the physical parameters (``r*`` = small rotation vector, rad,
#: applied on the left of the model's ``R``; ``C*`` = camera centre, mm).
PHYSICAL_PARAMETERS = ("f", "cx", "cy", "rx", "ry", "rz", "Cx", "Cy", "Cz", "k1", "k2")
#: Names of the entries of ``M`` (row-major) for a DLT-only model.
MATRIX_PARAMETERS = tuple(f"m{r}{c}" for r in (1, 2, 3) for c in (1, 2, 3, 4))

_DISTORTIONS = {"none": (), "k1": ("k1",), "k1k2": ("k1", "k2")}


# ----------------------------------------------------------------------------- checks


def _points(a, name: str, dim: int) -> np.ndarray:
    """``a`` as a float64 (N, dim) array of finite values, or an irdic error."""
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`{name}` must be a numeric array of shape (N, {dim}); {exc}") from None
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ConfigError(f"`{name}` must be an array of shape (N, {dim}), got shape {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise DataError(
            f"`{name}` contains NaN or infinite values in rows {np.flatnonzero(bad)[:10].tolist()}"
            f"{' ...' if bad.sum() > 10 else ''}; remove those points first"
        )
    return arr


def _pairs(x, uv) -> tuple[np.ndarray, np.ndarray]:
    x = _points(x, "x", 3)
    uv = _points(uv, "uv", 2)
    if len(x) != len(uv):
        raise ConfigError(f"`x` has {len(x)} points but `uv` has {len(uv)}; expected one pixel position per point")
    return x, uv


def _weights(weights, n: int) -> np.ndarray | None:
    if weights is None:
        return None
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n,):
        raise ConfigError(f"`weights` must have shape ({n},) (one per point), got {w.shape}")
    if not np.isfinite(w).all() or (w < 0).any():
        raise ConfigError("`weights` must be finite and >= 0")
    if (w > 0).sum() < 6:
        raise CalibrationError(f"only {(w > 0).sum()} points have a positive weight; the fit needs at least 6")
    return w


def _model_points(x) -> tuple[np.ndarray, bool]:
    """Points for projection: (N, 3) float array and whether a single (3,) point was given."""
    arr = np.asarray(x, dtype=np.float64)
    single = arr.ndim == 1
    arr = np.atleast_2d(arr)
    if arr.ndim != 2 or arr.shape[-1] != 3:
        raise ConfigError(f"`x` must have shape (3,) or (N, 3), got {np.shape(x)}")
    return arr, single


# ----------------------------------------------------------------------------- DLT


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
    x = _points(x, "x", 3)
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


def _normalise_M(M: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(M[2, :3])
    if not np.isfinite(n) or n == 0:
        raise CalibrationError("projection matrix has a zero third row; it is not a camera")
    M = M / n
    # det(K R) > 0 for a camera with f > 0 and a proper rotation: fixes the sign.
    if np.linalg.det(M[:, :3]) < 0:
        M = -M
    return M


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
    x, uv = _pairs(x, uv)
    n = len(x)
    if n < 6:
        raise CalibrationError(f"the DLT needs at least 6 marker/pixel pairs (11 unknowns), got {n}")
    w = _weights(weights, n)
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
    M = _normalise_M(M)
    _check_in_front(M, x)
    return M


def _project_M(M: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    h = x @ M[:, :3].T + M[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = h[:, :2] / h[:, 2:3]
    return uv, h[:, 2]


def _dlt_covariance(M: np.ndarray, x: np.ndarray, uv: np.ndarray, w: np.ndarray | None):
    """Covariance (12, 12) of the entries of M from the reprojection residuals.

    Gauss-Newton linearisation; the scale of M is a gauge direction (the
    projection does not change with it) and is removed by a rank-11
    pseudo-inverse.
    """
    proj, depth = _project_M(M, x)
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
    x, uv = _pairs(x, uv)
    w = _weights(weights, len(x))
    M = dlt(x, uv, w, min_planarity=min_planarity)
    cov, sigma = _dlt_covariance(M, x, uv, w)
    model = CameraModel(M, covariance=cov, parameters=MATRIX_PARAMETERS)
    res = model.project(x) - uv
    return model, _residual_info(res, sigma)


def _residual_info(res: np.ndarray, sigma: float) -> dict:
    norm = np.hypot(res[:, 0], res[:, 1])
    return {
        "residuals": res,
        "rms_px": float(np.sqrt(np.mean(norm**2))),
        "max_px": float(norm.max()),
        "sigma_px": float(sigma),
    }


# ----------------------------------------------------------------------------- model


@dataclasses.dataclass(frozen=True)
class CameraGeometry:
    """Decomposition ``M = K [R | -R C]`` of a projection matrix.

    Attributes
    ----------
    K : ndarray (3, 3)
        Upper triangular, positive diagonal, ``K[2, 2] = 1``; px.
    R : ndarray (3, 3)
        Proper rotation; rows = camera axes (right, down, viewing direction).
    C : ndarray (3,)
        Camera centre in the DIC frame, mm.
    focal_length_px : float
        Mean of ``fx`` and ``fy``, px.
    fx, fy, skew : float
        ``K[0, 0]``, ``K[1, 1]``, ``K[0, 1]``, px.
    ifov_mrad : float
        Instantaneous field of view, ``1000 / focal_length_px``, mrad.
    principal_point : ndarray (2,)
        ``(cx, cy)``, px.
    viewing_direction : ndarray (3,)
        Unit vector ``R[2]`` in the DIC frame.
    """

    K: np.ndarray
    R: np.ndarray
    C: np.ndarray
    focal_length_px: float
    fx: float
    fy: float
    skew: float
    ifov_mrad: float
    principal_point: np.ndarray
    viewing_direction: np.ndarray


def _decompose(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    Kr, Q = scipy.linalg.rq(M[:, :3])
    sgn = np.sign(np.diag(Kr))
    D = np.diag(np.where(sgn == 0, 1.0, sgn))
    K = Kr @ D
    R = D @ Q
    if np.linalg.det(R) < 0:  # only for a mirrored M, which _normalise_M excludes
        raise CalibrationError("projection matrix has det(M[:, :3]) < 0: it describes a mirrored camera")
    K = K / K[2, 2]
    C = -np.linalg.solve(M[:, :3], M[:, 3])
    return K, R, C


def _rotation(rvec: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(rvec).as_matrix()


def _project_physical(p: np.ndarray, x: np.ndarray, R0: np.ndarray) -> np.ndarray:
    """Projection with physical parameters ``p`` (see PHYSICAL_PARAMETERS) around rotation R0."""
    f, cx, cy = p[0], p[1], p[2]
    R = _rotation(p[3:6]) @ R0
    Xc = (x - p[6:9]) @ R.T
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = Xc[:, :2] / Xc[:, 2:3]
    r2 = (xn**2).sum(axis=1, keepdims=True)
    xd = xn * (1.0 + p[9] * r2 + p[10] * r2**2)
    return np.column_stack([f * xd[:, 0] + cx, f * xd[:, 1] + cy])


class CameraModel:
    """Pinhole camera with optional radial distortion.

    Build it from a projection matrix (pinhole) or from ``K, R, C`` and the
    distortion coefficients ``k1, k2`` (see the module docstring for the
    convention).

    Parameters
    ----------
    M : array_like (3, 4), optional
        Projection matrix (any scale and sign); normalised on input.
    K, R, C : array_like, optional
        Intrinsic matrix (3, 3) px, rotation (3, 3) and centre (3,) mm; used
        when ``M`` is not given.
    k1, k2 : float
        Radial distortion coefficients (dimensionless, normalised coordinates).
    covariance : array_like (P, P), optional
        Covariance of the parameters named in ``parameters``.
    parameters : sequence of str, optional
        :data:`PHYSICAL_PARAMETERS` or :data:`MATRIX_PARAMETERS`.

    Examples
    --------
    >>> cam = CameraModel(K=[[1754.4, 0, 511.5], [0, 1754.4, 383.5], [0, 0, 1]],
    ...                   R=np.eye(3), C=[0, 0, -500])
    >>> cam.project([[0, 0, 0]])
    array([[511.5, 383.5]])
    """

    def __init__(self, M=None, *, K=None, R=None, C=None, k1: float = 0.0, k2: float = 0.0,
                 covariance=None, parameters=None):
        if M is not None:
            M = np.asarray(M, dtype=np.float64)
            if M.shape != (3, 4) or not np.isfinite(M).all():
                raise ConfigError(f"`M` must be a finite (3, 4) array, got shape {M.shape}")
            self._M = _normalise_M(M)
            self._K, self._R, self._C = _decompose(self._M)
        else:
            if K is None or R is None or C is None:
                raise ConfigError("CameraModel needs either `M` or all of `K`, `R` and `C`")
            K = np.asarray(K, dtype=np.float64)
            R = np.asarray(R, dtype=np.float64)
            C = np.asarray(C, dtype=np.float64).reshape(-1)
            if K.shape != (3, 3) or R.shape != (3, 3) or C.shape != (3,):
                raise ConfigError(f"`K`, `R`, `C` must have shapes (3, 3), (3, 3), (3,); got {K.shape}, {R.shape}, {C.shape}")
            if not (np.isfinite(K).all() and np.isfinite(R).all() and np.isfinite(C).all()):
                raise ConfigError("`K`, `R` and `C` must be finite")
            if K[2, 2] == 0 or K[0, 0] <= 0 or K[1, 1] <= 0 or K[1, 0] or K[2, 0] or K[2, 1]:
                raise ConfigError(f"`K` must be upper triangular with positive focal lengths, got {K.tolist()}")
            if not np.allclose(R @ R.T, np.eye(3), atol=1e-8) or np.linalg.det(R) < 0:
                raise ConfigError("`R` must be a proper rotation matrix (R R^T = I, det R = +1)")
            self._K = K / K[2, 2]
            self._R = R
            self._C = C
            self._M = _normalise_M(self._K @ np.hstack([R, -(R @ C)[:, None]]))
        self.k1 = float(k1)
        self.k2 = float(k2)
        if not (np.isfinite(self.k1) and np.isfinite(self.k2)):
            raise ConfigError("`k1` and `k2` must be finite")
        self.covariance = None if covariance is None else np.asarray(covariance, dtype=np.float64)
        self.parameters = None if parameters is None else tuple(parameters)
        if self.covariance is not None:
            p = len(self.parameters or ())
            if self.covariance.shape != (p, p):
                raise ConfigError(f"`covariance` must have shape ({p}, {p}) for the {p} `parameters`, "
                                  f"got {self.covariance.shape}")

    # -- properties
    @property
    def M(self) -> np.ndarray:
        """Pinhole projection matrix (3, 4), normalised (``||M[2, :3]|| = 1``)."""
        return self._M.copy()

    @property
    def K(self) -> np.ndarray:
        return self._K.copy()

    @property
    def R(self) -> np.ndarray:
        return self._R.copy()

    @property
    def C(self) -> np.ndarray:
        return self._C.copy()

    @property
    def has_distortion(self) -> bool:
        return self.k1 != 0.0 or self.k2 != 0.0

    # -- projection
    def depth(self, x) -> np.ndarray:
        """Signed depth along the viewing direction, mm (> 0 in front), shape (N,)."""
        pts, single = _model_points(x)
        d = pts @ self._M[2, :3] + self._M[2, 3]
        return d[0] if single else d

    def project(self, x) -> np.ndarray:
        """Pixel positions of DIC points.

        Parameters
        ----------
        x : array_like, shape (N, 3) or (3,)
            Points in the DIC frame, mm.

        Returns
        -------
        ndarray, shape (N, 2) or (2,)
            ``(u, v)`` px; NaN for points at or behind the camera plane
            (depth <= 0), which have no image.
        """
        pts, single = _model_points(x)
        if self.has_distortion:
            Xc = (pts - self._C) @ self._R.T
            depth = Xc[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                xn = Xc[:, :2] / Xc[:, 2:3]
            r2 = (xn**2).sum(axis=1, keepdims=True)
            xd = xn * (1.0 + self.k1 * r2 + self.k2 * r2**2)
            uv = xd @ self._K[:2, :2].T + self._K[:2, 2]
        else:
            uv, depth = _project_M(self._M, pts)
        uv[~(depth > 0)] = np.nan
        return uv[0] if single else uv

    def jacobian(self, x) -> np.ndarray:
        """Derivative of the pixel position with respect to the 3-D point.

        Pinhole: eq. (derivProjection),
        ``J = (M[:2, :3] - uv ⊗ M[2, :3]) / (M[2, :3] · x + M[2, 3])``; with
        distortion the chain rule through ``d(r^2)``.

        Parameters
        ----------
        x : array_like, shape (N, 3) or (3,)
            Points, mm.

        Returns
        -------
        ndarray, shape (N, 2, 3) or (2, 3)
            px / mm; NaN for points behind the camera.
        """
        pts, single = _model_points(x)
        if not self.has_distortion:
            uv, depth = _project_M(self._M, pts)
            with np.errstate(divide="ignore", invalid="ignore"):
                J = (self._M[None, :2, :3] - uv[:, :, None] * self._M[None, 2, None, :3]) / depth[:, None, None]
        else:
            R = self._R
            Xc = (pts - self._C) @ R.T
            depth = Xc[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                xn = Xc[:, :2] / Xc[:, 2:3]
                # d(xn, yn)/dX = ([R0; R1] - xn ⊗ R2) / Zc
                dn = (R[None, :2, :] - xn[:, :, None] * R[None, 2, None, :]) / depth[:, None, None]
            r2 = (xn**2).sum(axis=1)
            d = 1.0 + self.k1 * r2 + self.k2 * r2**2
            dd = (2.0 * self.k1 + 4.0 * self.k2 * r2)[:, None] * xn  # grad of d w.r.t. (xn, yn)
            D = d[:, None, None] * np.eye(2)[None] + xn[:, :, None] * dd[:, None, :]
            J = np.einsum("ij,njk,nkl->nil", self._K[:2, :2], D, dn)
        J[~(depth > 0)] = np.nan
        return J[0] if single else J

    # -- geometry
    def decompose(self) -> CameraGeometry:
        """Camera centre, focal length, IFOV, principal point and viewing direction.

        RQ decomposition of ``M[:, :3]`` (for a model built from ``K, R, C``
        these are returned as given). Use these numbers to sanity-check a
        calibration: the paper's VarioCAM HD has IFOV 0.57 mrad, f ≈ 1754 px.
        """
        K, R, C = self._K.copy(), self._R.copy(), self._C.copy()
        fx, fy = float(K[0, 0]), float(K[1, 1])
        f = 0.5 * (fx + fy)
        return CameraGeometry(K=K, R=R, C=C, focal_length_px=f, fx=fx, fy=fy, skew=float(K[0, 1]),
                              ifov_mrad=1000.0 / f, principal_point=K[:2, 2].copy(),
                              viewing_direction=R[2].copy())

    # -- uncertainty
    def _param_vector(self) -> tuple[np.ndarray, callable]:
        if self.parameters == PHYSICAL_PARAMETERS:
            K = self._K
            p = np.array([0.5 * (K[0, 0] + K[1, 1]), K[0, 2], K[1, 2], 0, 0, 0, *self._C, self.k1, self.k2])
            R0 = self._R
            return p, lambda q, x: _project_physical(q, x, R0)
        if self.parameters == MATRIX_PARAMETERS:
            return self._M.ravel().copy(), lambda q, x: _project_M(q.reshape(3, 4), x)[0]
        raise CalibrationError(f"unknown parametrisation {self.parameters!r} of the covariance")

    def projection_uncertainty(self, x) -> np.ndarray:
        """Standard uncertainty of the projected position from the parameter covariance.

        ``sqrt(trace(J_p Σ J_p^T))`` where ``J_p`` (2, P) is the derivative of
        the pixel position with respect to the calibrated parameters (central
        differences) and ``Σ`` their covariance.

        Parameters
        ----------
        x : array_like, shape (N, 3) or (3,)
            Points, mm.

        Returns
        -------
        ndarray, shape (N,) or scalar
            px (the radial RMS of the projected position).
        """
        if self.covariance is None:
            raise CalibrationError(
                "this camera model carries no parameter covariance (it was built from M or K, R, C alone); "
                "use the model returned by fit_dlt, refine or load_camera"
            )
        pts, single = _model_points(x)
        p, fn = self._param_vector()
        var = np.zeros(len(pts))
        jac = np.zeros((len(pts), 2, len(p)))
        for j in range(len(p)):
            if not self.covariance[j].any():
                continue
            h = 1e-6 * max(1.0, abs(p[j]))
            qp, qm = p.copy(), p.copy()
            qp[j] += h
            qm[j] -= h
            jac[:, :, j] = (fn(qp, pts) - fn(qm, pts)) / (2 * h)
        var = np.einsum("nij,jk,nik->n", jac, self.covariance, jac)
        out = np.sqrt(np.clip(var, 0, None))
        out[~(self.depth(pts) > 0)] = np.nan
        return out[0] if single else out

    # -- storage
    def to_dataset(self) -> xr.Dataset:
        """The model as an xarray Dataset (names shared with ``calibration.zarr``)."""
        g = self.decompose()
        ds = xr.Dataset(
            {
                "projection_matrix": (("row", "col"), self._M,
                                      {"long_name": "pinhole projection matrix M = K [R | -R C], ||M[2,:3]|| = 1",
                                       "units": "px (rows 0-1), 1 (row 2); acts on [x, y, z in mm, 1]"}),
                "K": (("row3", "col3"), g.K, {"long_name": "intrinsic matrix", "units": "px"}),
                "R": (("row3", "col3"), g.R,
                      {"long_name": "rotation, rows = camera axes (right, down, viewing) in the DIC frame",
                       "units": "1"}),
                "camera_centre": (("component",), g.C, {"long_name": "camera centre in the DIC frame", "units": "mm"}),
                "viewing_direction": (("component",), g.viewing_direction,
                                      {"long_name": "unit viewing direction in the DIC frame", "units": "1"}),
                "principal_point": (("axis",), g.principal_point, {"long_name": "principal point", "units": "px"}),
                "focal_length_px": ((), g.focal_length_px, {"long_name": "focal length", "units": "px"}),
                "ifov_mrad": ((), g.ifov_mrad, {"long_name": "instantaneous field of view 1000/f", "units": "mrad"}),
                "distortion": (("coefficient",), np.array([self.k1, self.k2]),
                               {"long_name": "radial distortion d = 1 + k1 r^2 + k2 r^4 (normalised coordinates)",
                                "units": "1"}),
            },
            coords={"row": [0, 1, 2], "col": [0, 1, 2, 3], "row3": [0, 1, 2], "col3": [0, 1, 2],
                    "component": ["x", "y", "z"], "axis": ["u", "v"], "coefficient": ["k1", "k2"]},
        )
        if self.covariance is not None:
            ds["covariance"] = xr.DataArray(
                self.covariance, dims=("parameter", "parameter_2"),
                coords={"parameter": list(self.parameters), "parameter_2": list(self.parameters)},
                attrs={"long_name": "covariance of the camera parameters (f, cx, cy px; r rad, small rotation "
                                    "applied left of R; C mm; k1, k2) or of the entries of M",
                       "units": "mixed (products of the parameter units)"},
            )
        return ds

    @classmethod
    def from_dataset(cls, ds: xr.Dataset) -> "CameraModel":
        """Rebuild a model from :meth:`to_dataset` output or a ``calibration.zarr`` dataset."""
        missing = [k for k in ("projection_matrix", "distortion") if k not in ds]
        if missing:
            raise DataError(f"dataset is not a camera calibration: variables {missing} are missing")
        cov = params = None
        if "covariance" in ds:
            cov = np.asarray(ds["covariance"].values, dtype=np.float64)
            params = [str(p) for p in ds["parameter"].values]
        k = np.asarray(ds["distortion"].values, dtype=np.float64)
        M = np.asarray(ds["projection_matrix"].values, dtype=np.float64)
        if M.shape != (3, 4) or k.shape != (2,):
            raise DataError(f"projection_matrix must be (3, 4) and distortion (2,), got {M.shape} and {k.shape}")
        if (k != 0).any() or tuple(params or ()) == PHYSICAL_PARAMETERS:
            return cls(K=ds["K"].values, R=ds["R"].values, C=ds["camera_centre"].values, k1=k[0], k2=k[1],
                       covariance=cov, parameters=params)
        return cls(M, covariance=cov, parameters=params)

    def __repr__(self) -> str:
        g = self.decompose()
        c = ", ".join(f"{v:.2f}" for v in g.C)
        vd = ", ".join(f"{v:.3f}" for v in g.viewing_direction)
        return (f"CameraModel(centre=({c}) mm, f={g.focal_length_px:.1f} px, IFOV={g.ifov_mrad:.4f} mrad, "
                f"principal point=({g.principal_point[0]:.1f}, {g.principal_point[1]:.1f}) px, "
                f"viewing direction=({vd}), k1={self.k1:.3g}, k2={self.k2:.3g})")


# ----------------------------------------------------------------------------- refinement


def refine(model: CameraModel, x, uv, *, distortion: str = "none", weights=None,
           max_nfev: int = 200) -> tuple[CameraModel, dict]:
    """Minimise the reprojection error by Levenberg-Marquardt from a start model.

    Parameters: ``f, cx, cy`` (square pixels, no skew), a rotation vector
    (applied to the start rotation), the camera centre ``C`` and, with
    ``distortion``, ``k1`` (and ``k2``). The parameter covariance is
    ``s^2 (J^T J)^-1`` with ``J`` the Jacobian at the solution and ``s^2``
    the residual variance ``SSR / (2N - P)``.

    Parameters
    ----------
    model : CameraModel
        Start (usually the DLT); its skew and aspect ratio are dropped.
    x : array_like, shape (N, 3)
        Points, mm.
    uv : array_like, shape (N, 2)
        Measured pixel positions, px.
    distortion : {"none", "k1", "k1k2"}
        Which radial distortion coefficients are free ("none": pinhole, k = 0).
    weights : array_like, shape (N,), optional
        Weight of each point's residual (``1 / sigma``).
    max_nfev : int
        Limit of function evaluations (per free parameter scale, see
        :func:`scipy.optimize.least_squares`).

    Returns
    -------
    model : CameraModel
        With ``covariance`` over :data:`PHYSICAL_PARAMETERS` (rows and columns
        of parameters held fixed are 0).
    info : dict
        ``residuals`` (N, 2) px, ``rms_px``, ``max_px``, ``sigma_px``,
        ``nfev``, ``message``, ``free`` (names of the free parameters).

    Raises
    ------
    CalibrationError
        Too few points, or the refinement failed or ended behind the camera.
    """
    if not isinstance(model, CameraModel):
        raise ConfigError(f"`model` must be a CameraModel, got {type(model).__name__}")
    if distortion not in _DISTORTIONS:
        raise ConfigError(f"`distortion` must be one of {sorted(_DISTORTIONS)}, got {distortion!r}")
    x, uv = _pairs(x, uv)
    n = len(x)
    free_names = ("f", "cx", "cy", "rx", "ry", "rz", "Cx", "Cy", "Cz") + _DISTORTIONS[distortion]
    if 2 * n <= len(free_names):
        raise CalibrationError(f"refinement of {len(free_names)} parameters needs more than {len(free_names) // 2} "
                               f"points, got {n}")
    w = _weights(weights, n)
    wr = None if w is None else np.repeat(w, 2)
    free = np.array([PHYSICAL_PARAMETERS.index(k) for k in free_names])
    g = model.decompose()
    p0 = np.array([g.focal_length_px, g.K[0, 2], g.K[1, 2], 0, 0, 0, *g.C,
                   model.k1 if "k1" in free_names else 0.0, model.k2 if "k2" in free_names else 0.0])
    R0 = g.R

    def fun(q, R_base=R0, base=p0):
        p = base.copy()
        p[free] = q
        r = (_project_physical(p, x, R_base) - uv).ravel()
        return r if wr is None else r * wr

    try:
        res = least_squares(fun, p0[free], method="lm", x_scale="jac", max_nfev=max_nfev * len(free))
    except (ValueError, np.linalg.LinAlgError) as exc:  # pragma: no cover - defensive
        raise CalibrationError(f"refinement of the camera failed: {exc}") from exc
    if not np.isfinite(res.x).all() or res.status <= 0:
        raise CalibrationError(f"refinement of the camera did not converge: {res.message}")
    p = p0.copy()
    p[free] = res.x
    R = _rotation(p[3:6]) @ R0
    if p[0] <= 0:
        raise CalibrationError(f"refinement ended with a negative focal length ({p[0]:.1f} px)")
    # Jacobian at the solution with the rotation re-based there, so that the
    # covariance of (rx, ry, rz) is that of a small rotation about the final R.
    pb = p.copy()
    pb[3:6] = 0.0
    J = np.empty((2 * n, len(free)))
    for j, k in enumerate(free):
        h = 1e-6 * max(1.0, abs(pb[k]))
        qp, qm = pb[free].copy(), pb[free].copy()
        qp[j] += h
        qm[j] -= h
        J[:, j] = (fun(qp, R, pb) - fun(qm, R, pb)) / (2 * h)
    r = fun(pb[free], R, pb)
    dof = max(2 * n - len(free), 1)
    s2 = float(r @ r) / dof
    try:
        cov_free = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov_free = np.full((len(free), len(free)), np.nan)
    cov = np.zeros((len(PHYSICAL_PARAMETERS),) * 2)
    cov[np.ix_(free, free)] = cov_free
    K = np.array([[p[0], 0, p[1]], [0, p[0], p[2]], [0, 0, 1.0]])
    out = CameraModel(K=K, R=R, C=p[6:9], k1=p[9], k2=p[10], covariance=cov, parameters=PHYSICAL_PARAMETERS)
    if not (out.depth(x) > 0).all():
        raise CalibrationError("refinement moved the camera so that markers lie behind it; check the correspondence")
    resid = out.project(x) - uv
    info = _residual_info(resid, np.sqrt(s2))
    info.update(nfev=int(res.nfev), message=str(res.message), free=list(free_names))
    log.debug("refine(%s): rms %.4f px after %d evaluations", distortion, info["rms_px"], res.nfev)
    return out, info


def leave_one_out(x, uv, *, method: str = "dlt", distortion: str = "none", weights=None,
                  start: CameraModel | None = None) -> np.ndarray:
    """Residual of each point when it is left out of the fit.

    A marker whose leave-one-out residual is far above the others is badly
    detected or wrongly assigned.

    Parameters
    ----------
    x, uv : array_like, shapes (N, 3) and (N, 2)
        Points (mm) and pixel positions (px).
    method : {"dlt", "refine"}
        Fit used for each subset: the DLT alone, or the DLT followed by
        :func:`refine` with ``distortion``.
    distortion : {"none", "k1", "k1k2"}
        For ``method="refine"``.
    weights : array_like (N,), optional
        As in :func:`dlt`.
    start : CameraModel, optional
        Start of each refinement (the fit to all points converges faster
        than each subset's DLT); default: the subset's DLT.

    Returns
    -------
    ndarray, shape (N,)
        Distance in px between each left-out point's measured and predicted
        position; NaN when the remaining points cannot be fitted (fewer than
        6, coplanar).
    """
    if method not in ("dlt", "refine"):
        raise ConfigError(f"`method` must be 'dlt' or 'refine', got {method!r}")
    x, uv = _pairs(x, uv)
    n = len(x)
    w = _weights(weights, n) if weights is not None else None
    out = np.full(n, np.nan)
    keep = np.ones(n, dtype=bool)
    for i in range(n):
        keep[:] = True
        keep[i] = False
        wi = None if w is None else w[keep]
        try:
            if method == "refine" and start is not None:
                m, _ = refine(start, x[keep], uv[keep], distortion=distortion, weights=wi)
            else:
                m = CameraModel(dlt(x[keep], uv[keep], wi))
                if method == "refine":
                    m, _ = refine(m, x[keep], uv[keep], distortion=distortion, weights=wi)
        except CalibrationError:
            continue
        out[i] = float(np.hypot(*(m.project(x[i]) - uv[i])))
    return out
