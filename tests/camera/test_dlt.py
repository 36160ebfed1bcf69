"""Exact-math tests of irdic.camera.dlt against the independent true camera of irdic.synthetic."""

import numpy as np
import pytest

from irdic.camera import dlt, planarity
from irdic.errors import CalibrationError, ConfigError, DataError
from irdic.synthetic.camera import lab_camera

from ._cameras import POSES, cloud


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
