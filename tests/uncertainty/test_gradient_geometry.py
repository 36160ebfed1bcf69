"""The in-plane gradient's uncertainty from the DIC noise of its tangent plane
(irdic.uncertainty.gradient_geometry)."""

from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr

from irdic.camera import CameraModel
from irdic.coupling import couple
from irdic.fields import fields
from irdic.uncertainty.gradient_geometry import TANGENT_PROBES, gradient_dic_var, tangent_noise
from irdic.surface import fit_stages
from irdic.surface.geometry import surface_geometry
from irdic.synthetic import HalfShell, experiment, lab_camera


def test_gradient_dic_var_matches_the_perturbed_dual_basis():
    """First-order variance of ``g = θ_a a^a`` under white tangent noise against the exact (nonlinear) result
    of perturbed tangents, Monte Carlo: oblique, non-orthogonal, unequal tangents; a gradient with both
    parametric derivatives. Noise 1e-3 of the tangents: first order holds to ~1e-3, the Monte Carlo of 20,000
    draws to ~2 % (1 std of a variance: sqrt(2 / 20000))."""
    rng = np.random.default_rng(0)
    a = np.array([[1.2, 0.1, 0.3], [0.2, 0.8, -0.4]])
    theta = np.array([0.7, -1.9])  # K per unit psi
    s = np.array([1e-3, 2e-3])  # per-component tangent noise of a_1, a_2
    geo = surface_geometry(a[None, None])
    g = np.einsum("a,tnaj->tnj", theta, geo.dual)
    var = gradient_dic_var(g, geo, (s ** 2)[None])[0, 0]
    M = 20000
    noisy = a + rng.standard_normal((M, 2, 3)) * s[:, None]
    g_mc = np.einsum("a,maj->mj", theta, surface_geometry(noisy).dual)
    var_mc = np.var(g_mc, axis=0)
    np.testing.assert_allclose(var, var_mc, rtol=0.05)
    # both parts matter here: the stretch in the plane and the tilt out of it (the normal's components)
    n = geo.normal[0, 0]
    tilt = sum(s[b] ** 2 * (g[0, 0] @ geo.dual[0, 0, b]) ** 2 for b in range(2)) * n ** 2
    assert np.all(tilt > 0.1 * var), (tilt, var)


def test_tangent_noise_against_the_realised_tangent_error_of_the_fit():
    """The probes' tangent noise against the realised error of the same spatial regression on independent
    noise draws (a cylinder patch R 20 mm, 0.003 mm, centres every 3 point spacings): pooled within 10 %, and
    the noise variance scales as s_x²."""
    u, v = np.meshgrid(np.linspace(-10, 10, 21), np.linspace(-10, 10, 21))
    psi = np.column_stack([u.ravel(), v.ravel()])
    R = 20.0
    x0 = np.column_stack([R * np.sin(psi[:, 0] / R), psi[:, 1], R * np.cos(psi[:, 0] / R)])
    x = np.repeat(x0[None], 5, axis=0)
    p = dict(c_space=0.95, R0_space=1.0, solver="auto")
    sf = SimpleNamespace(psi=psi, x=x, info={"smoothing": 3.0})
    s2 = tangent_noise(x, sf, 0.003, p, np.random.default_rng(1))
    assert s2.shape == (psi.shape[0], 2) and np.isfinite(s2).all()
    rng = np.random.default_rng(2)
    draws = 40
    stages = np.concatenate([x0[None]] + [x0[None] + rng.standard_normal((1,) + x0.shape) * 0.003
                                          for _ in range(draws)])
    _, tang = fit_stages(stages, psi, smoothing=3.0, shape_stage=stages, c=0.95, R0=1.0)
    real = np.mean(np.square(tang[1:] - tang[0]), axis=(0, 3))
    ratio = np.mean(s2) / np.mean(real)
    assert abs(ratio - 1) < 0.1, ratio
    s2b = tangent_noise(x, sf, 0.006, p, np.random.default_rng(1))
    np.testing.assert_allclose(s2b, 4 * s2, rtol=1e-6)
    assert TANGENT_PROBES >= 2


@pytest.mark.slow
def test_barrel_gradient_std_holds_the_tangent_planes_dic_noise():
    """Regression: a barrel patch (R 40 mm, heated from one end, |g| ~1 K/mm) with 0.05 K IR and 0.003 mm DIC
    noise; the DIC noise tilts and stretches the fitted tangent plane, an error of ~0.4 x the IR noise's
    (benchmark scene) that the std left out: within 2 std 0.868 before, 0.895 with it, 0.98 since the bias
    against the half-spacing reference is its RMS over the specimen where no neighbourhood resolves it
    (:func:`irdic.uncertainty.regression_bias.reference_options`). Within 1 std 0.78 on these clean exports (0.67-0.75
    on the benchmark's rounded ones, benchmarks/README): that RMS stands also where the ripple is small.

    At the 4 spacings the gradient's risk chooses on single times, pinned: judged after the regression in time
    (irdic.fields.spatial._after_time) it takes 3, where the gradient errs by 0.35 % against 0.33 % and its std
    is a little narrow (within 1 / 2 std 0.68 / 0.915, RMS of error/std 1.14; benchmarks/README)."""
    ex = experiment("halfshell", "demo", ir_noise=0.05, dic_noise=0.003, seed=3,
                    specimen=HalfShell(R_o=40.0, R_i=36.0, axis_z=-40.0), camera=lab_camera())
    ir = xr.Dataset({"temperature": ex.ir_stack().drop_vars("frame_number")})
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=cam.width, sensor_height=cam.height)
    pts = couple(ex.dic()[["x"]], ir, cal)
    truth = ex.truth().sel(point=pts.point)
    f = fields(pts, cal, temperature_smoothing_space=4.0)
    m = pts.visible.values & (truth.patch_edge_distance.values >= 2.0)
    m[[0, -1]] = False
    mm = m[..., None] & ~f.temperature_gradient_bias_dominated.values
    z = np.abs(f.temperature_gradient.values - truth.temperature_gradient.values)[mm] / \
        f.temperature_gradient_std.values[mm]
    assert 0.60 <= np.mean(z <= 1) <= 0.80 and 0.92 <= np.mean(z <= 2) <= 0.99, (np.mean(z <= 1), np.mean(z <= 2))
