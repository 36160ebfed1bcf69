"""The IR camera model: a projection of DIC points (mm) into IR pixels.

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

This module knows projections and nothing about images, files or RBFs; the
fits that produce a model are in :mod:`irdic.camera.dlt` and
:mod:`irdic.camera.refine`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.linalg
import xarray as xr
from scipy.spatial.transform import Rotation

from ..errors import CalibrationError, ConfigError, DataError

__all__ = [
    "CameraModel",
    "CameraGeometry",
    "load_camera",
    "PHYSICAL_PARAMETERS",
    "MATRIX_PARAMETERS",
    "point_array",
    "point_pairs",
    "pair_weights",
    "normalise_matrix",
    "project_matrix",
    "project_physical",
    "rotation_from_vector",
]

#: Names of the physical parameters (``r*`` = small rotation vector, rad,
#: applied on the left of the model's ``R``; ``C*`` = camera centre, mm).
PHYSICAL_PARAMETERS = ("f", "cx", "cy", "rx", "ry", "rz", "Cx", "Cy", "Cz", "k1", "k2")
#: Names of the entries of ``M`` (row-major) for a DLT-only model.
MATRIX_PARAMETERS = tuple(f"m{r}{c}" for r in (1, 2, 3) for c in (1, 2, 3, 4))


# ----------------------------------------------------------------------------- checks
# TODO(redesign): move point_array / point_pairs / pair_weights into irdic.validation


def point_array(a, name: str, dim: int) -> np.ndarray:
    """``a`` as a float64 (N, dim) array of finite values, or an irdic error.

    Parameters
    ----------
    a : array_like, shape (N, dim)
        Points (mm or px).
    name : str
        Argument name for the message.
    dim : int
        Number of coordinates per point.

    Returns
    -------
    ndarray, shape (N, dim)

    Raises
    ------
    ConfigError
        Not numeric or of the wrong shape.
    DataError
        NaN or infinite rows (named).
    """
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


def point_pairs(x, uv) -> tuple[np.ndarray, np.ndarray]:
    """Checked marker/pixel pairs: ``x`` (N, 3) mm and ``uv`` (N, 2) px of equal length."""
    x = point_array(x, "x", 3)
    uv = point_array(uv, "uv", 2)
    if len(x) != len(uv):
        raise ConfigError(f"`x` has {len(x)} points but `uv` has {len(uv)}; expected one pixel position per point")
    return x, uv


def pair_weights(weights, n: int) -> np.ndarray | None:
    """Checked per-pair weights (N,), finite, >= 0, at least 6 positive; None stays None."""
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


def normalise_matrix(M: np.ndarray) -> np.ndarray:
    """Projection matrix (3, 4) scaled to ``||M[2, :3]|| = 1`` with ``det(M[:, :3]) > 0``.

    Raises
    ------
    CalibrationError
        The third row is zero (no camera).
    """
    n = np.linalg.norm(M[2, :3])
    if not np.isfinite(n) or n == 0:
        raise CalibrationError("projection matrix has a zero third row; it is not a camera")
    M = M / n
    # det(K R) > 0 for a camera with f > 0 and a proper rotation: fixes the sign.
    if np.linalg.det(M[:, :3]) < 0:
        M = -M
    return M


def project_matrix(M: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of points ``x`` (N, 3) mm: ``(uv (N, 2) px, depth (N,) mm)``.

    Points at depth 0 give inf/NaN pixel positions (no warning).
    """
    h = x @ M[:, :3].T + M[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = h[:, :2] / h[:, 2:3]
    return uv, h[:, 2]


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
    if np.linalg.det(R) < 0:  # only for a mirrored M, which normalise_matrix excludes
        raise CalibrationError("projection matrix has det(M[:, :3]) < 0: it describes a mirrored camera")
    # A DLT of nearly degenerate pairs can give a singular left block: its camera centre lies at
    # infinity (an affine camera), which no pinhole calibration describes.
    if not np.isfinite(Kr).all() or np.linalg.cond(M[:, :3]) > 1e12 or K[2, 2] == 0:
        raise CalibrationError("projection matrix has a singular left 3x3 block (camera centre at infinity): "
                               "it is not a pinhole camera")
    K = K / K[2, 2]
    C = -np.linalg.solve(M[:, :3], M[:, 3])
    return K, R, C


def rotation_from_vector(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a rotation vector (3,), rad."""
    return Rotation.from_rotvec(rvec).as_matrix()


def project_physical(p: np.ndarray, x: np.ndarray, R0: np.ndarray) -> np.ndarray:
    """Projection with physical parameters ``p`` around rotation ``R0``.

    Parameters
    ----------
    p : ndarray, shape (11,)
        Values of :data:`PHYSICAL_PARAMETERS` (the rotation vector is applied
        on the left of ``R0``).
    x : ndarray, shape (N, 3)
        Points, mm.
    R0 : ndarray, shape (3, 3)
        Base rotation.

    Returns
    -------
    ndarray, shape (N, 2)
        Pixel positions, px.
    """
    f, cx, cy = p[0], p[1], p[2]
    R = rotation_from_vector(p[3:6]) @ R0
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
            self._M = normalise_matrix(M)
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
            self._M = normalise_matrix(self._K @ np.hstack([R, -(R @ C)[:, None]]))
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
            uv, depth = project_matrix(self._M, pts)
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
            uv, depth = project_matrix(self._M, pts)
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
            return p, lambda q, x: project_physical(q, x, R0)
        if self.parameters == MATRIX_PARAMETERS:
            return self._M.ravel().copy(), lambda q, x: project_matrix(q.reshape(3, 4), x)[0]
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



def load_camera(cal_ds: xr.Dataset) -> CameraModel:
    """The calibrated :class:`CameraModel` from a calibration dataset/store.

    Parameters
    ----------
    cal_ds : xarray.Dataset
        ``calibration.zarr`` content (see :func:`irdic.calibration.calibrate`)
        or :meth:`CameraModel.to_dataset` output.

    Returns
    -------
    CameraModel
    """
    return CameraModel.from_dataset(cal_ds)
