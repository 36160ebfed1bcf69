"""In-memory synthetic experiments: IR frames, DIC stages with defects, truth.

:func:`halfshell_experiment` and :func:`tube_experiment` return an
:class:`Experiment` from which tests and benchmarks take frames, DIC data and
truth without going through files; :func:`irdic.synthetic.make_demo` writes
the same experiment as raw exports.

Time 0 is the first DIC stage AND the first IR frame (simultaneous trigger);
IR frames come at ``k / ir_rate``, DIC stages at ``k / dic_rate`` (IR
faster), both ending at ``duration``. Per scale (frames, stages, points):

- ``tiny``: half-shell 4 s, IR 2 Hz (9 frames), DIC 1 Hz (5 stages), 273
  points; tube 6 s, IR 2 Hz (13 frames, one dropped), DIC 1 Hz (7), 273.
- ``demo``: half-shell 30 s, IR 2 Hz (61), DIC 1 Hz (31), 1683 points; tube
  10 s, IR 4 Hz (41, one dropped), DIC 2 Hz (21), 1581 points.
- ``paper``: half-shell 250 s, IR 2 Hz (501), DIC 1 Hz (251), 9875 points;
  tube 20 s, IR 25 Hz (501, one dropped), DIC 5 Hz (101), 9821 points.

DIC points lie on a grid that is regular in the DIC frame's x and y (as
facet grids in the DIC images are), inside the patch ``|s| <= s_e - 1 mm,
1 <= h <= 49 mm`` (half-shell) or ``|theta| <= 55 deg, |Z| <= 20 mm``
(tube). IDs are ``1000 * row + column + 1``. Measured coordinates carry
Gaussian noise (``dic_noise`` mm per component, per stage). Defects, never in
the reference stage 0: in about half of the later stages 1 % of the points
are NaN (failed facets), and a few points (N / 600, at least 2) are absent
from one or two stages.

IR crop windows (u0, v0, width, height) for the lab camera: half-shell
(360, 265, 330, 240), tube (430, 240, 190, 290): the specimen plus some
plate / clamp / room. With another camera the window is the box around the
projected specimen surface plus 20 px.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from ..errors import ConfigError
from ..validation import choice, positive
from .camera import TrueCamera, lab_camera
from .render import FrameRenderer, check_window
from .specimens import HalfShell, Specimen, Tube
from .truth import point_truth

__all__ = ["Experiment", "halfshell_experiment", "tube_experiment", "experiment", "SCALES", "EXPERIMENTS"]

log = logging.getLogger(__name__)

SCALES = ("tiny", "demo", "paper")
EXPERIMENTS = ("halfshell", "tube")

# duration (s), IR rate (Hz), DIC rate (Hz), grid (n_x, n_y), dropped IR frame (position) or None
_PLAN = {
    "halfshell": {
        "tiny": (4.0, 2.0, 1.0, (21, 13), None),
        "demo": (30.0, 2.0, 1.0, (51, 33), None),
        "paper": (250.0, 2.0, 1.0, (125, 79), None),
    },
    "tube": {
        "tiny": (6.0, 2.0, 1.0, (13, 21), 5),
        "demo": (10.0, 4.0, 2.0, (31, 51), 17),
        "paper": (20.0, 25.0, 5.0, (61, 161), 217),
    },
}
_WINDOW = {"halfshell": (360, 265, 330, 240), "tube": (430, 240, 190, 290)}
_CODE = {"halfshell": 1, "tube": 2}


@dataclass
class Experiment:
    """One synthetic experiment held in memory.

    Attributes
    ----------
    name : str
        ``"halfshell"`` or ``"tube"``.
    scale : str
    specimen : Specimen
    camera : TrueCamera
    window : (u0, v0, width, height)
        IR crop window (px).
    ir_times : numpy.ndarray, shape (F,)
        Times of the recorded IR frames (s), dropped frame excluded.
    ir_frame_numbers : numpy.ndarray of int, shape (F,)
        Position of each frame in the recording (0-based, with a gap where a
        frame was dropped).
    dic_times : numpy.ndarray, shape (M,)
        DIC stage times (s).
    ids : numpy.ndarray of int, shape (N,)
        DIC point IDs.
    s, h : numpy.ndarray, shape (N,)
        Material coordinates of the DIC points (mm).
    patch : tuple
        ``(s_min, s_max, h_min, h_max)`` of the DIC patch (mm).
    x_dic : numpy.ndarray, shape (M, N, 3)
        Measured coordinates (true + noise; NaN where failed or absent).
    present : numpy.ndarray of bool, shape (M, N)
        False where a point is absent from a stage's export.
    ir_noise, dic_noise : float
        Noise levels (K, mm).
    seed : int
    """

    name: str
    scale: str
    specimen: Specimen
    camera: TrueCamera
    window: tuple
    ir_times: np.ndarray
    ir_frame_numbers: np.ndarray
    dic_times: np.ndarray
    ids: np.ndarray
    s: np.ndarray
    h: np.ndarray
    patch: tuple
    x_dic: np.ndarray
    present: np.ndarray
    ir_noise: float
    dic_noise: float
    seed: int
    _renderer: FrameRenderer | None = field(default=None, repr=False)
    _truth: xr.Dataset | None = field(default=None, repr=False)

    @property
    def renderer(self) -> FrameRenderer:
        if self._renderer is None:
            self._renderer = FrameRenderer(self.specimen, self.camera, self.window)
        return self._renderer

    def ir_frame(self, i: int, *, noise: bool = True) -> xr.DataArray:
        """IR frame ``i`` (index into :attr:`ir_times`) as a DataArray (v, u), deg C.

        The noise of a frame is reproducible: it is drawn from a generator
        seeded by ``(seed, experiment, frame number)``.
        """
        if not 0 <= i < self.ir_times.size:
            raise ConfigError(f"frame index {i} out of range 0..{self.ir_times.size - 1}")
        rng = np.random.default_rng([self.seed, _CODE[self.name], int(self.ir_frame_numbers[i])])
        frame = self.renderer(self.ir_times[i], noise=self.ir_noise if noise else 0.0, rng=rng)
        frame.attrs["frame_number"] = int(self.ir_frame_numbers[i])
        return frame

    def ir_frames(self, *, noise: bool = True):
        """Iterate over all IR frames (one in memory at a time)."""
        for i in range(self.ir_times.size):
            yield self.ir_frame(i, noise=noise)

    def ir_stack(self, *, noise: bool = True) -> xr.DataArray:
        """All IR frames as one DataArray ``(time, v, u)`` (float32, deg C)."""
        frames = [f.values for f in self.ir_frames(noise=noise)]
        r = self.renderer
        return xr.DataArray(
            np.stack(frames), dims=("time", "v", "u"),
            coords={"time": self.ir_times, "v": r.v.astype(np.int64), "u": r.u.astype(np.int64),
                    "frame_number": ("time", self.ir_frame_numbers)},
            attrs={"units": "°C", "long_name": "apparent temperature"}, name="temperature")

    def dic(self) -> xr.Dataset:
        """DIC data as measured: ``x(time, point, component)`` (mm, NaN = failed or
        absent) and ``present(time, point)``."""
        return xr.Dataset(
            {"x": (("time", "point", "component"), self.x_dic, {"units": "mm", "long_name": "current coordinates"}),
             "present": (("time", "point"), self.present, {"long_name": "point present in the stage export"})},
            coords={"time": ("time", self.dic_times, {"units": "s"}), "point": self.ids,
                    "component": ["x", "y", "z"]})

    def truth(self) -> xr.Dataset:
        """Every truth quantity on ``(time = DIC times, point)`` (see :mod:`irdic.synthetic.truth`)."""
        if self._truth is None:
            ds = point_truth(self.specimen, self.camera, self.s, self.h, self.dic_times, ids=self.ids,
                             window=self.window, patch=self.patch)
            ds["x_dic"] = (("time", "point", "component"), self.x_dic,
                           {"units": "mm", "long_name": "coordinates as written to the DIC export (noise, NaN defects)"})
            ds["present"] = (("time", "point"), self.present, {"long_name": "point present in the stage export"})
            ds = ds.assign_coords(ir_time=("ir_frame", self.ir_times, {"units": "s", "long_name": "IR frame time"}),
                                  ir_frame_number=("ir_frame", self.ir_frame_numbers))
            if hasattr(self.specimen, "axial_force"):
                t = self.dic_times
                ds["force"] = ("time", np.asarray(self.specimen.axial_force(t), float),
                               {"units": "N", "long_name": "axial force of the testing machine (E A u / L)"})
                ds["torque"] = ("time", np.asarray(self.specimen.torque(t), float),
                                {"units": "N m", "long_name": "torque of the testing machine (G J phi / L)"})
                ds["displacement"] = ("time", np.asarray(self.specimen.axial_displacement(t)[0], float),
                                      {"units": "mm", "long_name": "grip displacement"})
                ds["angle"] = ("time", np.degrees(np.asarray(self.specimen.twist(t)[0], float)),
                               {"units": "deg", "long_name": "grip twist angle"})
            ds.attrs.update({"experiment": self.name, "scale": self.scale, "ir_window": list(self.window),
                             "ir_noise_K": self.ir_noise, "dic_noise_mm": self.dic_noise, "seed": self.seed})
            self._truth = ds
        return self._truth


def _grid(name: str, spec: Specimen, n: tuple[int, int]):
    """Material coordinates of a DIC grid regular in world x and y."""
    nx, ny = n
    if name == "halfshell":
        s_max = spec.s_e - 1.0
        x_max = spec.R_o * np.sin(s_max / spec.R_o)
        x = np.linspace(-x_max, x_max, nx)
        hh = np.linspace(1.0, spec.H - 1.0, ny)
        s = spec.R_o * np.arcsin(x / spec.R_o)
        patch = (-s_max, s_max, 1.0, spec.H - 1.0)
    else:
        th = np.radians(55.0)
        x = np.linspace(-spec.R * np.sin(th), spec.R * np.sin(th), nx)
        hh = np.linspace(-20.0, 20.0, ny)
        s = spec.R * np.arcsin(x / spec.R)
        patch = (-spec.R * th, spec.R * th, -20.0, 20.0)
    S, Hh = np.meshgrid(s, hh)  # rows = height, columns = x
    row, col = np.meshgrid(np.arange(nx), np.arange(ny))[::-1]
    ids = 1000 * row.ravel() + col.ravel() + 1
    return S.ravel(), Hh.ravel(), ids.astype(np.int64), patch


def _auto_window(spec: Specimen, camera: TrueCamera, duration: float, margin: int = 20):
    """Crop window around the projected observed surface over the experiment."""
    if isinstance(spec, HalfShell):
        s = np.linspace(-spec.s_e, spec.s_e, 41)
        h = np.linspace(0.0, spec.H, 21)
    else:
        s = np.linspace(-spec.R * np.pi / 2, spec.R * np.pi / 2, 41)
        h = np.linspace(spec.Z_b, spec.Z_b + spec.L, 31)
    S, Hh = np.meshgrid(s, h)
    t = np.linspace(0.0, duration, 11)[:, None]
    return window_around(camera.project(spec.position(S.ravel()[None], Hh.ravel()[None], t)), camera, margin)


def window_around(uv, camera: TrueCamera, margin: int = 20):
    """Crop window ``(u0, v0, width, height)`` around projected surface points ``uv`` (..., 2) plus ``margin`` px,
    on the sensor."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    if uv.size == 0:
        raise ConfigError("the specimen is not in front of `camera`; no IR window can be placed")
    u0 = int(np.clip(np.floor(uv[:, 0].min()) - margin, 0, camera.width - 1))
    v0 = int(np.clip(np.floor(uv[:, 1].min()) - margin, 0, camera.height - 1))
    u1 = int(np.clip(np.ceil(uv[:, 0].max()) + margin + 1, u0 + 1, camera.width))
    v1 = int(np.clip(np.ceil(uv[:, 1].max()) + margin + 1, v0 + 1, camera.height))
    return (u0, v0, u1 - u0, v1 - v0)


