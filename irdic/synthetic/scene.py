"""A specimen of the scene family: a reference surface, a motion and a temperature pattern, ray-cast exactly.

:class:`SceneSpecimen` joins a :class:`~irdic.synthetic.shapes.Geometry`, a
:class:`~irdic.synthetic.shapes.Motion` and a
:class:`~irdic.synthetic.patterns.Pattern` over a rectangle of material
coordinates ``(s, h)`` (the specimen; beyond its edges the camera sees the
room at ``T_background``). It provides the
:class:`~irdic.synthetic.specimens.Specimen` interface, so the renderer
(:mod:`irdic.synthetic.render`) and the truth (:mod:`irdic.synthetic.truth`)
treat it as the half-shell and the tube.

Ray casting (:meth:`SceneSpecimen.trace`) solves ``x(s, h, t) = o + τ d``
for ``(s, h, τ)`` by Newton's method from the nearest of a grid of surface
points seen from the ray origin, to 1e-10 mm: the hit is exact to rounding,
so the truth's identities (the rate as local plus convective part, the
gradient from the pixel gradient) hold as for the analytic specimens. A hit
counts where it lies on the specimen's rectangle and the surface faces the
ray.

The reference coordinates of a barrel or a sphere cap are not orthonormal:
:meth:`SceneSpecimen.green_lagrange` gives the strain's components in the
orthonormal reference basis ``E_1 = A_s/|A_s|``, ``E_2 = N x E_1``
(:meth:`SceneSpecimen.reference_basis`), ``E_ij = ½ (a_αβ - A_αβ) (A^α · E_i)
(A^β · E_j)``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ConfigError
from .patterns import Pattern
from .shapes import Geometry, Motion
from .specimens import LABEL_BACKGROUND, LABEL_SURFACE, Hit, Specimen

__all__ = ["SceneSpecimen"]

#: Newton steps of the ray caster at most; it converges in 3-6 from the grid's nearest point (a ray that
#: misses the surface wanders off instead)
NEWTON_STEPS = 12
#: the ray caster's last step (mm, on s, h and τ): the quadratic convergence leaves ~1e-16 mm after it
NEWTON_TOL = 1e-8
#: times closer than this (s) share one grid of the ray caster's starting points
GRID_TIME = 0.05


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


class SceneSpecimen(Specimen):
    """A reference surface, carried by a motion, with a temperature pattern (module docstring).

    Parameters
    ----------
    geometry : Geometry
    motion : Motion
    pattern : Pattern
    domain : (s_min, s_max, h_min, h_max)
        The specimen's material rectangle (mm).
    T0 : float
        Temperature of the specimen before the pattern (degC).
    T_background : float
        Apparent temperature of the room behind it (degC).
    name : str
    """

    def __init__(self, geometry: Geometry, motion: Motion, pattern: Pattern, domain, *, T0=22.0,
                 T_background=20.0, name="scene"):
        self.geometry, self.motion, self.pattern = geometry, motion, pattern
        s0, s1, h0, h1 = (float(v) for v in domain)
        if not (s1 > s0 and h1 > h0):
            raise ConfigError(f"domain must be (s_min, s_max, h_min, h_max) with min < max, got {domain!r}")
        self.domain = (s0, s1, h0, h1)
        self.T0, self.T_background, self.name = float(T0), float(T_background), str(name)
        self._grids = {}
        self._static_hits = None

    def describe(self) -> dict:
        return {"geometry": self.geometry.describe(), "motion": self.motion.describe(),
                "pattern": self.pattern.describe(), "domain": list(self.domain), "T0": self.T0,
                "T_background": self.T_background}

    # -- kinematics -----------------------------------------------------------------
    def _state(self, s, h, t):
        s, h, t = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64),
                                      np.asarray(t, np.float64))
        X = self.geometry.point(s, h)
        A_s, A_h = self.geometry.tangents(s, h)
        x, (a_s, a_h), v = self.motion.apply(X, t, (A_s, A_h))
        return x, a_s, a_h, v

    def position(self, s, h, t):
        return self._state(s, h, t)[0]

    def tangents(self, s, h, t):
        _, a_s, a_h, _ = self._state(s, h, t)
        return a_s, a_h

    def velocity(self, s, h, t):
        return self._state(s, h, t)[3]

    # -- temperature ----------------------------------------------------------------
    def temperature(self, s, h, t):
        return self.T0 + self.pattern.evaluate(s, h, t)[0]

    def temperature_derivatives(self, s, h, t):
        """``dTheta/ds`` (K/mm), ``dTheta/dh`` (K/mm), ``dTheta/dt`` (K/s) at fixed material point."""
        return self.pattern.evaluate(s, h, t)[1:4]

    def laplacian(self, s, h, t, *, step=1e-4):
        """Laplace-Beltrami operator of the temperature on the current surface (K/mm²).

        ``Δ Θ = a^{αβ} (Θ_{,αβ} - Γ^γ_{αβ} Θ_{,γ})`` with the pattern's exact
        second derivatives and the Christoffel symbols ``Γ^γ_{αβ} = a^{γδ}
        a_δ · ∂_β a_α`` from central differences (``step`` mm) of the exact
        tangents (relative error ~1e-8).
        """
        s, h, t = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64),
                                      np.asarray(t, np.float64))
        out = self.pattern.evaluate(s, h, t, second=True)
        d1 = np.stack([out[1], out[2]], axis=-1)
        d2 = np.stack([np.stack([out[4], out[5]], -1), np.stack([out[5], out[6]], -1)], axis=-2)
        a = np.stack(self.tangents(s, h, t), axis=-2)  # (..., 2, 3)
        g = np.einsum("...ai,...bi->...ab", a, a)
        gi = np.linalg.inv(g)
        da = np.stack([(np.stack(self.tangents(s + step, h, t), -2) - np.stack(self.tangents(s - step, h, t), -2)),
                       (np.stack(self.tangents(s, h + step, t), -2) - np.stack(self.tangents(s, h - step, t), -2))],
                      axis=-3) / (2 * step)  # (..., β, α, 3) = ∂_β a_α
        gam = np.einsum("...gd,...di,...bai->...gab", gi, a, da)  # Γ^γ_{αβ}
        return np.einsum("...ab,...ab->...", gi, d2 - np.einsum("...gab,...g->...ab", gam, d1))

    # -- strain in the orthonormal reference basis ------------------------------------
    def reference_basis(self, s, h):
        """Orthonormal reference tangents ``E_1 = A_s/|A_s|``, ``E_2 = N x E_1`` (each (..., 3))."""
        s, h = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64))
        A_s, A_h = self.tangents(s, h, np.full_like(s, self.reference_time))
        e1 = A_s / np.linalg.norm(A_s, axis=-1, keepdims=True)
        n = np.cross(A_s, A_h)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        return e1, np.cross(n, e1)

    def green_lagrange(self, s, h, t):
        """Green-Lagrange strain (..., 2, 2) in the orthonormal reference basis (:meth:`reference_basis`)."""
        s, h, t = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64),
                                      np.asarray(t, np.float64))
        g = self.metric(s, h, t)
        G = self.metric(s, h, np.full_like(t, self.reference_time))
        A = np.stack(self.tangents(s, h, np.full_like(t, self.reference_time)), axis=-2)
        dual = np.einsum("...ab,...bi->...ai", np.linalg.inv(G), A)  # A^α
        E = np.stack(self.reference_basis(s, h), axis=-2)  # (..., i, 3)
        P = np.einsum("...ak,...ik->...ia", dual, E)  # P_iα = A^α · E_i
        return 0.5 * np.einsum("...ia,...ab,...jb->...ij", P, g - G, P)

    # -- edges ------------------------------------------------------------------------
    def edge_distance(self, s, h):
        """Distance (mm, in material coordinates) to the nearest edge of the specimen's rectangle.

        Exact along the reference surface where the coordinates are arc
        lengths (plane, cylinder); on a barrel or sphere cap the coordinate
        distance (within a few per cent of the arc).
        """
        s, h = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(h, np.float64))
        s0, s1, h0, h1 = self.domain
        return np.minimum(np.minimum(s - s0, s1 - s), np.minimum(h - h0, h1 - h))

    # -- ray casting --------------------------------------------------------------------
    def _grid(self, o, t):
        """Surface points of a grid over the rectangle (slightly beyond) at time ``t``: unit directions from
        ``o`` (a k-d tree), their ``(s, h)`` and distances."""
        key = (tuple(np.round(o, 9)), round(float(t) / GRID_TIME))
        grid = self._grids.get(key)
        if grid is None:
            s0, s1, h0, h1 = self.domain
            ms, mh = 0.02 * (s1 - s0), 0.02 * (h1 - h0)
            n_s = int(np.clip((s1 - s0) / 0.5, 40, 120))
            n_h = int(np.clip((h1 - h0) / 0.5, 40, 120))
            S, Hh = np.meshgrid(np.linspace(s0 - ms, s1 + ms, n_s), np.linspace(h0 - mh, h1 + mh, n_h))
            S, Hh = S.ravel(), Hh.ravel()
            with np.errstate(invalid="ignore"):
                x = self.position(S, Hh, key[1] * GRID_TIME)
            ok = np.isfinite(x).all(axis=1)
            v = x[ok] - o
            dist = np.linalg.norm(v, axis=1)
            tree = cKDTree(v / dist[:, None])
            # the grid's angular step: a ray farther than a few of them from every grid point misses the specimen
            step = float(np.max(tree.query(tree.data[:: max(1, ok.sum() // 500)], k=2)[0][:, 1]))
            grid = (tree, S[ok], Hh[ok], dist, 3.0 * step)
            if len(self._grids) > 64:
                self._grids.clear()
            self._grids[key] = grid
        return grid

    def trace(self, o, d, t) -> Hit:
        """Cast rays ``o + τ d`` from one origin ``o`` (3,) (the camera centre) into the scene at times ``t``
        (broadcast against the rays): the specimen's surface or the room."""
        o = np.asarray(o, np.float64)
        if o.shape != (3,):
            raise ConfigError(f"rays of a scene must share one origin (3,); got origins of shape {o.shape}")
        d = np.asarray(d, np.float64)
        shape = d.shape[:-1]
        tt = np.broadcast_to(np.asarray(t, np.float64), shape).ravel()
        D = d.reshape(-1, 3)
        n = D.shape[0]
        s, h, tau, done = self._hits(o, D, tt)
        s0, s1, h0, h1 = self.domain
        tol = 1e-9
        with np.errstate(invalid="ignore"):
            on = done & (tau > 0) & (s >= s0 - tol) & (s <= s1 + tol) & (h >= h0 - tol) & (h <= h1 + tol)
        if on.any():
            a_s, a_h = self.tangents(s[on], h[on], tt[on])
            on[np.flatnonzero(on)] = _dot(np.cross(a_s, a_h), D[on]) < 0  # the surface faces the ray
        label = np.where(on, LABEL_SURFACE, LABEL_BACKGROUND)
        temp = np.full(n, self.T_background)
        if on.any():
            temp[on] = self.temperature(s[on], h[on], tt[on])
        nan = np.full(n, np.nan)
        return Hit(np.where(on, tau, np.nan).reshape(shape), label.reshape(shape), temp.reshape(shape),
                   np.where(on, s, nan).reshape(shape), np.where(on, h, nan).reshape(shape))

    def _hits(self, o, D, tt):
        """``(s, h, τ, converged)`` of the rays ``D`` (n, 3) from ``o`` at times ``tt`` (n,): the nearest grid
        point's start (rays far from every grid point miss), then :meth:`_newton`. A static specimen's hits
        do not depend on the time: the last ray set's are kept (the frames of a record share their rays)."""
        key = None
        if self.motion.static:
            key = (hash(D.tobytes()), hash(o.tobytes()), D.shape)
            if self._static_hits is not None and self._static_hits[0] == key:
                return tuple(a.copy() for a in self._static_hits[1])
            tt = np.zeros_like(tt)
        n = D.shape[0]
        s, h, tau = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
        ok_dir = np.isfinite(D).all(axis=1) & np.isfinite(tt)
        keys = np.round(np.where(ok_dir, tt, 0.0) / GRID_TIME)
        for k in np.unique(keys[ok_dir]):
            sel = np.flatnonzero(ok_dir & (keys == k))
            tree, S, Hh, dist, reach = self._grid(o, k * GRID_TIME)
            gap, j = tree.query(D[sel] / np.linalg.norm(D[sel], axis=1, keepdims=True), distance_upper_bound=reach)
            near = np.isfinite(gap)
            sel, j = sel[near], j[near]
            s[sel], h[sel], tau[sel] = S[j], Hh[j], dist[j]
        out = self._newton(o, D, tt, s, h, tau)
        if key is not None:
            self._static_hits = (key, tuple(a.copy() for a in out))
        return out

    def _newton(self, o, D, tt, s, h, tau):
        """Newton's method on ``x(s, h, t) - o - τ d = 0`` from the starting values; ``done`` where converged."""
        done = np.zeros(s.size, bool)
        act = np.flatnonzero(np.isfinite(s))
        s0, s1, h0, h1 = self.domain
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            for _ in range(NEWTON_STEPS):
                if act.size == 0:
                    break
                x, a_s, a_h, _ = self._state(s[act], h[act], tt[act])
                F = x - o - tau[act, None] * D[act]
                J = np.stack([a_s, a_h, -D[act]], axis=-1)
                good = np.isfinite(F).all(axis=1) & np.isfinite(J).all(axis=(1, 2))
                good[good] = np.abs(np.linalg.det(J[good])) > 1e-14
                step = np.full((act.size, 3), np.nan)
                if good.any():
                    step[good] = np.linalg.solve(J[good], F[good][..., None])[..., 0]
                s[act] -= step[:, 0]
                h[act] -= step[:, 1]
                tau[act] -= step[:, 2]
                conv = good & (np.abs(step).max(axis=1) < NEWTON_TOL)
                done[act[conv]] = True
                # a ray that left the rectangle by more than its size misses the specimen
                far = (np.abs(s[act] - 0.5 * (s0 + s1)) > s1 - s0) | (np.abs(h[act] - 0.5 * (h0 + h1)) > h1 - h0)
                act = act[good & ~conv & ~far]
        return s, h, tau, done
