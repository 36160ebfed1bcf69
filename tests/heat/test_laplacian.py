"""The Laplace–Beltrami operator of a regressed temperature against closed forms on plane, cylinder, sphere, tube."""

import numpy as np
import pytest

from irdic.errors import DataError
from irdic.heat import laplace_beltrami, surface_laplacian
from irdic.surface import edge_distance


def _grid(lo1, hi1, lo2, hi2, h, seed=0):
    rng = np.random.default_rng(seed)
    a, b = np.meshgrid(np.arange(lo1, hi1, h), np.arange(lo2, hi2, h), indexing="ij")
    return np.c_[a.ravel(), b.ravel()] + rng.uniform(-0.2 * h, 0.2 * h, (a.size, 2))


def _relative(lap, true, inner):
    """RMS and largest error over the inner points, relative to the largest true value."""
    e = (lap - true)[..., inner]
    scale = np.abs(true).max()
    return np.sqrt(np.mean(e ** 2)) / scale, np.abs(e).max() / scale


def test_plane_any_parametrisation():
    """A plane in a curvilinear, non-orthogonal parametrisation: the ordinary Laplacian of Θ(x, y)."""
    psi = _grid(-12, 12, -12, 12, 0.5)
    p1, p2 = psi.T
    x = np.c_[p1 + 0.02 * p2 ** 2, p2 + 0.01 * p1 * p2, np.zeros_like(p1)]
    # a rotated plane in space: the operator only sees the metric
    rot = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    X, Y = x[:, 0], x[:, 1]
    theta = 0.01 * (2 * X ** 2 + X * Y + Y ** 2) + 0.5 * np.sin(X / 4) * np.cos(Y / 6)
    true = 0.06 - 0.5 * np.sin(X / 4) * np.cos(Y / 6) * (1 / 16 + 1 / 36)
    res = surface_laplacian(psi, theta[None], (x @ rot.T)[None], spacing=4)
    rms, worst = _relative(res.laplacian[0], true, edge_distance(psi) > 3)
    assert rms < 5e-3 and worst < 2e-2, (rms, worst)


def test_cylinder_static():
    """Ψ = (Rφ, z): Δ = ∂²/∂z² + R⁻² ∂²/∂φ²."""
    R = 8.0
    psi = _grid(-R * 1.4, R * 1.4, -15, 15, 0.5, seed=1)
    phi, z = psi[:, 0] / R, psi[:, 1]
    x = np.c_[R * np.cos(phi), R * np.sin(phi), z]
    theta = 0.03 * z ** 2 + 1.2 * np.cos(2 * phi) + 0.4 * np.sin(z / 5) * np.sin(phi)
    true = 0.06 - 4.8 * np.cos(2 * phi) / R ** 2 - 0.4 * np.sin(z / 5) * np.sin(phi) * (1 / 25 + 1 / R ** 2)
    res = surface_laplacian(psi, theta[None], x[None], spacing=4)
    rms, worst = _relative(res.laplacian[0], true, edge_distance(psi) > 3)
    assert rms < 5e-3 and worst < 2e-2, (rms, worst)


def test_sphere_cap_spherical_harmonics():
    """Cap of a sphere, parametrised by its projection on the tangent plane: Y_l has eigenvalue −l(l+1)/R²."""
    R = 20.0
    psi = _grid(-12, 12, -12, 12, 0.5, seed=2)
    psi = psi[np.hypot(*psi.T) < 12]
    z = np.sqrt(R ** 2 - np.sum(psi ** 2, axis=1))
    x = np.c_[psi, z]
    c = z / R  # cos of the polar angle
    y1, y2 = c, 0.5 * (3 * c ** 2 - 1)
    y2b = psi[:, 0] * psi[:, 1] / R ** 2  # sin²θ sin 2φ / 2: l = 2
    theta = 10 * y1 + 20 * y2 + 15 * y2b
    true = -(2 * 10 * y1 + 6 * (20 * y2 + 15 * y2b)) / R ** 2
    res = surface_laplacian(psi, theta[None], x[None], spacing=4)
    rms, worst = _relative(res.laplacian[0], true, edge_distance(psi) > 3)
    assert rms < 5e-3 and worst < 2e-2, (rms, worst)


