"""Calibration figures: the target image with detections, marker IDs and residuals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .maps import annotate_point, save_figure

__all__ = ["plot_calibration", "plot_detections", "FAINT_SNR"]


def _figure(image, title: str):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..validation import image_array

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
        annotate_point(ax, f"{ui:.0f},{vi:.0f}", (ui, vi), (-12, 7), "navy")
    _zoom(ax, u, v)
    return save_figure(fig, path)


#: contrast/noise below which a used marker is drawn as faint in :func:`plot_calibration`
FAINT_SNR = 10.0


#: caption of the calibration figure (drawn under it and stored in the PNG for the report page)
CAPTION = ("IR image of the reference object with every marker of the DIC export. Green circles: markers used "
           "for the projection matrix; red: outliers (leave-one-out residual above calibration.outlier_factor "
           "times the median); orange crosses: markers not found in the image, at their reprojected position; "
           "magenta squares: detections that match no marker. Arrows: reprojection residuals (detected minus "
           "reprojected), magnified as the scale bar says. The title gives the markers used, the RMS and largest "
           "residual (px), the focal length and the camera centre in the DIC frame: an RMS well below 0.1 px "
           "and a plausible camera position mean the calibration can be trusted.")


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
    # TODO(redesign): use irdic.camera.load_camera (breaks the import cycle calibrate -> plot)
    from ..camera import load_camera

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
        ax.quiver(rep[finite, 0], rep[finite, 1], res[finite, 0] * vector_length_px / big,
                  res[finite, 1] * vector_length_px / big, angles="xy", scale_units="xy", scale=1.0, color="red",
                  width=0.002)
    for i in np.flatnonzero(used | out | missing):
        pos = det[i] if np.isfinite(det[i]).all() else rep[i]
        annotate_point(ax, str(ids[i]), pos, (4, 5), "red" if out[i] else "navy")
    pts = np.vstack([det[np.isfinite(det).all(axis=1)], rep[missing]])
    _zoom(ax, pts[:, 0], pts[:, 1])
    if big > 0:
        _scale_bar(ax, big, vector_length_px / big)
    flagged = json.loads(cal_ds.attrs.get("outlier_ids", "[]"))
    if flagged:
        ax.text(0.99, 0.01, "outliers: " + ", ".join(flagged), transform=ax.transAxes, ha="right", va="bottom",
                color="red", fontsize=7, bbox=dict(facecolor="black", alpha=0.5, lw=0))
    ax.legend(loc="upper right", fontsize=7, framealpha=0.6)
    return save_figure(fig, path, caption=CAPTION)


def _scale_bar(ax, big, scale):
    """A bar of a round residual size near the largest one (``big``, px), drawn ``scale`` times longer."""
    bar = float(10 ** np.floor(np.log10(big)))
    bar *= 5 if 5 * bar <= big else (2 if 2 * bar <= big else 1)
    xl, yl = ax.get_xlim(), ax.get_ylim()
    bx = xl[0] + 0.04 * (xl[1] - xl[0])
    by = yl[1] + 0.05 * (yl[0] - yl[1])  # y axis inverted: yl = (bottom, top)
    ax.plot([bx, bx + bar * scale], [by, by], color="red", lw=2)
    ax.text(bx, by - 0.02 * (yl[0] - yl[1]), f"residual scale: {bar:g} px", color="red", fontsize=8,
            va="bottom", bbox=dict(facecolor="black", alpha=0.5, lw=0))
