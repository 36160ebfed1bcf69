"""The calibration's summary for logs and the CLI, and its warnings (outliers, undetected markers)."""

from __future__ import annotations

import json
import logging
import warnings

import numpy as np
import xarray as xr

from ..camera import load_camera
from ..errors import IrdicWarning

__all__ = ["summarize", "report"]

log = logging.getLogger("irdic.calibration.solve")


def report(ds: xr.Dataset) -> None:
    """Warn about outliers and log undetected markers, unassigned detections and the summary."""
    if ds.attrs["n_outliers"]:
        flagged = ", ".join(json.loads(ds.attrs["outlier_ids"]))
        warnings.warn(f"calibration: markers {flagged} are outliers (large leave-one-out residual) "
                      "and were left out of the fit; check them in the calibration figure", IrdicWarning,
                      stacklevel=3)  # the caller of calibrate
    if ds.attrs["n_not_detected"]:
        log.warning("calibration: markers %s are in the image but were not detected",
                    ", ".join(json.loads(ds.attrs["not_detected_ids"])))
    if ds.attrs["n_unassigned"]:
        log.info("calibration: %d detections have no marker", ds.attrs["n_unassigned"])
    log.info("%s", summarize(ds))


def summarize(cal_ds: xr.Dataset) -> str:
    """A few lines for logs and the CLI: residuals, camera, flagged markers."""
    g = load_camera(cal_ds).decompose()
    a = cal_ds.attrs
    k = np.asarray(cal_ds["distortion"].values)
    lines = [
        f"IR camera calibration ({a.get('correspondence', '?')} correspondence): "
        f"{a.get('n_used', '?')} of {a.get('n_markers', '?')} markers used, "
        f"RMS {float(cal_ds['rms_px']):.3f} px, max {float(cal_ds['max_px']):.3f} px",
        f"camera centre ({', '.join(f'{c:.1f}' for c in g.C)}) mm, viewing direction "
        f"({', '.join(f'{c:.3f}' for c in g.viewing_direction)})",
        f"focal length {g.focal_length_px:.1f} px, IFOV {g.ifov_mrad:.4f} mrad, principal point "
        f"({g.principal_point[0]:.1f}, {g.principal_point[1]:.1f}) px, k1 {k[0]:.4g}, k2 {k[1]:.4g}",
    ]
    for key, label in (("outlier_ids", "outliers (not used)"), ("not_detected_ids", "not detected"),
                       ("not_measured_ids", "no DIC coordinates")):
        flagged = json.loads(a.get(key, "[]"))
        if flagged:
            lines.append(f"{label}: {', '.join(flagged)}")
    if a.get("n_unassigned"):
        lines.append(f"{a['n_unassigned']} detections without a marker")
    return "\n".join(lines)
