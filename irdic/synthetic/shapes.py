"""Reference surfaces and motions of the scene family, in closed form.

A scene's specimen (:class:`~irdic.synthetic.scene.SceneSpecimen`) is a
reference surface ``X0(s, h)`` (:class:`Plane`, :class:`Cylinder`,
:class:`Barrel`, :class:`SphereCap`) carried by a motion of space
``x = Φ(X, t)`` (:class:`Motion`). Material coordinates ``(s, h)`` are in
mm; ``h`` runs along world y (up), ``s`` across it; every surface faces +z
(towards the DIC cameras) at ``s = h = 0``, where it passes through the
origin.

Surfaces (``A_s = ∂X0/∂s``, ``A_h = ∂X0/∂h``):

- plane: ``X0 = (s, h, 0)``;
- cylinder of radius ``R`` about the vertical axis ``x = 0, z = -R``:
  ``X0 = (R sin(s/R), h, R cos(s/R) - R)`` (``s`` the arc length);
- barrel: the surface of revolution about that axis whose radius
  ``r(h) = R - Rm + sqrt(Rm² - h²)`` bulges with the meridian radius ``Rm``:
  ``X0 = (r sin(s/R), h, r cos(s/R) - R)`` (``s`` the arc length on the
  equator ``h = 0``; the coordinates are orthogonal, not unit);
- sphere cap of radius ``Rs`` about ``(0, 0, -Rs)``, as a height field:
  ``X0 = (s, h, sqrt(Rs² - s² - h²) - Rs)`` (not orthogonal).

The motion (the tube's of :class:`~irdic.synthetic.specimens.Tube`, for any
surface) stretches space along y from the fixed plane ``y = Yb``, contracts
it towards the vertical axis ``(ax, az)`` isochorically and twists it about
that axis in proportion to the height over the free length ``L``::

    ζ = (Y - Yb) / L,   ψ = φ(t) ζ,   c = λ(t)^(-1/2)
    y = Yb + λ(t) (Y - Yb)
    (x - ax, z - az) = c Rot(ψ) (X - ax, Z - az),   Rot(ψ) q = (q_x cos ψ + q_z sin ψ, q_z cos ψ - q_x sin ψ)

with ``λ = 1 + ε S(t)`` and ``φ = φ_max S(t)``, ``S`` the quintic smooth step
of :func:`~irdic.synthetic.specimens.smoothstep` over the loading interval.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ConfigError
from .specimens import smoothstep

__all__ = ["Geometry", "Plane", "Cylinder", "Barrel", "SphereCap", "Motion", "GEOMETRIES"]


def _bc(*a):
    return np.broadcast_arrays(*(np.asarray(v, np.float64) for v in a))


class Geometry:
    """A reference surface ``X0(s, h)``: positions, tangents, the material coordinates of world ``(x, y)``.

    ``axis``: ``(ax, az)`` of the vertical axis the motion contracts towards and twists about.
    """

    kind = "geometry"
    axis = (0.0, 0.0)

    def point(self, s, h):  # pragma: no cover - interface
        raise NotImplementedError

    def tangents(self, s, h):  # pragma: no cover - interface
        raise NotImplementedError

    def material(self, x, y):  # pragma: no cover - interface
        """Material ``(s, h)`` of the surface point above world ``(x, y)``."""
        raise NotImplementedError

    def max_half_width(self) -> float:
        """Largest world ``|x|`` (mm) of a patch on this surface (its normal within 45-50 deg of +z)."""
        return math.inf

    def max_half_height(self) -> float:
        """Largest world ``|y|`` (mm) of a patch (the normal within 50 deg of +z)."""
        return math.inf

    def describe(self) -> dict:
        return {"kind": self.kind, **{k: v for k, v in vars(self).items() if not k.startswith("_")}}


class Plane(Geometry):
    """The plane ``z = 0``."""

    kind = "plane"

    def point(self, s, h):
        s, h = _bc(s, h)
        return np.stack([s, h, np.zeros_like(s)], axis=-1)

    def tangents(self, s, h):
        s, h = _bc(s, h)
        o, z = np.ones_like(s), np.zeros_like(s)
        return np.stack([o, z, z], axis=-1), np.stack([z, o, z], axis=-1)

    def material(self, x, y):
        return _bc(x, y)


class Cylinder(Geometry):
    """A cylinder of radius ``R`` (mm) about the vertical axis ``x = 0, z = -R``."""

    kind = "cylinder"

    def __init__(self, R: float):
        self.R = float(R)
        if not self.R > 0:
            raise ConfigError(f"cylinder radius must be > 0 mm, got {R!r}")
        self.axis = (0.0, -self.R)

    def point(self, s, h):
        s, h = _bc(s, h)
        th = s / self.R
        return np.stack([self.R * np.sin(th), h, self.R * np.cos(th) - self.R], axis=-1)

    def tangents(self, s, h):
        s, h = _bc(s, h)
        th = s / self.R
        z = np.zeros_like(th)
        return np.stack([np.cos(th), z, -np.sin(th)], axis=-1), np.stack([z, np.ones_like(th), z], axis=-1)

    def material(self, x, y):
        x, y = _bc(x, y)
        return self.R * np.arcsin(np.clip(x / self.R, -1, 1)), y

    def max_half_width(self):
        return self.R * math.sin(math.radians(45.0))


class Barrel(Geometry):
    """A barrel: equator radius ``R``, meridian radius ``Rm`` (mm), about the vertical axis ``x = 0, z = -R``."""

    kind = "barrel"

    def __init__(self, R: float, Rm: float):
        self.R, self.Rm = float(R), float(Rm)
        if not (self.R > 0 and self.Rm > 0):
            raise ConfigError(f"barrel radii must be > 0 mm, got R={R!r}, Rm={Rm!r}")
        self.axis = (0.0, -self.R)

    def radius(self, h):
        """``r(h)`` (mm) and ``dr/dh``."""
        w = np.sqrt(self.Rm ** 2 - np.asarray(h, np.float64) ** 2)
        return self.R - self.Rm + w, -np.asarray(h, np.float64) / w

    def point(self, s, h):
        s, h = _bc(s, h)
        r, _ = self.radius(h)
        th = s / self.R
        return np.stack([r * np.sin(th), h, r * np.cos(th) - self.R], axis=-1)

    def tangents(self, s, h):
        s, h = _bc(s, h)
        r, dr = self.radius(h)
        th = s / self.R
        c, sn = np.cos(th), np.sin(th)
        return (np.stack([r / self.R * c, np.zeros_like(c), -r / self.R * sn], axis=-1),
                np.stack([dr * sn, np.ones_like(c), dr * c], axis=-1))

    def material(self, x, y):
        x, y = _bc(x, y)
        r, _ = self.radius(y)
        return self.R * np.arcsin(np.clip(x / r, -1, 1)), y

    def max_half_width(self):
        return self.R * math.sin(math.radians(45.0))

    def max_half_height(self):
        return self.Rm * math.sin(math.radians(50.0))


class SphereCap(Geometry):
    """A sphere cap of radius ``Rs`` (mm) about ``(0, 0, -Rs)``, parametrised as a height field over x, y."""

    kind = "sphere"

    def __init__(self, Rs: float):
        self.Rs = float(Rs)
        if not self.Rs > 0:
            raise ConfigError(f"sphere radius must be > 0 mm, got {Rs!r}")
        self.axis = (0.0, -self.Rs)

    def point(self, s, h):
        s, h = _bc(s, h)
        return np.stack([s, h, np.sqrt(self.Rs ** 2 - s * s - h * h) - self.Rs], axis=-1)

    def tangents(self, s, h):
        s, h = _bc(s, h)
        w = np.sqrt(self.Rs ** 2 - s * s - h * h)
        o, z = np.ones_like(s), np.zeros_like(s)
        return np.stack([o, z, -s / w], axis=-1), np.stack([z, o, -h / w], axis=-1)

    def material(self, x, y):
        return _bc(x, y)

    def max_half_width(self):
        # the patch's corner within 50 deg of the pole
        return self.Rs * math.sin(math.radians(50.0)) / math.sqrt(2.0)

    max_half_height = max_half_width


GEOMETRIES = {"plane": Plane, "cylinder": Cylinder, "barrel": Barrel, "sphere": SphereCap}


class Motion:
    """Stretch, isochoric contraction and twist of space (module docstring).

    Parameters
    ----------
    strain : float
        ``ε``: the axial stretch ``λ = 1 + ε`` at the end of the loading.
    twist : float
        ``φ_max`` (rad): the twist over the free length ``L``.
    load : (t_a, t_b)
        Loading interval (s).
    axis : (ax, az)
        The vertical axis (mm).
    y_fixed : float
        ``Yb``: the fixed end's plane (mm).
    length : float
        ``L``: the free length the twist is spread over (mm).
    """

    def __init__(self, *, strain=0.0, twist=0.0, load=(0.0, 1.0), axis=(0.0, 0.0), y_fixed=-30.0, length=60.0):
        self.strain, self.twist = float(strain), float(twist)
        self.load = (float(load[0]), float(load[1]))
        self.axis = (float(axis[0]), float(axis[1]))
        self.y_fixed, self.length = float(y_fixed), float(length)
        if not self.load[1] > self.load[0]:
            raise ConfigError(f"loading interval must be increasing, got {load!r}")
        if not self.length > 0:
            raise ConfigError(f"free length must be > 0 mm, got {length!r}")

    @property
    def static(self) -> bool:
        return self.strain == 0.0 and self.twist == 0.0

    def describe(self) -> dict:
        return {k: v for k, v in vars(self).items() if not k.startswith("_")}

    def history(self, t):
        """``λ, dλ/dt, φ, dφ/dt`` at times ``t``."""
        S, dS, _ = smoothstep(t, *self.load)
        return 1.0 + self.strain * S, self.strain * dS, self.twist * S, self.twist * dS

    def apply(self, X, t, A=None):
        """Current positions (..., 3) of reference points ``X`` (..., 3) at ``t``; with reference vectors ``A``
        (sequence of (..., 3)), also their images ``DΦ A``; last the velocity ``∂Φ/∂t`` (..., 3).

        Returns
        -------
        x, [DΦ A for A in A], v
        """
        X = np.asarray(X, np.float64)
        lam, dlam, phi, dphi = self.history(np.asarray(t, np.float64))
        ax, az = self.axis
        qx, Y, qz = X[..., 0] - ax, X[..., 1], X[..., 2] - az
        zeta = (Y - self.y_fixed) / self.length
        psi = phi * zeta
        c = lam ** -0.5
        cs, sn = np.cos(psi), np.sin(psi)
        rx, rz = cs * qx + sn * qz, cs * qz - sn * qx  # Rot(ψ) q
        px, pz = c * rx, c * rz
        y = self.y_fixed + lam * (Y - self.y_fixed)
        x = np.stack(np.broadcast_arrays(ax + px, y, az + pz), axis=-1)
        dc = -0.5 * lam ** -1.5 * dlam
        dpsi = dphi * zeta
        v = np.stack(np.broadcast_arrays(dc * rx + c * dpsi * rz, dlam * (Y - self.y_fixed),
                                         dc * rz - c * dpsi * rx), axis=-1)
        images = []
        for a in A or ():
            a = np.asarray(a, np.float64)
            ax_, ay_, az_ = a[..., 0], a[..., 1], a[..., 2]
            # ∂/∂X, ∂/∂Z: c Rot(ψ); ∂/∂Y: λ along y and the rotation's change with ψ = φ (Y - Yb) / L
            dpsi_dY = phi / self.length
            ix = c * (cs * ax_ + sn * az_) + c * dpsi_dY * rz * ay_
            iz = c * (cs * az_ - sn * ax_) - c * dpsi_dY * rx * ay_
            images.append(np.stack(np.broadcast_arrays(ix, lam * ay_, iz), axis=-1))
        return x, images, v
