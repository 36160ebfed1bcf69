"""Exact-math tests of irdic.camera against the independent true camera of irdic.synthetic."""

import numpy as np
import pytest

from irdic.camera import (MATRIX_PARAMETERS, PHYSICAL_PARAMETERS, CameraModel, dlt, fit_dlt, leave_one_out,
                          planarity, refine)
from irdic.errors import CalibrationError, ConfigError, DataError
from irdic.synthetic.camera import IR_F, TrueCamera, lab_camera

POSES = [
    dict(distance=450.0, azimuth_deg=17.5, elevation_deg=10.0, roll_deg=1.0),
    dict(distance=380.0, azimuth_deg=-25.0, elevation_deg=-8.0, roll_deg=-3.0),
    dict(distance=600.0, azimuth_deg=5.0, elevation_deg=20.0, roll_deg=90.0),
]


def cloud(n=60, seed=0):
    """Random 3-D points in a 80 x 60 x 40 mm box around the lab target point."""
    rng = np.random.default_rng(seed)
    return rng.uniform([-40, -30, -25], [40, 30, 15], (n, 3))


def model_of(cam: TrueCamera) -> CameraModel:
    return CameraModel(K=cam.K, R=cam.R, C=cam.C, k1=cam.k1, k2=cam.k2)


def fd_jacobian(model, x, h=1e-4):
    cols = [(model.project(x + h * e) - model.project(x - h * e)) / (2 * h) for e in np.eye(3)]
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("pose", POSES)
def test_dlt_recovers_M_exactly(pose):
    cam = lab_camera(**pose)
    x = cloud()
    M = dlt(x, cam.project(x))
    M_true = cam.matrix()
    assert np.linalg.norm(M[2, :3]) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(M, M_true, rtol=0, atol=1e-9 * np.abs(M_true).max())
    assert (x @ M[2, :3] + M[2, 3] > 0).all()


def test_dlt_minimum_six_points_and_weights():
    cam = lab_camera()
    x = cloud(6, seed=3)
    np.testing.assert_allclose(dlt(x, cam.project(x)), cam.matrix(), atol=1e-7 * np.abs(cam.matrix()).max())
    # a wrong point with zero weight does not disturb the weighted DLT
    x = cloud(20, seed=4)
    uv = cam.project(x)
    uv[3] += [25.0, -10.0]
    w = np.ones(20)
    w[3] = 0.0
    np.testing.assert_allclose(dlt(x, uv, weights=w), cam.matrix(), atol=1e-8 * np.abs(cam.matrix()).max())
    assert np.abs(dlt(x, uv) - cam.matrix()).max() > 1e-4  # ... while the unweighted one is disturbed
    with pytest.raises(ConfigError, match=r"weights.*shape \(20,\)"):
        dlt(x, uv, weights=np.ones(19))
    with pytest.raises(ConfigError, match="finite and >= 0"):
        dlt(x, uv, weights=-w)


def test_dlt_rejects_bad_input():
    cam = lab_camera()
    x = cloud(10)
    uv = cam.project(x)
    with pytest.raises(CalibrationError, match="at least 6 .* got 5"):
        dlt(x[:5], uv[:5])
    with pytest.raises(ConfigError, match=r"`x` has 10 points but `uv` has 9"):
        dlt(x, uv[:9])
    with pytest.raises(ConfigError, match=r"shape \(N, 3\), got shape \(10, 2\)"):
        dlt(x[:, :2], uv)
    bad = uv.copy()
    bad[4, 1] = np.nan
    with pytest.raises(DataError, match=r"`uv` contains NaN .* rows \[4\]"):
        dlt(x, bad)


@pytest.mark.parametrize("thickness", [0.0, 1e-3])
def test_dlt_coplanar_markers(thickness):
    cam = lab_camera()
    x = cloud(30)
    x[:, 2] = -5.0 + thickness * np.random.default_rng(1).standard_normal(30)
    with pytest.raises(CalibrationError, match=r"coplanar .*thickness ratio s3/s1 = \d"):
        dlt(x, cam.project(x))
    assert planarity(x) < 1e-3


def test_dlt_collinear_subset_is_rank_deficient():
    cam = lab_camera()
    # 3-D cloud, but all points on two lines: the 12x12 normal matrix loses rank
    t = np.linspace(-20, 20, 8)[:, None]
    x = np.vstack([t * [1.0, 0.2, 0.0], [0, 0, -20] + t * [0.0, 1.0, 0.5]])
    with pytest.raises(CalibrationError, match="rank-deficient|coplanar"):
        dlt(x, cam.project(x))


