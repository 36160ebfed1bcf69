"""Specimens with closed-form kinematics and temperature (the truth).

Both specimens are parametrised by material surface coordinates ``(s, h)`` in
mm: ``s`` is the arc length around the (vertical, world-y) axis in the
reference configuration, ``h`` the height coordinate. They are orthonormal
coordinates of the reference surface (``A_ss = A_hh = 1, A_sh = 0``), so tensor
components in ``(s, h)`` are components in the orthonormal reference basis
``(e_s, e_h)``. All methods are vectorised and broadcast ``s, h, t``.

Cylindrical half-shell (:class:`HalfShell`, the paper's PLA specimen)
    Outer radius 65 mm, inner 60 mm, height 50 mm, cut by a plane 52 mm from
    the axis, so the observed outer surface spans +-36.87 deg (``s`` in
    +-41.83 mm): width 78 mm, depth 13 mm. Axis parallel to y through
    ``x = 0, z = -65``: the apex of the outer surface is at ``z = 0``, facing
    the DIC cameras (+z). It stands on a heat plate whose top is ``y = -25``
    (``h = y + 25``). Static: the current position equals the reference one.
    Temperature (deg C), heated from the lower edge::

        Theta(s, h, t) = T0 + A(t) g(s) exp(-h / lam(t))
        A(t)   = A_max (1 - exp(-(t + t_pre) / tau))       A_max = 66 K, tau = 20 s
        lam(t) = lam_inf - (lam_inf - lam_0) exp(-(t + t_pre) / tau_lam)
                                                          lam_0 = 6, lam_inf = 14 mm, tau_lam = 30 s
        g(s)   = 1 - b (s / s_e)^2                        b = 0.12, s_e = 41.83 mm

    with ``T0 = 22 degC`` and ``t_pre = 5 s`` (the plate was switched on 5 s
    before the recording started, so every quantity is smooth on ``t >= 0``).
    The heat plate (visible in the IR background below the specimen) is at
    ``T0 + A(t) / 0.85``: a real discontinuity of 2.6 to 10 K at the lower
    edge; the room behind is at 20 degC.

Thin-walled tube under proportional tension-torsion (:class:`Tube`)
    Outer radius 15 mm (inner 13 mm), axis parallel to y through ``x = 0,
    z = -15``; free length 60 mm between clamps at ``Z = -30`` (fixed) and
    ``Z = +30`` (moving); the DIC observes ``|Z| <= 20`` (gauge 40 mm).
    Kinematics of material point ``(theta = s / R, Z = h)``::

        y   = Z_b + (Z - Z_b) lam_z(t),  lam_z = 1 + u(t) / L
        psi = theta + phi(t) (Z - Z_b) / L
        r   = R / sqrt(lam_z)                 (isochoric)
        x   = (r sin psi, y, z_axis + r cos psi)

    with quintic smooth steps (C^2): ``u`` 0 -> 2 mm and twist ``phi``
    0 -> 25 deg during 0.5..5.5 s, hold, torque unloading 6.5..7.5 s (phi
    recovers 2 deg), force unloading 7.5..8.5 s (u recovers 0.2 mm), rest.
    Temperature (plastic heating with Newton cooling to clamps and air)::

        Theta = T0 + dT(t) p(s, h),  p = (1 - beta (h / 30)^2) (1 + gamma sin(s / R))
        d(dT)/dt = Q ds_load/dt - dT / tau_c      (s_load: the loading smooth step)

    ``T0 = 22.5 degC``, ``Q = 4 K``, ``tau_c = 6 s``, ``beta = 0.5``,
    ``gamma = 0.04``: the centre heats at up to ~1.4 K/s, peaks ~2.8 K above T0
    at the end of loading and relaxes afterwards. ``dT`` is evaluated by
    20-point Gauss-Legendre quadrature of the convolution (exact to rounding).
    Clamps: radius 24 mm, 40 mm long, apparent 24.5 degC; room 20 degC.
    Testing machine signals (linear elastic proxies, steel-like E = 210 GPa,
    G = 81 GPa): ``F = E pi (R^2 - R_inner^2) u / L`` (N) and
    ``T = G pi / 2 (R^4 - R_inner^4) phi / L`` (N mm; written in N m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._geometry import hit_points, nearest, ray_plane_y, ray_vertical_cylinder
from .loads import hardening_stress

__all__ = [
    "Specimen", "HalfShell", "Tube", "Hit", "smoothstep",
    "LABEL_BACKGROUND", "LABEL_SURFACE", "LABEL_OTHER_FACE", "LABEL_PLATE", "LABEL_CLAMP",
]

LABEL_BACKGROUND = 0  #: room / wall behind the scene
LABEL_SURFACE = 1     #: the observed specimen surface (the DIC surface)
LABEL_OTHER_FACE = 2  #: another face of the specimen (top face, inner surface)
LABEL_PLATE = 3       #: the heat plate
LABEL_CLAMP = 4       #: the grips of the testing machine


@dataclass
class Hit:
    """Result of casting rays into a scene (all arrays of the ray shape).

    Attributes
    ----------
    tau : numpy.ndarray
        Distance to the first hit (mm), NaN for background.
    label : numpy.ndarray of int
        What was hit (``LABEL_*``).
    temperature : numpy.ndarray
        Apparent temperature (deg C) of what was hit, noise-free.
    s, h : numpy.ndarray
        Material coordinates (mm) where the observed surface was hit, else NaN.
    """

    tau: np.ndarray
    label: np.ndarray
    temperature: np.ndarray
    s: np.ndarray
    h: np.ndarray


def smoothstep(t, a: float, b: float):
    """Quintic smooth step from 0 (t <= a) to 1 (t >= b), C^2.

    Returns
    -------
    S, dS/dt, d2S/dt2 : numpy.ndarray
    """
    T = b - a
    xi = np.clip((np.asarray(t, np.float64) - a) / T, 0.0, 1.0)
    S = xi**3 * (10.0 - 15.0 * xi + 6.0 * xi * xi)
    dS = 30.0 * xi * xi * (1.0 - xi) ** 2 / T
    d2S = 60.0 * xi * (1.0 - xi) * (1.0 - 2.0 * xi) / T**2
    return S, dS, d2S


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _unit(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def _bc(s, h, t):
    s, h, t = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64),
                                  np.asarray(t, np.float64))
    return s, h, t


class Specimen:
    """Interface and the generic differential geometry shared by the specimens.

    Subclasses provide :meth:`position`, :meth:`tangents`, :meth:`velocity`,
    :meth:`temperature`, :meth:`temperature_derivatives`,
    :meth:`edge_distance` and :meth:`trace`.
    """

    name = "specimen"
    #: time of the reference (undeformed) configuration, s
    reference_time = 0.0
    param_names = ("s", "h")

    # -- to be provided -------------------------------------------------------
    def position(self, s, h, t):  # pragma: no cover - interface
        raise NotImplementedError

    def tangents(self, s, h, t):  # pragma: no cover - interface
        raise NotImplementedError

    def velocity(self, s, h, t):  # pragma: no cover - interface
        raise NotImplementedError

    def temperature(self, s, h, t):  # pragma: no cover - interface
        raise NotImplementedError

    def temperature_derivatives(self, s, h, t):  # pragma: no cover - interface
        raise NotImplementedError

    def edge_distance(self, s, h):  # pragma: no cover - interface
        raise NotImplementedError

    def trace(self, o, d, t) -> Hit:  # pragma: no cover - interface
        raise NotImplementedError

    # -- generic --------------------------------------------------------------
    def normal(self, s, h, t):
        """Outward unit normal ``a_s x a_h / |a_s x a_h|`` (..., 3)."""
        a_s, a_h = self.tangents(s, h, t)
        return _unit(np.cross(a_s, a_h))

    def metric(self, s, h, t):
        """Covariant metric ``a_ab = a_a . a_b`` (..., 2, 2) of the current surface."""
        a_s, a_h = self.tangents(s, h, t)
        g = np.empty(a_s.shape[:-1] + (2, 2))
        g[..., 0, 0] = _dot(a_s, a_s)
        g[..., 0, 1] = g[..., 1, 0] = _dot(a_s, a_h)
        g[..., 1, 1] = _dot(a_h, a_h)
        return g

    def dual_tangents(self, s, h, t):
        """Contravariant base vectors ``a^s, a^h`` (each (..., 3))."""
        a_s, a_h = self.tangents(s, h, t)
        g = self.metric(s, h, t)
        det = g[..., 0, 0] * g[..., 1, 1] - g[..., 0, 1] ** 2
        i11, i12, i22 = g[..., 1, 1] / det, -g[..., 0, 1] / det, g[..., 0, 0] / det
        return (i11[..., None] * a_s + i12[..., None] * a_h, i12[..., None] * a_s + i22[..., None] * a_h)

    def temperature_gradient(self, s, h, t):
        """In-plane temperature gradient in the current configuration (K/mm, (..., 3)).

        ``grad Theta = dTheta/ds a^s + dTheta/dh a^h``: tangent to the current
        surface, and ``grad Theta . dx`` is the temperature change along any
        surface increment ``dx``.
        """
        Ts, Th, _ = self.temperature_derivatives(s, h, t)
        d_s, d_h = self.dual_tangents(s, h, t)
        return Ts[..., None] * d_s + Th[..., None] * d_h

    def temperature_rate(self, s, h, t):
        """Material temperature rate ``dTheta/dt`` at fixed ``(s, h)`` (K/s)."""
        return self.temperature_derivatives(s, h, t)[2]

    def green_lagrange(self, s, h, t):
        """Green-Lagrange strain ``E = (a_ab - A_ab) / 2`` (..., 2, 2).

        Components in the orthonormal reference basis ``(e_s, e_h)`` (the
        reference metric ``A_ab`` is the identity for these coordinates; it
        is still subtracted as computed, not assumed).
        """
        s, h, t = _bc(s, h, t)
        g = self.metric(s, h, t)
        G = self.metric(s, h, np.full_like(t, self.reference_time))
        return 0.5 * (g - G)

    def principal_strains(self, s, h, t):
        """Principal Green-Lagrange strains and directions.

        Returns
        -------
        e_max, e_min : numpy.ndarray, shape (...)
            Principal values (1).
        n_max, n_min : numpy.ndarray, shape (..., 2)
            Unit principal directions in the ``(e_s, e_h)`` basis, signed so
            that the ``h`` component is > 0 (or the ``s`` component when it is
            0); NaN where the two principal values are equal (within 1e-12).
        """
        E = self.green_lagrange(s, h, t)
        a, b, c = E[..., 0, 0], E[..., 0, 1], E[..., 1, 1]
        mean = 0.5 * (a + c)
        rad = np.hypot(0.5 * (a - c), b)
        ang = 0.5 * np.arctan2(2.0 * b, a - c)
        n_max = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
        n_min = np.stack([-np.sin(ang), np.cos(ang)], axis=-1)
        out = []
        for n in (n_max, n_min):
            flip = (n[..., 1] < 0) | ((n[..., 1] == 0) & (n[..., 0] < 0))
            n = np.where(flip[..., None], -n, n)
            out.append(np.where((rad > 1e-12)[..., None], n, np.nan))
        return mean + rad, mean - rad, out[0], out[1]

    def reference_basis(self, s, h):
        """Orthonormal reference tangents ``e_s, e_h`` (each (..., 3))."""
        s, h = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64))
        return self.tangents(s, h, np.full_like(s, self.reference_time))


# ---------------------------------------------------------------------------------
class HalfShell(Specimen):
    """The static cylindrical half-shell heated from below (see module docstring).

    All parameters are keyword arguments with the documented defaults.
    """

    name = "halfshell"

    def __init__(self, *, R_o=65.0, R_i=60.0, H=50.0, axis_z=-65.0, y0=-25.0, T0=22.0, A_max=66.0,
                 tau=20.0, t_pre=5.0, lam_0=6.0, lam_inf=14.0, tau_lam=30.0, b=0.12, kappa=0.85,
                 T_background=20.0, plate_x=(-110.0, 110.0), plate_z=(-140.0, 70.0)):
        self.R_o, self.R_i, self.H = float(R_o), float(R_i), float(H)
        self.axis_z, self.y0 = float(axis_z), float(y0)
        self.phi_e = math.asin(0.6)  # 36.87 deg: cut plane at R_o cos(phi_e) = 52 mm
        self.cut = self.R_o * math.cos(self.phi_e)
        self.s_e = self.R_o * self.phi_e
        self.T0, self.A_max, self.tau, self.t_pre = float(T0), float(A_max), float(tau), float(t_pre)
        self.lam_0, self.lam_inf, self.tau_lam = float(lam_0), float(lam_inf), float(tau_lam)
        self.b, self.kappa, self.T_background = float(b), float(kappa), float(T_background)
        self.plate_x, self.plate_z = tuple(plate_x), tuple(plate_z)

    def describe(self) -> dict:
        return {k: v for k, v in vars(self).items() if not k.startswith("_")}

    # time functions
    def amplitude(self, t):
        """``A(t)`` (K) and ``dA/dt`` (K/s)."""
        e = np.exp(-(np.asarray(t, np.float64) + self.t_pre) / self.tau)
        return self.A_max * (1.0 - e), self.A_max / self.tau * e

    def decay_length(self, t):
        """``lam(t)`` (mm) and ``dlam/dt`` (mm/s)."""
        e = np.exp(-(np.asarray(t, np.float64) + self.t_pre) / self.tau_lam)
        return self.lam_inf - (self.lam_inf - self.lam_0) * e, (self.lam_inf - self.lam_0) / self.tau_lam * e

    def plate_temperature(self, t):
        """Apparent temperature of the heat plate (deg C)."""
        return self.T0 + self.amplitude(t)[0] / self.kappa

    # kinematics (static)
    def position(self, s, h, t=0.0):
        s, h, t = _bc(s, h, t)
        phi = s / self.R_o
        return np.stack([self.R_o * np.sin(phi), self.y0 + h, self.axis_z + self.R_o * np.cos(phi)], axis=-1)

    def tangents(self, s, h, t=0.0):
        s, h, t = _bc(s, h, t)
        phi = s / self.R_o
        a_s = np.stack([np.cos(phi), np.zeros_like(phi), -np.sin(phi)], axis=-1)
        a_h = np.stack([np.zeros_like(phi), np.ones_like(phi), np.zeros_like(phi)], axis=-1)
        return a_s, a_h

    def velocity(self, s, h, t=0.0):
        s, h, t = _bc(s, h, t)
        return np.zeros(s.shape + (3,))

    # temperature
    def _g(self, s):
        return 1.0 - self.b * (s / self.s_e) ** 2, -2.0 * self.b * s / self.s_e**2

    def temperature(self, s, h, t):
        A, _ = self.amplitude(t)
        lam, _ = self.decay_length(t)
        s, h, A = _bc(s, h, A)
        return self.T0 + A * self._g(s)[0] * np.exp(-h / lam)

    def temperature_derivatives(self, s, h, t):
        """``dTheta/ds`` (K/mm), ``dTheta/dh`` (K/mm), ``dTheta/dt`` (K/s) at fixed material point."""
        s, h, t = _bc(s, h, t)
        A, dA = self.amplitude(t)
        lam, dlam = self.decay_length(t)
        g, dg = self._g(s)
        e = np.exp(-h / lam)
        return A * dg * e, -A * g * e / lam, g * e * (dA + A * h * dlam / lam**2)

    def edge_distance(self, s, h):
        """Distance (mm, along the reference surface) to the nearest edge of the
        observed outer surface: the side cuts ``s = +-s_e``, the plate ``h = 0``
        and the top ``h = H`` (exact: the cylinder develops into a rectangle)."""
        s, h = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64))
        return np.minimum(np.minimum(self.s_e - np.abs(s), h), self.H - h)

    # ray casting
    def trace(self, o, d, t) -> Hit:
        """Cast rays into the scene: half-shell, heat plate, room.

        Exact for viewpoints in front of the shell (``z > 0`` side), as in the
        lab: the outer surface, the top face, the inner surface seen through
        the hollow, the plate and the room are all treated; the cut faces
        (facing -z) are not.
        """
        d = np.asarray(d, np.float64)
        t = np.asarray(t, np.float64)  # broadcast against the rays, not expanded
        ytop = self.y0 + self.H

        def in_shell(p, rmin, rmax):
            rx, rz = p[..., 0], p[..., 2] - self.axis_z
            rho2 = rx * rx + rz * rz
            return ((p[..., 1] >= self.y0) & (p[..., 1] <= ytop) & (rz >= self.cut - 1e-9)
                    & (rho2 >= rmin**2 * (1 - 1e-12)) & (rho2 <= rmax**2 * (1 + 1e-12)))

        on, _ = ray_vertical_cylinder(o, d, 0.0, self.axis_z, self.R_o)
        po = hit_points(o, d, on)
        on = np.where(in_shell(po, self.R_o, self.R_o), on, np.nan)
        # inner surface seen from the hollow: where a ray leaves the r < R_i cylinder
        _, inf_ = ray_vertical_cylinder(o, d, 0.0, self.axis_z, self.R_i)
        pi = hit_points(o, d, inf_)
        ri = pi[..., 2] - self.axis_z
        inf_ = np.where((pi[..., 1] >= self.y0) & (pi[..., 1] <= ytop) & (ri >= self.cut), inf_, np.nan)
        top = ray_plane_y(o, d, ytop)
        top = np.where(in_shell(hit_points(o, d, top), self.R_i, self.R_o), top, np.nan)
        pl = ray_plane_y(o, d, self.y0)
        pp = hit_points(o, d, pl)
        pl = np.where((pp[..., 0] >= self.plate_x[0]) & (pp[..., 0] <= self.plate_x[1])
                      & (pp[..., 2] >= self.plate_z[0]) & (pp[..., 2] <= self.plate_z[1]), pl, np.nan)
        idx, tau = nearest([on, inf_, top, pl])
        label = np.choose(idx + 1, [LABEL_BACKGROUND, LABEL_SURFACE, LABEL_OTHER_FACE, LABEL_OTHER_FACE,
                                    LABEL_PLATE])
        p = hit_points(o, d, tau)
        phi = np.arctan2(p[..., 0], p[..., 2] - self.axis_z)
        s_any = self.R_o * phi
        h_any = np.clip(p[..., 1] - self.y0, 0.0, self.H)
        spec = (label == LABEL_SURFACE) | (label == LABEL_OTHER_FACE)
        with np.errstate(invalid="ignore"):
            T_spec = self.temperature(np.where(spec, s_any, 0.0), np.where(spec, h_any, 0.0), t)
        temp = np.where(spec, T_spec, np.where(label == LABEL_PLATE, self.plate_temperature(t), self.T_background))
        surf = label == LABEL_SURFACE
        return Hit(tau, label, temp, np.where(surf, s_any, np.nan), np.where(surf, h_any, np.nan))


# ---------------------------------------------------------------------------------
class Tube(Specimen):
    """Thin-walled tube under proportional tension-torsion (see module docstring)."""

    name = "tube"

    def __init__(self, *, R=15.0, R_inner=13.0, axis_z=-15.0, L=60.0, Z_b=-30.0, u_max=2.0,
                 phi_max_deg=25.0, load=(0.5, 5.5), unload_torque=(6.5, 7.5), phi_recovery_deg=2.0,
                 unload_force=(7.5, 8.5), u_recovery=0.2, T0=22.5, Q=4.0, tau_c=6.0, beta=0.5,
                 gamma=0.04, Z_c=30.0, clamp_radius=24.0, clamp_length=40.0, T_clamp=24.5,
                 T_background=20.0, E=210000.0, G=81000.0, yield_stress=300.0, hardening=1000.0):
        self.R, self.R_inner, self.axis_z = float(R), float(R_inner), float(axis_z)
        self.L, self.Z_b = float(L), float(Z_b)
        self.u_max, self.phi_max = float(u_max), math.radians(phi_max_deg)
        self.load, self.unload_torque, self.unload_force = tuple(load), tuple(unload_torque), tuple(unload_force)
        self.phi_recovery, self.u_recovery = math.radians(phi_recovery_deg), float(u_recovery)
        self.T0, self.Q, self.tau_c = float(T0), float(Q), float(tau_c)
        self.beta, self.gamma, self.Z_c = float(beta), float(gamma), float(Z_c)
        self.clamp_radius, self.clamp_length = float(clamp_radius), float(clamp_length)
        self.T_clamp, self.T_background = float(T_clamp), float(T_background)
        self.E, self.G = float(E), float(G)
        self.yield_stress, self.hardening = float(yield_stress), float(hardening)
        self._xg, self._wg = np.polynomial.legendre.leggauss(20)

    def describe(self) -> dict:
        return {k: v for k, v in vars(self).items() if not k.startswith("_")}

    # loading histories
    def axial_displacement(self, t):
        """Grip displacement ``u(t)`` (mm) and ``du/dt`` (mm/s)."""
        S1, d1, _ = smoothstep(t, *self.load)
        S2, d2, _ = smoothstep(t, *self.unload_force)
        return self.u_max * S1 - self.u_recovery * S2, self.u_max * d1 - self.u_recovery * d2

    def twist(self, t):
        """Twist of the moving grip ``phi(t)`` (rad) and ``dphi/dt`` (rad/s)."""
        S1, d1, _ = smoothstep(t, *self.load)
        S2, d2, _ = smoothstep(t, *self.unload_torque)
        return self.phi_max * S1 - self.phi_recovery * S2, self.phi_max * d1 - self.phi_recovery * d2

    def stretch(self, t):
        """Axial stretch ``lam_z`` and its rate (1/s)."""
        u, du = self.axial_displacement(t)
        return 1.0 + u / self.L, du / self.L

    def axial_force(self, t):
        """Axial force of the testing machine, N (elastic-plastic proxy).

        Notes
        -----
        ``F = A sigma(eps)``, ``A = pi (R^2 - R_inner^2)`` (reference section,
        mm^2), ``eps = u / L`` (grip displacement over the free length), with
        the stress of a steel-like bar of linear kinematic hardening
        (:func:`irdic.synthetic.loads.hardening_stress`: ``E`` = 210 GPa, yield stress 300 MPa,
        hardening modulus 1 GPa). The 2 mm stretch is plastic: about 58 kN at
        the peak, and the 0.2 mm push back reverses the yield (about
        -50 kN), the range of a 100 kN machine. Only the demo's signals use
        it; the kinematics do not depend on it.
        """
        S1, _, _ = smoothstep(t, *self.load)
        S2, _, _ = smoothstep(t, *self.unload_force)
        sigma = hardening_stress(self.u_max * S1 / self.L, self.u_recovery * S2 / self.L, self.E,
                                  self.yield_stress, self.hardening)
        return math.pi * (self.R**2 - self.R_inner**2) * sigma

    def torque(self, t):
        """Torque of the testing machine, N m (elastic-plastic proxy).

        Notes
        -----
        ``T = tau(gamma) 2 pi R_m^2 w`` of the thin wall (mean radius ``R_m``,
        thickness ``w``; the shear stress uniform across it once plastic),
        with the surface shear strain ``gamma = R phi / L`` and the shear
        stress of :func:`irdic.synthetic.loads.hardening_stress` with ``G``, the von Mises shear
        yield stress ``yield_stress / sqrt(3)`` and hardening
        ``hardening / 3``: about 510 N m at the 25 deg peak and, the 2 deg
        twisted back reversing the yield, about -340 N m after. N mm divided
        by 1000 for N m.
        """
        S1, _, _ = smoothstep(t, *self.load)
        S2, _, _ = smoothstep(t, *self.unload_torque)
        tau = hardening_stress(self.R * self.phi_max * S1 / self.L, self.R * self.phi_recovery * S2 / self.L,
                                self.G, self.yield_stress / math.sqrt(3.0), self.hardening / 3.0)
        r_m, w = 0.5 * (self.R + self.R_inner), self.R - self.R_inner
        return tau * 2.0 * math.pi * r_m**2 * w / 1000.0

    def radius(self, t):
        """Current outer radius ``R / sqrt(lam_z)`` (mm)."""
        return self.R / np.sqrt(self.stretch(t)[0])

    def heating(self, t):
        """Temperature rise of the centre ``dT(t)`` (K) and its rate (K/s).

        ``dT = Q int_a^min(t,b) s'(t') exp(-(t - t') / tau_c) dt'`` (the
        loading smooth step ``s`` on ``[a, b]``), by Gauss-Legendre quadrature
        in the smooth-step variable; the rate follows from the ODE.
        """
        t = np.asarray(t, np.float64)
        a, b = self.load
        T = b - a
        xi_t = np.clip((t - a) / T, 0.0, 1.0)
        xi = 0.5 * xi_t[..., None] * (self._xg + 1.0)
        f = 30.0 * xi**2 * (1.0 - xi) ** 2 * np.exp(-(t[..., None] - a - T * xi) / self.tau_c)
        dT = self.Q * 0.5 * xi_t * np.sum(self._wg * f, axis=-1)
        _, ds, _ = smoothstep(t, a, b)
        return dT, self.Q * ds - dT / self.tau_c

    # kinematics
    def _frame(self, s, h, t):
        # time functions on the times as given (often one per frame), then broadcast
        t = np.asarray(t, np.float64)
        lam, dlam = self.stretch(t)
        phi, dphi = self.twist(t)
        s, h, _ = _bc(s, h, t)
        zr = (h - self.Z_b) / self.L
        psi = s / self.R + phi * zr
        lam, dlam, phi, dphi = (np.broadcast_to(q, psi.shape) for q in (lam, dlam, phi, dphi))
        r = self.R / np.sqrt(lam)
        e_r = np.stack([np.sin(psi), np.zeros_like(psi), np.cos(psi)], axis=-1)
        e_psi = np.stack([np.cos(psi), np.zeros_like(psi), -np.sin(psi)], axis=-1)
        return s, h, t, lam, dlam, phi, dphi, zr, psi, r, e_r, e_psi

    def position(self, s, h, t):
        s, h, t, lam, _, _, _, _, _, r, e_r, _ = self._frame(s, h, t)
        p = r[..., None] * e_r
        p[..., 1] = self.Z_b + (h - self.Z_b) * lam
        p[..., 2] += self.axis_z
        return p

    def tangents(self, s, h, t):
        s, h, t, lam, _, phi, _, _, _, r, _, e_psi = self._frame(s, h, t)
        a_s = (r / self.R)[..., None] * e_psi
        a_h = (r * phi / self.L)[..., None] * e_psi
        a_h[..., 1] = lam
        return a_s, a_h

    def velocity(self, s, h, t):
        s, h, t, lam, dlam, _, dphi, zr, _, r, e_r, e_psi = self._frame(s, h, t)
        dr = -0.5 * self.R * lam**-1.5 * dlam
        v = dr[..., None] * e_r + (r * dphi * zr)[..., None] * e_psi
        v[..., 1] = (h - self.Z_b) * dlam
        return v

    # temperature
    def _profile(self, s, h):
        ax = 1.0 - self.beta * (h / self.Z_c) ** 2
        ci = 1.0 + self.gamma * np.sin(s / self.R)
        return ax * ci, ax * self.gamma * np.cos(s / self.R) / self.R, -2.0 * self.beta * h / self.Z_c**2 * ci

    def temperature(self, s, h, t):
        dT, _ = self.heating(t)
        s, h, dT = _bc(s, h, dT)
        return self.T0 + dT * self._profile(s, h)[0]

    def temperature_derivatives(self, s, h, t):
        """``dTheta/ds`` (K/mm), ``dTheta/dh`` (K/mm), ``dTheta/dt`` (K/s) at fixed material point."""
        dT, ddT = self.heating(t)
        s, h, dT = _bc(s, h, dT)
        ddT = np.broadcast_to(ddT, dT.shape)
        p, ps, ph = self._profile(s, h)
        return dT * ps, dT * ph, ddT * p

    def edge_distance(self, s, h):
        """Distance (mm, reference) to the nearest clamp (``Z = Z_b`` or ``Z_b + L``).

        The tube has no other edge: sideways it wraps round; where the camera
        stops seeing it is a silhouette, not a material edge.
        """
        s, h = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64))
        return np.minimum(h - self.Z_b, self.Z_b + self.L - h)

    def material_coordinates(self, p, t):
        """Material ``(s, h)`` of current points ``p`` (..., 3) on the tube at time ``t``."""
        p = np.asarray(p, np.float64)
        lam, _ = self.stretch(t)
        phi, _ = self.twist(t)
        Z = self.Z_b + (p[..., 1] - self.Z_b) / lam
        psi = np.arctan2(p[..., 0], p[..., 2] - self.axis_z)
        theta = psi - phi * (Z - self.Z_b) / self.L
        theta = (theta + np.pi) % (2 * np.pi) - np.pi
        return self.R * theta, Z

    def trace(self, o, d, t) -> Hit:
        """Cast rays into the scene: tube, both clamps (sides and end faces), room."""
        d = np.asarray(d, np.float64)
        t = np.asarray(t, np.float64)  # broadcast against the rays, not expanded
        lam, _ = self.stretch(t)
        r = self.radius(t)
        y_top = self.Z_b + self.L * lam  # lower face of the moving clamp
        tn, _ = ray_vertical_cylinder(o, d, 0.0, self.axis_z, r)
        py = hit_points(o, d, tn)[..., 1]
        tube = np.where((py >= self.Z_b) & (py <= y_top), tn, np.nan)
        cn, _ = ray_vertical_cylinder(o, d, 0.0, self.axis_z, self.clamp_radius)
        cy = hit_points(o, d, cn)[..., 1]
        cl = self.clamp_length
        clamp_side = np.where(((cy >= self.Z_b - cl) & (cy <= self.Z_b)) | ((cy >= y_top) & (cy <= y_top + cl)),
                              cn, np.nan)
        caps = []
        for y in (self.Z_b - cl, self.Z_b, y_top, y_top + cl):
            tc = ray_plane_y(o, d, y)
            pc = hit_points(o, d, tc)
            rho2 = pc[..., 0] ** 2 + (pc[..., 2] - self.axis_z) ** 2
            caps.append(np.where(rho2 <= self.clamp_radius**2, tc, np.nan))
        idx, tau = nearest([tube, clamp_side, *caps])
        label = np.where(idx == 0, LABEL_SURFACE, np.where(idx > 0, LABEL_CLAMP, LABEL_BACKGROUND))
        surf = label == LABEL_SURFACE
        s, h = self.material_coordinates(hit_points(o, d, np.where(surf, tau, np.nan)), t)
        with np.errstate(invalid="ignore"):
            T_surf = self.temperature(np.where(surf, s, 0.0), np.where(surf, h, 0.0), t)
        temp = np.where(surf, T_surf, np.where(label == LABEL_CLAMP, self.T_clamp, self.T_background))
        return Hit(tau, label, temp, np.where(surf, s, np.nan), np.where(surf, h, np.nan))