def _tube(T=4, h=0.5, seed=4):
    """A tube under tension and torsion: reference Ψ = (Rφ, z), current φ' = φ + γ z, z' = λ z."""
    R = 10.0
    psi = _grid(-15, 15, -20, 20, h, seed=seed)
    phi, z = psi[:, 0] / R, psi[:, 1]
    lam, gam = np.linspace(1.0, 1.06, T), np.linspace(0.0, 0.04, T)
    x = np.stack([np.c_[R * np.cos(phi + g * z), R * np.sin(phi + g * z), lm * z] for lm, g in zip(lam, gam)])
    A, B = 0.02, 1.5
    theta = np.tile(A * z ** 2 + B * np.cos(2 * phi), (T, 1))
    # in the current coordinates Θ = A z'²/λ² + B cos 2(φ' − γ z'/λ)
    true = np.stack([2 * A / lm ** 2 - 4 * B * np.cos(2 * phi) * ((g / lm) ** 2 + 1 / R ** 2) for lm, g in zip(lam, gam)])
    return psi, x, theta, true


def test_moving_tube_stretch_and_twist():
    psi, x, theta, true = _tube()
    res = surface_laplacian(psi, theta, x, spacing=4)
    rms, worst = _relative(res.laplacian, true, edge_distance(psi) > 3)
    assert rms < 5e-3 and worst < 2e-2, (rms, worst)
    # the twist's contribution −4B cos 2φ (γ/λ)² is resolved, not lost in the error
    twist = 4 * 1.5 * (0.04 / 1.06) ** 2
    assert twist > 10 * rms * np.abs(true).max()


def test_noisy_tube_std_covers_and_auto_spacing():
    """0.05 K noise, 2 decimals: the chosen spacing's error is far below a fine one's, and the std covers it."""
    psi, x, theta, true = _tube(T=3)
    noisy = np.round(theta + np.random.default_rng(5).normal(0, 0.05, theta.shape), 2)
    inner = edge_distance(psi) > 3
    auto = surface_laplacian(psi, noisy, x)
    fine = surface_laplacian(psi, noisy, x, spacing=5)
    e_auto, e_fine = (auto.laplacian - true)[:, inner], (fine.laplacian - true)[:, inner]
    assert np.sqrt(np.mean(e_auto ** 2)) < 0.3 * np.sqrt(np.mean(e_fine ** 2))
    assert np.sqrt(np.mean(e_auto ** 2)) < 0.03 * np.abs(true).max()
    assert np.allclose(auto.noise, 0.05, rtol=0.1)
    # where noise dominates (a fixed moderate spacing) the std is calibrated
    mid = surface_laplacian(psi, noisy, x, spacing=8)
    z = np.abs(mid.laplacian - true)[:, inner] / mid.std[:, inner]
    assert 0.6 < np.mean(z < 1) < 0.76 and 0.91 < np.mean(z < 2) < 0.98


def test_missing_temperatures_are_nan_and_neighbours_unharmed():
    psi, x, theta, true = _tube(T=2)
    gap = np.hypot(psi[:, 0] - 3, psi[:, 1] + 2) < 1.5
    theta = theta.copy()
    theta[1, gap] = np.nan
    res = surface_laplacian(psi, theta, x, spacing=4)
    assert np.isnan(res.laplacian[1, gap]).all() and np.isfinite(res.laplacian[0, gap]).all()
    rms, _ = _relative(res.laplacian, true, (edge_distance(psi) > 3) & ~gap)
    assert rms < 5e-3


def test_laplace_beltrami_closed_form_derivatives():
    """Exact derivatives of a cylinder in a plane projection Ψ = (R sin φ, z): the Christoffel term matters."""
    R = 5.0
    phi = np.linspace(-1.0, 1.0, 9)
    s, c = np.sin(phi), np.cos(phi)
    # x = (R sin φ, R cos φ, z) with Ψ1 = R sin φ: dφ/dΨ1 = 1/(R cos φ), d²φ/dΨ1² = sin φ/(R² cos³ φ)
    a1 = np.c_[np.ones_like(phi), -np.tan(phi), 0 * phi]
    a2 = np.tile([0.0, 0.0, 1.0], (phi.size, 1))
    x11 = np.c_[0 * phi, -1 / (R * c ** 3), 0 * phi]
    zeros = np.zeros_like(x11)
    # Θ = φ²: Δ = R⁻² d²Θ/dφ² = 2/R²
    d1 = 2 * phi / (R * c)
    d11 = 2 / (R * c) ** 2 + 2 * phi * s / (R ** 2 * c ** 3)
    lap, w = laplace_beltrami(np.c_[d1, 0 * phi], np.c_[d11, 0 * phi, 0 * phi], np.stack([a1, a2], 1),
                              np.stack([x11, zeros, zeros], 1))
    assert np.allclose(lap, 2 / R ** 2, rtol=1e-12)
    assert w.shape == (phi.size, 5)


def test_shape_mismatch_is_a_clear_error():
    psi, x, theta, _ = _tube(T=2)
    with pytest.raises(DataError, match="disagree"):
        surface_laplacian(psi, theta, x[:1])


