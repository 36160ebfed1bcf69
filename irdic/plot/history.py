"""Figures over time: temperature history at chosen points, temperature against load."""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import ConfigError
from ..selection import aligned_fields, select_points
from ..vocabulary import Status
from .maps import (DPI, View, annotate_point, colour_limits, colour_norm, draw_map, experiment_name, note,
                   point_values, save_figure, unit_label)

__all__ = ["plot_history", "plot_load", "load_signals", "LOAD_AXES"]


def plot_history(points, path, *, fields=None, point_ids=None, experiment=None):
    """Temperature and temperature rate over time at chosen points, and where they are.

    Top: temperature (°C); hollow markers where the value is extrapolated
    from the specimen mask edge (``Status.EXTRAPOLATED_FROM_EDGE``). Bottom: the material rate with
    its local and convective parts (``fields.zarr``), else the local rate
    at the fixed pixel (``points.zarr``). Right: the surface at the middle
    time with the points marked.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    path : path-like
        PNG to write.
    fields : xarray.Dataset, optional
        ``fields.zarr``.
    point_ids : sequence of int, optional
        DIC point IDs (at most 8); default the visible point nearest the
        centre of the cloud.
    experiment : str, optional
        Name shown in the title.

    Returns
    -------
    pathlib.Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ids = select_points(points, point_ids, name="point_ids")
    if ids.size > 8:
        raise ConfigError(f"point_ids: at most 8 points in one history figure, got {ids.size}")
    name = experiment_name(points, experiment)
    pos = {int(p): k for k, p in enumerate(points["point"].values)}
    sel = np.array([pos[int(p)] for p in ids])
    t = points["time"].values.astype(float)
    theta = np.asarray(points["temperature"].isel(point=sel).transpose("time", "point").values, dtype=float)
    status = (np.asarray(points["status"].isel(point=sel).transpose("time", "point").values)
              if "status" in points else np.zeros(theta.shape, dtype=np.int8))
    fig = Figure(figsize=(11.0, 6.2), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, 2, width_ratios=[2.0, 1.0])
    ax_t = fig.add_subplot(gs[0, 0])
    ax_r = fig.add_subplot(gs[1, 0], sharex=ax_t)
    ax_m = fig.add_subplot(gs[0, 1])
    ax_i = fig.add_subplot(gs[1, 1])
    colors = [f"C{k}" for k in range(ids.size)]
    _history_temperature(ax_t, points, t, theta, status, ids, colors)
    _history_rate(ax_r, points, fields, t, ids, sel, colors)
    _history_positions(fig, ax_m, points, t, ids, sel, colors)
    _history_summary(ax_i, points, ids, sel, theta, status, colors)
    fig.suptitle(f"{name}: temperature history at point{'s' if ids.size > 1 else ''} "
                 f"{', '.join(map(str, ids))}", fontsize=11)
    caption = (f"Temperature (top) and material temperature rate (bottom) of DIC point(s) {', '.join(map(str, ids))} "
               f"of {name} over t = {t[0]:g} .. {t[-1]:g} s; hollow markers: extrapolated from the specimen mask "
               "edge. Right: where the points are (IR camera view), their DIC-frame position and how many times "
               "have a temperature.")
    if fields is not None and "temperature_rate_std" in fields:
        caption += (" Shaded: the material rate ± 2 standard uncertainties (fields.temperature_rate_std; not a bound "
                    "where fields.temperature_rate_bias_dominated is set: mask edge, first and last time).")
    return save_figure(fig, path, caption=caption)



def _history_temperature(ax_t, points, t, theta, status, ids, colors):
    """Temperature curves; filled markers inside the mask, hollow where extrapolated (status 1)."""
    for k, (pid, c) in enumerate(zip(ids, colors)):
        ax_t.plot(t, theta[:, k], "-", color=c, lw=1.2, label=f"point {pid}")
        inside = status[:, k] == Status.INTERPOLATED
        ax_t.plot(t[inside], theta[inside, k], "o", color=c, ms=3)
        extra = status[:, k] == Status.EXTRAPOLATED_FROM_EDGE
        if extra.any():
            ax_t.plot(t[extra], theta[extra, k], "o", mfc="none", mec=c, ms=5,
                      label="extrapolated from the mask edge" if k == 0 else None)
    ax_t.set_ylabel(f"temperature ({unit_label(points['temperature'], 'degC')})")
    ax_t.grid(True, alpha=0.3)
    ax_t.legend(fontsize=8, loc="best")
    ax_t.tick_params(labelbottom=False)


def _history_rate(ax_r, points, fields, t, ids, sel, colors):
    """Material rate and its parts (fields.zarr), else the local rate at the fixed pixel (points.zarr)."""
    parts = []
    if fields is not None and "temperature_rate" in fields:
        f = fields.sel(point=ids)
        parts = [("temperature_rate", "material rate", "-"), ("temperature_rate_local", "local part", "--"),
                 ("temperature_rate_convective", "convective part", ":")]
        parts = [(f[v], lab, ls) for v, lab, ls in parts if v in f]
    elif "temperature_local_rate" in points:
        parts = [(points["temperature_local_rate"].isel(point=sel), "local rate at the fixed pixel (no fields.zarr)", "-")]
    for da, lab, ls in parts:
        a = np.asarray(da.transpose("time", "point").values, dtype=float)
        for k, c in enumerate(colors):
            ax_r.plot(t, a[:, k], ls, color=c, lw=1.2, label=lab if k == 0 else None)
    if parts and fields is not None and "temperature_rate_std" in fields:
        a = np.asarray(fields["temperature_rate"].sel(point=ids).transpose("time", "point").values, dtype=float)
        s = np.asarray(fields["temperature_rate_std"].sel(point=ids).transpose("time", "point").values, dtype=float)
        for k, c in enumerate(colors):
            ax_r.fill_between(t, a[:, k] - 2 * s[:, k], a[:, k] + 2 * s[:, k], color=c, alpha=0.15, lw=0,
                              label="material rate ± 2 std" if k == 0 else None)
    ax_r.axhline(0.0, color="0.5", lw=0.6)
    ax_r.set_ylabel("temperature rate (K/s)")
    ax_r.set_xlabel("time (s)")
    ax_r.grid(True, alpha=0.3)
    if parts:  # above the axes: rate curves fill the whole box
        n = len(ax_r.get_legend_handles_labels()[0])
        ax_r.legend(fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncols=n, frameon=False)


def _history_positions(fig, ax_m, points, t, ids, sel, colors):
    """The surface at the middle time with the chosen points marked and an inset colour bar."""
    view = View(points)
    k_mid = int(np.clip(len(t) // 2, 0, len(t) - 1))
    x = point_values(points, "x", k_mid)
    px, py = view.xy(x)
    v = point_values(points, "temperature", k_mid).astype(float)
    m = draw_map(ax_m, view, x, v, cmap="inferno", norm=colour_norm(*colour_limits([v])), fit=True)
    for k, c in enumerate(colors):
        ax_m.plot(px[sel[k]], py[sel[k]], "o", mfc=c, mec="white", ms=8, mew=1.5)
        annotate_point(ax_m, str(ids[k]), (px[sel[k]], py[sel[k]]), (6, 6), "k")
    ax_m.set_aspect("equal", adjustable="box")
    ax_m.set_title(f"position at t = {t[k_mid]:g} s (IR camera view)", fontsize=9)
    ax_m.set_xlabel("right in IR view (mm)")
    ax_m.set_ylabel("up in IR view (mm)")
    # an inset colour bar follows the equal-aspect map box (a layout colour bar would sit at the cell edge)
    cb = fig.colorbar(m, cax=ax_m.inset_axes([1.04, 0.0, 0.05, 1.0]))
    cb.set_label(f"temperature ({unit_label(points['temperature'], 'degC')})", fontsize=8)
    cb.ax.tick_params(labelsize=7)

def _history_summary(ax, points, ids, sel, theta, status, colors):
    """Per point: reference position, how often it has a temperature, its range."""
    ax.axis("off")
    x = np.asarray(points["x"].isel(point=sel).transpose("time", "point", "component").values, dtype=float)
    n_t = theta.shape[0]
    lines = []
    for k, pid in enumerate(ids):
        ok = np.isfinite(x[:, k]).all(axis=1)
        ref = np.round(x[np.argmax(ok), k], 1) + 0.0 if ok.any() else np.full(3, np.nan)  # + 0.0: no "-0.0"
        has = np.isfinite(theta[:, k])
        rng = (f"{np.nanmin(theta[:, k]):.2f} .. {np.nanmax(theta[:, k]):.2f} °C" if has.any() else "no temperature")
        n_ex = int((status[:, k] == Status.EXTRAPOLATED_FROM_EDGE).sum())
        lines.append((colors[k], f"point {pid} at ({ref[0]:.1f}, {ref[1]:.1f}, {ref[2]:.1f}) mm\n"
                                 f"  (DIC frame x, y, z at its first time)\n"
                                 f"  temperature at {int(has.sum())} of {n_t} times,\n"
                                 f"  {n_ex} of them extrapolated from the mask edge"
                                 f"\n  {rng}"))
    step = min(0.16, 1.0 / max(len(lines), 1))
    for k, (c, text) in enumerate(lines):
        ax.text(0.0, 1.0 - step * k, text, color=c, fontsize=8 if len(lines) < 5 else 6.5, va="top", ha="left",
                transform=ax.transAxes, family="monospace")


#: quantities the load figure puts on its horizontal axes, in this order
LOAD_AXES = ("force", "displacement", "torque", "angle")


def load_signals(fields) -> list[tuple[int, str]]:
    """(signal index, axis label) of the signals to plot against.

    One signal per standard quantity (force, displacement, torque, angle), the
    one with the most values where several sources have it (a machine record
    has no gaps where a DIC stage lacks a signal); without any of those the
    first two signals that are neither a time nor a cycle count.
    """
    if fields is None or "signal_value" not in fields:
        return []
    names = [str(n) for n in fields["signal"].values]
    n = len(names)

    def coord(c):
        return [str(v) for v in fields[c].values] if c in fields.coords else [""] * n

    std, unit = coord("signal_standard_name"), coord("signal_unit")
    v = np.asarray(fields["signal_value"].transpose("time", "signal").values, dtype=float)
    count = np.isfinite(v).sum(axis=0)
    picks = []
    for q in LOAD_AXES:
        cands = [j for j in range(n) if std[j] == q and count[j] > 0]
        if cands:
            picks.append(max(cands, key=lambda j: (count[j], -j)))
    if not picks:
        picks = [j for j in range(n) if std[j] not in ("time", "cycles") and count[j] > 0][:2]
    return [(j, _label(std[j], names[j], unit[j])) for j in picks]


def _label(standard: str, name: str, unit: str) -> str:
    """``force (Kraft) [kN]``: the standard name, the record's own name in brackets when it differs, the unit."""
    text = f"{standard} ({name})" if standard and standard != name else name
    return f"{text} [{unit}]" if unit else text


