"""Maps of one experiment's results on the surface: temperature, gradient, rate, strain.

One panel per chosen time, in the IR camera view of :mod:`irdic.plot.maps`.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import ConfigError, DataError, IrdicWarning
from .maps import (View, colour_limits, map_caption, colour_norm, draw_map, experiment_name, grid_sample, map_figure,
                   no_temperature_note, note, pick_source, point_values, round_scale, save_figure, time_indices,
                   unit_label)
from .uncertainty import field_uncertainty, pixel_uncertainty

__all__ = ["plot_temperature", "plot_gradient", "plot_rate", "plot_strain"]


def plot_temperature(points, path, *, times=None, experiment=None):
    """Temperature on the surface at the chosen times, one panel per time.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``: ``temperature(time, point)`` °C, ``x`` mm, ``pixel`` px.
    path : path-like
        PNG to write.
    times : sequence of float, optional
        Times, s (nearest DIC time); default 1/3 and 2/3 of the series.
    experiment : str, optional
        Name shown in the title.

    Returns
    -------
    pathlib.Path
    """
    view = View(points)
    idx = time_indices(points, times)
    t = points["time"].values
    xs = [point_values(points, "x", i) for i in idx]
    vals = [point_values(points, "temperature", i).astype(float) for i in idx]
    name = experiment_name(points, experiment)
    fig, axes = map_figure(len(idx), view, xs, f"{name}: temperature on the surface (IR camera view)")
    norm = colour_norm(*colour_limits(vals))
    m = None
    for ax, i, x, v in zip(axes, idx, xs, vals):
        m = draw_map(ax, view, x, v, cmap="inferno", norm=norm)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
    cb = fig.colorbar(m, ax=list(axes), shrink=0.9, pad=0.02)
    unit = unit_label(points['temperature'], 'degC')
    cb.set_label(f"temperature ({unit})")
    no_temperature_note(fig, xs, vals)
    unc = pixel_uncertainty(points, "temperature", idx, points.sizes["point"])
    return save_figure(fig, path, caption=map_caption(f"Temperature ({unit}) at the DIC points", name, t[idx], xs,
                                                      vals, unc=unc, unit=unit))


def plot_gradient(points, path, *, fields=None, times=None, experiment=None, arrows: int = 18):
    """Temperature with arrows of the in-plane temperature gradient, one panel per time.

    The gradient is ``fields.temperature_gradient`` (K/mm, current
    configuration) projected onto the view plane; without ``fields`` the
    pixel gradient of ``points.zarr`` (K/px, image plane) is drawn instead
    and the title says so.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    path : path-like
        PNG to write.
    fields : xarray.Dataset, optional
        ``fields.zarr`` of the same experiment.
    times : sequence of float, optional
        Times, s; default 1/3 and 2/3 of the series.
    experiment : str, optional
        Name shown in the title.
    arrows : int
        About this many arrows across the wider extent of the surface.

    Returns
    -------
    pathlib.Path
    """
    if not (isinstance(arrows, (int, np.integer)) and 2 <= arrows <= 200):
        raise ConfigError(f"arrows must be an integer in 2 .. 200, got {arrows!r}")
    view = View(points)
    idx = time_indices(points, times)
    t = points["time"].values
    name = experiment_name(points, experiment)
    ds, var, surface = pick_source(points, fields, "temperature_gradient", "temperature_pixel_gradient")
    if ds is None:
        raise DataError("neither fields.temperature_gradient nor points.temperature_pixel_gradient is available")
    unit = unit_label(ds[var], "K/mm" if surface else "K/px")
    what = "in-plane temperature gradient" if surface else "temperature gradient in the IR image (no fields.zarr)"
    xs = [point_values(points, "x", i) for i in idx]
    vals = [point_values(points, "temperature", i).astype(float) for i in idx]
    vecs = []
    for i in idx:
        g = point_values(ds, var, i).astype(float)
        if surface:
            vecs.append(view.vec(g))
        else:  # image plane: u right, v down
            vecs.append((g[:, 0], -g[:, 1]))
    fig, axes = map_figure(len(idx), view, xs, f"{name}: temperature and {what}")
    norm = colour_norm(*colour_limits(vals))
    mags = np.concatenate([np.hypot(*vv) for vv in vecs])
    big = float(np.nanpercentile(mags, 98)) if np.isfinite(mags).any() else 0.0
    m = None
    for ax, i, x, v, (gx, gy) in zip(axes, idx, xs, vals, vecs):
        m = draw_map(ax, view, x, v, cmap="inferno", norm=norm)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
        px, py = view.xy(x)
        ok = np.isfinite(px) & np.isfinite(gx) & np.isfinite(gy) & np.isfinite(v)
        sel, cell = grid_sample(px, py, ok, arrows)
        if not sel.size or not cell > 0 or not big > 0:
            continue
        scale = big / (0.9 * cell)  # the 98th-percentile gradient spans 0.9 grid cells
        q = ax.quiver(px[sel], py[sel], gx[sel], gy[sel], angles="xy", scale_units="xy", scale=scale,
                      color="cyan", width=0.004, headwidth=4, edgecolor="k", linewidth=0.3)
        key = round_scale(big)
        ax.quiverkey(q, 0.80, 1.01, key, f"{key:g} {unit}", labelpos="E", coordinates="axes", fontproperties={"size": 8})
    cb = fig.colorbar(m, ax=list(axes), shrink=0.9, pad=0.02)
    cb.set_label(f"temperature ({unit_label(points['temperature'], 'degC')})")
    no_temperature_note(fig, xs, vals)
    arrows_what = ("in-plane temperature gradient (current configuration), projected on the view plane" if surface
                   else "temperature gradient in the IR image plane")
    # the arrows' length is the gradient's magnitude (in the view plane): judged by its 3-D magnitude's std
    unc = (field_uncertainty(ds, var, idx, vector=True) if surface
           else pixel_uncertainty(points, "gradient_per_px", idx, points.sizes["point"], factor=np.sqrt(2.0)))
    mags3 = [np.linalg.norm(point_values(ds, var, i).astype(float), axis=-1) for i in idx]
    caption = map_caption(f"Temperature (colours) and {arrows_what} (arrows, {unit})", name, t[idx], xs,
                          mags3, unc=unc, unit=unit)
    return save_figure(fig, path, caption=caption)


def plot_rate(points, path, *, fields=None, times=None, experiment=None):
    """Temperature rate on the surface, one panel per time.

    The material rate ``fields.temperature_rate`` (K/s); without ``fields``
    the local rate at the fixed pixel of ``points.zarr``. Diverging colours,
    symmetric about 0 K/s.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    path : path-like
        PNG to write.
    fields : xarray.Dataset, optional
        ``fields.zarr``.
    times : sequence of float, optional
        Times, s; default 1/3 and 2/3 of the series.
    experiment : str, optional
        Name shown in the title.

    Returns
    -------
    pathlib.Path
    """
    view = View(points)
    idx = time_indices(points, times)
    t = points["time"].values
    name = experiment_name(points, experiment)
    ds, var, surface = pick_source(points, fields, "temperature_rate", "temperature_local_rate")
    if ds is None:
        raise DataError("neither fields.temperature_rate nor points.temperature_local_rate is available")
    what = "material temperature rate" if surface else "local temperature rate at the fixed pixel (no fields.zarr)"
    xs = [point_values(points, "x", i) for i in idx]
    vals = [point_values(ds, var, i).astype(float) for i in idx]
    fig, axes = map_figure(len(idx), view, xs, f"{name}: {what}")
    norm = colour_norm(*colour_limits(vals, symmetric=True, pct=(1, 99)))
    m = None
    for ax, i, x, v in zip(axes, idx, xs, vals):
        m = draw_map(ax, view, x, v, cmap="RdBu_r", norm=norm)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
    cb = fig.colorbar(m, ax=list(axes), shrink=0.9, pad=0.02, extend="both")
    unit = unit_label(ds[var], 'K/s')
    cb.set_label(f"temperature rate ({unit})")
    no_temperature_note(fig, xs, vals)
    what = ("Material temperature rate (following each material point)" if surface
            else "Local temperature rate at the fixed IR pixel")
    unc = (field_uncertainty(ds, var, idx) if surface
           else pixel_uncertainty(points, "rate_per_s", idx, points.sizes["point"]))
    return save_figure(fig, path, caption=map_caption(f"{what} ({unit})", name, t[idx], xs, vals, unc=unc, unit=unit))


def plot_strain(fields, path, *, points=None, times=None, experiment=None, segments: int = 18):
    """Maximum principal strain with its directions (short line segments), one panel per time.

    Parameters
    ----------
    fields : xarray.Dataset
        ``fields.zarr``: ``max_principal_strain(time, point)``, ``x`` mm and
        ``principal_direction_current`` (or ``principal_direction``)
        ``(time, point, principal, component)`` as 3-D unit vectors.
    path : path-like
        PNG to write.
    points : xarray.Dataset, optional
        ``points.zarr``, for the IR camera view; else the cloud's main axes.
    times : sequence of float, optional
        Times, s; default 1/3 and 2/3 of the series.
    experiment : str, optional
        Name shown in the title.
    segments : int
        About this many direction segments across the wider extent.

    Returns
    -------
    pathlib.Path
    """
    if fields is None or "max_principal_strain" not in fields or "x" not in fields:
        raise DataError("the strain figure needs fields.zarr with max_principal_strain and x")
    if not (isinstance(segments, (int, np.integer)) and 2 <= segments <= 200):
        raise ConfigError(f"segments must be an integer in 2 .. 200, got {segments!r}")
    view = View(points if points is not None else fields)
    idx = time_indices(fields, times)
    t = fields["time"].values
    name = experiment_name(points if points is not None else fields, experiment)
    dname = next((d for d in ("principal_direction_current", "principal_direction") if d in fields), None)
    if dname is not None and fields[dname].shape[-1] != 3:
        warnings.warn(f"fields.{dname} has {fields[dname].shape[-1]} components ({fields[dname].dims[-1]}), "
                      "expected 3 (x, y, z): principal directions are not drawn", IrdicWarning, stacklevel=2)
        dname = None
    xs = [point_values(fields, "x", i) for i in idx]
    vals = [100.0 * point_values(fields, "max_principal_strain", i).astype(float) for i in idx]
    fig, axes = map_figure(len(idx), view, xs, f"{name}: maximum principal Green-Lagrange strain and its direction")
    lo, hi = colour_limits(vals, pct=(1, 99))
    if lo < 0 < hi and min(-lo, hi) > 0.2 * max(-lo, hi):
        norm, cmap = colour_norm(*colour_limits(vals, symmetric=True, pct=(1, 99))), "RdBu_r"
    else:
        norm, cmap = colour_norm(lo, hi), "viridis"
    from matplotlib.collections import LineCollection

    m = None
    for ax, i, x, v in zip(axes, idx, xs, vals):
        m = draw_map(ax, view, x, v, cmap=cmap, norm=norm, grey_missing=False)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
        if dname is None:
            continue
        d = np.asarray(fields[dname].isel(time=int(i)).transpose("point", "principal", ...).values,
                       dtype=float)[:, 0, :]  # principal = max
        dx, dy = view.vec(d)
        px, py = view.xy(x)
        ok = np.isfinite(px) & np.isfinite(dx) & np.isfinite(dy)
        sel, cell = grid_sample(px, py, ok, segments)
        if not sel.size or not cell > 0:
            continue
        half = 0.4 * cell  # a unit vector in the view plane is 0.8 cells long
        segs = np.stack([np.column_stack([px[sel] - half * dx[sel], py[sel] - half * dy[sel]]),
                         np.column_stack([px[sel] + half * dx[sel], py[sel] + half * dy[sel]])], axis=1)
        ax.add_collection(LineCollection(segs, colors="k", linewidths=1.0))
    cb = fig.colorbar(m, ax=list(axes), shrink=0.9, pad=0.02)
    cb.set_label("max. principal strain E_max (%)")
    if dname is not None:
        note(fig, "segments: direction of E_max (current configuration)" if dname.endswith("current")
              else "segments: direction of E_max (reference configuration)")
    caption = map_caption("Maximum principal Green-Lagrange strain E_max (%, relative to the reference stage)",
                          name, t[idx], xs, vals, unc=field_uncertainty(fields, "max_principal_strain", idx,
                                                                        scale=100.0), unit="%")
    return save_figure(fig, path, caption=caption)
