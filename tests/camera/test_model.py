"""Exact-math tests of irdic.camera.model against the independent true camera of irdic.synthetic."""

import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from irdic.camera import CameraModel, fit_dlt, refine
from irdic.camera.model import MATRIX_PARAMETERS, PHYSICAL_PARAMETERS
from irdic.errors import CalibrationError, ConfigError, DataError
from irdic.synthetic.camera import IR_F, lab_camera

from ._cameras import POSES, cloud, fd_jacobian, model_of


@pytest.mark.parametrize("k1,k2", [(0.0, 0.0), (-0.35, 0.2)])
def test_project_and_jacobian_match_truth(k1, k2):
    cam = lab_camera(k1=k1, k2=k2)
    m = model_of(cam)
    x = cloud(40)
    np.testing.assert_allclose(m.project(x), cam.project(x), rtol=0, atol=1e-9)
    J = m.jacobian(x)
    assert J.shape == (40, 2, 3)
    np.testing.assert_allclose(J, fd_jacobian(m, x), rtol=0, atol=1e-7 * np.abs(J).max())
    np.testing.assert_allclose(J, cam.jacobian(x), rtol=0, atol=1e-9 * np.abs(J).max())
    np.testing.assert_allclose(m.depth(x), cam.to_camera(x)[:, 2], rtol=1e-12)
    assert m.project(x[0]).shape == (2,) and m.jacobian(x[0]).shape == (2, 3)


def test_pinhole_jacobian_is_eq_derivProjection():
    cam = lab_camera()
    m = CameraModel(cam.matrix())
    x = cloud(5)
    M = m.M
    uv = m.project(x)
    sigma = x @ M[2, :3] + M[2, 3]
    expected = (M[None, :2, :3] - uv[:, :, None] * M[None, 2, None, :3]) / sigma[:, None, None]
    np.testing.assert_allclose(m.jacobian(x), expected, rtol=1e-13)


def test_points_behind_camera_project_to_nan():
    cam = lab_camera()
    m = model_of(cam)
    behind = cam.C + 2 * (cam.C - np.array([0.0, 0.0, -5.0]))
    out = m.project(np.vstack([behind, [0.0, 0.0, 0.0]]))
    assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()
    assert m.depth(behind) < 0
    assert np.isnan(m.jacobian(behind)).all()


@pytest.mark.parametrize("pose", POSES)
def test_decompose_round_trip(pose):
    cam = lab_camera(**pose)
    m = CameraModel(-3.7 * cam.matrix())  # any scale and sign
    g = m.decompose()
    np.testing.assert_allclose(g.K, cam.K, rtol=0, atol=1e-9 * IR_F)
    np.testing.assert_allclose(g.R, cam.R, atol=1e-12)
    np.testing.assert_allclose(g.C, cam.C, atol=1e-9)
    assert np.linalg.det(g.R) == pytest.approx(1.0, abs=1e-12)
    assert g.focal_length_px == pytest.approx(IR_F, rel=1e-10)
    assert g.ifov_mrad == pytest.approx(0.57, rel=1e-10)
    np.testing.assert_allclose(g.principal_point, [511.5, 383.5], atol=1e-7)
    np.testing.assert_allclose(g.viewing_direction, cam.R[2], atol=1e-12)
    assert abs(g.skew) < 1e-7
    text = repr(m)
    assert "f=1754.4 px" in text and "IFOV=0.5700 mrad" in text and "centre=(" in text


def test_model_argument_checks():
    with pytest.raises(ConfigError, match="either `M` or all of `K`, `R` and `C`"):
        CameraModel(K=np.eye(3))
    with pytest.raises(ConfigError, match="proper rotation"):
        CameraModel(K=np.eye(3), R=np.diag([1.0, 1.0, -1.0]), C=np.zeros(3))
    with pytest.raises(ConfigError, match=r"finite \(3, 4\)"):
        CameraModel(np.ones((3, 3)))
    with pytest.raises(CalibrationError, match="no parameter covariance"):
        CameraModel(lab_camera().matrix()).projection_uncertainty([0.0, 0.0, 0.0])


@pytest.mark.parametrize("kind", ["dlt", "refine"])
def test_projection_uncertainty_matches_monte_carlo(kind):
    cam = lab_camera()
    x = cloud(40, seed=11)
    probe = np.array([[0.0, 0.0, -5.0], [30.0, 20.0, 10.0]])
    sigma = 0.05
    preds, last = [], None
    rng = np.random.default_rng(12)
    for _ in range(60):
        uv = cam.project(x) + rng.normal(0, sigma, (40, 2))
        m, _ = fit_dlt(x, uv)
        if kind == "refine":
            m, _ = refine(m, x, uv)
        preds.append(m.project(probe))
        last = m
    preds = np.array(preds)
    empirical = np.sqrt(preds.var(axis=0).sum(axis=-1))
    predicted = last.projection_uncertainty(probe)
    assert last.parameters == (MATRIX_PARAMETERS if kind == "dlt" else PHYSICAL_PARAMETERS)
    np.testing.assert_array_less(0.6 * empirical, predicted)
    np.testing.assert_array_less(predicted, 1.6 * empirical)


@pytest.mark.parametrize("k1", [0.0, -0.2])
def test_dataset_round_trip(k1):
    cam = lab_camera(k1=k1)
    x = cloud()
    uv = cam.project(x) + np.random.default_rng(0).normal(0, 0.02, (60, 2))
    m, _ = fit_dlt(x, uv)
    if k1:
        m, _ = refine(m, x, uv, distortion="k1")
    ds = m.to_dataset()
    for name in ("projection_matrix", "K", "R", "camera_centre", "focal_length_px", "ifov_mrad", "distortion",
                 "covariance"):
        assert name in ds
    assert ds["distortion"].coefficient.values.tolist() == ["k1", "k2"]
    back = CameraModel.from_dataset(ds)
    np.testing.assert_allclose(back.project(x), m.project(x), rtol=0, atol=1e-9)
    np.testing.assert_allclose(back.projection_uncertainty(x), m.projection_uncertainty(x), rtol=1e-6)
    xr.testing.assert_allclose(back.to_dataset(), ds, rtol=1e-9)
    with pytest.raises(DataError, match="not a camera calibration"):
        CameraModel.from_dataset(ds.drop_vars("projection_matrix"))




def test_camera_model_does_not_load_marker_detection():
    # couple and fields rebuild the camera from a store: they must not pay for (or depend on) the
    # calibration algorithm and scikit-image
    code = ("import sys, irdic.camera; "
            "print(sorted(m for m in ('irdic.calibration', 'skimage', 'irdic.plot') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
