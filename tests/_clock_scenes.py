"""Synthetic experiments whose IR clock runs behind the DIC clock by a known offset, and a family of them."""

import numpy as np
import xarray as xr

from irdic.camera import CameraModel
from irdic.synthetic import Tube, experiment
from irdic.synthetic.render import realistic_stack

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
    :data:`STRONG_TUBE`; ``{}`` is the default tube).
    """
    spec = Tube(**(STRONG_TUBE if tube is None else tube)) if name == "tube" else None
    ex = experiment(name, scale, ir_noise=IR_NOISE if realistic else 0.0, dic_noise=DIC_NOISE if realistic else 0.0,
                    seed=seed, specimen=spec)
    rng = np.random.default_rng([seed, 30])
    keep = np.arange(ex.ir_times.size)
    if same_rate:  # the frames at the DIC times (the dropped frame lies between two of them)
        keep = np.flatnonzero(np.isin(np.round(ex.ir_times, 9), np.round(ex.dic_times, 9)))
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


def family_scene(member, offset_frames, *, realistic, seed=0):
    """:func:`clock_scene` of :data:`FAMILY` member ``member`` with the IR clock ``offset_frames`` periods behind;
    also returns the offset (s) and the IR frame period (s)."""
    scale, tube, same_rate = FAMILY[member]
    dic, ir, cal, ex = clock_scene(0.0, scale=scale, realistic=realistic, seed=seed, same_rate=same_rate, tube=tube)
    period = float(np.median(np.diff(ir["time"].values)))
    offset = offset_frames * period
    return dic, ir.assign_coords(time=ir["time"].values - offset), cal, ex, offset, period
