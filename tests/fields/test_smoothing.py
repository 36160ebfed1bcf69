"""The guards on the fields' regression in time (irdic.fields.smoothing.guarded_time_smoothing,
value_time_smoothing)."""

import numpy as np

from irdic.fields.smoothing import guarded_time_smoothing, parameter_dual, value_time_smoothing
from irdic.fields.spatial import regressed_gradient

P = {"c_time": 1.0, "R0_time": 1.0, "c_space": 0.95, "R0_space": 1.0}


def _grid(n=24):
    g = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2) * 0.5
    return g.astype(float)


def test_the_guard_keeps_a_regression_that_follows_the_signal_and_interpolates_where_it_cannot():
    rng = np.random.default_rng(1)
    psi = _grid()
    t = np.arange(21) * 0.5
    sigma = 0.01
    # a gradient that changes slowly in time, with white noise of the stated variance
    slow = np.broadcast_to(np.stack([1.0 + 0.02 * t, 0.5 - 0.01 * t, 0 * t], -1)[:, None], (21, psi.shape[0], 3))
    noisy = slow + rng.normal(0.0, sigma, slow.shape)
    assert guarded_time_smoothing(3.0, t, noisy, psi, sigma**2, P) == 3.0
    # a band 0.6 mm wide passing every point at 1.9 mm/s: its gradient changes within two samples
    band = np.zeros_like(noisy)
    band[..., 0] = -2.0 * (1.9 * t[:, None] - psi[None, :, 0]) / 0.36 * np.exp(
        -((1.9 * t[:, None] - psi[None, :, 0]) ** 2) / 0.36)
    assert guarded_time_smoothing(3.0, t, band + rng.normal(0.0, sigma, band.shape), psi, sigma**2, P) == 1.0
    # the rim's points are not judged: jumps there (mixed pixels at a moving outline) leave the choice alone
    rim = noisy.copy()
    edge = (psi.min(axis=1) < 0.5) | (psi.max(axis=1) > 11.0)
    rim[:, edge] += rng.normal(0.0, 50 * sigma, (21, edge.sum(), 3))
    assert guarded_time_smoothing(3.0, t, rim, psi, sigma**2, P) == 3.0
    # interpolation already, or no noise known: nothing to guard
    assert guarded_time_smoothing(1.0, t, band, psi, sigma**2, P) == 1.0
    assert guarded_time_smoothing(3.0, t, band, psi, float("nan"), P) == 3.0


def test_the_value_has_its_own_guard_for_a_bias_the_gradient_does_not_see():
    """A heating uniform over the patch whose rate jumps from 0 to 1 K/s between two of 17 DIC times at 4 Hz:
    its gradient is constant in time (the gradient's guard keeps the regression), its value is not: the value's
    regression with centres every 3 times leaves ~25 x its noise (Mallows: interpolation is the better estimate
    above 2 x), a smooth heating's ~1 x."""
    rng = np.random.default_rng(4)
    psi = _grid()
    t = np.arange(17) * 0.25
    sigma, n = 0.005, psi.shape[0]
    grad = np.broadcast_to([0.2, -0.1, 0.0], (t.size, n, 3)) + rng.normal(0.0, sigma, (t.size, n, 3))
    knee = 20.0 + np.maximum(t - 2.0, 0.0)[:, None] + 0.01 * psi[None, :, 0] + rng.normal(0.0, sigma, (t.size, n))
    smooth = 20.0 + (0.5 * t + 0.05 * t**2)[:, None] + 0.01 * psi[None, :, 0] + rng.normal(0.0, sigma, (t.size, n))
    assert guarded_time_smoothing(3.0, t, grad, psi, sigma**2, P) == 3.0
    assert value_time_smoothing(3.0, t, knee, psi, sigma**2, P) == 1.0
    assert value_time_smoothing(3.0, t, smooth, psi, sigma**2, P) == 3.0
    # the value's noise unknown (no pixel positions: irdic.fields.smoothing.regression_noise_var): not judged
    assert value_time_smoothing(3.0, t, knee, psi, float("nan"), P) == 3.0
    # a bias only in the rim's values (mixed pixels at a moving outline) is not judged either
    rim = smooth.copy()
    edge = (psi.min(axis=1) < 0.5) | (psi.max(axis=1) > 11.0)
    rim[:, edge] = knee[:, edge]
    assert value_time_smoothing(3.0, t, rim, psi, sigma**2, P) == 3.0
    # the gradient interpolated already: the value with it
    assert value_time_smoothing(1.0, t, smooth, psi, sigma**2, P) == 1.0


def test_the_parameter_dual_gives_the_gradient_in_the_surface_parameters():
    psi = _grid(12)
    theta = np.broadcast_to(20.0 + 0.3 * psi[:, 0] - 0.2 * psi[:, 1], (2, psi.shape[0]))
    grad = regressed_gradient(theta, psi, parameter_dual(psi.shape[0]), 3.0, c=0.95, R0=1.0)[0]
    np.testing.assert_allclose(grad, np.broadcast_to([0.3, -0.2, 0.0], grad.shape), atol=1e-6)


def test_regressed_field_everywhere_holds_the_points_without_a_temperature():
    """``everywhere``: the regressed value also at a point without a temperature (the field the time's other
    points give there, close to the truth of a smooth field), the values elsewhere and the gradient as without."""
    rng = np.random.default_rng(3)
    psi = np.stack(np.meshgrid(np.arange(14.0), np.arange(12.0)), -1).reshape(-1, 2)
    truth = 20 + 0.3 * psi[:, 0] - 0.02 * psi[:, 1] ** 2
    theta = np.stack([truth + k + rng.normal(0, 0.01, truth.size) for k in range(3)])
    theta[1, 50] = np.nan
    dual = parameter_dual(psi.shape[0])
    g0, v0, _ = regressed_gradient(theta, psi, dual, 3.0, c=0.95, R0=1.0)
    g1, v1, _ = regressed_gradient(theta, psi, dual, 3.0, c=0.95, R0=1.0, everywhere=True)
    assert np.isnan(v0[1, 50]) and abs(v1[1, 50] - (truth[50] + 1)) < 0.05
    np.testing.assert_array_equal(np.where(np.isfinite(theta), v1, np.nan), v0)
    np.testing.assert_array_equal(g1, g0)
