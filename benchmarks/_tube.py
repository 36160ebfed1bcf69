"""The moving tube of the couple benchmarks at any size: 10 Hz IR and DIC, tension-torsion all along."""

from __future__ import annotations

import numpy as np

from irdic.synthetic import experiments as _ex


def tube(frames: int = 300, grid: tuple[int, int] = (78, 168), *, ir_noise: float = 0.05, dic_noise: float = 0.005):
    """``frames`` IR frames and DIC stages at 10 Hz; ``grid`` DIC points (78 x 168 = 13,104)."""
    plan = _ex._PLAN["tube"]
    plan["bench"] = ((frames - 1) / 10.0, 10.0, 10.0, tuple(grid), None)
    scales = _ex.SCALES
    _ex.SCALES = scales + ("bench",)
    try:
        return _ex.tube_experiment("bench", ir_noise=ir_noise, dic_noise=dic_noise)
    finally:
        _ex.SCALES = scales
        del plan["bench"]


def inputs(ex):
    """(dic, ir, calibration) datasets of an experiment, in memory."""
    import xarray as xr

    from irdic.camera import CameraModel

    dic = ex.dic()
    ir = xr.Dataset({"temperature": ex.ir_stack(noise=ex.ir_noise > 0)})
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    return dic, ir, cal


def accuracy(points, ex):
    """RMS (K) of the point temperatures against the analytic truth, over visible points."""
    tr = ex.truth().sel(point=points.point)
    vis = points.visible.values
    err = points.temperature.values - tr.temperature.values
    return float(np.sqrt(np.mean(err[vis] ** 2))), int(vis.sum())