@pytest.mark.parametrize("flip", ["u", "swap"])
def test_dlt_behind_the_camera(flip):
    cam = lab_camera()
    x = cloud()
    uv = cam.project(x)
    uv = np.column_stack([1023 - uv[:, 0], uv[:, 1]]) if flip == "u" else uv[:, ::-1]
    with pytest.raises(CalibrationError, match="behind"):
        dlt(x, uv)


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


@pytest.mark.parametrize("pose", POSES[:2])
def test_refine_recovers_k1_and_beats_pinhole(pose):
    k1 = -0.4
    cam = lab_camera(k1=k1, **{**pose, "distance": 0.55 * pose["distance"]})
    rng = np.random.default_rng(5)
    x = cloud(120, seed=6)
    uv = cam.project(x) + rng.normal(0, 0.02, (120, 2))
    start, _ = fit_dlt(x, uv)
    pin, ipin = refine(start, x, uv, distortion="none")
    dist, idist = refine(start, x, uv, distortion="k1")
    sd = np.sqrt(np.diag(dist.covariance))
    assert abs(dist.k1 - k1) < 4 * sd[PHYSICAL_PARAMETERS.index("k1")]
    assert abs(dist.k1 - k1) < 0.02
    assert idist["rms_px"] < 0.03  # noise 0.02 px per coordinate -> 0.028 px radial
    assert ipin["rms_px"] > 5 * idist["rms_px"]
    np.testing.assert_allclose(dist.C, cam.C, atol=1.0)
    # the refined camera projects new points like the truth
    xt = cloud(50, seed=9)
    assert np.abs(dist.project(xt) - cam.project(xt)).max() < 0.05
    assert sd[PHYSICAL_PARAMETERS.index("k2")] == 0.0  # k2 held at 0


def test_refine_argument_checks():
    cam = lab_camera()
    x = cloud()
    m = CameraModel(cam.matrix())
    with pytest.raises(ConfigError, match="`distortion` must be one of"):
        refine(m, x, cam.project(x), distortion="k3")
    with pytest.raises(ConfigError, match="must be a CameraModel"):
        refine(cam.matrix(), x, cam.project(x))
    with pytest.raises(CalibrationError, match="needs more than 4 points, got 4"):
        refine(m, x[:4], cam.project(x[:4]))


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


def test_leave_one_out_shows_the_bad_marker():
    cam = lab_camera()
    x = cloud(30, seed=2)
    uv = cam.project(x) + np.random.default_rng(3).normal(0, 0.03, (30, 2))
    uv[17] += [0.8, -0.5]
    for method in ("dlt", "refine"):
        loo = leave_one_out(x, uv, method=method)
        assert np.argmax(loo) == 17
        assert loo[17] > 5 * np.median(loo)
        assert loo[17] == pytest.approx(np.hypot(0.8, 0.5), rel=0.2)
    assert np.isnan(leave_one_out(x[:6], uv[:6])).all()  # 5 left: no fit possible


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
    with pytest.raises(DataError, match="not a camera calibration"):
        CameraModel.from_dataset(ds.drop_vars("projection_matrix"))


def test_collinear_markers_are_called_collinear():
    t = np.linspace(0, 1, 8)[:, None]
    x = np.array([0.0, 0.0, 500.0]) + t * np.array([40.0, 10.0, 5.0])
    uv = np.column_stack([100 + 300 * t[:, 0], 200 + 50 * t[:, 0] ** 2])
    with pytest.raises(CalibrationError, match=r"the 8 markers are \(nearly\) collinear .*line of markers") as exc:
        dlt(x, uv)
    assert "coplanar" not in str(exc.value) and "rank-deficient" not in str(exc.value)


def test_collinear_pixel_positions_are_named():
    rng = np.random.default_rng(2)
    x = rng.uniform(-20, 20, (10, 3)) + [0, 0, 500]
    t = np.linspace(0, 1, 10)
    uv = np.column_stack([100 + 300 * t, 200 + 60 * t])
    with pytest.raises(CalibrationError, match=r"the 10 pixel positions are \(nearly\) collinear") as exc:
        dlt(x, uv)
    assert "rank-deficient" not in str(exc.value)
