"""Temperature patterns of the scene family: closed forms with their derivatives.

Each pattern is a temperature rise ``θ(s, h, t)`` (K) over the material
coordinates ``(s, h)`` (mm) and time (s), fixed to the material (a moving
band moves through it). :meth:`Pattern.evaluate` returns ``θ`` and its
derivatives ``θ_s, θ_h, θ_t`` (and with ``second`` ``θ_ss, θ_sh, θ_hh``),
all broadcast together.

- :class:`SmoothHeating`: ``A S(t) (1 - β ((h - h_c)/a)² - β_s ((s - s_c)/b)²
  + γ (s - s_c)/b)``, a plastic heating that follows the loading (``S`` the
  quintic smooth step over ``[t_a, t_b]``).
- :class:`EdgeHeating`: ``A(t) exp(-(h - h_e)/λ(t)) (1 - β ((s - s_c)/b)²)``
  with ``A = A_max (1 - e^{-(t + t_pre)/τ})`` and ``λ = λ_∞ - (λ_∞ - λ_0)
  e^{-(t + t_pre)/τ_λ}``: the half-shell's heating from its lower edge ``h_e``.
- :class:`MovingBand`: ``A exp(-u²/(2 w²))`` with ``u = n · (s - s_c, h) -
  c_0 - v t``, ``n = (sin α, cos α)``: a narrow hot band of width ``w`` (the
  Gaussian's standard deviation; full width at half maximum ``2.355 w``),
  inclined by ``α`` to the s axis, travelling at ``v`` (mm/s) along ``n``
  (a Lüders band).
- :class:`HotSpot`: ``A S(t) exp(-((s - s_0)² + (h - h_0)²)/(2 w²))``.
"""

from __future__ import annotations

import math

import numpy as np

from .specimens import smoothstep

__all__ = ["Pattern", "SmoothHeating", "EdgeHeating", "MovingBand", "HotSpot", "PATTERNS"]


def _bc(s, h, t):
    return np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64), np.asarray(t, np.float64))


class Pattern:
    """A temperature rise in closed form (module docstring)."""

    kind = "pattern"

    def evaluate(self, s, h, t, second=False):  # pragma: no cover - interface
        """``(θ, θ_s, θ_h, θ_t)`` (K, K/mm, K/mm, K/s), and with ``second`` ``(θ_ss, θ_sh, θ_hh)`` (K/mm²) after."""
        raise NotImplementedError

    def describe(self) -> dict:
        return {"kind": self.kind, **{k: v for k, v in vars(self).items() if not k.startswith("_")}}


class SmoothHeating(Pattern):
    """Heating with the loading, smooth in space (module docstring)."""

    kind = "smooth"

    def __init__(self, *, amplitude, load, centre=(0.0, 0.0), size=(20.0, 20.0), beta=0.5, beta_s=0.1,
                 gamma=0.05):
        self.amplitude, self.load = float(amplitude), (float(load[0]), float(load[1]))
        self.centre, self.size = tuple(map(float, centre)), tuple(map(float, size))
        self.beta, self.beta_s, self.gamma = float(beta), float(beta_s), float(gamma)

    def evaluate(self, s, h, t, second=False):
        s, h, t = _bc(s, h, t)
        S, dS, _ = smoothstep(t, *self.load)
        b, a = self.size
        xs, xh = (s - self.centre[0]) / b, (h - self.centre[1]) / a
        p = 1.0 - self.beta * xh ** 2 - self.beta_s * xs ** 2 + self.gamma * xs
        ps = (-2.0 * self.beta_s * xs + self.gamma) / b
        ph = -2.0 * self.beta * xh / a
        A = self.amplitude
        out = (A * S * p, A * S * ps, A * S * ph, A * dS * p)
        if not second:
            return out
        z = np.zeros_like(p)
        return out + (A * S * (-2.0 * self.beta_s / b ** 2), z, A * S * (-2.0 * self.beta / a ** 2))


