"""What every result figure shares: the IR camera view, triangulated colour maps, colour scales.

The surface is drawn as the IR camera sees it, orthographically and in mm:
the view axes are the directions in which the image coordinates u (right)
and -v (up) grow, fitted to the projected points (:func:`view_basis`).
Vectors (gradients, principal directions) are drawn projected onto that
view plane, so they are foreshortened where the surface turns away from the
camera. Points without a temperature are grey.

Matplotlib is used through its object interface with the Agg canvas, so no
global pyplot state or display is involved (safe in Snakemake jobs).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..selection import select_times

__all__ = ["PANEL_IN", "DPI", "save_figure", "annotate_point", "point_values", "experiment_name", "view_basis",
           "View", "triangulation", "draw_map", "fit_limits", "map_figure", "colour_limits", "colour_norm",
           "time_indices", "unit_label", "pick_source", "grid_sample", "round_scale", "note", "no_temperature_note",
           "noise_dominated", "map_caption", "NOISE_RATIO", "NOISE_NEIGHBOURS"]

PANEL_IN = 4.2  # width of one map panel, inches
DPI = 120


def annotate_point(ax, text, pos, offset, color):
    import matplotlib.patheffects as pe

    ax.annotate(text, pos, xytext=offset, textcoords="offset points", fontsize=6.5, color=color,
                path_effects=[pe.withStroke(linewidth=2, foreground="white")])


def save_figure(fig, path, caption: str | None = None) -> Path:
    """Write ``fig`` as PNG; a ``caption`` is drawn under the figure and stored as its ``Description``.

    The stored caption is what ``irdic report`` shows beside the figure, so
    the page and the image always say the same.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    metadata = None
    if caption:
        import textwrap

        width = max(60, int(fig.get_figwidth() * 15))  # characters of 7.5 pt text across the figure
        fig.text(0.01, 0.0, "\n".join(textwrap.wrap(caption, width)), ha="left", va="top", fontsize=7.5,
                 color="0.15")
        metadata = {"Description": caption}
    fig.savefig(os.fspath(p), bbox_inches="tight", metadata=metadata)
    return p


#: a map is called noise-dominated when the RMS difference of its values from the mean of their
#: NOISE_NEIGHBOURS nearest neighbours exceeds NOISE_RATIO times the map's 5-95 % range
NOISE_NEIGHBOURS, NOISE_RATIO = 6, 0.2


def noise_dominated(x, values) -> bool:
    """Whether a map of ``values`` at the points ``x`` is dominated by point-to-point noise.

    Parameters
    ----------
    x : ndarray, shape (N, 3)
        Point positions, mm (NaN rows are ignored).
    values : ndarray, shape (N,)
        The mapped quantity (NaN ignored).

    Returns
    -------
    bool
        False with fewer than 20 usable points or a constant map.

    Notes
    -----
    A spatial high-pass: with :math:`\\bar v_i` the mean over the
    :data:`NOISE_NEIGHBOURS` nearest neighbours of point :math:`i`, the
    roughness :math:`r = \\sqrt{\\langle (v_i - \\bar v_i)^2 \\rangle}` of
    a smooth field sampled at the DIC spacing is a small fraction of its
    range :math:`R = v_{95} - v_5`, while for uncorrelated noise of standard
    deviation :math:`\\sigma` it is :math:`r \\approx 1.08\\,\\sigma` with
    :math:`R \\approx 3.3\\,\\sigma`, :math:`r/R \\approx 0.33`. The map is
    flagged when :math:`r > 0.2\\,R`, i.e. roughly when the signal's range is
    below about twice the noise's standard deviation.
    """
    from scipy.spatial import cKDTree

    x = np.asarray(x, dtype=float)
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(x).all(axis=1) & np.isfinite(v)
    if ok.sum() < 20:
        return False
    x, v = x[ok], v[ok]
    spread = float(np.percentile(v, 95) - np.percentile(v, 5))
    if not spread > 0:
        return False
    _, nb = cKDTree(x).query(x, k=NOISE_NEIGHBOURS + 1)
    rough = float(np.sqrt(np.mean((v - v[nb[:, 1:]].mean(axis=1)) ** 2)))
    return rough > NOISE_RATIO * spread