@pytest.mark.parametrize("name", ["tube", "halfshell"])
def test_synthetic_specimens_on_their_material_grid(name):
    """The demo specimens' exact positions and temperatures (no IR, no DIC): the closed form of
    :mod:`irdic.synthetic.laplacian`, the tube stretched and twisted at mid-load."""
    from irdic.synthetic.laplacian import temperature_laplacian
    from irdic.synthetic.specimens import HalfShell, Tube

    sp, box = (Tube(), (-14, 14, -20, 20)) if name == "tube" else (HalfShell(), (-38, 38, 1, 49))
    psi = _grid(*box, 0.5, seed=6)
    s, h = psi.T
    t = np.array([3.0, 6.0])[:, None]
    x = sp.position(s[None], h[None], t)
    res = surface_laplacian(psi, sp.temperature(s[None], h[None], t), x, spacing=4)
    true = temperature_laplacian(sp, s[None], h[None], t)
    rms, _ = _relative(res.laplacian, true, edge_distance(psi) > 3)
    assert rms < 0.03, rms


def test_regression_in_time_cuts_the_noise_and_propagates_the_std():
    """A tube heating linearly in time (Laplacian ∝ t) with 0.05 K noise: the time regression's error is far
    below each time's, and its std still describes it."""
    from irdic.heat import smooth_in_time

    psi, x, theta, true = _tube(T=1)
    t = np.arange(0.0, 20.0, 0.5)
    ramp = 0.5 + t / 20.0
    th = 20.0 + ramp[:, None] * (theta[0] - 20.0)
    x = np.repeat(x, t.size, axis=0)
    tr = ramp[:, None] * true[0]
    noisy = th + np.random.default_rng(7).normal(0, 0.05, th.shape)
    inner = edge_distance(psi) > 3
    each = surface_laplacian(psi, noisy, x, spacing=8)
    smooth, k = smooth_in_time(each, t)
    assert k > 2
    e0, e1 = (each.laplacian - tr)[:, inner], (smooth.laplacian - tr)[:, inner]
    assert np.sqrt(np.mean(e1 ** 2)) < 0.7 * np.sqrt(np.mean(e0 ** 2))  # centres every 4 of 40 times: ~0.6
    z = np.abs(e1) / smooth.std[:, inner]
    assert 0.55 < np.mean(z < 1) < 0.8 and np.mean(z < 2) > 0.88
    same, k1 = smooth_in_time(each, t, None)
    assert k1 == 1.0 and same is each


def test_spacing_judged_on_the_regression_in_time():
    """A 4 mm hot spot under 0.2 K noise, 24 times: judged on each time's noise the risk criterion takes a
    spacing that the regression in time then leaves bias-dominated; judged on the temperatures regressed in
    time as the Laplacian will be, one no wider and no larger an error (the least estimated risk is at a
    finer one, 6 spacings against 8; the one-standard-error rule takes 8 from both here)."""
    from irdic.heat import smooth_in_time
    from irdic.heat.laplacian import judging_weights

    rng = np.random.default_rng(0)
    a, b = np.meshgrid(np.arange(-15, 15, 0.6), np.arange(-15, 15, 0.6), indexing="ij")
    psi = np.c_[a.ravel(), b.ravel()] + rng.uniform(-0.12, 0.12, (a.size, 2))
    X, Y = psi.T
    t = np.arange(24, dtype=float)
    ramp = (0.5 + t / 24)[:, None]
    r2 = X ** 2 + Y ** 2
    g = 6.0 * np.exp(-0.5 * r2 / 16.0)
    true = ramp * (r2 / 16.0 - 2.0) / 16.0 * g
    noisy = np.round(20.0 + ramp * g + rng.normal(0.0, 0.2, true.shape), 2)
    x = np.repeat(np.c_[X, Y, 0 * X][None], t.size, axis=0)
    inner = np.broadcast_to(edge_distance(psi) > 4, true.shape).copy()
    inner[[0, -1]] = False
    W = judging_weights(t)
    assert W.shape == (24, 24) and np.allclose(W.sum(axis=1), 1.0)
    assert judging_weights(t, None) is None and judging_weights(t[:3]) is None
    each, _ = smooth_in_time(surface_laplacian(psi, noisy, x), t)
    judged, _ = smooth_in_time(surface_laplacian(psi, noisy, x, time_weights=W), t)
    rms = lambda r: np.sqrt(np.mean((r.laplacian - true)[inner] ** 2))  # noqa: E731
    assert judged.spacing <= each.spacing
    assert rms(judged) <= rms(each)
