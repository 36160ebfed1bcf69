"""The Laplacian's regression bias in its std, and ``_bias_dominated`` meaning what it says (bias > noise), against
the regressions' own bias on the noise-free temperatures."""

import numpy as np
import pytest

from irdic.heat import laplacian_bias, smooth_in_time, surface_laplacian, with_bias
from irdic.heat.dataset import _bias_flags
from irdic.heat.balance import heat_balance
from irdic.surface import edge_distance


def _plane(field, T=16, noise=0.05, seed=0):
    """A 30 x 30 mm plane, points 0.6 mm apart (jittered), ``field(X, Y)`` growing linearly in time, white noise
    and 2-decimal exports; the truth Laplacian from ``field``'s own closed form."""
    rng = np.random.default_rng(seed)
    a, b = np.meshgrid(np.arange(-15, 15, 0.6), np.arange(-15, 15, 0.6), indexing="ij")
    psi = np.c_[a.ravel(), b.ravel()] + rng.uniform(-0.12, 0.12, (a.size, 2))
    X, Y = psi.T
    t = np.arange(T, dtype=float)
    ramp = (0.5 + t / T)[:, None]
    value, lap = field(X, Y)
    theta = 20.0 + ramp * value
    noisy = np.round(theta + rng.normal(0.0, noise, theta.shape), 2)
    x = np.repeat(np.c_[X, Y, 0 * X][None], T, axis=0)
    return psi, t, noisy, x, ramp * lap, theta


def _spot(X, Y, w=2.5, A=6.0):
    r2 = X ** 2 + Y ** 2
    g = A * np.exp(-0.5 * r2 / w ** 2)
    return g, (r2 / w ** 2 - 2.0) / w ** 2 * g


def _gentle(X, Y):
    return 0.5 * np.sin(X / 9.0) * np.cos(Y / 11.0), -0.5 * np.sin(X / 9.0) * np.cos(Y / 11.0) * (1 / 81 + 1 / 121)


def _run(psi, t, noisy, x, spacing):
    ops = {}
    res, k_t = smooth_in_time(surface_laplacian(psi, noisy, x, spacing=spacing, ops=ops), t)
    return res, laplacian_bias(psi, noisy, x, res, ops=ops)


def _inner(psi, shape):
    inner = np.broadcast_to(edge_distance(psi) > 4, shape).copy()
    inner[[0, -1]] = False
    return inner


def _true_bias(psi, t, clean, x, res, true):
    """The regression's own bias: the same regressions (spacing, time) of the noise-free temperatures."""
    k_t = 4.0 if t.size >= 4 else None
    return smooth_in_time(surface_laplacian(psi, clean, x, spacing=res.spacing), t, k_t)[0].laplacian - true


def test_bias_estimate_covers_a_biased_regression():
    """A narrow hot spot (2.5 mm) at the chosen spacing: the bias is larger than the noise std, which alone
    misses most of the error; with the estimate in the std the errors are covered about as a Gaussian width
    would cover them, and the flag marks where the bias exceeds the noise."""
    psi, t, noisy, x, true, clean = _plane(_spot)
    inner = _inner(psi, true.shape)
    res, bias = _run(psi, t, noisy, x, spacing="auto")
    err = np.abs(res.laplacian - true)[inner]
    z0 = err / res.std[inner]
    z = err / with_bias(res, bias).std[inner]
    assert np.mean(z < 1) > np.mean(z0 < 1) + 0.2  # the noise std alone misses the bias
    assert 0.58 < np.mean(z < 1) < 0.76 and np.mean(z < 2) > 0.92
    assert 0.85 < np.sqrt(np.mean(z ** 2)) < 1.2
    # flagged where the regression's own bias exceeds the noise std, not where it does not
    b = np.abs(_true_bias(psi, t, clean, x, res, true))[inner]
    flag = (bias > res.std)[inner]
    noise = res.std[inner]
    assert 0.3 < flag.mean() < 0.95
    assert np.sqrt(np.mean(b[flag] ** 2)) > 1.5 * np.sqrt(np.mean(noise[flag] ** 2))
    assert np.sqrt(np.mean(b[~flag] ** 2)) < np.sqrt(np.mean(noise[~flag] ** 2))


