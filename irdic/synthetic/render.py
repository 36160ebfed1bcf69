"""Ray casting of IR frames and of the continuous IR field of a scene.

An IR frame is rendered by POINT SAMPLING: each pixel gets the noise-free
temperature where the ray through its centre (integer ``u, v``) first hits the
scene, plus independent Gaussian noise (default 0.05 K, the camera's NETD).
No optical blur and no pixel-area integration: the value at pixel ``(u, v)``
is exactly ``Theta_hat(u, v, t)``, the ray-cast field, so a material point
that projects onto a pixel centre carries exactly its closed-form temperature.
(The calibration target, where the perspective bias of marker centres must be
real, is area-sampled instead: see :mod:`irdic.synthetic.target`.)

``Theta_hat(u, v, t)`` is defined for any real pixel position; its pixel
derivatives and its local time derivative at a fixed pixel are evaluated by
central differences of the ray caster (:func:`pixel_derivatives`).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..errors import ConfigError
from ..validation import positive
from .camera import TrueCamera
from .specimens import LABEL_SURFACE, Hit

__all__ = ["Window", "check_window", "FrameRenderer", "field", "pixel_derivatives", "visibility", "realistic_stack"]

#: Crop window ``(u0, v0, width, height)`` in px (``u0, v0`` = StartPos).
Window = tuple


def check_window(window, camera: TrueCamera) -> tuple[int, int, int, int]:
    """Validate a crop window against the sensor; ``None`` = full sensor."""
    if window is None:
        return (0, 0, camera.width, camera.height)
    try:
        u0, v0, w, h = (int(x) for x in window)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`window` must be (u0, v0, width, height) in px; got {window!r}") from exc
    if w < 1 or h < 1 or u0 < 0 or v0 < 0 or u0 + w > camera.width or v0 + h > camera.height:
        raise ConfigError(
            f"`window` {(u0, v0, w, h)} must lie on the {camera.width} x {camera.height} sensor "
            f"(u0 >= 0, v0 >= 0, u0 + width <= {camera.width}, v0 + height <= {camera.height})")
    return (u0, v0, w, h)


def _times_like(t, a):
    """``t`` with leading unit axes so that it broadcasts against ``a``.

    It is not expanded: the time functions of a scene are then evaluated once
    per distinct time, not once per ray.
    """
    t = np.asarray(t, np.float64)
    a = np.asarray(a)
    if t.ndim > a.ndim or np.broadcast_shapes(t.shape, a.shape) != a.shape:
        raise ConfigError(f"times of shape {t.shape} do not broadcast against points of shape {a.shape}")
    return t.reshape((1,) * (a.ndim - t.ndim) + t.shape)


def field(specimen, camera: TrueCamera, u, v, t) -> Hit:
    """The noise-free ray-cast IR field ``Theta_hat(u, v, t)``.

    Parameters
    ----------
    specimen : Specimen
        The scene (specimen with its surroundings).
    camera : TrueCamera
    u, v : array_like
        Pixel positions (any real values, broadcast together).
    t : float or array_like
        Time (s), broadcast against ``u, v``.

    Returns
    -------
    Hit
        ``temperature`` is ``Theta_hat``; ``label`` says what was hit.
    """
    o, d = camera.ray(u, v)
    return specimen.trace(o, d, t)


def pixel_derivatives(specimen, camera: TrueCamera, uv, t, *, du: float = 1e-2, dt: float = 1e-3):
    """Pixel-space gradient and local rate of the ray-cast field.

    Central differences of :func:`field` (step ``du`` px and ``dt`` s; the
    truncation error is below 1e-7 K/px for the demo fields).

    Parameters
    ----------
    uv : array_like, shape (..., 2)
        Pixel positions.
    t : float or array_like
        Times (s), broadcast against ``uv[..., 0]``.

    Returns
    -------
    dT_du, dT_dv : numpy.ndarray
        ``dTheta_hat/du``, ``dTheta_hat/dv`` (K/px).
    dT_dt : numpy.ndarray
        ``dTheta_hat/dt`` at the fixed pixel (K/s).
        All NaN where a stencil point does not hit the observed surface.
    """
    uv = np.asarray(uv, np.float64)
    u, v = uv[..., 0], uv[..., 1]
    t = _times_like(t, u)
    ok = np.isfinite(u) & np.isfinite(v)
    u = np.where(ok, u, camera.cx)
    v = np.where(ok, v, camera.cy)
    # one batched cast for the six stencil points
    U = np.stack([u + du, u - du, u, u, u, u])
    V = np.stack([v, v, v + du, v - du, v, v])
    Tt = np.stack([t, t, t, t, t + dt, t - dt])
    hit = field(specimen, camera, U, V, Tt)
    T = np.where(hit.label == LABEL_SURFACE, hit.temperature, np.nan)
    dTdu = (T[0] - T[1]) / (2 * du)
    dTdv = (T[2] - T[3]) / (2 * du)
    dTdt = (T[4] - T[5]) / (2 * dt)
    bad = ~ok
    return (np.where(bad, np.nan, dTdu), np.where(bad, np.nan, dTdv), np.where(bad, np.nan, dTdt))


def visibility(specimen, camera: TrueCamera, x, t, *, tol: float = 1e-6) -> np.ndarray:
    """Whether the camera sees the surface points ``x`` (..., 3) at time ``t``.

    A point is visible when it is in front of the camera, projects onto the
    sensor, and the first thing the ray from the camera centre towards it hits
    is the observed surface at that very point (within ``tol`` mm): this
    covers back faces, self-occlusion and occlusion by fixtures.
    """
    x = np.asarray(x, np.float64)
    t = _times_like(t, x[..., 0])
    ok = np.all(np.isfinite(x), axis=-1)
    xs = np.where(ok[..., None], x, camera.C + camera.R[2])
    dvec = xs - camera.C
    dist = np.linalg.norm(dvec, axis=-1)
    hit = specimen.trace(camera.C, dvec / dist[..., None], t)
    uv, depth = camera.project(xs, return_depth=True)
    with np.errstate(invalid="ignore"):
        seen = (hit.label == LABEL_SURFACE) & (np.abs(hit.tau - dist) <= tol * np.maximum(1.0, dist / 100))
    return ok & seen & (depth > 0) & camera.in_frame(uv)


class FrameRenderer:
    """Render IR frames of one scene through one camera in one crop window.

    The pixel rays (with undistortion) are computed once.

    Parameters
    ----------
    specimen : Specimen
    camera : TrueCamera
    window : (u0, v0, width, height) or None
        Crop window in sensor pixels (``None``: the full sensor).
    """

    def __init__(self, specimen, camera: TrueCamera, window=None):
        self.specimen = specimen
        self.camera = camera
        self.window = check_window(window, camera)
        u0, v0, w, h = self.window
        self.u = np.arange(u0, u0 + w, dtype=np.float64)
        self.v = np.arange(v0, v0 + h, dtype=np.float64)
        uu, vv = np.meshgrid(self.u, self.v)
        self.origin, self.dirs = camera.ray(uu, vv)

    def clean(self, t: float) -> Hit:
        """Noise-free ray-cast result at time ``t`` (arrays of shape (height, width))."""
        return self.specimen.trace(self.origin, self.dirs, float(t))

    def __call__(self, t: float, *, noise: float = 0.05, rng=None) -> xr.DataArray:
        """One IR frame at time ``t`` (s).

        Parameters
        ----------
        noise : float
            Standard deviation of the Gaussian pixel noise (K).
        rng : numpy.random.Generator, optional
            Source of the noise (default: a fresh unseeded generator).

        Returns
        -------
        xarray.DataArray
            float32 temperatures (deg C), dims ``("v", "u")`` with full-sensor
            pixel coordinates and the scalar coordinate ``time``.
        """
        noise = positive(noise, "noise", allow_zero=True)
        T = self.clean(t).temperature
        if noise > 0:
            rng = np.random.default_rng() if rng is None else rng
            T = T + rng.normal(0.0, noise, T.shape)
        return xr.DataArray(
            T.astype(np.float32), dims=("v", "u"),
            coords={"v": self.v.astype(np.int64), "u": self.u.astype(np.int64), "time": float(t)},
            attrs={"units": "°C", "long_name": "apparent temperature", "noise_K": noise,
                   "sampling": "point sample at the pixel centre"},
            name="temperature",
        )


def realistic_stack(renderer: FrameRenderer, times, rng, *, noise: float = 0.05, decimals: int | None = 2,
                    mixed_edges: bool = True) -> np.ndarray:
    """IR frames as a real camera exports them: mixed edge pixels, pixel noise, rounding.

    Parameters
    ----------
    renderer : FrameRenderer
    times : array_like, shape (F,)
        Times of the frames (s, the scene's clock).
    rng : numpy.random.Generator
        Source of the noise.
    noise : float
        Standard deviation of the Gaussian pixel noise (K).
    decimals : int or None
        Exported decimals (2: 0.01 K steps); None keeps every digit.
    mixed_edges : bool
        Each pixel on either side of the specimen's outline gets the mean of
        its 3 x 3 neighbourhood: it sees specimen and background at once.

    Returns
    -------
    numpy.ndarray, shape (F, height, width)
        float32 deg C.
    """
    from scipy import ndimage

    noise = positive(noise, "noise", allow_zero=True)
    frames = []
    for t in np.asarray(times, float):
        hit = renderer.clean(t)
        T = np.asarray(hit.temperature, dtype=float)
        if mixed_edges:
            spec = hit.label == LABEL_SURFACE
            edge = ndimage.binary_dilation(spec) & ~ndimage.binary_erosion(spec)
            T = np.where(edge, ndimage.uniform_filter(T, 3, mode="nearest"), T)
        if noise > 0:
            T = T + rng.normal(0.0, noise, T.shape)
        frames.append((T if decimals is None else np.round(T, decimals)).astype(np.float32))
    return np.stack(frames)
