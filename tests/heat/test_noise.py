"""The Laplacian's noise model against the noise that was added: each point's own level (mixed pixels on the
rim), temperatures a time lacks, and few-frame spikes."""

import numpy as np
import pytest

from irdic.heat import surface_laplacian
from irdic.surface import edge_distance

SPACING = 8.0


def _plane(seed, T=16):
    """A 30 x 30 mm plane, points 0.6 mm apart (jittered), a smooth field growing in time; the outer row of
    points has three times the noise of the others (0.15 K against 0.05 K: mixed edge pixels)."""
    rng = np.random.default_rng(seed)
    a, b = np.meshgrid(np.arange(-15, 15, 0.6), np.arange(-15, 15, 0.6), indexing="ij")
    psi = np.c_[a.ravel(), b.ravel()] + rng.uniform(-0.12, 0.12, (a.size, 2))
    X, Y = psi.T
    ramp = (0.5 + np.arange(T) / T)[:, None]
    clean = 20.0 + ramp * (3.0 * np.exp(-0.5 * (X ** 2 + Y ** 2) / 8.0 ** 2) + 0.02 * X * Y)
    edge = edge_distance(psi)
    level = np.where(edge < 0.7, 0.15, 0.05)
    noise = level * rng.standard_normal(clean.shape)
    x = np.repeat(np.c_[X, Y, 0 * X][None], T, axis=0)
    return psi, x, clean, noise, edge


def _noise_z(psi, x, clean, noisy, near):
    """The Laplacian's error against the same regression of the noise-free field, over its std, at ``near``."""
    res = surface_laplacian(psi, noisy, x, spacing=SPACING)
    ref = surface_laplacian(psi, clean, x, spacing=SPACING)
    z = ((res.laplacian - ref.laplacian) / res.std)[:, near]
    return res, z[np.isfinite(z)]


@pytest.mark.parametrize("seed", [0, 1])
def test_each_point_has_its_own_level(seed):
    """The outer row's noise, nine times the variance of the rest, is read from the data and propagated: near
    the rim (within one centre spacing, where it weighs most) the std describes the Laplacian's error."""
    psi, x, clean, noise, edge = _plane(seed)
    near = (edge > 1.0) & (edge < SPACING * 0.6)
    res, z = _noise_z(psi, x, clean, clean + noise, near)
    assert np.median(res.profile[edge < 0.7]) == pytest.approx(9.0, rel=0.25)
    assert np.median(res.profile[edge > 2.0]) == pytest.approx(1.0, rel=0.1)
    assert 0.85 < np.sqrt(np.mean(z ** 2)) < 1.15
    assert 0.6 < np.mean(np.abs(z) < 1) < 0.76 and np.mean(np.abs(z) < 2) > 0.92


@pytest.mark.parametrize("share", [1.0, 0.3])
def test_missing_temperatures_are_the_fit_of_the_others(share):
    """The outer row along one side (all of it, or a third of its points) vanishes at every other time (a
    moving silhouette): its Laplacian is NaN there, and its neighbours' keeps about the noise the std says
    (filled by the interpolant, the gap held the visible points' noise extrapolated, which the regression took
    for data: 4.1 times the std near a gap three rows wide, 1.6 with the gap refitted)."""
    psi, x, clean, noise, edge = _plane(2)
    noisy = clean + 0.05 / np.where(edge < 0.7, 0.15, 0.05) * noise  # white, one level
    gap = (psi[:, 0] > psi[:, 0].max() - 0.5) & (np.random.default_rng(0).random(psi.shape[0]) < share)
    noisy[1::2, gap] = np.nan
    near = ~gap & (psi[:, 0] > psi[:, 0].max() - SPACING * 0.6) & (edge > 1.0)
    res, z = _noise_z(psi, x, clean, noisy, near)
    assert np.isnan(res.laplacian[1::2][:, gap]).all() and np.isfinite(res.laplacian[::2][:, gap]).all()
    assert 0.85 < np.sqrt(np.mean(z ** 2)) < 1.2


def test_spikes_are_left_out():
    """Forty temperatures of the outer rows off by ±1.5 K for one frame each (30 times the noise): left out
    and refitted, the Laplacian near them is as accurate as without them, and its std still describes it."""
    psi, x, clean, noise, edge = _plane(3)
    noisy = clean + 0.05 / np.where(edge < 0.7, 0.15, 0.05) * noise
    rng = np.random.default_rng(4)
    rim = np.flatnonzero(edge < 1.3)
    spiked = noisy.copy()
    t, i = rng.integers(0, noisy.shape[0], 40), rng.choice(rim, 40, replace=False)
    spiked[t, i] += rng.choice([-1.5, 1.5], 40)
    near = (edge > 1.0) & (edge < SPACING * 0.6)
    ref = surface_laplacian(psi, clean, x, spacing=SPACING).laplacian[:, near]
    without = surface_laplacian(psi, noisy, x, spacing=SPACING)
    res, z = _noise_z(psi, x, clean, spiked, near)
    rms = lambda r: np.sqrt(np.mean((r.laplacian[:, near] - ref) ** 2))  # noqa: E731
    assert rms(res) < 1.1 * rms(without)
    assert 0.85 < np.sqrt(np.mean(z ** 2)) < 1.2
