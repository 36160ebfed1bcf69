"""The guards on the fields' regression in time (irdic.fields.smoothing.guarded_time_smoothing,
value_time_smoothing)."""

import numpy as np
import pytest

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


def _after_time_scene(seed=3):
    """A plane patch (0.5 mm apart) whose pattern grows in time, with ripples 6 mm long that wide spacings smooth
    away, under 0.3 K of white noise: ``(psi, t, data (T, N), true gradient (T, N, 2))``."""
    rng = np.random.default_rng(seed)
    psi = _grid(36) + rng.uniform(-0.1, 0.1, (36 * 36, 2))
    t = np.arange(41.0)
    a = 1.0 + t / 40.0
    g = 0.3 * np.sin(psi[:, 0] / 1.0) + 0.1 * psi[:, 1]
    dg = np.c_[0.3 * np.cos(psi[:, 0] / 1.0), np.full(len(psi), 0.1)]
    return psi, t, a[:, None] * g + rng.normal(0.0, 0.3, (t.size, len(psi))), a[:, None, None] * dg


def test_the_noise_share_a_regression_in_time_keeps_is_measured_on_white_noise():
    """``_after_time``'s share of the noise (the median ``Σ w²`` of the regression in time's weights) is what
    the regression keeps of white noise, and its sampled times keep no more than 1.25 x that share."""
    from irdic.fields.spatial import AFTER_TIME_SHARE, _after_time
    from irdic.numerics.series import smooth_series

    t = np.arange(41.0)
    noise = np.random.default_rng(0).normal(0.0, 1.0, (t.size, 4000))
    sampled, share = _after_time(noise, t, 6.0, P["c_time"], P["R0_time"])
    smoothed = smooth_series(noise, t, None, smoothing=6.0, c=P["c_time"], R0=P["R0_time"]).value
    times = [int(np.flatnonzero(np.all(np.isclose(smoothed, row, atol=1e-10), axis=1))[0]) for row in sampled]
    kept = np.mean(smoothed ** 2, axis=1)
    assert 0.05 < share < 0.5 and len(times) == 8
    assert np.median(kept) == pytest.approx(share, rel=0.1)
    assert np.all(kept[times] <= AFTER_TIME_SHARE * share * 1.15)
    assert 0 not in times and t.size - 1 not in times  # the record's ends keep more


def test_the_spatial_spacing_is_judged_after_the_regression_in_time():
    """On single times the noise hides the ripples' bias at wide spacings; the fields' gradient is regressed in
    time, which keeps a fraction of the noise and all of the bias. Judged after it, the chosen spacing is
    narrower and its gradient, through both regressions, the best candidate's within 10 %, where the single
    times' choice errs by 1.3 x more (seeds 1-6: the choice after time the best on each, the single times' 1.2-1.5 x
    off)."""
    from irdic.fields.spatial import judged_points, space_gcv_filled
    from irdic.numerics.series import smooth_series
    from irdic.surface import SpatialInterpolant

    psi, t, data, true = _after_time_scene()
    kt = 8.0
    k_single = space_gcv_filled(data, psi, c=P["c_space"], R0=P["R0_space"])
    k_after = space_gcv_filled(data, psi, c=P["c_space"], R0=P["R0_space"],
                               after=(t, kt, P["c_time"], P["R0_time"], k_single))
    smoothed = smooth_series(data, t, None, smoothing=kt, c=P["c_time"], R0=P["R0_time"]).value
    inner = judged_points(psi)

    def error(k):  # RMS of the delivered gradient's error on the judged points, the record's ends left out
        _, d1, d2 = SpatialInterpolant(psi, c=P["c_space"], R0=P["R0_space"], smoothing=k).evaluate(
            smoothed.T, value=False)
        e = np.stack([d1.T, d2.T], -1)[5:-5, inner] - true[5:-5, inner]
        return float(np.sqrt(np.mean(e ** 2)))

    errors = {k: error(k) for k in (2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0)}
    assert k_after < k_single
    assert error(k_after) <= 1.1 * min(errors.values())
    assert error(k_single) > 1.3 * error(k_after)


def test_the_spacing_after_time_is_never_wider_and_the_pilot_only_where_single_times_chose_it():
    """Less noise moves the least risk to narrower spacings: a wider choice after the regression in time is the
    estimate's scatter. The pilot (the least smoothed candidate), whose risk is its noise alone, stays only where
    the single times chose it."""
    from irdic.fields.spatial import _narrower

    table = [(2.0, 400, 1.0, 0.9), (3.0, 200, 1.2, 0.5), (4.0, 120, 0.8, 0.3), (6.0, 60, 0.5, 0.1)]
    assert _narrower(table, 6.0) == 6.0
    assert _narrower(table, 4.0) == 4.0
    assert _narrower(table, 3.0) == 3.0  # the pilot's lower risk is its noise alone
    assert _narrower(table, 2.0) == 2.0
    assert _narrower(table, None) == 6.0