def map_caption(what: str, name: str, times, xs, vals, *, unc=None, unit: str = "") -> str:
    """Caption of a map figure: what, at which times, in which configuration, and how far to trust it.

    Parameters
    ----------
    what, name : str
        What is drawn (with its unit) and the experiment's name.
    times : sequence of float
        Panel times, s.
    xs, vals : sequence of ndarray
        Point positions (N, 3) mm and mapped values (N,) per panel.
    unc : irdic.plot.uncertainty.Uncertainty, optional
        The values' standard uncertainty: the caption then gives it and calls
        a panel noise-dominated by it too (:mod:`irdic.plot.uncertainty`).
    unit : str
        Unit of ``vals`` (for the uncertainty sentence).
    """
    from .uncertainty import uncertainty_sentence

    t = ", ".join(f"{float(v):g}" for v in times)
    text = (f"{what} of experiment {name} at t = {t} s (DIC times), drawn on the current (deformed) surface as the "
            "IR camera sees it (orthographic, mm).")
    by_std, sentence = uncertainty_sentence(unc, times, vals, unit)
    rough = [f"{float(ti):g} s" for ti, x, v in zip(times, xs, vals) if noise_dominated(x, v)]
    if sentence:
        text += " " + sentence
    if by_std:
        why = ("most values lie within 2 standard uncertainties of zero" if unc.against == "zero"
               else "the standard uncertainty exceeds a fifth of the map's range")
        text = (f"Noise-dominated at t = {', '.join(by_std)}: {why}, so the pattern shown is mostly noise "
                "(smoothing: docs/parameters.md). " + text)
    elif rough and not sentence:  # the uncertainty, where known, is the better judge
        text = (f"Noise-dominated at t = {', '.join(rough)}: the point-to-point scatter exceeds a fifth of the "
                "map's range, so the pattern shown is mostly noise (smoothing: docs/parameters.md). " + text)
    return text


def point_values(ds, name, time_index=None):
    da = ds[name]
    if time_index is not None and "time" in da.dims:
        da = da.isel(time=int(time_index))
    order = [d for d in ("point", "principal", "component", "axis") if d in da.dims]
    return np.asarray(da.transpose(*order, ...).values)


def experiment_name(ds, experiment):
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
    x = point_values(points, "x", k).astype(float)
    ok = np.isfinite(x).all(axis=1)
    if not ok.any():
        finite = np.isfinite(np.asarray(x_all.transpose("time", "point", "component").values)).all(axis=2).sum(axis=1)
        k = int(np.argmax(finite))
        x = point_values(points, "x", k).astype(float)
        ok = np.isfinite(x).all(axis=1)
    if ok.sum() < 3:
        raise DataError(f"the points store has {int(ok.sum())} points with coordinates at any time: nothing to draw")
    centre = x[ok].mean(axis=0)
    if vis is not None:
        pix = point_values(points, "pixel", k).astype(float)
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


class View:
    """Projection of points and vectors onto the view plane (mm from the centre)."""

    def __init__(self, points):
        self.right, self.up, self.centre = view_basis(points)

    def xy(self, x):
        d = np.asarray(x, dtype=float) - self.centre
        return d @ self.right, d @ self.up

    def vec(self, g):
        g = np.asarray(g, dtype=float)
        return g @ self.right, g @ self.up


def triangulation(px, py, values=None, max_edge_factor=2.5):
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


def draw_map(ax, view, x, values, *, cmap, norm, grey_missing=True, fit=False):
    """Surface coloured by ``values`` (gouraud over the triangulated points); grey where no value."""
    from matplotlib.collections import PolyCollection

    px, py = view.xy(x)
    tri, idx, novalue = triangulation(px, py, values)
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
        fit_limits(ax, [(px, py)])
    return m


def fit_limits(ax, xys, margin=0.02):
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


def map_figure(n, view, xs, title):
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
    fig = Figure(figsize=(n * PANEL_IN + 1.3, PANEL_IN * aspect + 1.1), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(1, n, sharex=True, sharey=True, squeeze=False)[0])
    for ax in axes:
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("right in IR view (mm)")
        ax.tick_params(labelsize=8)
    axes[0].set_ylabel("up in IR view (mm)")
    fit_limits(axes[0], xys)
    fig.suptitle(title, fontsize=11)
    return fig, axes


def colour_limits(arrays, symmetric=False, pct=(0.5, 99.5)):
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


def colour_norm(lo, hi):
    from matplotlib.colors import Normalize

    return Normalize(vmin=lo, vmax=hi)


def time_indices(points, times):
    return select_times(points["time"].values, times, name="times")


def unit_label(da, default):
    u = str(da.attrs.get("units", default))
    return {"degC": "°C", "1": "-"}.get(u, u)


def pick_source(points, fields, name_fields, name_points):
    """(dataset, variable name, from fields?) of the first available source."""
    if fields is not None and name_fields in fields:
        return fields, name_fields, True
    if name_points is not None and name_points in points:
        return points, name_points, False
    return None, None, False


def grid_sample(px, py, ok, n_across):
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


def round_scale(v):
    """A round number (1, 2, 5 x 10^k) not larger than ``v``."""
    if not np.isfinite(v) or v <= 0:
        return 1.0
    e = 10.0 ** np.floor(np.log10(v))
    for m in (5.0, 2.0, 1.0):
        if m * e <= v:
            return m * e
    return e


def note(fig, text):
    """A small grey note under the panels (space reserved by the constrained layout)."""
    fig.supxlabel(text, x=0.01, ha="left", fontsize=7, color="0.35")


def no_temperature_note(fig, xs, vals):
    if any((np.isfinite(x).all(axis=1) & ~np.isfinite(v)).any() for x, v in zip(xs, vals)):
        note(fig, "grey: no temperature (hidden, outside the IR image or the specimen mask)")
