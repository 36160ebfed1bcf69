"""The TRUE IR camera of the synthetic experiments.

This is the ground truth the calibration code (:mod:`irdic.camera`) is tested
against, so it is written independently of it and follows the shared
convention exactly:

- World frame = DIC frame (mm). Pose: centre ``C`` (3,), rotation ``R`` (3, 3)
  whose rows are the camera axes in world coordinates: row 0 = image right
  (+u), row 1 = image down (+v), row 2 = viewing direction. Camera coordinates
  ``X_c = R (X - C)``; a point is in front when ``X_c[2] > 0``.
- Normalised coordinates ``x_n = X_c[0] / X_c[2]``, ``y_n = X_c[1] / X_c[2]``;
  radial distortion ``r2 = x_n**2 + y_n**2``, ``d = 1 + k1 r2 + k2 r2**2``,
  ``x_d = d x_n``, ``y_d = d y_n``.
- Pixels ``u = f x_d + cx``, ``v = f y_d + cy`` (square pixels, no skew);
  pixel centres on integers, ``u`` = column, ``v`` = row (downwards).
- Pinhole projection matrix ``M = K [R | -R C]``, normalised so that
  ``||M[2, :3]|| = 1`` and ``M[2] @ [X, 1] > 0`` in front.

The lab camera (:func:`lab_camera`) is the paper's InfraTec VarioCAM HD with
the 30 mm lens: 1024 x 768 px, IFOV 0.57 mrad, hence ``f = 1/0.57e-3 =
1754.39 px``, principal point (511.5, 383.5). It stands 450 mm from the point
(0, 0, -5) mm of the DIC frame (the centre of the observed specimen surfaces),
17.5 deg to the +x side of the DIC z axis and 10 deg above it, with a 1 deg
roll: an 80 x 50 mm specimen then covers about 310 x 190 px and a 1.6 mm
marker radius about 6.2 px.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, GeometryError
from ..validation import as_finite, as_int, as_points, positive

__all__ = ["TrueCamera", "look_at", "lab_camera", "IR_F", "IR_SIZE", "LAB_TARGET"]

#: Focal length of the paper's IR camera in px (IFOV 0.57 mrad).
IR_F = 1.0 / 0.57e-3
#: Sensor size (width, height) in px.
IR_SIZE = (1024, 768)
#: The point (mm, DIC frame) the lab camera looks at.
LAB_TARGET = (0.0, 0.0, -5.0)


def look_at(centre, target, up=(0.0, 1.0, 0.0), roll_deg: float = 0.0) -> np.ndarray:
    """Rotation matrix of a camera at ``centre`` looking at ``target``.

    Parameters
    ----------
    centre, target : array_like, shape (3,)
        Camera centre and the point on the optical axis (mm).
    up : array_like, shape (3,)
        World direction that appears upwards in the image (before roll).
    roll_deg : float
        Roll of the camera about its viewing direction (deg): positive turns
        the image axes from +u towards +v, so the scene appears turned
        counter-clockwise in the image.

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        ``R`` with rows image-right, image-down, viewing direction.
    """
    c = as_finite(centre, "centre", (3,))
    t = as_finite(target, "target", (3,))
    up = as_finite(up, "up", (3,))
    z = t - c
    nz = np.linalg.norm(z)
    if nz == 0:
        raise ConfigError("`centre` and `target` coincide; the viewing direction is undefined")
    z = z / nz
    x = np.cross(z, up)
    nx = np.linalg.norm(x)
    if nx < 1e-9 * max(1.0, np.linalg.norm(up)):
        raise ConfigError(f"`up` {up.tolist()} is parallel to the viewing direction {z.tolist()}")
    x = x / nx
    y = np.cross(z, x)
    r = math.radians(float(roll_deg))
    x, y = math.cos(r) * x + math.sin(r) * y, -math.sin(r) * x + math.cos(r) * y
    return np.stack([x, y, z])


@dataclass(frozen=True, eq=False)
class TrueCamera:
    """A pinhole camera with two-term radial distortion (the truth).

    Parameters
    ----------
    f : float
        Focal length (px).
    cx, cy : float
        Principal point (px).
    R : array_like, shape (3, 3)
        Rotation, rows = camera axes in world coordinates (see module doc).
    C : array_like, shape (3,)
        Camera centre (mm, world = DIC frame).
    k1, k2 : float
        Radial distortion coefficients (0 = pinhole).
    width, height : int
        Sensor size (px).
    """

    f: float
    cx: float
    cy: float
    R: np.ndarray
    C: np.ndarray
    k1: float = 0.0
    k2: float = 0.0
    width: int = IR_SIZE[0]
    height: int = IR_SIZE[1]
    _rmax: float = field(init=False, repr=False, compare=False, default=np.inf)

    def __post_init__(self):
        positive(self.f, "f")
        for name in ("cx", "cy", "k1", "k2"):
            as_finite(getattr(self, name), name, ())
        as_int(self.width, "width")
        as_int(self.height, "height")
        R = as_finite(self.R, "R", (3, 3))
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
            raise ConfigError("`R` must be a proper rotation (R R^T = I, det R = +1) within 1e-9")
        object.__setattr__(self, "R", R.copy())
        object.__setattr__(self, "C", as_finite(self.C, "C", (3,)).copy())
        self.R.flags.writeable = False
        self.C.flags.writeable = False
        for name in ("f", "cx", "cy", "k1", "k2"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "_rmax", self._monotone_radius())

    # -- construction -------------------------------------------------------------
    @classmethod
    def looking_at(cls, centre, target, *, up=(0.0, 1.0, 0.0), roll_deg=0.0, f=IR_F,
                   cx=None, cy=None, k1=0.0, k2=0.0, size=IR_SIZE) -> "TrueCamera":
        """Camera at ``centre`` looking at ``target`` (see :func:`look_at`).

        ``cx, cy`` default to the sensor centre ``((W-1)/2, (H-1)/2)``.
        """
        w, h = size
        cx = (w - 1) / 2 if cx is None else cx
        cy = (h - 1) / 2 if cy is None else cy
        R = look_at(centre, target, up, roll_deg)
        return cls(f=f, cx=cx, cy=cy, R=R, C=np.asarray(centre, float), k1=k1, k2=k2, width=w, height=h)

    def _monotone_radius(self) -> float:
        """Largest normalised radius up to which ``r -> r d(r)`` increases.

        Beyond it the distortion model folds the image and undistortion has
        no unique answer.
        """
        # d/dr [r + k1 r^3 + k2 r^5] = 1 + 3 k1 r^2 + 5 k2 r^4, a quadratic in r^2
        roots = np.roots([5 * self.k2, 3 * self.k1, 1.0]) if self.k2 != 0 else (
            np.array([-1.0 / (3 * self.k1)]) if self.k1 != 0 else np.array([]))
        roots = [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and r.real > 0]
        return math.sqrt(min(roots)) if roots else np.inf

    # -- matrices ---------------------------------------------------------------
    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix (3, 3)."""
        return np.array([[self.f, 0.0, self.cx], [0.0, self.f, self.cy], [0.0, 0.0, 1.0]])

    def matrix(self) -> np.ndarray:
        """Normalised pinhole projection matrix ``M = K [R | -R C]`` (3, 4).

        ``||M[2, :3]|| = 1`` (it is the viewing direction) and ``M[2] @ [X, 1]``
        is the depth of ``X``, positive in front. Distortion is not part of it.
        """
        Rt = np.hstack([self.R, -(self.R @ self.C)[:, None]])
        M = self.K @ Rt
        return M / np.linalg.norm(M[2, :3])

    # -- projection -------------------------------------------------------------
    def to_camera(self, X) -> np.ndarray:
        """Camera coordinates ``R (X - C)`` of world points ``X`` (..., 3)."""
        X = as_points(X, "X")
        return (X - self.C) @ self.R.T

    def distort(self, xn, yn):
        """Apply radial distortion to normalised coordinates (arrays)."""
        r2 = xn * xn + yn * yn
        d = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
        return d * xn, d * yn

    def undistort(self, xd, yd, *, tol: float = 1e-12, maxiter: int = 60):
        """Invert :meth:`distort` by Newton iteration on the radius.

        Parameters
        ----------
        xd, yd : array_like
            Distorted normalised coordinates.
        tol : float
            Absolute tolerance on the normalised radius (1e-12 is ~2e-9 px).

        Returns
        -------
        xn, yn : numpy.ndarray
            Undistorted normalised coordinates.

        Raises
        ------
        GeometryError
            A point lies beyond the radius where the distortion folds.
        """
        xd = np.asarray(xd, dtype=np.float64)
        yd = np.asarray(yd, dtype=np.float64)
        if self.k1 == 0.0 and self.k2 == 0.0:
            return xd.copy(), yd.copy()
        rd = np.hypot(xd, yd)
        r = rd.copy()
        for _ in range(maxiter):
            r2 = r * r
            g = r * (1.0 + self.k1 * r2 + self.k2 * r2 * r2) - rd
            dg = 1.0 + 3.0 * self.k1 * r2 + 5.0 * self.k2 * r2 * r2
            step = g / dg
            r = r - step
            if np.all(np.abs(step) <= tol):
                break
        else:
            raise GeometryError(f"undistortion did not converge to {tol} in {maxiter} Newton steps "
                                f"(k1={self.k1}, k2={self.k2}, largest radius {rd.max():.4g})")
        if np.any(r > self._rmax) or np.any(r < 0):
            raise GeometryError(
                f"pixel beyond the fold of the distortion model (normalised radius > {self._rmax:.4g} "
                f"with k1={self.k1}, k2={self.k2})")
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.where(rd > 0, r / np.where(rd > 0, rd, 1.0), 1.0)
        return xd * scale, yd * scale

    def project(self, X, *, return_depth: bool = False):
        """Pixel coordinates of world points.

        Parameters
        ----------
        X : array_like, shape (..., 3)
            World points (mm).
        return_depth : bool
            Also return the depth ``X_c[2]`` (mm).

        Returns
        -------
        uv : numpy.ndarray, shape (..., 2)
            ``(u, v)`` in px; NaN for points not in front of the camera.
        depth : numpy.ndarray, shape (...)
            Only with ``return_depth``.
        """
        Xc = self.to_camera(X)
        z = Xc[..., 2]
        front = z > 0
        zs = np.where(front, z, np.nan)
        xd, yd = self.distort(Xc[..., 0] / zs, Xc[..., 1] / zs)
        uv = np.stack([self.f * xd + self.cx, self.f * yd + self.cy], axis=-1)
        return (uv, z) if return_depth else uv

    def jacobian(self, X) -> np.ndarray:
        """Derivative of :meth:`project` with respect to the world point.

        Returns
        -------
        numpy.ndarray, shape (..., 2, 3)
            ``d(u, v)/dX`` in px/mm (distortion included).
        """
        Xc = self.to_camera(X)
        x, y, z = Xc[..., 0], Xc[..., 1], Xc[..., 2]
        xn, yn = x / z, y / z
        r2 = xn * xn + yn * yn
        d = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
        dd = 2.0 * (self.k1 + 2.0 * self.k2 * r2)  # d(d)/d(xn) = dd * xn
        D = np.empty(x.shape + (2, 2))
        D[..., 0, 0] = d + dd * xn * xn
        D[..., 0, 1] = dd * xn * yn
        D[..., 1, 0] = dd * xn * yn
        D[..., 1, 1] = d + dd * yn * yn
        N = np.zeros(x.shape + (2, 3))
        N[..., 0, 0] = 1.0 / z
        N[..., 0, 2] = -x / z**2
        N[..., 1, 1] = 1.0 / z
        N[..., 1, 2] = -y / z**2
        return self.f * (D @ N @ self.R)

    def ray(self, u, v):
        """World ray through pixel position ``(u, v)``.

        Parameters
        ----------
        u, v : array_like
            Pixel coordinates (broadcast together).

        Returns
        -------
        origin : numpy.ndarray, shape (3,)
            The camera centre ``C`` (mm).
        direction : numpy.ndarray, shape (..., 3)
            Unit direction vectors in world coordinates.
        """
        u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
        xn, yn = self.undistort((u - self.cx) / self.f, (v - self.cy) / self.f)
        # R^T (xn, yn, 1); R is orthonormal, so the length is sqrt(1 + xn^2 + yn^2)
        inv = 1.0 / np.sqrt(1.0 + xn * xn + yn * yn)
        xn, yn = xn * inv, yn * inv
        d = xn[..., None] * self.R[0] + yn[..., None] * self.R[1] + inv[..., None] * self.R[2]
        return self.C.copy(), d

    def in_frame(self, uv) -> np.ndarray:
        """True where pixel positions ``uv`` (..., 2) lie on the sensor."""
        uv = np.asarray(uv, dtype=np.float64)
        u, v = uv[..., 0], uv[..., 1]
        with np.errstate(invalid="ignore"):
            return (u >= -0.5) & (u <= self.width - 0.5) & (v >= -0.5) & (v <= self.height - 0.5)

    def describe(self) -> dict:
        """Plain-number summary (for stores and logs)."""
        return {"f": self.f, "cx": self.cx, "cy": self.cy, "k1": self.k1, "k2": self.k2,
                "width": self.width, "height": self.height, "C": self.C.tolist(), "R": self.R.tolist()}


def lab_camera(*, distance: float = 450.0, azimuth_deg: float = 17.5, elevation_deg: float = 10.0,
               roll_deg: float = 1.0, target=LAB_TARGET, k1: float = 0.0, k2: float = 0.0) -> TrueCamera:
    """The IR camera of the synthetic lab (see the module docstring).

    Parameters
    ----------
    distance : float
        Distance from ``target`` (mm).
    azimuth_deg : float
        Angle of the camera towards +x from the DIC z axis (deg).
    elevation_deg : float
        Angle above the horizontal x-z plane (deg).
    roll_deg : float
        Image roll (deg).
    target : array_like, shape (3,)
        Point on the optical axis (mm).
    k1, k2 : float
        Radial distortion of the true camera.

    Returns
    -------
    TrueCamera
    """
    positive(distance, "distance")
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    t = as_finite(target, "target", (3,))
    centre = t + distance * np.array([math.sin(a) * math.cos(e), math.sin(e), math.cos(a) * math.cos(e)])
    return TrueCamera.looking_at(centre, t, roll_deg=roll_deg, k1=k1, k2=k2)
