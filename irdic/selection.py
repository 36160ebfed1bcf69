"""Which times and points a figure or an export shows.

:func:`select_times`, :func:`select_points` and :func:`central_point` turn
configured times (s) and point IDs (``experiments.<name>.report``) into
indices and IDs, with the defaults the figures and the export share;
:func:`aligned_fields` puts ``fields.zarr`` on the axes of ``points.zarr``.
"""

from __future__ import annotations

import logging
import math
from typing import Iterable

import numpy as np
import xarray as xr

from .errors import ConfigError, DataError

__all__ = ["select_times", "select_points", "central_point", "aligned_fields", "require_variables"]

log = logging.getLogger(__name__)


def require_variables(ds, names, what):
    """Raise DataError naming the variables of ``names`` that ``ds`` lacks (``what`` names the store)."""
    missing = [n for n in names if n not in ds.variables]
    if missing:
        raise DataError(f"{what} lacks {', '.join(missing)}: is it the output of the couple stage?")


def select_times(times, requested=None, *, name: str = "times") -> np.ndarray:
    """Indices of the stored times nearest to the requested ones.

    Parameters
    ----------
    times : array_like, shape (T,)
        Stored times, s, increasing.
    requested : sequence of float or None
        Wanted times, s. None or empty: the stored times nearest 1/3 and 2/3
        of the series' span (one time if the series has one).
    name : str
        Name of the setting, for error messages (``report.times``).

    Returns
    -------
    ndarray of int, shape (K,)
        Increasing, distinct indices into ``times``.

    Raises
    ------
    ConfigError
        A requested time is not a finite number or lies outside the stored
        span by more than half the median step.
    """
    t = np.asarray(times, dtype=float)
    if t.ndim != 1 or t.size == 0 or not np.isfinite(t).all():
        raise DataError(f"the store has no usable time axis (got {t.size} times, all finite: {np.isfinite(t).all()})")
    if requested is None or (not isinstance(requested, str) and len(requested) == 0):
        if t.size == 1:
            return np.array([0])
        want = t[0] + np.array([1.0, 2.0]) / 3.0 * (t[-1] - t[0])
    else:
        if isinstance(requested, (str, bytes)) or not isinstance(requested, Iterable):
            raise ConfigError(f"{name} must be a list of times in s, got {requested!r}")
        bad = [r for r in requested
               if isinstance(r, bool) or not isinstance(r, (int, float, np.integer, np.floating))
               or not math.isfinite(float(r))]
        if bad:
            raise ConfigError(f"{name} must be finite numbers (s); got {', '.join(map(repr, bad))}")
        want = np.asarray(requested, dtype=float)
        tol = 0.5 * float(np.median(np.diff(t))) if t.size > 1 else 0.0
        out = want[(want < t[0] - tol) | (want > t[-1] + tol)]
        if out.size:
            raise ConfigError(f"{name}: {', '.join(f'{v:g}' for v in out)} s outside the stored times "
                              f"{t[0]:g} .. {t[-1]:g} s")
    idx = np.abs(t[None, :] - want[:, None]).argmin(axis=1)
    for w, i in zip(want, idx):
        if not np.isclose(w, t[i], rtol=0, atol=1e-9 * max(1.0, abs(w))):
            log.info("%s: %g s -> nearest stored time %g s", name, w, t[i])
    return np.unique(idx)


def central_point(points: xr.Dataset) -> int:
    """The visible point nearest the centre of the point cloud.

    Candidates are the points visible at nearly every time (at least 90 % of
    the largest visible count); among those visible at the middle time the
    one nearest (3-D) to the centroid of the visible points there is taken.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``: ``x(time, point, component)`` mm, ``visible(time, point)``.

    Returns
    -------
    int
        The point ID.
    """
    require_variables(points, ("x", "visible"), "the points store")
    vis = np.asarray(points["visible"].transpose("time", "point").values, dtype=bool)
    count = vis.sum(axis=0)
    if count.max(initial=0) == 0:
        raise DataError("no point is visible at any time: there is no point to show")
    steady = count >= 0.9 * count.max()
    ids = points["point"].values
    # the time with the most steady visible points near the middle of the series
    n_t = vis.shape[0]
    order = np.argsort(np.abs(np.arange(n_t) - (n_t - 1) / 2.0), kind="stable")
    k = next((i for i in order if (vis[i] & steady).any()), order[0])
    x = np.asarray(points["x"].isel(time=int(k)).transpose("point", "component").values, dtype=float)
    cand = vis[k] & steady & np.isfinite(x).all(axis=1)
    if not cand.any():
        cand = steady & np.isfinite(x).all(axis=1)
    centre = x[vis[k] & np.isfinite(x).all(axis=1)].mean(axis=0)
    d = np.where(cand, np.linalg.norm(x - centre, axis=1), np.inf)
    return int(ids[int(np.argmin(d))])


def select_points(points: xr.Dataset, ids=None, *, name: str = "points") -> np.ndarray:
    """Validated point IDs, in the given order without repeats.

    Parameters
    ----------
    points : xarray.Dataset
        A store with a ``point`` coordinate.
    ids : sequence of int, "all" or None
        Point IDs. None or empty: :func:`central_point`; "all": every point.
    name : str
        Name of the setting, for error messages.

    Returns
    -------
    ndarray of int64

    Raises
    ------
    ConfigError
        An ID is not an integer or not in the store (all unknown IDs are named).
    """
    known = np.asarray(points["point"].values)
    if isinstance(ids, str):
        if ids != "all":
            raise ConfigError(f"{name} must be a list of point IDs or 'all', got {ids!r}")
        return known.astype(np.int64)
    if ids is None or len(ids) == 0:
        return np.array([central_point(points)], dtype=np.int64)
    bad = [i for i in ids if isinstance(i, bool) or not isinstance(i, (int, np.integer))]
    if bad:
        raise ConfigError(f"{name} must be integer point IDs; got {', '.join(map(repr, bad))}")
    req = np.asarray(ids, dtype=np.int64)
    unknown = req[~np.isin(req, known)]
    if unknown.size:
        shown = ", ".join(map(str, unknown[:20])) + (f" and {unknown.size - 20} more" if unknown.size > 20 else "")
        raise ConfigError(f"{name}: point ID{'s' if unknown.size > 1 else ''} {shown} not in the store "
                          f"({known.size} points, IDs {known.min()} .. {known.max()})")
    _, first = np.unique(req, return_index=True)
    return req[np.sort(first)]




def aligned_fields(points: xr.Dataset, fields: xr.Dataset | None) -> xr.Dataset | None:
    """``fields`` on the time and point axes of ``points`` (DataError if they differ)."""
    if fields is None:
        return None
    tp, tf = points["time"].values, fields["time"].values
    if tp.shape != tf.shape or not np.allclose(tp, tf, rtol=0, atol=1e-9):
        raise DataError(f"fields store has {tf.size} times, points store {tp.size} (or different values): "
                        "were they computed from the same couple result?")
    pp, pf = points["point"].values, fields["point"].values
    if not np.array_equal(pp, pf):
        if np.setxor1d(pp, pf).size:
            raise DataError(f"fields store has {pf.size} points, points store {pp.size}, "
                            f"{np.setxor1d(pp, pf).size} IDs in only one of them")
        fields = fields.sel(point=pp)
    return fields.assign_coords(time=points["time"].values)
