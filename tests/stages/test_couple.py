"""Couple stage against the analytic truth of the synthetic experiments."""

import warnings

import numpy as np
import pytest
import xarray as xr

from irdic.errors import CalibrationError, DataError, IrdicWarning
from irdic.stages import calibrate as calibrate_stage
from irdic.stages import couple as couple_stage
from irdic.coupling import couple
from irdic.synthetic.demo_folder import make_demo
from irdic.ingest.dic import ingest_dic
from irdic.ingest.ir import ingest_ir
from irdic.store import open_store
from irdic.vocabulary import Status

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The tiny demo without noise, ingested and calibrated."""
    d = tmp_path_factory.mktemp("couple")
    make_demo(d / "demo", scale="tiny", ir_noise=0.0, dic_noise=0.0)
    calibrate_stage.run({"markers": d / "demo/setup/markers.txt", "target": d / "demo/setup/target.txt"},
                        {"store": d / "cal.zarr"})
    out = {"cal": open_store(d / "cal.zarr"), "dir": d}
    for exp in ("halfshell", "tube"):
        ingest_ir(d / f"demo/{exp}/ir", d / f"{exp}_ir.zarr")
        ingest_dic(d / f"demo/{exp}/dic", d / f"{exp}_dic.zarr")
        out[exp] = (open_store(d / f"{exp}_dic.zarr"), open_store(d / f"{exp}_ir.zarr"),
                    open_store(d / f"demo/{exp}/truth.zarr"))
    return out


@pytest.fixture(scope="module")
def coupled(demo):
    return {exp: couple(demo[exp][0], demo[exp][1], demo["cal"]) for exp in ("halfshell", "tube")}


@pytest.mark.parametrize("exp", ["halfshell", "tube"])
def test_temperature_against_truth(demo, coupled, exp):
    ds = coupled[exp]
    truth = demo[exp][2].sel(point=ds.point)
    vis = ds.visible.values
    assert vis.mean() > 0.9
    err = ds.temperature.values - truth.temperature.values
    rms_all = np.sqrt(np.mean(err[vis] ** 2))
    inner = vis & (truth.patch_edge_distance.values >= 2.0)
    rms_inner = np.sqrt(np.mean(err[inner] ** 2))
    assert rms_all <= 0.01, rms_all
    assert rms_inner <= 0.005, rms_inner
    # pixel gradient: interior points within 1 % of the largest true gradient, plus the
    # floor set by the 3 decimals (0.001 K) of the IR text exports
    g_true = np.stack([truth.dT_du.values, truth.dT_dv.values], axis=-1)
    g_err = ds.temperature_pixel_gradient.values - g_true
    assert np.sqrt(np.mean(g_err[inner] ** 2)) <= 0.01 * np.abs(g_true[vis]).max() + 1e-3
    # local rate at the fixed pixel, away from the ends of the series
    mid = inner.copy()
    mid[[0, -1]] = False
    r_err = ds.temperature_local_rate.values - truth.dT_dt_pixel.values
    assert np.sqrt(np.mean(r_err[mid] ** 2)) <= 0.02 * np.abs(truth.dT_dt_pixel.values[vis]).max()


@pytest.mark.parametrize("exp", ["halfshell", "tube"])
def test_projection_status_and_layout(demo, coupled, exp):
    ds = coupled[exp]
    truth = demo[exp][2].sel(point=ds.point)
    assert ds.temperature.dims == ("time", "point")
    assert list(ds.axis.values) == ["u", "v"]
    assert ds.temperature.attrs["units"] == "degC"
    assert ds.temperature_pixel_gradient.attrs["units"] == "K/px"
    ok = np.isfinite(ds.pixel.values).all(axis=2) & np.isfinite(truth.pixel.values).all(axis=2)
    # the calibrated camera puts the points within a few hundredths of a pixel of the true projection
    assert np.sqrt(np.mean(np.sum((ds.pixel.values - truth.pixel.values)[ok] ** 2, axis=-1))) < 0.03
    missing = ~np.isfinite(demo[exp][0].x.values).all(axis=2)
    assert missing.any()  # the demo has failed DIC points ...
    np.testing.assert_array_equal(ds.status.values[missing], 2)  # ... and they are flagged, not filled
    assert np.isnan(ds.temperature.values[missing]).all()
    extrap = ds.status.values == 1
    assert extrap.any() and (ds.edge_distance.values[extrap] < 0).all()
    assert (ds.edge_distance.values[ds.status.values == 0] >= -0.5).all()


def test_pixel_uncertainty_from_the_calibration(demo, coupled):
    """pixel_std is the calibration's projection uncertainty of each point, where the point has a pixel."""
    from irdic.camera import load_camera

    ds = coupled["halfshell"]
    has = np.isfinite(ds.pixel.values).all(axis=2)
    std = ds.pixel_std.values
    assert ds.pixel_std.dims == ("time", "point") and ds.pixel_std.attrs["units"] == "px"
    assert np.isnan(std[~has]).all() and np.isfinite(std[has]).all()
    expect = load_camera(demo["cal"]).projection_uncertainty(ds.x.values[has])
    np.testing.assert_allclose(std[has], expect, rtol=1e-9)
    # a noise-free demo calibrates to a few thousandths of a pixel: so must its uncertainty be
    assert 0 < std[has].max() < 0.05
    # the true error is of the size of the stated uncertainty (not 10 x larger)
    truth = demo["halfshell"][2].sel(point=ds.point)
    ok = has & np.isfinite(truth.pixel.values).all(axis=2)
    err = np.hypot(*np.moveaxis(ds.pixel.values - truth.pixel.values, -1, 0))[ok]
    assert np.sqrt(np.mean(err**2)) < 10 * np.sqrt(np.mean(std[ok] ** 2)) + 1e-3


