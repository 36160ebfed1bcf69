"""The scene family of the heat benchmark: the synthetic tube and half-shells, and half-shells with other
heating patterns (a narrow hot band, a hot spot), each with its closed-form Laplacian."""

from __future__ import annotations

import numpy as np

from irdic.synthetic import HalfShell, experiment, lab_camera
from irdic.synthetic.laplacian import temperature_laplacian


class _Pattern(HalfShell):
    """A static half-shell whose temperature is ``T0 + A(t) g(s, h)`` (``A`` the half-shell's amplitude
    history scaled to ``peak`` K): subclasses give ``g`` with its first and second derivatives."""

    def __init__(self, *, peak=8.0, width=4.0, centre=25.0, **kw):
        super().__init__(**kw)
        self.peak, self.width, self.centre = float(peak), float(width), float(centre)

    def _amp(self, t):
        A, dA = self.amplitude(t)
        return A * self.peak / self.A_max, dA * self.peak / self.A_max

    def temperature(self, s, h, t):
        A, _ = self._amp(t)
        s, h, A = np.broadcast_arrays(np.asarray(s, float), np.asarray(h, float), A)
        return self.T0 + A * self._g(s, h)[0]

    def temperature_derivatives(self, s, h, t):
        A, dA = self._amp(t)
        s, h, A, dA = np.broadcast_arrays(np.asarray(s, float), np.asarray(h, float), A, dA)
        g, gs, gh, _ = self._g(s, h)
        return A * gs, A * gh, dA * g

    def laplacian(self, s, h, t):
        """``Θ_ss + Θ_hh`` (K/mm²): the static cylinder developed by arc length."""
        A, _ = self._amp(t)
        return A * self._g(s, h)[3]


class HotBand(_Pattern):
    """A narrow hot band round the shell: ``g = exp(−(h − centre)² / (2 width²))``."""

    def _g(self, s, h):
        u = h - self.centre
        w2 = self.width ** 2
        g = np.exp(-0.5 * u * u / w2) + 0.0 * s
        return g, 0.0 * g, -u / w2 * g, (u * u / w2 - 1.0) / w2 * g


class HotSpot(_Pattern):
    """A hot spot: ``g = exp(−(s² + (h − centre)²) / (2 width²))``."""

    def _g(self, s, h):
        u = h - self.centre
        w2 = self.width ** 2
        r2 = s * s + u * u
        g = np.exp(-0.5 * r2 / w2)
        return g, -s / w2 * g, -u / w2 * g, (r2 / w2 - 2.0) / w2 * g


#: name -> (experiment, specimen or None); half-shells of radius R have their axis R behind the origin
FAMILY = {
    "tube": ("tube", None),
    "barrel": ("halfshell", dict(R_o=40.0, R_i=36.0, axis_z=-40.0)),
    "shell30": ("halfshell", dict(R_o=30.0, R_i=26.0, axis_z=-30.0)),
    "shell65": ("halfshell", dict(R_o=65.0, R_i=61.0, axis_z=-65.0)),
    "band": ("halfshell", dict(R_o=40.0, R_i=36.0, axis_z=-40.0, pattern=HotBand, width=4.0)),
    "spot": ("halfshell", dict(R_o=40.0, R_i=36.0, axis_z=-40.0, pattern=HotSpot, width=5.0)),
}


def family_scene(name, scale, seed, ir_noise, dic_noise):
    """The experiment of family member ``name``."""
    kind, spec = FAMILY[name]
    if spec is None:
        return experiment(kind, scale, ir_noise=ir_noise, dic_noise=dic_noise, seed=seed)
    spec = dict(spec)
    cls = spec.pop("pattern", HalfShell)
    if cls is HalfShell:
        spec.pop("width", None)
    return experiment(kind, scale, ir_noise=ir_noise, dic_noise=dic_noise, seed=seed, specimen=cls(**spec),
                      camera=lab_camera())


def true_laplacian(specimen, s, h, t):
    """The closed-form ``Δ_s Θ`` (K/mm²) of a family member's specimen."""
    if isinstance(specimen, _Pattern):
        return specimen.laplacian(s, h, t)
    return temperature_laplacian(specimen, s, h, t)
