"""Marker detection, perspective bias and correspondence on exactly rendered synthetic targets."""

import numpy as np
import pytest
import xarray as xr

from irdic.camera import CameraModel
from irdic.errors import CalibrationError, ConfigError
from irdic.markers import (assign, detect_markers, match_lattice, match_seeds, perspective_bias, plane_normals)
from irdic.synthetic.camera import lab_camera
from irdic.synthetic.target import open_book_target


def book_order(tg):
    """Index into the book's grid-ordered arrays for each marker of the Dataset (sorted by ID)."""
    pos = {int(i): k for k, i in enumerate(tg.book.ids)}
    return np.array([pos[int(i)] for i in tg.markers.marker.values])


def erase(tg, keep):
    """Paint the markers with ``keep == False`` over with the wing temperature (same noise level)."""
    img = tg.image.values.astype(np.float64).copy()
    vv, uu = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    rng = np.random.default_rng(99)
    body = tg.truth.attrs["body_temperature"]
    for (u, v), r in zip(tg.truth.marker_centroid.values[~keep], tg.truth.marker_radius_px.values[~keep]):
        disc = np.hypot(uu - u, vv - v) <= 2 * r + 3
        img[disc] = body + rng.normal(0, 0.04, disc.sum())
    return tg.image.copy(data=img.astype(np.float32))


@pytest.fixture(scope="module")
def target():
    return open_book_target(lab_camera())


@pytest.fixture(scope="module")
def detections(target):
    return detect_markers(target.image)


def uv_of(det):
    return np.column_stack([det.u.values, det.v.values])


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


def test_perspective_bias_is_exact():
    # close and oblique, where the bias is large
    cam = lab_camera(distance=250.0, azimuth_deg=35.0)
    tg = open_book_target(cam, noise=0.0)
    model = CameraModel(K=cam.K, R=cam.R, C=cam.C)
    x = tg.truth.marker_x.values
    truth = tg.truth.marker_centroid.values - tg.truth.marker_pixel.values
    normals = plane_normals(x)
    book_normals = tg.book.marker_normals()[book_order(tg)]
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", normals, book_normals)), 1.0, atol=1e-12)
    bias = perspective_bias(model, x, normals, tg.book.radius)
    assert np.abs(truth).max() > 0.03
    np.testing.assert_allclose(bias, truth, rtol=0, atol=1e-6)
    # the detector sees the imaged centroid: corrected detections hit the projected centres
    det = detect_markers(tg.image)
    mi, di = assign(tg.truth.marker_pixel.values + bias, uv_of(det), 0.5)
    raw = uv_of(det)[di] - tg.truth.marker_pixel.values[mi]
    corrected = raw - bias[mi]
    assert np.sqrt(np.mean(np.sum(corrected**2, axis=1))) < 0.5 * np.sqrt(np.mean(np.sum(raw**2, axis=1)))


def test_perspective_bias_with_distortion():
    cam = lab_camera(distance=250.0, k1=-0.3)
    tg = open_book_target(cam, noise=0.0, supersample=4)
    model = CameraModel(K=cam.K, R=cam.R, C=cam.C, k1=cam.k1)
    normals = tg.book.marker_normals()[book_order(tg)]
    bias = perspective_bias(model, tg.truth.marker_x.values, normals, tg.book.radius)
    truth = tg.truth.marker_centroid.values - tg.truth.marker_pixel.values
    assert np.abs(truth).max() > 0.03
    np.testing.assert_allclose(bias, truth, rtol=0, atol=1e-4)


def test_assign_is_one_to_one_and_gated():
    pred = np.array([[0.0, 0.0], [10.0, 0.0], [np.nan, np.nan], [50.0, 50.0]])
    det = np.array([[10.4, 0.0], [0.3, 0.1], [9.0, 0.0], [80.0, 80.0]])
    mi, di = assign(pred, det, 2.0)
    assert mi.tolist() == [0, 1] and di.tolist() == [1, 0]


def test_match_seeds(target, detections):
    ids = target.markers.marker.values
    x = target.markers.x.values
    pix = target.truth.marker_pixel.values
    D = uv_of(detections)
    rng = np.random.default_rng(1)
    pick = [0, 9, 23, 44, 61, 80]  # both wings
    seeds = {int(ids[i]): (pix[i] + rng.uniform(-3, 3, 2)).tolist() for i in pick}
    mi, di, model = match_seeds(D, x, ids, seeds)
    true_mi, true_di = assign(pix, D, 1.0)
    assert mi.tolist() == true_mi.tolist() and di.tolist() == true_di.tolist()
    assert np.abs(model.project(x) - pix).max() < 0.2
    # string keys (from YAML/JSON) name the same markers
    mi2, _, _ = match_seeds(D, x, ids, {str(k): v for k, v in seeds.items()})
    assert mi2.tolist() == mi.tolist()


