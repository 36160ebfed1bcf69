"""The thin-wall heat balance's terms and units, and the loss time constant from a cooling window."""

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError
from irdic.heat import heat_balance, loss_time_constant

STEEL = dict(density=7850.0, specific_heat=470.0, conductivity=50.0)


def test_terms_and_units():
    """1 K/s of storage in steel is ρc = 3.69 MW/m³; 1 K/mm² of Laplacian with k = 50 is 50 MW/m³."""
    h = heat_balance(np.array([1.0]), np.array([22.0]), 20.0, np.array([1.0]), tau=40.0, rate_std=0.1,
                     theta_std=0.03, theta0_std=0.04, laplacian_std=0.01, **STEEL)
    rc = 7850.0 * 470.0
    assert h.storage[0] == pytest.approx(rc)
    assert h.losses[0] == pytest.approx(rc * 2.0 / 40.0)
    assert h.conduction[0] == pytest.approx(50e6)
    assert h.source[0] == pytest.approx(rc + rc / 20.0 - 50e6)
    assert h.losses_std[0] == pytest.approx(rc / 40.0 * 0.05)
    assert h.source_std[0] == pytest.approx(np.sqrt((0.1 * rc) ** 2 + (rc / 40 * 0.05) ** 2 + (0.5e6) ** 2))


def test_no_losses_without_tau():
    h = heat_balance(np.ones((2, 3)), np.full((2, 3), 25.0), np.zeros(3), np.zeros((2, 3)), **STEEL)
    assert np.all(h.losses == 0) and np.all(h.losses_std == 0) and h.source.shape == (2, 3)


@pytest.mark.parametrize("bad", [{"density": -1.0}, {"conductivity": "50"}, {"specific_heat": True}])
def test_bad_material_is_a_config_error(bad):
    with pytest.raises(ConfigError, match="material"):
        heat_balance(np.ones(2), np.ones(2), 0.0, np.zeros(2), **{**STEEL, **bad})


def _cooling(tau=45.0, noise=0.0, seed=0):
    """Uniform excess plus a conducting profile: Θ − Θ0 = e^{-t/τ} (2 + 0.5 cos(z/L) e^{-D t/L²})."""
    D, L = 50.0 / (7850 * 470) * 1e6, 6.0  # mm²/s, mm
    t = np.arange(0.0, 60.0, 0.5)
    z = np.linspace(-10, 10, 41)
    decay = np.exp(-t / tau)[:, None]
    prof = np.cos(z / L)[None, :] * np.exp(-D * t / L ** 2)[:, None]
    excess = decay * (2.0 + 0.5 * prof)
    lap = -decay * 0.5 * prof / L ** 2
    rate = -excess / tau - decay * 0.5 * prof * D / L ** 2
    rng = np.random.default_rng(seed)
    rate = rate + rng.normal(0, noise, rate.shape)
    return t, rate, 20.0 + excess, np.full(z.size, 20.0), lap, D


def test_tau_recovered_exactly_from_a_clean_cooling():
    t, rate, theta, theta0, lap, D = _cooling()
    tau, std = loss_time_constant(t, rate, theta, theta0, lap, diffusivity=D, window=(10, 50))
    assert tau == pytest.approx(45.0, rel=1e-9) and std < 1e-6


def test_tau_std_covers_its_error_over_seeds():
    z = []
    for seed in range(40):
        t, rate, theta, theta0, lap, D = _cooling(noise=0.02, seed=seed)
        tau, std = loss_time_constant(t, rate, theta, theta0, lap, diffusivity=D, window=(5, 55))
        z.append((tau - 45.0) / std)
    z = np.abs(z)
    assert 0.5 < np.mean(z < 1) < 0.85 and np.mean(z < 2) > 0.85


def test_tau_errors_name_the_window():
    t, rate, theta, theta0, lap, D = _cooling()
    with pytest.raises(DataError, match="material.cooling"):
        loss_time_constant(t, rate, theta, theta0, lap, diffusivity=D, window=(100, 200))
    with pytest.raises(ConfigError, match="material.cooling"):
        loss_time_constant(t, rate, theta, theta0, lap, diffusivity=D, window=(5, 1))
    with pytest.raises(DataError, match="no cooling"):
        loss_time_constant(t, -rate, theta, theta0, -lap, diffusivity=D, window=(5, 50))
