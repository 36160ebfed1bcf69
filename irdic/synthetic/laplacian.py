"""Closed-form Laplace–Beltrami operator of the synthetic specimens' temperature on their current surface.

The truth of the heat stage's ``temperature_laplacian`` (K/mm²), and with
the rate the truth of its heat source.
"""

from __future__ import annotations

import numpy as np

from .specimens import HalfShell, Specimen, Tube

__all__ = ["temperature_laplacian"]


def _halfshell(sp: HalfShell, s, h, t):
    """Static cylinder, ``(s, h)`` arc length and height: ``Δ_s Θ = ∂²Θ/∂s² + ∂²Θ/∂h²``."""
    A, _ = sp.amplitude(t)
    lam, _ = sp.decay_length(t)
    g = 1.0 - sp.b * (s / sp.s_e) ** 2
    return A * np.exp(-h / lam) * (-2.0 * sp.b / sp.s_e**2 + g / lam**2)


def _tube(sp: Tube, s, h, t):
    """Stretched and twisted tube (see :func:`temperature_laplacian`, Notes)."""
    dT, _ = sp.heating(t)
    lam, _ = sp.stretch(t)
    phi, _ = sp.twist(t)
    ax = 1.0 - sp.beta * (h / sp.Z_c) ** 2
    ax1, ax2 = -2.0 * sp.beta * h / sp.Z_c**2, -2.0 * sp.beta / sp.Z_c**2
    ci = 1.0 + sp.gamma * np.sin(s / sp.R)
    ci1, ci2 = sp.gamma * np.cos(s / sp.R) / sp.R, -sp.gamma * np.sin(s / sp.R) / sp.R**2
    k = sp.R * phi / (lam * sp.L)
    return dT * (ax * ci2 * (lam + k**2) - 2.0 * ax1 * ci1 * k / lam + ax2 * ci / lam**2)


def temperature_laplacian(specimen: Specimen, s, h, t):
    """``Δ_s Θ`` (K/mm²) at material points ``(s, h)`` (mm) and times ``t`` (s), broadcast.

    Notes
    -----
    Half-shell: a static cylinder developed by arc length, ``Θ_ss + Θ_hh``.
    Tube: the current surface is a cylinder of radius ``r = R / sqrt(λ)``
    with angle ``ψ = s/R + φ (h − Z_b)/L`` and axial coordinate
    ``Y = Z_b + λ (h − Z_b)``, so ``Δ_s = ∂²/∂Y² + r⁻² ∂²/∂ψ²``; with
    ``s = R ψ − R φ (Y − Z_b)/(λ L)`` and ``h = Z_b + (Y − Z_b)/λ`` (linear),
    ``Δ_s Θ = Θ_ss (λ + (Rφ/(λL))²) − 2 Θ_sh Rφ/(λ² L) + Θ_hh / λ²``.
    """
    s, h, t = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64), np.asarray(t, np.float64))
    if isinstance(specimen, Tube):
        return _tube(specimen, s, h, t)
    if isinstance(specimen, HalfShell):
        return _halfshell(specimen, s, h, t)
    if hasattr(specimen, "laplacian"):  # a scene of the family (irdic.synthetic.scene)
        return specimen.laplacian(s, h, t)
    raise TypeError(f"no closed-form Laplacian for {type(specimen).__name__}")