def _defects(rng, M: int, N: int):
    """NaN (failed) and absent masks, (M, N) each; stage 0 is clean."""
    failed = np.zeros((M, N), bool)
    absent = np.zeros((M, N), bool)
    if M < 2:
        return failed, absent
    n_fail = max(1, int(round(0.01 * N)))
    for k in range(1, M):
        if rng.random() < 0.5:
            failed[k, rng.choice(N, n_fail, replace=False)] = True
    for p in rng.choice(N, max(2, N // 600), replace=False):
        stages = rng.choice(np.arange(1, M), min(M - 1, int(rng.integers(1, 3))), replace=False)
        absent[stages, p] = True
    return failed, absent


def n_stages(name: str, scale: str) -> int | None:
    """Number of DIC stages of demo experiment ``name`` at ``scale`` (None: not a demo experiment)."""
    plan = _PLAN.get(name, {}).get(scale)
    if plan is None:
        return None
    duration, _, dic_rate = plan[:3]
    return int(round(duration * dic_rate)) + 1


def experiment(name: str, scale: str = "demo", *, ir_noise: float = 0.05, dic_noise: float = 0.005,
               seed: int = 0, camera: TrueCamera | None = None, specimen: Specimen | None = None) -> Experiment:
    """Build the in-memory experiment ``name`` at ``scale``.

    Parameters
    ----------
    name : {"halfshell", "tube"}
    scale : {"tiny", "demo", "paper"}
        Size (see the module docstring).
    ir_noise : float
        IR pixel noise (K).
    dic_noise : float
        DIC coordinate noise (mm, per component).
    seed : int
        Seed of all noise and defects.
    camera : TrueCamera, optional
        Default :func:`~irdic.synthetic.camera.lab_camera` (and the documented
        crop windows); another camera gets a window fitted around the specimen.
    specimen : Specimen, optional
        Default ``HalfShell()`` / ``Tube()`` with the documented parameters.

    Returns
    -------
    Experiment
    """
    choice(name, "name", EXPERIMENTS)
    choice(scale, "scale", SCALES)
    ir_noise = positive(ir_noise, "ir_noise", allow_zero=True)
    dic_noise = positive(dic_noise, "dic_noise", allow_zero=True)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"`seed` must be a non-negative integer; got {seed!r}")
    camera_given = camera
    camera = lab_camera() if camera is None else camera
    if not isinstance(camera, TrueCamera):
        raise ConfigError(f"`camera` must be a TrueCamera; got {type(camera).__name__}")
    spec = (HalfShell() if name == "halfshell" else Tube()) if specimen is None else specimen
    duration, ir_rate, dic_rate, n, dropped = _PLAN[name][scale]
    window = check_window(_WINDOW[name] if camera_given is None else _auto_window(spec, camera, duration),
                          camera)
    n_ir = int(round(duration * ir_rate)) + 1
    numbers = np.arange(n_ir)
    if dropped is not None:
        numbers = numbers[numbers != dropped]
    ir_times = numbers / ir_rate
    dic_times = np.arange(int(round(duration * dic_rate)) + 1) / dic_rate
    s, h, ids, patch = _grid(name, spec, n)
    rng = np.random.default_rng([seed, _CODE[name], 1_000_000])
    x_true = spec.position(s[None], h[None], dic_times[:, None])
    x_dic = x_true + rng.normal(0.0, dic_noise, x_true.shape) if dic_noise > 0 else x_true.copy()
    failed, absent = _defects(rng, dic_times.size, s.size)
    x_dic[failed | absent] = np.nan
    log.info("%s (%s): %d IR frames, %d DIC stages, %d points", name, scale, ir_times.size, dic_times.size, s.size)
    return Experiment(name=name, scale=scale, specimen=spec, camera=camera, window=window, ir_times=ir_times,
                      ir_frame_numbers=numbers, dic_times=dic_times, ids=ids, s=s, h=h, patch=patch, x_dic=x_dic,
                      present=~absent, ir_noise=ir_noise, dic_noise=dic_noise, seed=int(seed))


def halfshell_experiment(scale: str = "demo", **kwargs) -> Experiment:
    """The heated half-shell (see :class:`~irdic.synthetic.specimens.HalfShell`); kwargs as :func:`experiment`."""
    return experiment("halfshell", scale, **kwargs)


def tube_experiment(scale: str = "demo", **kwargs) -> Experiment:
    """The tension-torsion tube (see :class:`~irdic.synthetic.specimens.Tube`); kwargs as :func:`experiment`."""
    return experiment("tube", scale, **kwargs)
