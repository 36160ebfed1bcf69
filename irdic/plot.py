"""Figures: functions that take datasets/arrays and a path and write a PNG.

Matplotlib is used through its object interface with the Agg canvas, so no
global pyplot state or display is involved (safe in Snakemake jobs).

Calibration: :func:`plot_calibration`, :func:`plot_detections`.

Results of one experiment (``points.zarr``, optionally ``fields.zarr``):
:func:`plot_temperature`, :func:`plot_gradient`, :func:`plot_rate`,
:func:`plot_history`, :func:`plot_strain`, :func:`plot_load` (temperature
against the testing machine's signals), and :func:`plot_experiment` for
all of them. The surface is drawn as the IR camera sees it, orthographically
and in mm: the view axes are the directions in which the image coordinates
u (right) and -v (up) grow, fitted to the projected points
(:func:`view_basis`). Vectors (gradients, principal directions) are drawn
projected onto that view plane, so they are foreshortened where the surface
turns away from the camera. Points without a temperature are grey.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Mapping

import logging
import warnings

import numpy as np

from .errors import ConfigError, DataError, IrdicWarning
from .export import select_points, select_times

log = logging.getLogger(__name__)

__all__ = [
    "plot_calibration",
    "plot_detections",
    "view_basis",
    "plot_temperature",
    "plot_gradient",
    "plot_rate",
    "plot_history",
    "plot_strain",
    "plot_load",
    "plot_experiment",
    "FIGURES",
]


def _figure(image, title: str):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .calibration.image import image_array

    img, u0, v0 = image_array(image)
    h, w = img.shape
    fig = Figure(figsize=(min(16.0, 4 + w / 80), min(12.0, 3 + h / 80)), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    lo, hi = np.nanpercentile(img, [1, 99])
    # pixel centres on integers: the pixel (u, v) covers [u - 0.5, u + 0.5]
    im = ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest",
                   extent=(u0 - 0.5, u0 + w - 0.5, v0 + h - 0.5, v0 - 0.5))
    cb = fig.colorbar(im, ax=ax, fraction=0.03, pad=0.01)
    cb.set_label("°C")
    ax.set_xlabel("u (px, column)")
    ax.set_ylabel("v (px, row)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, color="tab:cyan", alpha=0.35, lw=0.5)
    return fig, ax


def _circles(ax, u, v, r, color, lw, label=None):
    """Circles of radius ``r`` in data (pixel) units."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    ok = np.isfinite(u) & np.isfinite(v)
    pc = PatchCollection([Circle((a, b), c) for a, b, c in zip(u[ok], v[ok], r[ok])], facecolors="none",
                         edgecolors=color, linewidths=lw)
    ax.add_collection(pc)
    if label:  # PatchCollection has no legend entry of its own
        ax.plot([], [], "o", mfc="none", mec=color, label=label)


def _label(ax, text, pos, offset, color):
    import matplotlib.patheffects as pe

    ax.annotate(text, pos, xytext=offset, textcoords="offset points", fontsize=6.5, color=color,
                path_effects=[pe.withStroke(linewidth=2, foreground="white")])


def _save(fig, path) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(os.fspath(p), bbox_inches="tight")
    return p


def _zoom(ax, u, v, margin: float = 40.0):
    ok = np.isfinite(u) & np.isfinite(v)
    if ok.any():
        ax.set_xlim(np.nanmin(u[ok]) - margin, np.nanmax(u[ok]) + margin)
        ax.set_ylim(np.nanmax(v[ok]) + margin, np.nanmin(v[ok]) - margin)


def plot_detections(detections, target_image, path) -> Path:
    """The target image with every detection circled and labelled ``u,v`` (px).

    Written when the marker correspondence fails, so that seed positions
    can be read off it.

    Parameters
    ----------
    detections : xarray.Dataset
        :func:`irdic.calibration.detect_markers` output.
    target_image : xarray.DataArray
        The IR image (``("v", "u")``, °C).
    path : path-like
        PNG to write.
    """
    u = detections["u"].values
    v = detections["v"].values
    r = detections["radius_px"].values
    fig, ax = _figure(target_image, f"{len(u)} detected markers (label: u,v in px) - use these positions as seeds")
    _circles(ax, u, v, r, "tab:orange", 1.0)
    for ui, vi in zip(u, v):
        _label(ax, f"{ui:.0f},{vi:.0f}", (ui, vi), (-12, 7), "navy")
    _zoom(ax, u, v)
    return _save(fig, path)


#: contrast/noise below which a used marker is drawn as faint in :func:`plot_calibration`
FAINT_SNR = 10.0


