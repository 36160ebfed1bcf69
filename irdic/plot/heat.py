"""The heat source of one experiment: maps at the figures' times and the region's mean against the load."""

from __future__ import annotations

import numpy as np

from ..errors import DataError
from ..selection import aligned_fields
from .history import load_signals
from .maps import (DPI, PANEL_IN, View, colour_limits, colour_norm, draw_map, experiment_name, fit_limits,
                   map_caption, no_temperature_note, point_values, save_figure, time_indices, unit_label)
from .uncertainty import field_uncertainty

__all__ = ["plot_heat"]

#: W/m³ to MW/m³: the maps' and the curve's unit (a steel specimen's sources are of order 1-100 MW/m³)
MEGA = 1.0e-6


def _region_mean(heat):
    """Mean source over the points with one (T,) MW/m³, and the mean of their stds (an upper bound of the
    mean's std: the points' errors are correlated through the regressions)."""
    v = heat["heat_source"].transpose("time", "point").values.astype(float) * MEGA
    s = heat["heat_source_std"].transpose("time", "point").values.astype(float) * MEGA
    with np.errstate(invalid="ignore"):
        n = np.isfinite(v).sum(axis=1)
        mean = np.where(n > 0, np.nansum(v, axis=1) / np.maximum(n, 1), np.nan)
        std = np.where(n > 0, np.nansum(np.where(np.isfinite(v), s, 0.0), axis=1) / np.maximum(n, 1), np.nan)
    return mean, std


def _figure(n, view, xs, title):
    """Maps of ``n`` times in a row (equal aspect, shared limits) above one full-width axes for the curve."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(n * PANEL_IN + 1.3, 2 * PANEL_IN + 1.6), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, n)
    maps = [fig.add_subplot(gs[0, 0])]
    maps += [fig.add_subplot(gs[0, k], sharex=maps[0], sharey=maps[0]) for k in range(1, n)]
    for ax in maps:
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("right in IR view (mm)")
        ax.tick_params(labelsize=8)
    maps[0].set_ylabel("up in IR view (mm)")
    fit_limits(maps[0], [view.xy(x) for x in xs])
    fig.suptitle(title, fontsize=11)
    return fig, maps + [fig.add_subplot(gs[1, :])]


def _curve(ax, x, mean, std, label):
    ax.fill_between(x, mean - std, mean + std, color="tab:red", alpha=0.25, lw=0, label="± mean std")
    ax.plot(x, mean, ".-", color="tab:red", ms=3, lw=0.8, label="mean source")
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlabel(label)
    ax.set_ylabel("mean heat source (MW/m³)")


def plot_heat(points, path, *, fields, times=None, experiment=None):
    """Heat source on the surface (one panel per time) and the region's mean against the load (or time).

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    path : path-like
        PNG to write.
    fields : xarray.Dataset
        ``fields.zarr`` with the variables of ``heat.zarr`` merged in (``heat_source``, ``heat_source_std``,
        ``heat_source_bias_dominated``) and its signals.
    times : sequence of float, optional
        Times, s; default 1/3 and 2/3 of the series.
    experiment : str, optional
        Name shown in the title.

    Returns
    -------
    pathlib.Path
    """
    fields = aligned_fields(points, fields)
    if fields is None or "heat_source" not in fields:
        raise DataError("the heat figure needs heat.zarr (heat_source): does the experiment have a material block?")
    view = View(points)
    idx = time_indices(points, times)
    t = points["time"].values
    name = experiment_name(points, experiment)
    xs = [point_values(points, "x", i) for i in idx]
    vals = [point_values(fields, "heat_source", i).astype(float) * MEGA for i in idx]
    fig, axes = _figure(len(idx), view, xs, f"{name}: heat source")
    norm = colour_norm(*colour_limits(vals, symmetric=True, pct=(1, 99)))
    m = None
    for ax, i, x, v in zip(axes[:-1], idx, xs, vals):
        m = draw_map(ax, view, x, v, cmap="RdBu_r", norm=norm)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
    cb = fig.colorbar(m, ax=list(axes[:-1]), shrink=0.9, pad=0.02, extend="both")
    cb.set_label("heat source (MW/m³)")
    no_temperature_note(fig, xs, vals)
    mean, std = _region_mean(fields)
    signals = load_signals(fields)
    if signals:
        j, label = signals[0]
        x = np.asarray(fields["signal_value"].transpose("time", "signal").values[:, j], dtype=float)
    else:
        x, label = t, "time (s)"
    _curve(axes[-1], x, mean, std, label)
    unc = field_uncertainty(fields, "heat_source", idx, scale=MEGA)
    what = ("Heat source s = ρc (Θ̇ + (Θ − Θ0)/τ) − k Δ_s Θ, averaged through the wall's thickness "
            f"({unit_label(fields['heat_source'], 'W/m3')} shown in MW/m³; red: heat produced, blue: absorbed)")
    caption = map_caption(what, name, t[idx], xs, vals, unc=unc, unit="MW/m³")
    caption += (f" Bottom: the mean source over the points against {label}, the band the mean of the points' "
                "stds (an upper bound: their errors are correlated).")
    return save_figure(fig, path, caption=caption)