def test_bias_estimate_stays_on_the_feature():
    """The spot's bias is on the spot: so is the estimate (a specimen-wide average would spread it)."""
    psi, t, noisy, x, true, clean = _plane(_spot)
    res, bias = _run(psi, t, noisy, x, spacing="auto")
    b = np.abs(_true_bias(psi, t, clean, x, res, true))
    r = np.hypot(*psi.T)
    rings = [_inner(psi, true.shape) & (r >= lo) & (r < hi) for lo, hi in ((0, 3), (3, 6), (6, 9), (9, 99))]
    rms = lambda a, m: np.sqrt(np.mean(a[m] ** 2))  # noqa: E731
    assert rms(b, rings[0]) > 3 * rms(b, rings[-1])
    assert rms(bias, rings[0]) > 2 * rms(bias, rings[-1])
    for ring in rings:
        assert 0.7 < rms(bias, ring) / rms(b, ring) < 1.4


def test_a_spacing_far_too_wide_is_flagged():
    """The same spot under a regression wider than needed: the error is all bias, tens of times the noise;
    flagged everywhere, and the estimate is of the bias's size."""
    psi, t, noisy, x, true, _ = _plane(_spot)
    inner = _inner(psi, true.shape)
    res, bias = _run(psi, t, noisy, x, spacing=8)
    err = (res.laplacian - true)[inner]
    assert np.sqrt(np.mean(err ** 2)) > 10 * np.sqrt(np.mean(res.std[inner] ** 2))
    assert np.mean((bias > res.std)[inner]) > 0.95
    assert 0.6 < np.sqrt(np.mean(bias[inner] ** 2)) / np.sqrt(np.mean(err ** 2)) < 1.3


def test_no_bias_no_flag():
    """A gentle field that the regression follows (its bias a sixth of the noise): over four noise draws the
    flag is rare and the std covers the error as the noise's alone would."""
    flags = []
    for seed in range(4):
        psi, t, noisy, x, true, clean = _plane(_gentle, seed=seed)
        inner = _inner(psi, true.shape)
        res, bias = _run(psi, t, noisy, x, spacing=10)
        b = _true_bias(psi, t, clean, x, res, true)[inner]
        assert np.sqrt(np.mean(b ** 2)) < 0.25 * np.sqrt(np.mean(res.std[inner] ** 2))
        flags.append(np.mean((bias > res.std)[inner]))
        z = np.abs(res.laplacian - true)[inner] / with_bias(res, bias).std[inner]
        assert 0.6 < np.mean(z < 1) < 0.8 and np.mean(z < 2) > 0.92
    assert np.mean(flags) < 0.15


def test_bias_estimate_follows_the_true_bias():
    """Noise-free data: the estimate's RMS is of the order of the regression's actual error (no noise to
    mistake for it)."""
    psi, t, _, x, true, clean = _plane(_spot, noise=0.0)
    inner = np.broadcast_to(edge_distance(psi) > 4, true.shape)
    ops = {}
    res = surface_laplacian(psi, clean, x, spacing=6, ops=ops)
    bias = laplacian_bias(psi, clean, x, res, ops=ops)
    rb, re = np.sqrt(np.mean(bias[inner] ** 2)), np.sqrt(np.mean((res.laplacian - true)[inner] ** 2))
    assert 0.7 * re < rb < 1.4 * re


def test_source_flag_means_bias_above_noise():
    """``heat_source_bias_dominated``: set exactly where the source's bias parts exceed the rest of its std."""
    shape = (2, 4)
    rate_flag = np.array([[True, False, False, False]] * 2)
    fields = {"temperature_rate_bias_dominated": type("V", (), {"values": rate_flag})()}
    lap_noise = np.full(shape, 1e-3)
    lap_bias = np.array([[0.0, 2e-3, 5e-4, 0.0]] * 2)
    terms = heat_balance(np.zeros(shape), np.zeros(shape), 0.0, np.zeros(shape), density=7850.0,
                         specific_heat=470.0, conductivity=50.0, rate_std=np.full(shape, 0.05),
                         laplacian_std=np.hypot(lap_noise, lap_bias))
    flags = _bias_flags(fields, terms, 50e6 * lap_bias, lap_noise, lap_bias, False, shape)
    assert flags["temperature_laplacian"][0].tolist() == [False, True, False, False]
    assert flags["heat_conduction"][0].tolist() == [False, True, False, False]
    assert flags["heat_storage"][0].tolist() == rate_flag[0].tolist()
    # point 0: the storage (0.05 K/s x ρc = 184 kW/m³) is all bias, against 50 kW/m³ of conduction noise;
    # point 1: a conduction bias of 100 kW/m³ is below the 184 kW/m³ of (unflagged) rate noise
    assert flags["heat_source"][0].tolist() == [True, False, False, False]
    assert not flags["heat_losses"].any()