def plot_calibration(cal_ds, target_image, path, *, vector_length_px: float = 25.0) -> Path:
    """The target image with detections, marker IDs and scaled residual vectors.

    Used markers are green circles (gold when their contrast/noise is below
    :data:`FAINT_SNR`; the title gives its minimum and median), outliers red, markers that were not
    detected are drawn at their projected position as crosses. Residual
    vectors (detected - bias - reprojected) are scaled so that the largest is
    ``vector_length_px`` image pixels long; the scale bar gives their size.

    Parameters
    ----------
    cal_ds : xarray.Dataset
        :func:`irdic.calibration.calibrate` output.
    target_image : xarray.DataArray
        The IR image of the target.
    path : path-like
        PNG to write.
    vector_length_px : float
        Drawn length of the largest residual, image px.
    """
    status = cal_ds["status"].values.astype(str)
    det = cal_ds["detected"].values
    rep = cal_ds["reprojected"].values
    res = cal_ds["residual"].values
    ids = cal_ds["marker"].values
    rms, mx = float(cal_ds["rms_px"]), float(cal_ds["max_px"])
    from .camera import load_camera

    g = load_camera(cal_ds).decompose()
    title = (f"IR camera calibration: {int((status == 'used').sum())} markers, RMS {rms:.3f} px, max {mx:.3f} px; "
             f"f {g.focal_length_px:.1f} px (IFOV {g.ifov_mrad:.3f} mrad), centre "
             f"({', '.join(f'{c:.0f}' for c in g.C)}) mm")
    snr = cal_ds["marker_snr"].values if "marker_snr" in cal_ds else np.full(len(ids), np.nan)
    used = status == "used"
    if np.isfinite(snr[used]).any():
        title += f"\nmarker contrast/noise: min {np.nanmin(snr[used]):.1f}, median {np.nanmedian(snr[used]):.1f}"
    fig, ax = _figure(target_image, title)
    out = status == "outlier"
    missing = np.isin(status, ["not_detected"])
    r = np.where(np.isfinite(cal_ds["marker_radius_px"].values), cal_ds["marker_radius_px"].values, 5.0)
    # faint markers have noisier centres: they are drawn in their own colour
    faint = used & (snr < FAINT_SNR)
    _circles(ax, det[used & ~faint, 0], det[used & ~faint, 1], r[used & ~faint], "limegreen", 1.0, "used")
    if faint.any():
        _circles(ax, det[faint, 0], det[faint, 1], r[faint], "gold", 1.0, f"used, contrast/noise < {FAINT_SNR:g}")
    if out.any():
        _circles(ax, det[out, 0], det[out, 1], r[out], "red", 1.5, "outlier")
    if missing.any():
        ax.scatter(rep[missing, 0], rep[missing, 1], marker="x", color="orange", s=30, label="not detected")
    un = cal_ds["unassigned_uv"].values
    if len(un):
        ax.scatter(un[:, 0], un[:, 1], marker="s", facecolors="none", edgecolors="magenta", s=40,
                   label="detection without marker")
    norm = np.hypot(res[:, 0], res[:, 1])
    finite = np.isfinite(norm) & (used | out)
    big = float(np.nanmax(norm[finite])) if finite.any() else 0.0
    if big > 0:
        scale = vector_length_px / big
        ax.quiver(rep[finite, 0], rep[finite, 1], res[finite, 0] * scale, res[finite, 1] * scale,
                  angles="xy", scale_units="xy", scale=1.0, color="red", width=0.002)
        # scale bar: a round residual size near the largest one
        bar = float(10 ** np.floor(np.log10(big)))
        bar *= 5 if 5 * bar <= big else (2 if 2 * bar <= big else 1)
    for i in np.flatnonzero(used | out | missing):
        pos = det[i] if np.isfinite(det[i]).all() else rep[i]
        _label(ax, str(ids[i]), pos, (4, 5), "red" if out[i] else "navy")
    pts = np.vstack([det[np.isfinite(det).all(axis=1)], rep[missing]])
    _zoom(ax, pts[:, 0], pts[:, 1])
    if big > 0:
        xl, yl = ax.get_xlim(), ax.get_ylim()
        bx = xl[0] + 0.04 * (xl[1] - xl[0])
        by = yl[1] + 0.05 * (yl[0] - yl[1])  # y axis inverted: yl = (bottom, top)
        ax.plot([bx, bx + bar * scale], [by, by], color="red", lw=2)
        ax.text(bx, by - 0.02 * (yl[0] - yl[1]), f"residual scale: {bar:g} px", color="red", fontsize=8,
                va="bottom", bbox=dict(facecolor="black", alpha=0.5, lw=0))
    flagged = json.loads(cal_ds.attrs.get("outlier_ids", "[]"))
    if flagged:
        ax.text(0.99, 0.01, "outliers: " + ", ".join(flagged), transform=ax.transAxes, ha="right", va="bottom",
                color="red", fontsize=7, bbox=dict(facecolor="black", alpha=0.5, lw=0))
    ax.legend(loc="upper right", fontsize=7, framealpha=0.6)
    return _save(fig, path)


