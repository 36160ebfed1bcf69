"""Synthetic experiments whose IR clock runs behind the DIC clock by a known offset."""

import numpy as np
import xarray as xr

from irdic.camera import CameraModel
from irdic.synthetic import Tube, experiment
from irdic.synthetic.render import realistic_stack

#: the tube with a temperature pattern that the small scenes can see move: 40 % around the tube, 6 K of heating
STRONG_TUBE = dict(gamma=0.4, Q=6.0)
IR_NOISE, DIC_NOISE, DECIMALS = 0.05, 0.003, 2


def clock_scene(offset, *, name="tube", scale="tiny", realistic=False, seed=0, same_rate=False, mode="auto"):
    """(dic, ir, calibration, experiment) with the IR times ``offset`` s behind the DIC clock.

    The frames are rendered at the true times ``t``; ``ir.zarr`` holds
    ``t - offset``, so adding ``offset`` puts IR back on the DIC clock (the
    ``time_offset`` to find). ``realistic``: 0.05 K pixel noise, 2-decimal
    exports, mixed edge pixels, 0.003 mm DIC noise; else noise-free.
    ``same_rate``: every second IR frame (IR at the DIC rate, frames at the
    DIC times); else IR at twice the DIC rate. ``mode`` is what ingest
    would have written (``"auto"`` or the configured number).
    """
    spec = Tube(**STRONG_TUBE) if name == "tube" else None
    ex = experiment(name, scale, ir_noise=IR_NOISE if realistic else 0.0, dic_noise=DIC_NOISE if realistic else 0.0,
                    seed=seed, specimen=spec)
    rng = np.random.default_rng([seed, 30])
    keep = np.arange(0, ex.ir_times.size, 2) if same_rate else np.arange(ex.ir_times.size)
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