def test_dic_times_outside_ir_span(demo):
    dic, ir, _ = demo["tube"]
    shifted = dic.assign_coords(time=dic.time + 0.75 * float(ir.time[-1]))
    with pytest.warns(IrdicWarning, match="outside the frame span"):
        ds = couple(shifted, ir, demo["cal"])
    late = shifted.time.values > float(ir.time[-1])
    assert late.any() and (~late).any()
    st = ds.status.values[late]
    assert (st == 6).any() and np.isin(st, [2, 3, 4, 5, 6]).all()
    assert np.isnan(ds.temperature.values[late]).all()
    assert np.isfinite(ds.temperature.values[~late]).any()
    with pytest.raises(DataError, match="no DIC time .* inside the IR time span"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IrdicWarning)
            couple(dic.assign_coords(time=dic.time + 1000.0), ir, demo["cal"])


def test_calibration_of_another_setup_is_refused(demo):
    dic, ir, _ = demo["halfshell"]
    # a calibration of a camera 150 mm further to the side: the points fall outside the crop window
    cal = demo["cal"].copy()
    shift = np.array([150.0, 0.0, 0.0])
    M = cal.projection_matrix.values.copy()
    M[:, 3] -= M[:, :3] @ shift
    cal["projection_matrix"] = (cal.projection_matrix.dims, M)
    cal["camera_centre"] = (cal.camera_centre.dims, cal.camera_centre.values + shift)
    with pytest.raises(CalibrationError, match="project into the IR frames"):
        couple(dic, ir, cal)


def test_ir_frames_larger_than_the_calibration_image(demo):
    dic, ir, _ = demo["halfshell"]
    cal = demo["cal"].copy()
    cal.attrs = {**cal.attrs, "sensor_width": 320, "sensor_height": 240}
    with pytest.raises(DataError, match="calibration image was 320 x 240 px"):
        couple(dic, ir, cal)


def test_couple_stage_writes_points_zarr(demo):
    d = demo["dir"]
    couple_stage.run({"dic": d / "tube_dic.zarr", "ir": d / "tube_ir.zarr", "calibration": d / "cal.zarr"},
                     {"store": d / "points.zarr"}, threads=1, method="bilinear")
    ds = open_store(d / "points.zarr")
    assert ds.attrs["irdic_stage"] == "couple" and '"method": "bilinear"' in ds.attrs["irdic_parameters"]
    assert {"temperature", "pixel", "temperature_pixel_gradient", "temperature_local_rate", "visible",
            "edge_distance", "x", "status"} <= set(ds.data_vars)


def test_nan_under_the_specimen_is_named_in_sensor_pixels(demo, coupled):
    # the message used to name the pixel of the cropped frame array (u=.., v=.. from 0)
    dic, ir, _ = demo["halfshell"]
    ds = coupled["halfshell"]
    vis = np.argwhere(ds.status.values == Status.INTERPOLATED)
    k, j = vis[len(vis) // 2]
    pu, pv = np.rint(ds.pixel.values[k, j]).astype(int)
    u0, v0 = int(ir.u[0]), int(ir.v[0])
    assert u0 > 0 and v0 > 0  # a crop window, so array and sensor pixels differ
    temp = ir.temperature.values.copy()
    temp[3, pv - v0, pu - u0] = np.nan
    bad = ir.assign(temperature=(ir.temperature.dims, temp))
    with pytest.raises(DataError, match=rf"ir: frames: 1 non-finite value\(s\) at masked pixels, first in IR frame 3 "
                                        rf"\(t = {float(ir.time[3]):g} s\) at sensor pixel \(u={pu}, v={pv}\)"):
        couple(dic, bad, demo["cal"])


def test_couple_stage_refuses_unknown_parameters_and_paths(demo):
    from irdic.errors import ConfigError

    d = demo["dir"]
    inputs = {"dic": d / "tube_dic.zarr", "ir": d / "tube_ir.zarr", "calibration": d / "cal.zarr"}
    # a typo must not fall back to the default silently
    with pytest.raises(ConfigError, match="interpolation: unknown parameter.*c_spaec.*expected.*c_space"):
        couple_stage.run(inputs, {"store": d / "p2.zarr"}, c_spaec=3.0)
    with pytest.raises(ConfigError, match="stage couple: inputs must name dic, ir, calibration; missing.*'ir'"):
        couple_stage.run({"dic": inputs["dic"], "calibration": inputs["calibration"]}, {"store": d / "p2.zarr"})
    assert not (d / "p2.zarr").exists()


def test_status_flags_follow_the_vocabulary(coupled):
    ds = coupled["halfshell"]
    assert ds.status.attrs["flag_values"] == [int(s) for s in Status]
    assert ds.status.attrs["flag_meanings"].split() == [s.name.lower() for s in Status]
    # visible is exactly status interpolated or extrapolated, and only visible points have a temperature
    vis = ds.status.values <= Status.EXTRAPOLATED_FROM_EDGE
    np.testing.assert_array_equal(ds.visible.values, vis)
    np.testing.assert_array_equal(np.isfinite(ds.temperature.values), vis)
    assert ds.attrs["count_interpolated"] == int((ds.status.values == Status.INTERPOLATED).sum())
