"""Ray-primitive intersections used by the ray casters (vectorised numpy).

Rays are ``o + tau d`` with unit ``d``; ``tau`` is then the distance in mm.
Every function returns NaN where a ray misses or the hit is behind the
origin, so that callers can combine primitives with ``np.fmin``-style logic.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ray_vertical_cylinder", "ray_plane_y", "nearest", "hit_points", "TAU_MIN"]

#: Hits closer than this to the ray origin (mm) are ignored (self-hits).
TAU_MIN = 1e-9


def ray_vertical_cylinder(o, d, axis_x: float, axis_z, radius):
    """Intersections of rays with an infinite cylinder whose axis is parallel to y.

    Parameters
    ----------
    o : array_like, shape (3,) or (..., 3)
        Ray origins (mm).
    d : array_like, shape (..., 3)
        Unit ray directions.
    axis_x, axis_z : float
        Where the axis crosses the x-z plane (mm).
    radius : float or array_like
        Cylinder radius (mm), broadcast against the rays.

    Returns
    -------
    tau_near, tau_far : numpy.ndarray, shape (...)
        Distances to the entry and exit points (NaN: missed, or behind).
    """
    o = np.asarray(o, np.float64)
    d = np.asarray(d, np.float64)
    px = o[..., 0] - axis_x
    pz = o[..., 2] - axis_z
    dx, dz = d[..., 0], d[..., 2]
    a = dx * dx + dz * dz
    b = 2.0 * (px * dx + pz * dz)
    c = px * px + pz * pz - np.asarray(radius, np.float64) ** 2
    disc = b * b - 4.0 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(disc)
        # the numerically stable pair of roots (no cancellation in either)
        q = -0.5 * (b + np.copysign(sq, b))
        t1 = q / a
        t2 = c / q
    near = np.fmin(t1, t2)
    far = np.fmax(t1, t2)
    miss = ~(disc >= 0) | ~(a > 0)
    near = np.where(miss | (near <= TAU_MIN), np.nan, near)
    far = np.where(miss | (far <= TAU_MIN), np.nan, far)
    return near, far


def ray_plane_y(o, d, y0):
    """Distance along rays to the plane ``y = y0`` (NaN: parallel or behind)."""
    o = np.asarray(o, np.float64)
    d = np.asarray(d, np.float64)
    dy = d[..., 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        tau = (np.asarray(y0, np.float64) - o[..., 1]) / dy
    return np.where((dy != 0) & (tau > TAU_MIN), tau, np.nan)


def hit_points(o, d, tau):
    """Points ``o + tau d`` (NaN where tau is NaN)."""
    return np.asarray(o, np.float64) + np.asarray(tau)[..., None] * np.asarray(d, np.float64)


def nearest(candidates):
    """Index and distance of the nearest valid hit among candidate distances.

    Parameters
    ----------
    candidates : sequence of numpy.ndarray, each shape (...)
        Distances (NaN = no hit) for each primitive.

    Returns
    -------
    index : numpy.ndarray of int, shape (...)
        Position in ``candidates`` of the nearest hit, -1 where none hits.
    tau : numpy.ndarray, shape (...)
        Its distance (NaN where none hits).
    """
    best = None
    idx = None
    for k, c in enumerate(candidates):
        c = np.asarray(c, np.float64)
        if best is None:
            best = np.where(np.isnan(c), np.inf, c)
            idx = np.zeros(best.shape, np.int64)
            continue
        better = c < best  # NaN never wins
        best = np.where(better, c, best)
        idx = np.where(better, k, idx)
    none = ~np.isfinite(best)
    return np.where(none, -1, idx), np.where(none, np.nan, best)
