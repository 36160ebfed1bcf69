"""In-memory stores of synthetic experiments (no file round trip, no quantisation)."""

import numpy as np
import xarray as xr

from irdic.camera import CameraModel
from irdic.synthetic import experiment


def synthetic_inputs(name, scale="tiny", *, ir_noise=0.0, dic_noise=0.0, seed=0):
    """(dic, ir, calibration, truth) datasets laid out like dic.zarr, ir.zarr and
    calibration.zarr, from the true camera and unquantised frames."""
    ex = experiment(name, scale, ir_noise=ir_noise, dic_noise=dic_noise, seed=seed)
    stack = ex.ir_stack()
    ir = xr.Dataset({"temperature": stack.drop_vars("frame_number")})
    dic = ex.dic()[["x"]]
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    return dic, ir, cal, ex.truth()
