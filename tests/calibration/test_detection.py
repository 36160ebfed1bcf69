"""Marker detection (irdic.calibration.detection) on exactly rendered synthetic targets."""

import numpy as np
import pytest
import xarray as xr

from irdic.calibration import detect_markers
from irdic.calibration.detection import CENTRE_FLOOR_PX, centre_weights
from irdic.calibration.correspondence import assign
from irdic.errors import CalibrationError, ConfigError
from irdic.synthetic.camera import lab_camera
from irdic.synthetic.target import open_book_target

from ._targets import uv_of


def test_detects_every_marker_at_its_imaged_centroid(target, detections):
    det = detections
    assert det.sizes["detection"] == 84
    assert det.attrs["polarity"] == "dark"
    assert det.attrs["noise_k"] == pytest.approx(0.04, rel=0.1)
    cen = target.truth.marker_centroid.values
    mi, di = assign(cen, uv_of(det), 1.0)
    assert len(mi) == 84
    err = np.hypot(*(uv_of(det)[di] - cen[mi]).T)
    # 0.04 K noise on a 2.5 K contrast: ~0.02 px per marker
    assert np.sqrt(np.mean(err**2)) < 0.035
    assert err.max() < 0.1
    # the reported uncertainty describes the scatter
    sig = det.sigma_px.values[di] * np.sqrt(2)
    assert 0.5 < np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(sig**2)) < 2.0
    np.testing.assert_allclose(det.radius_px.values[di], target.truth.marker_radius_px.values[mi], atol=0.5)
    np.testing.assert_allclose(det.contrast_k.values, 2.5, atol=0.15)
    assert (det.eccentricity.values < 0.85).all()


def test_bright_markers_and_polarity_override():
    tg = open_book_target(lab_camera(azimuth_deg=-10.0), polarity="bright", seed=4)
    det = detect_markers(tg.image)
    assert det.attrs["polarity"] == "bright" and det.sizes["detection"] == 84
    mi, di = assign(tg.truth.marker_centroid.values, uv_of(det), 0.2)
    assert len(mi) == 84
    # forcing the wrong polarity finds no marker-like blob
    with pytest.raises(CalibrationError, match="no marker-like blobs"):
        detect_markers(tg.image, polarity="dark")


def test_cropped_image_keeps_sensor_coordinates(target, detections):
    crop = target.image.isel(u=slice(300, 760), v=slice(250, 560))
    det = detect_markers(crop)
    assert det.attrs["sensor_u0"] == 300 and det.attrs["sensor_v0"] == 250
    mi, di = assign(uv_of(detections), uv_of(det), 0.5)
    assert len(mi) == 84
    # same centres; the top-hat near the crop edge changes the candidate masks, which
    # moves the background annulus a little: differences far below the 0.02 px noise
    np.testing.assert_allclose(uv_of(det)[di], uv_of(detections)[mi], atol=5e-3)


def test_blank_saturated_and_invalid_images(target):
    rng = np.random.default_rng(0)
    blank = target.image.copy(data=(22.0 + rng.normal(0, 0.04, target.image.shape)).astype(np.float32))
    with pytest.raises(CalibrationError, match="blank.*0.1 to 99.9 percentile"):
        detect_markers(blank)
    # a range ending at 21 °C: wings and (darker) markers both clip at 21 °C
    clipped = target.image.copy(data=np.minimum(target.image.values, 21.0))
    with pytest.raises(CalibrationError, match=r"saturated: \d+% of its pixels sit at the maximum 21.00"):
        detect_markers(clipped)
    nan = target.image.copy(data=np.where(np.arange(1024) < 700, np.nan, target.image.values).astype(np.float32))
    with pytest.raises(CalibrationError, match="mostly invalid"):
        detect_markers(nan)
    with pytest.raises(ConfigError, match="`polarity` must be"):
        detect_markers(target.image, polarity="cold")
    with pytest.raises(ConfigError, match="`min_radius_px` .* smaller than `max_radius_px`"):
        detect_markers(target.image, min_radius_px=8, max_radius_px=4)
    with pytest.raises(ConfigError, match=r"dims \('v', 'u'\)"):
        detect_markers(target.image.rename(u="x"))
    with pytest.raises(ConfigError, match="3 frames"):
        detect_markers(xr.concat([target.image] * 3, dim="time"))


def test_size_limits_reject_markers(target):
    with pytest.raises(CalibrationError, match="no marker-like blobs"):
        detect_markers(target.image, min_radius_px=8.0, max_radius_px=20.0)


def test_nan_pixels_reject_the_markers_they_touch_and_warn(target, detections):
    from irdic.errors import IrdicWarning

    img = target.image.values.astype(np.float64).copy()
    cen = target.truth.marker_centroid.values
    # a dead block over one marker: its window must not be measured on filled values
    u, v = np.round(cen[10]).astype(int)
    img[v - 2 : v + 3, u - 2 : u + 3] = np.nan
    da = target.image.copy(data=img.astype(np.float32))
    da.attrs["source"] = "target_0001.txt"
    with pytest.warns(IrdicWarning, match=r"target_0001\.txt: target image has 25 invalid \(NaN\) pixels .*"
                                          r"1 marker candidate\(s\) touching them were left out"):
        det = detect_markers(da)
    assert det.sizes["detection"] == 83 and det.attrs["n_rejected_invalid"] == 1
    assert np.hypot(det.u.values - cen[10, 0], det.v.values - cen[10, 1]).min() > 5
    # the other markers are measured exactly as in the clean image
    mi, di = assign(uv_of(detections), uv_of(det), 0.5)
    assert len(mi) == 83
    np.testing.assert_allclose(uv_of(det)[di], uv_of(detections)[mi], atol=1e-9)


def test_too_many_nan_pixels_are_refused_naming_the_image(target):
    rng = np.random.default_rng(3)
    img = target.image.values.astype(np.float64).copy()
    img[rng.random(img.shape) < 0.10] = np.nan
    da = target.image.copy(data=img.astype(np.float32))
    da.attrs["source"] = "target_0001.txt"
    with pytest.raises(CalibrationError, match=r"target_0001\.txt: target image has 10\.\d% invalid \(NaN\) pixels, "
                                               r"more than the 5% accepted"):
        detect_markers(da)




def test_centre_weights_are_inverse_sigmas_with_a_floor():
    """1 / sqrt(sigma^2 + floor^2) per detection; equal weights (None) when a sigma is missing."""
    sig = np.array([0.2, 0.1, 0.01, 0.001])
    det = xr.Dataset({"sigma_px": ("detection", sig)})
    np.testing.assert_allclose(centre_weights(det), 1 / np.sqrt(sig**2 + CENTRE_FLOOR_PX**2))
    # a marker 10 x less precise than another has 1/10 of its weight (GLS), until the floor
    assert centre_weights(det)[0] / centre_weights(det)[1] == pytest.approx(0.5, rel=0.01)
    assert centre_weights(det.assign(sigma_px=("detection", [0.1, np.nan, 0.1, 0.1]))) is None
    assert centre_weights(det.drop_vars("sigma_px")) is None