def test_match_seeds_errors(target, detections):
    ids = target.markers.marker.values
    x = target.markers.x.values
    pix = target.truth.marker_pixel.values
    D = uv_of(detections)
    pick = [0, 9, 23, 44, 61, 80, 70]
    seeds = {int(ids[i]): pix[i].tolist() for i in pick}
    with pytest.raises(ConfigError, match=r"not in the marker file: \['1000', '999'\]"):
        match_seeds(D, x, ids, {**seeds, 999: [1, 2], 1000: [3, 4]})
    with pytest.raises(ConfigError, match="at least 6 markers .* got 5"):
        match_seeds(D, x, ids, dict(list(seeds.items())[:5]))
    # one seed off by 25 px, then two seeds swapped: contradictory, and the culprits are named
    bad = dict(seeds)
    k23 = int(ids[23])
    bad[k23] = (pix[23] + [25.0, 0.0]).tolist()
    with pytest.raises(ConfigError, match=rf"contradict each other.*worst is seed {k23} at .* \(2\d.\d px off\)"):
        match_seeds(D, x, ids, bad)
    more = {**seeds, **{int(ids[i]): pix[i].tolist() for i in (30, 50)}}
    k44, k61 = int(ids[44]), int(ids[61])
    more[k44], more[k61] = seeds[k61], seeds[k44]
    with pytest.raises(ConfigError, match=rf"contradict each other.*worst are seed ({k44}|{k61}) .* and seed ({k44}|{k61}) "):
        match_seeds(D, x, ids, more)
    wing = target.book.marker_wing[book_order(target)]
    one_wing = {int(ids[i]): pix[i].tolist() for i in np.flatnonzero(wing == 0)[::6]}
    with pytest.raises(ConfigError, match="coplanar"):
        match_seeds(D, x, ids, one_wing)
    with pytest.raises(ConfigError, match=r"pair \[u, v\]"):
        match_seeds(D, x, ids, {**seeds, int(ids[5]): [1.0]})


def test_match_lattice_refuses_a_symmetric_target(target, detections):
    # the synthetic open book is symmetric under a half turn about its bisector:
    # an upside-down camera on the other side explains the image equally well
    with pytest.raises(CalibrationError, match=r"(?s)ambiguous.*seeds: \{<marker id>: \[u, v\]"):
        match_lattice(uv_of(detections), target.markers.x.values)


def test_match_lattice_on_an_asymmetric_target(target):
    book = target.book
    gone = book.ids[(book.marker_wing == 0) & (book.marker_col == 6)]  # one wing has a column less
    keep = ~np.isin(target.markers.marker.values, gone)
    image = erase(target, keep)
    det = detect_markers(image)
    assert det.sizes["detection"] == 78
    x = target.markers.x.values[keep]
    mi, di, model = match_lattice(uv_of(det), x)
    true_mi, true_di = assign(target.truth.marker_pixel.values[keep], uv_of(det), 1.0)
    assert len(mi) == 78
    assert mi.tolist() == true_mi.tolist() and di.tolist() == true_di.tolist()


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


def test_far_off_seed_is_named_with_its_distance(target, detections):
    ids = target.markers.marker.values
    x = target.markers.x.values
    pix = target.truth.marker_pixel.values
    D = uv_of(detections)
    pick = [0, 9, 23, 44, 61, 80]
    seeds = {int(ids[i]): pix[i].tolist() for i in pick}
    k = int(ids[44])
    seeds[k] = [1000.0, 760.0]  # far outside the target
    d = np.hypot(*(D - [1000.0, 760.0]).T).min()
    with pytest.raises(ConfigError, match=rf"seed for marker {k} at \(1000\.0, 760\.0\) is {d:.1f} px from any "
                                          r"detected blob \(detections are \d+\.\d px apart\)") as exc:
        match_seeds(D, x, ids, seeds)
    assert "coplanar" not in str(exc.value) and "rank" not in str(exc.value)


def test_collinear_seed_markers_are_called_collinear(target, detections):
    ids = target.markers.marker.values
    D = uv_of(detections)
    # six markers of the target moved onto one line in the DIC frame (e.g. a wrong column in the export)
    x = target.markers.x.values.copy()
    pick = [0, 9, 23, 44, 61, 80]
    x[pick] = np.array([1.0, 2.0, 3.0]) * np.arange(6)[:, None]
    seeds = {int(ids[i]): D[np.argmin(np.hypot(*(D - target.truth.marker_pixel.values[i]).T))].tolist()
             for i in pick}
    with pytest.raises(ConfigError, match=r"the 6 seed markers are \(nearly\) collinear"):
        match_seeds(D, x, ids, seeds)
