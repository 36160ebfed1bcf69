"""Perspective bias of imaged circle centres (irdic.calibration.bias) against exact renderings."""

import numpy as np

from irdic.calibration import detect_markers, perspective_bias
from irdic.calibration.bias import plane_normals
from irdic.calibration.correspondence import assign
from irdic.camera import CameraModel
from irdic.synthetic.camera import lab_camera
from irdic.synthetic.target import open_book_target

from ._targets import book_order, uv_of


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


