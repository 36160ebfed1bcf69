"""Testing-machine loads of the synthetic specimens: the stress of a hardening metal along a load history."""

from __future__ import annotations

import numpy as np

__all__ = ["hardening_stress"]


def hardening_stress(loaded, unloaded, modulus, yield_stress, hardening):
    """Stress of linear kinematic hardening after a monotone loading then a monotone unloading.

    Parameters
    ----------
    loaded, unloaded : numpy.ndarray
        Strain applied so far in the loading and then taken back in the
        unloading (both >= 0; the unloading starts once the loading is over).
    modulus, yield_stress, hardening : float
        Elastic modulus, initial yield stress and plastic hardening modulus, N/mm^2.

    Returns
    -------
    numpy.ndarray
        Stress, N/mm^2.

    Notes
    -----
    Loading: ``sigma = E eps`` up to ``sigma_y``, then the tangent modulus
    ``E_t = E H / (E + H)``. Unloading from ``sigma_max``: elastic over an
    elastic range of ``2 sigma_y`` (kinematic hardening: the yield surface
    moved with the back stress; ``sigma_max + sigma_y`` when the loading
    stayed elastic), then ``E_t`` again.
    """
    loaded, unloaded = np.asarray(loaded, float), np.asarray(unloaded, float)
    e_y = yield_stress / modulus
    e_t = modulus * hardening / (modulus + hardening)

    def curve(e, limit):  # elastic up to stress ``limit``, then the tangent modulus
        return np.where(e <= limit / modulus, modulus * e, limit + e_t * (e - limit / modulus))

    up = np.where(loaded <= e_y, modulus * loaded, yield_stress + e_t * (loaded - e_y))
    reach = np.where(loaded <= e_y, up + yield_stress, 2.0 * yield_stress)  # elastic range of the unloading
    return up - curve(unloaded, reach)