def plot_load(points, path, *, fields=None, point_ids=None, experiment=None):
    """Temperature of the specimen region against the testing machine's signals.

    One column per load quantity found in ``fields.zarr``'s signals (force,
    displacement, torque, angle; see :func:`load_signals`). Top: mean
    temperature of the points that have one (the specimen region seen by the
    IR camera), its minimum and maximum, and the chosen point's temperature.
    Bottom: mean material temperature rate and the chosen point's rate. Each
    marker is one DIC time. Without signals the figure says so, so that the
    workflow's set of outputs does not depend on the data.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    path : path-like
        PNG to write.
    fields : xarray.Dataset, optional
        ``fields.zarr`` with ``signal_value(time, signal)``.
    point_ids : sequence of int, optional
        The first is the chosen point; default the visible point nearest the
        centre of the cloud.
    experiment : str, optional
        Name shown in the title.

    Returns
    -------
    pathlib.Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    name = experiment_name(points, experiment)
    fields = aligned_fields(points, fields)
    axes = load_signals(fields)
    if not axes:
        return _no_load_figure(fields, name, path)
    ids = select_points(points, list(point_ids)[:1] if point_ids is not None and len(point_ids) else None,
                        name="point_ids")
    pid = int(ids[0])
    theta, t_mean, t_min, t_max, rate, r_mean = _region_statistics(points, fields)
    k = int(np.flatnonzero(points["point"].values == pid)[0])
    sig = np.asarray(fields["signal_value"].transpose("time", "signal").values, dtype=float)
    fig = Figure(figsize=(3.6 * len(axes) + 1.0, 6.4), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, len(axes))
    unit_t = unit_label(points["temperature"], "degC")
    for c, (j, label) in enumerate(axes):
        x = sig[:, j]
        ax_t = fig.add_subplot(gs[0, c])
        ax_r = fig.add_subplot(gs[1, c], sharex=ax_t)
        ax_t.plot(x, t_mean, "-o", color="C3", ms=3, lw=1.2, label="mean")
        ax_t.plot(x, t_min, "--", color="C0", lw=0.9, label="min")
        ax_t.plot(x, t_max, "--", color="C1", lw=0.9, label="max")
        ax_t.plot(x, theta[:, k], ":s", color="k", ms=2.5, lw=0.9, label=f"point {pid}")
        ax_t.grid(True, alpha=0.3)
        ax_t.tick_params(labelbottom=False)
        if r_mean is not None:
            ax_r.plot(x, r_mean, "-o", color="C3", ms=3, lw=1.2, label="mean rate")
            ax_r.plot(x, rate[:, k], ":s", color="k", ms=2.5, lw=0.9, label=f"point {pid}")
        ax_r.axhline(0.0, color="0.5", lw=0.6)
        ax_r.grid(True, alpha=0.3)
        ax_r.set_xlabel(label)
        if c == 0:
            ax_t.set_ylabel(f"temperature ({unit_t})")
            ax_r.set_ylabel("material temperature rate (K/s)")
            ax_t.legend(fontsize=7, loc="best")
            if r_mean is not None:
                ax_r.legend(fontsize=7, loc="best")
        if not np.isfinite(x).all():
            ax_t.set_title(f"{int((~np.isfinite(x)).sum())} time(s) without {label}", fontsize=8, color="0.35")
    note(fig, "mean, min, max over the points with a temperature (the specimen region seen by the IR camera); "
               "one marker per DIC time")
    fig.suptitle(f"{name}: temperature against load", fontsize=11)
    caption = (f"Mean, minimum and maximum temperature over the points of {name} that have a temperature, and their "
               f"mean material temperature rate, against the testing machine signals at the {sig.shape[0]} DIC times; "
               f"the first chosen point ({pid}) for comparison.")
    return save_figure(fig, path, caption=caption)


def _no_load_figure(fields, name, path):
    """A figure that says why there is no load figure (the workflow's outputs do not depend on the data)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 3.0), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.axis("off")
    why = ("no fields.zarr" if fields is None else
           "the DIC exports carry no testing machine signals (nodemap SIGNALS) and no machine record "
           "is configured (experiments.<name>.machine)")
    ax.text(0.5, 0.5, f"{name}: no load figure\n{why}", ha="center", va="center", wrap=True, fontsize=10)
    return save_figure(fig, path, caption=f"No load figure for {name}: {why}.")


def _region_statistics(points, fields):
    """Temperatures (T, N), their mean, min and max over the points per time, rates (T, N) and their mean.

    The rates are None without ``fields.temperature_rate``; the mean rate is
    over the points that have a temperature.
    """
    theta = np.asarray(points["temperature"].transpose("time", "point").values, dtype=float)
    seen = np.isfinite(theta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # times without any temperature stay NaN
        t_mean, t_min, t_max = np.nanmean(theta, axis=1), np.nanmin(theta, axis=1), np.nanmax(theta, axis=1)
        rate = (np.asarray(fields["temperature_rate"].transpose("time", "point").values, dtype=float)
                if "temperature_rate" in fields else None)
        r_mean = np.nanmean(np.where(seen, rate, np.nan), axis=1) if rate is not None else None
    return theta, t_mean, t_min, t_max, rate, r_mean

