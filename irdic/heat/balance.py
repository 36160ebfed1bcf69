"""The local heat balance of a thin wall and the loss time constant from a source-free window.

``s = ρc (Θ̇ + (Θ − Θ0)/τ) − k Δ_s Θ`` (Chrysochoos and Louche 2000): the
temperature averaged through the wall's thickness, the face losses
(convection and radiation) lumped into one time constant τ, uniform
properties. Units: ρ kg/m³, c J/(kg K), k W/(m K), τ s, Θ̇ K/s, Δ_s Θ K/mm²,
every term W/m³.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..errors import ConfigError, DataError
from ..validation import float_array

__all__ = ["HeatTerms", "heat_balance", "loss_time_constant", "MM2_PER_M2"]

#: K/mm² to K/m²: ``k Δ_s Θ`` in W/m³ from k in W/(m K) and Δ_s Θ in K/mm²
MM2_PER_M2 = 1.0e6


class HeatTerms(NamedTuple):
    """The terms of the balance (W/m³), each with its standard uncertainty; ``source = storage + losses −
    conduction``."""

    source: np.ndarray
    storage: np.ndarray
    losses: np.ndarray
    conduction: np.ndarray
    source_std: np.ndarray
    storage_std: np.ndarray
    losses_std: np.ndarray
    conduction_std: np.ndarray


def _positive(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
        raise ConfigError(f"material.{name} must be a positive number, got {value!r}")
    return float(value)


def heat_balance(rate, theta, theta0, laplacian, *, density, specific_heat, conductivity, tau=None,
                 rate_std=0.0, theta_std=0.0, theta0_std=0.0, laplacian_std=0.0) -> HeatTerms:
    """Heat source and the terms of the thin-wall balance.

    Parameters
    ----------
    rate : array_like, shape (...)
        Material temperature rate Θ̇ (K/s).
    theta, theta0 : array_like, broadcastable to ``rate``
        Temperature and the equilibrium temperature before loading (degC).
    laplacian : array_like, shape (...)
        ``Δ_s Θ`` (K/mm²).
    density, specific_heat, conductivity : float
        ρ (kg/m³), c (J/(kg K)), k (W/(m K)).
    tau : float or None
        Loss time constant (s); None: no face losses.
    rate_std, theta_std, theta0_std, laplacian_std : array_like
        Standard uncertainties of the inputs (same units), taken as independent.

    Returns
    -------
    HeatTerms
        ``storage = ρc Θ̇``, ``losses = ρc (Θ − Θ0)/τ``, ``conduction = k Δ_s Θ``
        (the heat conduction brings in per volume), ``source = storage +
        losses − conduction``, all W/m³, with their stds.
    """
    rc = _positive(density, "density") * _positive(specific_heat, "specific_heat")
    k = _positive(conductivity, "conductivity")
    rate, lap = float_array(rate, "rate"), float_array(laplacian, "laplacian")
    storage = rc * rate
    storage_std = rc * np.abs(float_array(rate_std, "rate_std")) + 0.0 * storage
    if tau is None:
        losses = np.zeros_like(storage)
        losses_std = np.zeros_like(storage)
    else:
        tau = _positive(tau, "loss_time_constant")
        losses = rc * (float_array(theta, "theta") - float_array(theta0, "theta0")) / tau + 0.0 * storage
        losses_std = rc / tau * np.hypot(float_array(theta_std, "theta_std"), float_array(theta0_std, "theta0_std"))
        losses_std = losses_std + 0.0 * storage
    conduction = k * MM2_PER_M2 * lap
    conduction_std = k * MM2_PER_M2 * np.abs(float_array(laplacian_std, "laplacian_std")) + 0.0 * conduction
    source = storage + losses - conduction
    source_std = np.sqrt(storage_std ** 2 + losses_std ** 2 + conduction_std ** 2)
    return HeatTerms(source, storage, losses, conduction, source_std, storage_std, losses_std, conduction_std)


def loss_time_constant(times, rate, theta, theta0, laplacian, *, diffusivity, window, points=None):
    """Loss time constant τ (s) and its std by least squares over a source-free window.

    Parameters
    ----------
    times : array_like, shape (T,)
        Times (s).
    rate, theta, laplacian : array_like, shape (T, N)
        Θ̇ (K/s), Θ (degC), Δ_s Θ (K/mm²).
    theta0 : array_like, shape (N,) or scalar
        Equilibrium temperature (degC).
    diffusivity : float
        ``k / (ρc)`` (mm²/s).
    window : (t0, t1)
        The times (s) without heat sources (``material.cooling``), e.g. a natural cooling after unloading.
    points : array_like of bool, shape (N,), optional
        The points that count (default all with finite values).

    Returns
    -------
    tau, tau_std : float
        s.

    Notes
    -----
    With ``s = 0`` the balance reads ``(Θ − Θ0)/τ = −Θ̇ + D Δ_s Θ``. The two
    sides are averaged over the points at each time of the window (the
    points' errors are correlated in space, the times' nearly independent),
    ``β = 1/τ`` is the least-squares slope through the origin of ``ȳ_t``
    against ``ū_t = mean(Θ − Θ0)``, and its std ``sqrt(Σ r² / (n − 1) / Σ ū²)``
    from the ``n`` residuals ``r``; ``std τ = std β / β²``.
    """
    t = float_array(times, "times")
    try:
        t0, t1 = (float(v) for v in window)
    except (TypeError, ValueError):
        raise ConfigError(f"material.cooling must be [t0, t1] in seconds, got {window!r}") from None
    if not t1 > t0:
        raise ConfigError(f"material.cooling must be [t0, t1] with t1 > t0, got {window!r}")
    sel = (t >= t0) & (t <= t1)
    excess = float_array(theta, "theta")[sel] - float_array(theta0, "theta0")
    y = -float_array(rate, "rate")[sel] + float(diffusivity) * float_array(laplacian, "laplacian")[sel]
    use = np.isfinite(excess) & np.isfinite(y)
    if points is not None:
        use &= np.asarray(points, bool)[None, :]
    rows = use.sum(axis=1) > 0
    if rows.sum() < 3:
        raise DataError(f"material.cooling {window!r}: {int(rows.sum())} DIC time(s) with data in the window "
                        f"(times {t.min():g}..{t.max():g} s); the least squares for loss_time_constant needs 3")
    u = np.where(use, excess, 0.0)[rows].sum(axis=1) / use[rows].sum(axis=1)
    v = np.where(use, y, 0.0)[rows].sum(axis=1) / use[rows].sum(axis=1)
    beta = float(np.dot(u, v) / np.dot(u, u))
    r = v - beta * u
    beta_std = float(np.sqrt(np.dot(r, r) / (u.size - 1) / np.dot(u, u)))
    if not beta > 2.0 * beta_std:
        raise DataError(f"material.cooling {window!r}: no cooling towards the reference temperature in the window "
                        f"(1/tau = {beta:.3g} ± {beta_std:.3g} 1/s); name a window after unloading where the "
                        "specimen cools, or give loss_time_constant in seconds")
    return 1.0 / beta, beta_std / beta ** 2