# =========================================================================== results of an experiment

#: figures of :func:`plot_experiment`, by name (the strain figure needs fields.zarr)
FIGURES = ("temperature", "gradient", "rate", "history", "strain", "load")

_PANEL_IN = 4.2  # width of one map panel, inches
_DPI = 120


def _values(ds, name, time_index=None):
    da = ds[name]
    if time_index is not None and "time" in da.dims:
        da = da.isel(time=int(time_index))
    order = [d for d in ("point", "principal", "component", "axis") if d in da.dims]
    return np.asarray(da.transpose(*order, ...).values)


def _experiment_name(ds, experiment):
    if experiment:
        return str(experiment)
    return str(ds.attrs.get("experiment", "")) or "experiment"


def view_basis(points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal view axes of the IR camera's view of the points.

    An affine map ``x -> (u, v)`` is fitted by least squares to the projected
    positions (``pixel``) of the visible points at the time with the most of
    them; its rows give the 3-D directions in which u grows (right) and v
    shrinks (up). Without usable pixel positions the two main axes of the
    point cloud (PCA) are taken.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr`` (``x(time, point, component)`` mm, ``pixel(time, point, axis)`` px).

    Returns
    -------
    right, up : ndarray, shape (3,)
        Unit vectors (DIC frame) of the horizontal and vertical view axes.
    centre : ndarray, shape (3,)
        Centroid of the points, mm (origin of the view coordinates).
    """
    x_all = points["x"]
    n_t = points.sizes["time"]
    if "pixel" in points and "visible" in points:
        vis = np.asarray(points["visible"].transpose("time", "point").values, dtype=bool)
        k = int(np.argmax(vis.sum(axis=1)))
    else:
        vis, k = None, n_t // 2
    x = _values(points, "x", k).astype(float)
    ok = np.isfinite(x).all(axis=1)
    if not ok.any():
        finite = np.isfinite(np.asarray(x_all.transpose("time", "point", "component").values)).all(axis=2).sum(axis=1)
        k = int(np.argmax(finite))
        x = _values(points, "x", k).astype(float)
        ok = np.isfinite(x).all(axis=1)
    if ok.sum() < 3:
        raise DataError(f"the points store has {int(ok.sum())} points with coordinates at any time: nothing to draw")
    centre = x[ok].mean(axis=0)
    if vis is not None:
        pix = _values(points, "pixel", k).astype(float)
        use = ok & vis[k] & np.isfinite(pix).all(axis=1)
        if use.sum() >= 4:
            A = np.column_stack([x[use] - centre, np.ones(use.sum())])
            coef, *_ = np.linalg.lstsq(A, pix[use], rcond=None)
            gu, gv = coef[:3, 0], coef[:3, 1]
            if np.linalg.norm(np.cross(gu, gv)) > 1e-9 * np.linalg.norm(gu) * np.linalg.norm(gv):
                right = gu / np.linalg.norm(gu)
                down = gv - (gv @ right) * right
                return right, -down / np.linalg.norm(down), centre
    # no camera information: the two main axes of the cloud
    _, _, vt = np.linalg.svd(x[ok] - centre, full_matrices=False)
    return vt[0], vt[1], centre


class _View:
    """Projection of points and vectors onto the view plane (mm from the centre)."""

    def __init__(self, points):
        self.right, self.up, self.centre = view_basis(points)

    def xy(self, x):
        d = np.asarray(x, dtype=float) - self.centre
        return d @ self.right, d @ self.up

    def vec(self, g):
        g = np.asarray(g, dtype=float)
        return g @ self.right, g @ self.up


def _triangulation(px, py, values=None, max_edge_factor=2.5):
    """Delaunay triangles of the projected points, long ones (holes, concave outline) masked.

    Returns the triangulation (over the finite points), the index of those
    points, and a mask of triangles with a non-finite value at a vertex.
    """
    from matplotlib.tri import Triangulation

    ok = np.isfinite(px) & np.isfinite(py)
    idx = np.flatnonzero(ok)
    if idx.size < 3:
        return None, idx, None
    try:
        tri = Triangulation(px[idx], py[idx])
    except (ValueError, RuntimeError):  # collinear or degenerate points
        return None, idx, None
    t = tri.triangles
    e = np.stack([np.hypot(px[idx][t[:, a]] - px[idx][t[:, b]], py[idx][t[:, a]] - py[idx][t[:, b]])
                  for a, b in ((0, 1), (1, 2), (2, 0))], axis=1)
    long = e.max(axis=1) > max_edge_factor * np.median(e)
    tri.set_mask(long)
    novalue = None
    if values is not None:
        bad = ~np.isfinite(values[idx])
        novalue = bad[t].any(axis=1) & ~long
    return tri, idx, novalue


def _map(ax, view, x, values, *, cmap, norm, grey_missing=True, fit=False):
    """Surface coloured by ``values`` (gouraud over the triangulated points); grey where no value."""
    from matplotlib.collections import PolyCollection

    px, py = view.xy(x)
    tri, idx, novalue = _triangulation(px, py, values)
    if tri is None:
        return ax.scatter(px, py, c=values, cmap=cmap, norm=norm, s=4)
    t = tri.triangles
    if grey_missing and novalue.any():
        verts = np.stack([np.column_stack([tri.x[t[novalue, k]], tri.y[t[novalue, k]]]) for k in range(3)], axis=1)
        ax.add_collection(PolyCollection(verts, facecolors="0.82", edgecolors="0.82", linewidths=0.3, zorder=0))
    from matplotlib.tri import Triangulation

    shown = Triangulation(tri.x, tri.y, t, mask=tri.mask | novalue)
    v = np.where(np.isfinite(values[idx]), values[idx], 0.0)  # masked triangles are not drawn
    m = ax.tripcolor(shown, v, shading="gouraud", cmap=cmap, norm=norm, rasterized=True)
    if fit:
        _fit(ax, [(px, py)])
    return m


def _fit(ax, xys, margin=0.02):
    """Axis limits around all projected points (of every panel: the panels share their axes)."""
    px = np.concatenate([np.ravel(a) for a, _ in xys])
    py = np.concatenate([np.ravel(b) for _, b in xys])
    ok = np.isfinite(px) & np.isfinite(py)
    if not ok.any():
        return
    (x0, x1), (y0, y1) = (px[ok].min(), px[ok].max()), (py[ok].min(), py[ok].max())
    d = margin * max(x1 - x0, y1 - y0, 1e-9)
    ax.set_xlim(x0 - d, x1 + d)
    ax.set_ylim(y0 - d, y1 + d)


def _map_figure(n, view, xs, title):
    """A row of ``n`` equal-aspect map panels sized to the projected extent of ``xs``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    xys = [view.xy(x) for x in xs]
    w = h = 0.0
    for px, py in xys:
        if np.isfinite(px).any():
            w = max(w, np.nanmax(px) - np.nanmin(px))
            h = max(h, np.nanmax(py) - np.nanmin(py))
    aspect = float(np.clip(h / w, 0.4, 1.6)) if w > 0 and h > 0 else 1.0
    fig = Figure(figsize=(n * _PANEL_IN + 1.3, _PANEL_IN * aspect + 1.1), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(1, n, sharex=True, sharey=True, squeeze=False)[0])
    for ax in axes:
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("right in IR view (mm)")
        ax.tick_params(labelsize=8)
    axes[0].set_ylabel("up in IR view (mm)")
    _fit(axes[0], xys)
    fig.suptitle(title, fontsize=11)
    return fig, axes


def _limits(arrays, symmetric=False, pct=(0.5, 99.5)):
    a = np.concatenate([np.ravel(np.asarray(x, dtype=float)) for x in arrays])
    a = a[np.isfinite(a)]
    if a.size == 0:
        return (-1.0, 1.0) if symmetric else (0.0, 1.0)
    if symmetric:
        m = float(np.percentile(np.abs(a), pct[1]))
        m = m if m > 0 else 1.0
        return -m, m
    lo, hi = (float(v) for v in np.percentile(a, pct))
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi


def _norm(lo, hi):
    from matplotlib.colors import Normalize

    return Normalize(vmin=lo, vmax=hi)


def _time_indices(points, times):
    return select_times(points["time"].values, times, name="times")


def _unit_label(da, default):
    u = str(da.attrs.get("units", default))
    return {"degC": "°C", "1": "-"}.get(u, u)


def _pick(points, fields, name_fields, name_points):
    """(dataset, variable name, from fields?) of the first available source."""
    if fields is not None and name_fields in fields:
        return fields, name_fields, True
    if name_points is not None and name_points in points:
        return points, name_points, False
    return None, None, False


def _grid_sample(px, py, ok, n_across):
    """Indices of about ``n_across`` evenly spread points across the wider extent (one per cell)."""
    if not ok.any():
        return np.array([], dtype=int), 0.0
    xs, ys = px[ok], py[ok]
    span = max(np.ptp(xs), np.ptp(ys))
    if span <= 0:
        return np.flatnonzero(ok)[:1], 0.0
    cell = span / max(int(n_across), 1)
    ix = np.floor((xs - xs.min()) / cell).astype(int)
    iy = np.floor((ys - ys.min()) / cell).astype(int)
    cx = xs.min() + (ix + 0.5) * cell
    cy = ys.min() + (iy + 0.5) * cell
    d = np.hypot(xs - cx, ys - cy)
    key = ix * (iy.max() + 1) + iy
    order = np.lexsort((d, key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return np.flatnonzero(ok)[order[first]], cell


def _round_scale(v):
    """A round number (1, 2, 5 x 10^k) not larger than ``v``."""
    if not np.isfinite(v) or v <= 0:
        return 1.0
    e = 10.0 ** np.floor(np.log10(v))
    for m in (5.0, 2.0, 1.0):
        if m * e <= v:
            return m * e
    return e


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
    view = _View(points)
    idx = _time_indices(points, times)
    t = points["time"].values
    xs = [_values(points, "x", i) for i in idx]
    vals = [_values(points, "temperature", i).astype(float) for i in idx]
    name = _experiment_name(points, experiment)
    fig, axes = _map_figure(len(idx), view, xs, f"{name}: temperature on the surface (IR camera view)")
    norm = _norm(*_limits(vals))
    m = None
    for ax, i, x, v in zip(axes, idx, xs, vals):
        m = _map(ax, view, x, v, cmap="inferno", norm=norm)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
    cb = fig.colorbar(m, ax=list(axes), shrink=0.9, pad=0.02)
    cb.set_label(f"temperature ({_unit_label(points['temperature'], 'degC')})")
    _no_temperature_note(fig, xs, vals)
    return _save(fig, path)


def _note(fig, text):
    """A small grey note under the panels (space reserved by the constrained layout)."""
    fig.supxlabel(text, x=0.01, ha="left", fontsize=7, color="0.35")


def _no_temperature_note(fig, xs, vals):
    if any((np.isfinite(x).all(axis=1) & ~np.isfinite(v)).any() for x, v in zip(xs, vals)):
        _note(fig, "grey: no temperature (hidden, outside the IR image or the specimen mask)")


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
    view = _View(points)
    idx = _time_indices(points, times)
    t = points["time"].values
    name = _experiment_name(points, experiment)
    ds, var, surface = _pick(points, fields, "temperature_gradient", "temperature_pixel_gradient")
    if ds is None:
        raise DataError("neither fields.temperature_gradient nor points.temperature_pixel_gradient is available")
    unit = _unit_label(ds[var], "K/mm" if surface else "K/px")
    what = "in-plane temperature gradient" if surface else "temperature gradient in the IR image (no fields.zarr)"
    xs = [_values(points, "x", i) for i in idx]
    vals = [_values(points, "temperature", i).astype(float) for i in idx]
    vecs = []
    for i in idx:
        g = _values(ds, var, i).astype(float)
        if surface:
            vecs.append(view.vec(g))
        else:  # image plane: u right, v down
            vecs.append((g[:, 0], -g[:, 1]))
    fig, axes = _map_figure(len(idx), view, xs, f"{name}: temperature and {what}")
    norm = _norm(*_limits(vals))
    mags = np.concatenate([np.hypot(*vv) for vv in vecs])
    big = float(np.nanpercentile(mags, 98)) if np.isfinite(mags).any() else 0.0
    m = None
    for ax, i, x, v, (gx, gy) in zip(axes, idx, xs, vals, vecs):
        m = _map(ax, view, x, v, cmap="inferno", norm=norm)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
        px, py = view.xy(x)
        ok = np.isfinite(px) & np.isfinite(gx) & np.isfinite(gy) & np.isfinite(v)
        sel, cell = _grid_sample(px, py, ok, arrows)
        if not sel.size or not cell > 0 or not big > 0:
            continue
        scale = big / (0.9 * cell)  # the 98th-percentile gradient spans 0.9 grid cells
        q = ax.quiver(px[sel], py[sel], gx[sel], gy[sel], angles="xy", scale_units="xy", scale=scale,
                      color="cyan", width=0.004, headwidth=4, edgecolor="k", linewidth=0.3)
        key = _round_scale(big)
        ax.quiverkey(q, 0.80, 1.01, key, f"{key:g} {unit}", labelpos="E", coordinates="axes", fontproperties={"size": 8})
    cb = fig.colorbar(m, ax=list(axes), shrink=0.9, pad=0.02)
    cb.set_label(f"temperature ({_unit_label(points['temperature'], 'degC')})")
    _no_temperature_note(fig, xs, vals)
    return _save(fig, path)


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
    view = _View(points)
    idx = _time_indices(points, times)
    t = points["time"].values
    name = _experiment_name(points, experiment)
    ds, var, surface = _pick(points, fields, "temperature_rate", "temperature_local_rate")
    if ds is None:
        raise DataError("neither fields.temperature_rate nor points.temperature_local_rate is available")
    what = "material temperature rate" if surface else "local temperature rate at the fixed pixel (no fields.zarr)"
    xs = [_values(points, "x", i) for i in idx]
    vals = [_values(ds, var, i).astype(float) for i in idx]
    fig, axes = _map_figure(len(idx), view, xs, f"{name}: {what}")
    norm = _norm(*_limits(vals, symmetric=True, pct=(1, 99)))
    m = None
    for ax, i, x, v in zip(axes, idx, xs, vals):
        m = _map(ax, view, x, v, cmap="RdBu_r", norm=norm)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
    cb = fig.colorbar(m, ax=list(axes), shrink=0.9, pad=0.02, extend="both")
    cb.set_label(f"temperature rate ({_unit_label(ds[var], 'K/s')})")
    _no_temperature_note(fig, xs, vals)
    return _save(fig, path)


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
    view = _View(points if points is not None else fields)
    idx = _time_indices(fields, times)
    t = fields["time"].values
    name = _experiment_name(points if points is not None else fields, experiment)
    dname = next((d for d in ("principal_direction_current", "principal_direction") if d in fields), None)
    if dname is not None and fields[dname].shape[-1] != 3:
        warnings.warn(f"fields.{dname} has {fields[dname].shape[-1]} components ({fields[dname].dims[-1]}), "
                      "expected 3 (x, y, z): principal directions are not drawn", IrdicWarning, stacklevel=2)
        dname = None
    xs = [_values(fields, "x", i) for i in idx]
    vals = [100.0 * _values(fields, "max_principal_strain", i).astype(float) for i in idx]
    fig, axes = _map_figure(len(idx), view, xs, f"{name}: maximum principal Green-Lagrange strain and its direction")
    lo, hi = _limits(vals, pct=(1, 99))
    if lo < 0 < hi and min(-lo, hi) > 0.2 * max(-lo, hi):
        norm, cmap = _norm(*_limits(vals, symmetric=True, pct=(1, 99))), "RdBu_r"
    else:
        norm, cmap = _norm(lo, hi), "viridis"
    from matplotlib.collections import LineCollection

    m = None
    for ax, i, x, v in zip(axes, idx, xs, vals):
        m = _map(ax, view, x, v, cmap=cmap, norm=norm, grey_missing=False)
        ax.set_title(f"t = {t[i]:g} s", fontsize=10)
        if dname is None:
            continue
        d = np.asarray(fields[dname].isel(time=int(i)).transpose("point", "principal", ...).values,
                       dtype=float)[:, 0, :]  # principal = max
        dx, dy = view.vec(d)
        px, py = view.xy(x)
        ok = np.isfinite(px) & np.isfinite(dx) & np.isfinite(dy)
        sel, cell = _grid_sample(px, py, ok, segments)
        if not sel.size or not cell > 0:
            continue
        half = 0.4 * cell  # a unit vector in the view plane is 0.8 cells long
        segs = np.stack([np.column_stack([px[sel] - half * dx[sel], py[sel] - half * dy[sel]]),
                         np.column_stack([px[sel] + half * dx[sel], py[sel] + half * dy[sel]])], axis=1)
        ax.add_collection(LineCollection(segs, colors="k", linewidths=1.0))
    cb = fig.colorbar(m, ax=list(axes), shrink=0.9, pad=0.02)
    cb.set_label("max. principal strain E_max (%)")
    if dname is not None:
        _note(fig, "segments: direction of E_max (current configuration)" if dname.endswith("current")
              else "segments: direction of E_max (reference configuration)")
    return _save(fig, path)


def plot_history(points, path, *, fields=None, point_ids=None, experiment=None):
    """Temperature and temperature rate over time at chosen points, and where they are.

    Top: temperature (°C); hollow markers where the value is extrapolated
    from the specimen mask edge (status 1). Bottom: the material rate with
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
    name = _experiment_name(points, experiment)
    pos = {int(p): k for k, p in enumerate(points["point"].values)}
    sel = np.array([pos[int(p)] for p in ids])
    t = points["time"].values.astype(float)
    theta = np.asarray(points["temperature"].isel(point=sel).transpose("time", "point").values, dtype=float)
    status = (np.asarray(points["status"].isel(point=sel).transpose("time", "point").values)
              if "status" in points else np.zeros(theta.shape, dtype=np.int8))
    fig = Figure(figsize=(11.0, 6.2), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, 2, width_ratios=[2.0, 1.0])
    ax_t = fig.add_subplot(gs[0, 0])
    ax_r = fig.add_subplot(gs[1, 0], sharex=ax_t)
    ax_m = fig.add_subplot(gs[0, 1])
    ax_i = fig.add_subplot(gs[1, 1])
    colors = [f"C{k}" for k in range(ids.size)]
    for k, (pid, c) in enumerate(zip(ids, colors)):
        ax_t.plot(t, theta[:, k], "-", color=c, lw=1.2, label=f"point {pid}")
        inside = status[:, k] == 0
        ax_t.plot(t[inside], theta[inside, k], "o", color=c, ms=3)
        extra = status[:, k] == 1
        if extra.any():
            ax_t.plot(t[extra], theta[extra, k], "o", mfc="none", mec=c, ms=5,
                      label="extrapolated from the mask edge" if k == 0 else None)
    ax_t.set_ylabel(f"temperature ({_unit_label(points['temperature'], 'degC')})")
    ax_t.grid(True, alpha=0.3)
    ax_t.legend(fontsize=8, loc="best")
    ax_t.tick_params(labelbottom=False)
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
    ax_r.axhline(0.0, color="0.5", lw=0.6)
    ax_r.set_ylabel("temperature rate (K/s)")
    ax_r.set_xlabel("time (s)")
    ax_r.grid(True, alpha=0.3)
    if parts:  # above the axes: rate curves fill the whole box
        ax_r.legend(fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncols=len(parts), frameon=False)
    # where the points are
    view = _View(points)
    k_mid = int(np.clip(len(t) // 2, 0, len(t) - 1))
    x = _values(points, "x", k_mid)
    px, py = view.xy(x)
    v = _values(points, "temperature", k_mid).astype(float)
    m = _map(ax_m, view, x, v, cmap="inferno", norm=_norm(*_limits([v])), fit=True)
    for k, c in enumerate(colors):
        ax_m.plot(px[sel[k]], py[sel[k]], "o", mfc=c, mec="white", ms=8, mew=1.5)
        _label(ax_m, str(ids[k]), (px[sel[k]], py[sel[k]]), (6, 6), "k")
    ax_m.set_aspect("equal", adjustable="box")
    ax_m.set_title(f"position at t = {t[k_mid]:g} s (IR camera view)", fontsize=9)
    ax_m.set_xlabel("right in IR view (mm)")
    ax_m.set_ylabel("up in IR view (mm)")
    # an inset colour bar follows the equal-aspect map box (a layout colour bar would sit at the cell edge)
    cb = fig.colorbar(m, cax=ax_m.inset_axes([1.04, 0.0, 0.05, 1.0]))
    cb.set_label(f"temperature ({_unit_label(points['temperature'], 'degC')})", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    _history_summary(ax_i, points, ids, sel, theta, status, colors)
    fig.suptitle(f"{name}: temperature history at point{'s' if ids.size > 1 else ''} "
                 f"{', '.join(map(str, ids))}", fontsize=11)
    return _save(fig, path)


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
        lines.append((colors[k], f"point {pid}: x = ({ref[0]:.1f}, {ref[1]:.1f}, {ref[2]:.1f}) mm\n"
                                 f"  temperature at {int(has.sum())}/{n_t} times, "
                                 f"extrapolated at {int((status[:, k] == 1).sum())}\n  {rng}"))
    step = min(0.16, 1.0 / max(len(lines), 1))
    for k, (c, text) in enumerate(lines):
        ax.text(0.0, 1.0 - step * k, text, color=c, fontsize=8 if len(lines) < 5 else 6.5, va="top", ha="left",
                transform=ax.transAxes, family="monospace")


#: quantities the load figure puts on its horizontal axes, in this order
_LOAD_AXES = ("force", "displacement", "torque", "angle")


def _load_signals(fields) -> list[tuple[int, str]]:
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
    for q in _LOAD_AXES:
        cands = [j for j in range(n) if std[j] == q and count[j] > 0]
        if cands:
            picks.append(max(cands, key=lambda j: (count[j], -j)))
    if not picks:
        picks = [j for j in range(n) if std[j] not in ("time", "cycles") and count[j] > 0][:2]
    return [(j, f"{names[j]} ({unit[j]})" if unit[j] else names[j]) for j in picks]


def plot_load(points, path, *, fields=None, point_ids=None, experiment=None):
    """Temperature of the specimen region against the testing machine's signals.

    One column per load quantity found in ``fields.zarr``'s signals (force,
    displacement, torque, angle; see :func:`_load_signals`). Top: mean
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

    from .export import _aligned_fields

    name = _experiment_name(points, experiment)
    fields = _aligned_fields(points, fields)
    axes = _load_signals(fields)
    if not axes:
        fig = Figure(figsize=(7.0, 3.0), dpi=_DPI, layout="constrained")
        FigureCanvasAgg(fig)
        ax = fig.add_subplot(1, 1, 1)
        ax.axis("off")
        why = ("no fields.zarr" if fields is None else
               "the DIC exports carry no testing machine signals (nodemap SIGNALS) and no machine record "
               "is configured (experiments.<name>.machine)")
        ax.text(0.5, 0.5, f"{name}: no load figure\n{why}", ha="center", va="center", wrap=True, fontsize=10)
        return _save(fig, path)
    ids = select_points(points, list(point_ids)[:1] if point_ids is not None and len(point_ids) else None,
                        name="point_ids")
    pid = int(ids[0])
    theta = np.asarray(points["temperature"].transpose("time", "point").values, dtype=float)
    seen = np.isfinite(theta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # times without any temperature stay NaN
        t_mean, t_min, t_max = np.nanmean(theta, axis=1), np.nanmin(theta, axis=1), np.nanmax(theta, axis=1)
        rate = (np.asarray(fields["temperature_rate"].transpose("time", "point").values, dtype=float)
                if "temperature_rate" in fields else None)
        r_mean = np.nanmean(np.where(seen, rate, np.nan), axis=1) if rate is not None else None
    k = int(np.flatnonzero(points["point"].values == pid)[0])
    sig = np.asarray(fields["signal_value"].transpose("time", "signal").values, dtype=float)
    fig = Figure(figsize=(3.6 * len(axes) + 1.0, 6.4), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, len(axes))
    unit_t = _unit_label(points["temperature"], "degC")
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
    _note(fig, "mean, min, max over the points with a temperature (the specimen region seen by the IR camera); "
               "one marker per DIC time")
    fig.suptitle(f"{name}: temperature against load", fontsize=11)
    return _save(fig, path)


def plot_experiment(points, outdir, *, fields=None, times=None, point_ids=None, experiment=None,
                    names=None) -> dict[str, Path]:
    """All figures of one experiment.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    outdir : path-like or mapping of str to path-like
        Folder of the PNGs (``<outdir>/<name>.png``), or the path of each
        figure by name (keys of :data:`FIGURES`; then ``names`` are its keys).
    fields : xarray.Dataset, optional
        ``fields.zarr``; the strain and load figures need it.
    times, point_ids, experiment
        See the single figure functions.
    names : sequence of str, optional
        Figures to draw (keys of :data:`FIGURES`); default all that the data
        allow (no strain or load figure without ``fields``).

    Returns
    -------
    dict of str to pathlib.Path
    """
    if isinstance(outdir, Mapping):
        paths = {str(k): Path(v) for k, v in outdir.items()}
        names = list(paths)
    else:
        if names is None:
            names = [n for n in FIGURES if n not in ("strain", "load") or fields is not None]
        paths = {n: Path(outdir) / f"{n}.png" for n in names}
    unknown = [n for n in names if n not in FIGURES]
    if unknown:
        raise ConfigError(f"unknown figure(s) {', '.join(map(repr, unknown))}; known: {', '.join(FIGURES)}")
    done = {}
    for n in names:
        p = paths[n]
        if n == "temperature":
            done[n] = plot_temperature(points, p, times=times, experiment=experiment)
        elif n == "gradient":
            done[n] = plot_gradient(points, p, fields=fields, times=times, experiment=experiment)
        elif n == "rate":
            done[n] = plot_rate(points, p, fields=fields, times=times, experiment=experiment)
        elif n == "history":
            done[n] = plot_history(points, p, fields=fields, point_ids=point_ids, experiment=experiment)
        elif n == "load":
            done[n] = plot_load(points, p, fields=fields, point_ids=point_ids, experiment=experiment)
        else:
            done[n] = plot_strain(fields, p, points=points, times=times, experiment=experiment)
        log.info("figure %s -> %s", n, p)
    return done
