"""Refinement and leave-one-out residuals of irdic.camera.refine against the true camera of irdic.synthetic."""

import numpy as np
import pytest

from irdic.camera import CameraModel, fit_dlt, leave_one_out, refine
from irdic.camera.model import PHYSICAL_PARAMETERS
from irdic.errors import CalibrationError, ConfigError
from irdic.synthetic.camera import lab_camera

from ._cameras import POSES, cloud


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




def test_covariance_from_anisotropic_point_covariances():
    """Centres precise in u (0.005 px) and not in v (0.05 px), fitted with one weight per point: the covariance
    from the points' 2 x 2 covariances matches the spread of the fitted principal point over noise draws; the
    pooled isotropic residual variance over-predicts it by 30-45 %."""
    cam = lab_camera()
    x = cloud(60, seed=4)
    start = CameraModel(K=cam.K, R=cam.R, C=cam.C)
    sd = np.array([0.005, 0.05])
    C = np.broadcast_to(np.diag(sd**2), (60, 2, 2))
    w = np.full(60, 1 / np.hypot(*sd))
    rng = np.random.default_rng(5)
    pp, new, old = [], [], []
    k = [PHYSICAL_PARAMETERS.index("cx"), PHYSICAL_PARAMETERS.index("cy")]
    for t in range(200):
        uv = cam.project(x) + rng.normal(0.0, sd, (60, 2))
        m, _ = refine(start, x, uv, weights=w, point_covariances=C)
        pp.append(m.decompose().principal_point)
        new.append(np.diag(m.covariance)[k])
        if t % 20 == 0:
            old.append(np.diag(refine(start, x, uv, weights=w)[0].covariance)[k])
    var = np.var(np.array(pp), axis=0)  # 200 draws: the variances to +-10 % (1 sigma)
    assert np.mean(new, axis=0) == pytest.approx(var, rel=0.15)  # 0.99, 1.03
    ratio = np.mean(old, axis=0) / var
    assert ratio[0] > 1.3 and ratio[1] > 1.2  # what the isotropic model said (1.44, 1.32)
    with pytest.raises(ConfigError, match="point_covariances"):
        refine(start, x, cam.project(x), point_covariances=np.zeros((60, 2, 2)))
