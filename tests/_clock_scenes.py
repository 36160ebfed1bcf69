"""Synthetic experiments whose IR clock runs behind the DIC clock by a known offset, and a family of them."""

import numpy as np
import xarray as xr

from irdic.camera import CameraModel
from irdic.synthetic import Tube, experiment
from irdic.synthetic.render import realistic_stack
from irdic.synthetic.specimens import smoothstep


class RampTube(Tube):
    """The tube loaded at a constant rate: the stretch and the twist ramp linearly over ``load`` (a testing
    machine at constant crosshead speed), so the motion has kinks where the ramps start and end."""

    @staticmethod
    def _ramp(t, a, b):
        t = np.asarray(t, np.float64)
        return np.clip((t - a) / (b - a), 0.0, 1.0), np.where((t > a) & (t < b), 1.0 / (b - a), 0.0)

    def axial_displacement(self, t):
        S1, d1 = self._ramp(t, *self.load)
        S2, d2 = self._ramp(t, *self.unload_force)
        return self.u_max * S1 - self.u_recovery * S2, self.u_max * d1 - self.u_recovery * d2

    def twist(self, t):
        S1, d1 = self._ramp(t, *self.load)
        S2, d2 = self._ramp(t, *self.unload_torque)
        return self.phi_max * S1 - self.phi_recovery * S2, self.phi_max * d1 - self.phi_recovery * d2


class SecondPatternTube(Tube):
    """The default tube plus a second pattern with its own history: an axial gradient of ``second`` K that
    heats from 3 to 7 s, after the first (a pattern of two components, not one that only scales)."""

    def __init__(self, *, second: float = 1.0, **kw):
        super().__init__(**kw)
        self.second = float(second)

    def temperature(self, s, h, t):
        S2, _, _ = smoothstep(np.asarray(t, np.float64), 3.0, 7.0)
        s, h, S2 = np.broadcast_arrays(s, h, S2)
        return super().temperature(s, h, t) + self.second * S2 * (h / 20.0) * (1.0 + 0.1 * np.cos(s / self.R))


class GripFrontTube(Tube):
    """The default tube plus heat flowing in from the upper grip: ``grip t/6`` K at the DIC patch's upper end
    (h = 20 mm), decaying over 2 mm at the start and 5 mm after 6 s (a front that changes its shape on the
    material)."""

    def __init__(self, *, grip: float = 1.0, **kw):
        super().__init__(**kw)
        self.grip = float(grip)

    def temperature(self, s, h, t):
        x = np.clip(np.asarray(t, np.float64) / 6.0, 0.0, 1.0)
        s, h, x = np.broadcast_arrays(s, h, x)
        return super().temperature(s, h, t) + self.grip * x * np.exp(-(20.0 - h) / (2.0 + 3.0 * x))


#: the tube with a temperature pattern that the small scenes can see move: 40 % around the tube, 6 K of heating
STRONG_TUBE = dict(gamma=0.4, Q=6.0)
IR_NOISE, DIC_NOISE, DECIMALS = 0.05, 0.003, 2

#: moving scenes of different pattern strength, motion and speed: (scale, Tube parameters, IR at the DIC rate)
FAMILY = {
    "weak-tiny": ("tiny", {}, False),                     # the default tube: 4 % around, 4 K; 12 frames at 2 Hz
    "weak-demo": ("demo", {}, False),                     # 41 frames at 4 Hz, DIC 2 Hz
    "weak-demo-same-rate": ("demo", {}, True),            # 21 frames at 2 Hz, at the DIC times
    "strong-demo": ("demo", STRONG_TUBE, False),
    "stretch-only": ("demo", dict(phi_max_deg=0.0, phi_recovery_deg=0.0), False),
    "twist-only": ("demo", dict(u_max=0.0, u_recovery=0.0, gamma=0.15), False),
    "fast-load": ("demo", dict(load=(0.5, 2.5)), False),  # the same motion in 2 s instead of 5
    "slow-small": ("demo", dict(load=(0.5, 9.5), u_max=1.0, phi_max_deg=10.0, Q=2.0), False),
    "ramp-tiny": ("tiny", dict(ramp=True), False),        # constant-rate loading: kinks between the DIC stages
    "second-pattern": ("demo", dict(second=1.0), False),  # two pattern components with their own histories
    "grip-front": ("demo", dict(grip=1.0), False),        # heat from the grip: a front that changes its shape
}


def clock_scene(offset, *, name="tube", scale="tiny", realistic=False, seed=0, same_rate=False, mode="auto",
                tube=None):
    """(dic, ir, calibration, experiment) with the IR times ``offset`` s behind the DIC clock.

    The frames are rendered at the true times ``t``; ``ir.zarr`` holds
    ``t - offset``, so adding ``offset`` puts IR back on the DIC clock (the
    ``time_offset`` to find). ``realistic``: 0.05 K pixel noise, 2-decimal
    exports, mixed edge pixels, 0.003 mm DIC noise; else noise-free.
    ``same_rate``: every second IR frame (IR at the DIC rate, frames at the
    DIC times); else IR at twice the DIC rate. ``mode`` is what ingest
    would have written (``"auto"`` or the configured number). ``tube``:
    the :class:`~irdic.synthetic.Tube` parameters (default
    :data:`STRONG_TUBE`; ``{}`` is the default tube; ``ramp=True`` loads it
    at a constant rate, :class:`RampTube`; ``second``: :class:`SecondPatternTube`,
    ``grip``: :class:`GripFrontTube`).
    """
    params = dict(STRONG_TUBE if tube is None else tube)
    kind = RampTube if params.pop("ramp", False) else SecondPatternTube if "second" in params else \
        GripFrontTube if "grip" in params else Tube
    spec = kind(**params) if name == "tube" else None
    ex = experiment(name, scale, ir_noise=IR_NOISE if realistic else 0.0, dic_noise=DIC_NOISE if realistic else 0.0,
                    seed=seed, specimen=spec)
    rng = np.random.default_rng([seed, 30])
    keep = np.arange(ex.ir_times.size)
    if same_rate:  # the frames at the DIC times (the dropped frame lies between two of them)
        keep = at_dic_times(ex.ir_times, ex.dic_times)
    t = ex.ir_times[keep]
    frames = realistic_stack(ex.renderer, t, rng, noise=IR_NOISE if realistic else 0.0,
                             decimals=DECIMALS if realistic else None, mixed_edges=realistic)
    r = ex.renderer
    ir = xr.Dataset({"temperature": (("time", "v", "u"), frames)},
                    coords={"time": t - offset, "v": r.v.astype(np.int64), "u": r.u.astype(np.int64)},
                    attrs={"time_offset": mode})
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    return ex.dic()[["x"]], ir, cal, ex


def at_dic_times(ir_times, dic_times):
    """Indices of the IR times that are DIC times (to the nanosecond): IR at the DIC rate from a faster record."""
    return np.flatnonzero(np.isin(np.round(np.asarray(ir_times, float), 9), np.round(np.asarray(dic_times, float), 9)))


def family_scene(member, offset_frames, *, realistic, seed=0):
    """:func:`clock_scene` of :data:`FAMILY` member ``member`` with the IR clock ``offset_frames`` periods behind;
    also returns the offset (s) and the IR frame period (s)."""
    scale, tube, same_rate = FAMILY[member]
    dic, ir, cal, ex = clock_scene(0.0, scale=scale, realistic=realistic, seed=seed, same_rate=same_rate, tube=tube)
    period = float(np.median(np.diff(ir["time"].values)))
    offset = offset_frames * period
    return dic, ir.assign_coords(time=ir["time"].values - offset), cal, ex, offset, period