class EdgeHeating(Pattern):
    """Heating from the lower edge ``h_e`` (module docstring)."""

    kind = "edge"

    def __init__(self, *, amplitude, edge, centre_s=0.0, half_width=20.0, beta=0.12, tau=20.0, t_pre=5.0,
                 decay_0=6.0, decay_inf=14.0, tau_decay=30.0):
        self.amplitude, self.edge = float(amplitude), float(edge)
        self.centre_s, self.half_width, self.beta = float(centre_s), float(half_width), float(beta)
        self.tau, self.t_pre = float(tau), float(t_pre)
        self.decay_0, self.decay_inf, self.tau_decay = float(decay_0), float(decay_inf), float(tau_decay)

    def evaluate(self, s, h, t, second=False):
        s, h, t = _bc(s, h, t)
        e = np.exp(-(t + self.t_pre) / self.tau)
        A, dA = self.amplitude * (1.0 - e), self.amplitude / self.tau * e
        el = np.exp(-(t + self.t_pre) / self.tau_decay)
        lam = self.decay_inf - (self.decay_inf - self.decay_0) * el
        dlam = (self.decay_inf - self.decay_0) / self.tau_decay * el
        xs = (s - self.centre_s) / self.half_width
        g, gs = 1.0 - self.beta * xs ** 2, -2.0 * self.beta * xs / self.half_width
        u = h - self.edge
        E = np.exp(-u / lam)
        out = (A * g * E, A * gs * E, -A * g * E / lam, g * E * (dA + A * u * dlam / lam ** 2))
        if not second:
            return out
        return out + (A * E * (-2.0 * self.beta / self.half_width ** 2), -A * gs * E / lam, A * g * E / lam ** 2)


class MovingBand(Pattern):
    """A narrow hot band travelling through the material (module docstring)."""

    kind = "band"

    def __init__(self, *, amplitude, width, speed, start, angle=0.0, centre_s=0.0):
        self.amplitude, self.width, self.speed = float(amplitude), float(width), float(speed)
        self.start, self.angle, self.centre_s = float(start), float(angle), float(centre_s)

    def evaluate(self, s, h, t, second=False):
        s, h, t = _bc(s, h, t)
        ns, nh = math.sin(self.angle), math.cos(self.angle)
        u = ns * (s - self.centre_s) + nh * h - self.start - self.speed * t
        w2 = self.width ** 2
        g = self.amplitude * np.exp(-0.5 * u * u / w2)
        gu = -u / w2 * g
        out = (g, ns * gu, nh * gu, -self.speed * gu)
        if not second:
            return out
        guu = (u * u / w2 - 1.0) / w2 * g
        return out + (ns * ns * guu, ns * nh * guu, nh * nh * guu)


class HotSpot(Pattern):
    """A hot spot growing with the loading (module docstring)."""

    kind = "spot"

    def __init__(self, *, amplitude, width, centre, load):
        self.amplitude, self.width = float(amplitude), float(width)
        self.centre, self.load = tuple(map(float, centre)), (float(load[0]), float(load[1]))

    def evaluate(self, s, h, t, second=False):
        s, h, t = _bc(s, h, t)
        S, dS, _ = smoothstep(t, *self.load)
        xs, xh = s - self.centre[0], h - self.centre[1]
        w2 = self.width ** 2
        G = self.amplitude * np.exp(-0.5 * (xs * xs + xh * xh) / w2)
        out = (S * G, -S * xs / w2 * G, -S * xh / w2 * G, dS * G)
        if not second:
            return out
        return out + (S * (xs * xs / w2 - 1.0) / w2 * G, S * xs * xh / w2 ** 2 * G, S * (xh * xh / w2 - 1.0) / w2 * G)


PATTERNS = {"smooth": SmoothHeating, "edge": EdgeHeating, "band": MovingBand, "spot": HotSpot}
