"""Calibration of the IR camera in the DIC frame from one IR image of a 3-D target.

:func:`calibrate` detects the markers, pairs them with the marker IDs of the
DIC export (from seeds or automatically), fits the projection matrix (DLT,
then optionally a Levenberg-Marquardt refinement with radial distortion),
corrects the perspective bias of the imaged circle centres, flags outliers
by leave-one-out residuals and returns everything as one Dataset: the
content of ``results/setups/{setup}/calibration.zarr``. Later stages rebuild
the camera with :func:`irdic.camera.load_camera`.

The algorithm returns data only; :func:`calibrate_from_files` (the stage's
entry) also writes the store and the figure.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from pathlib import Path
from typing import Mapping

import numpy as np
import xarray as xr

from ..camera import CameraModel, fit_dlt, leave_one_out, planarity
from ..camera import refine as refine_camera
from ..camera.dlt import degeneracy
from ..errors import CalibrationError, ConfigError
from .bias import perspective_bias, plane_normals
from .correspondence import check_ids, propagate
from .dataset import STATUSES, calibration_dataset
from .detection import centre_covariances, centre_weights, detect_markers
from .guided import estimate_radius, find_missing
from .image import image_array, mean_frame
from .lattice import match_lattice
from .seeds import judge_pending, match_seeds_deferred, warn_seeds_off
from .summary import report, summarize

__all__ = ["calibrate", "summarize", "calibrate_from_files", "STATUSES", "MarkerTable", "FitOptions", "Solution",
           "calibration_dataset"]

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class MarkerTable:
    """The markers of the DIC export.

    Attributes
    ----------
    ids : ndarray, shape (M,)
        Marker IDs (unique).
    x : ndarray, shape (M, 3)
        Marker centres in the DIC frame, mm; NaN rows have no coordinates.
    measured : ndarray of int
        Indices of the markers with finite coordinates (the ones calibrated).
    """

    ids: np.ndarray
    x: np.ndarray
    measured: np.ndarray


@dataclasses.dataclass(frozen=True)
class FitOptions:
    """Settings of the camera fit and the outlier loop (see :func:`calibrate`)."""

    refine: bool
    distortion: str
    correct_bias: bool
    marker_radius_mm: float | None
    outlier_factor: float
    outlier_min_px: float
    max_outliers: int | None


@dataclasses.dataclass
class Solution:
    """The fitted camera and the per-marker quantities of the final fit.

    Marker indices are into the measured markers (:attr:`MarkerTable.measured`).

    Attributes
    ----------
    model : CameraModel
        Final camera.
    info : dict
        Fit summary (``rms_px``, ``sigma_px``, ``dlt_rms_px``, ...).
    marker_index, detection_index : ndarray of int
        Matched (marker, detection) pairs.
    how : str
        ``"seeds"`` or ``"automatic"`` correspondence.
    outliers : list of int
        Matched markers left out of the fit.
    bias : ndarray, shape (n_measured, 2)
        Perspective bias subtracted from the detections, px.
    loo : ndarray, shape (n_measured,)
        Leave-one-out residual, px (NaN where not matched).
    radius_mm : float or None
        Marker radius used for the bias correction, mm.
    """

    model: CameraModel
    info: dict
    marker_index: np.ndarray
    detection_index: np.ndarray
    how: str
    outliers: list
    bias: np.ndarray
    loo: np.ndarray
    radius_mm: float | None


def _marker_table(markers) -> MarkerTable:
    """The markers from a marker Dataset or an ``(ids, x)`` pair, refused when they cannot calibrate a camera."""
    if isinstance(markers, xr.Dataset):
        if "x" not in markers or "marker" not in markers["x"].dims:
            raise ConfigError("`markers` must be a Dataset with x(marker, component) in mm (see irdic.io.read_markers)")
        da = markers["x"]
        if "component" in da.dims:
            da = da.transpose("marker", "component")
        ids = np.asarray(markers["marker"].values)
        x = np.asarray(da.values, dtype=np.float64)
    elif isinstance(markers, (tuple, list)) and len(markers) == 2:
        ids = np.asarray(markers[0])
        try:
            x = np.asarray(markers[1], dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"marker coordinates must be numeric, {exc}") from None
    else:
        raise ConfigError("`markers` must be a Dataset x(marker, component) or a pair (ids, x) of arrays")
    if x.ndim != 2 or x.shape[1] != 3:
        raise ConfigError(f"marker coordinates must have shape (M, 3), got {x.shape}")
    if len(ids) != len(x):
        raise ConfigError(f"{len(ids)} marker IDs but {len(x)} coordinate rows")
    check_ids(ids)
    table = MarkerTable(ids=ids, x=x, measured=np.flatnonzero(np.isfinite(x).all(axis=1)))
    _check_layout(table.x[table.measured])
    return table


def _check_layout(x: np.ndarray) -> None:
    """CalibrationError when the measured markers ``x`` (n, 3) mm are too few, collinear or coplanar."""
    if len(x) < 6:
        raise CalibrationError(f"only {len(x)} markers have finite coordinates; the calibration needs 6")
    thick = planarity(x)
    line = degeneracy(x, "markers")
    if line is not None and "coplanar" not in line:
        raise CalibrationError(f"{line}: markers on a line do not determine a camera. Use a 3-D target (open "
                               "book) and export the markers of both wings")
    if thick < 1e-3:
        raise CalibrationError(
            f"the {len(x)} markers are coplanar (thickness ratio s3/s1 = {thick:.1e} of the centred marker "
            "cloud): one image of a planar target cannot calibrate a projection matrix. Use a 3-D target (open "
            "book) and export the markers of both wings"
        )


def _check_options(opts: FitOptions) -> None:
    if opts.distortion not in ("none", "k1", "k1k2"):
        raise ConfigError(f"`distortion` must be 'none', 'k1' or 'k1k2', got {opts.distortion!r}")
    if opts.distortion != "none" and not opts.refine:
        raise ConfigError("`distortion` needs `refine=True` (the DLT is a pinhole model)")
    r = opts.marker_radius_mm
    if r is not None and not (np.isfinite(r) and r > 0):
        raise ConfigError(f"`marker_radius_mm` must be a positive number (mm), got {r!r}")
    if not opts.outlier_factor > 1:
        raise ConfigError(f"`outlier_factor` must be > 1, got {opts.outlier_factor!r}")


def _sensor_size(target_image) -> tuple[int, int]:
    """Sensor width and height (px): the image's attrs, else the extent of its pixel coordinates."""
    img, u0, v0 = image_array(target_image)
    img_shape = img.shape
    attrs = getattr(target_image, "attrs", {}) or {}
    w = attrs.get("sensor_width")
    h = attrs.get("sensor_height")
    if w is None or h is None:
        return int(u0 + img_shape[1]), int(v0 + img_shape[0])
    return int(w), int(h)


def _fit(x, uv, opts: FitOptions, start: CameraModel | None = None, weights: np.ndarray | None = None,
         cov: np.ndarray | None = None):
    """DLT (and refinement) of the pairs ``x`` (n, 3) mm, ``uv`` (n, 2) px, each weighted by ``weights`` (1 / px).

    ``cov`` (n, 2, 2) px^2, the centres' covariances, shapes the refined
    camera's covariance (:func:`irdic.camera.refine`).

    ``info["sigma_px"]`` is the residual standard deviation per coordinate
    in px also with weights (the weighted fit's own is relative to them).
    """
    model, info = fit_dlt(x, uv, weights)
    dlt_rms = info["rms_px"]
    if opts.refine:
        model, info = refine_camera(start if start is not None else model, x, uv, distortion=opts.distortion,
                                    weights=weights, point_covariances=cov)
    info["dlt_rms_px"] = dlt_rms
    if weights is not None:
        dof = max(2 * len(x) - len(info.get("free", range(11))), 1)
        info["sigma_px"] = float(np.sqrt(np.sum(info["residuals"] ** 2) / dof))
    return model, info


def calibrate(target_image, markers, *, seeds: Mapping | None = None, polarity: str = "auto",
              distortion: str = "none", refine: bool = True, correct_bias: bool = True,
              marker_radius_mm: float | None = None, min_radius_px: float = 2.0, max_radius_px: float = 30.0,
              min_contrast_k: float = 0.1, outlier_factor: float = 5.0, outlier_min_px: float = 0.3,
              max_outliers: int | None = None, detections: xr.Dataset | None = None) -> xr.Dataset:
    """Calibrate the IR camera from one IR image of a 3-D marker target.

    Parameters
    ----------
    target_image : xarray.DataArray
        IR image of the target, dims ``("v", "u")``, °C, full-sensor pixel
        coordinates (``sensor_width``/``sensor_height`` attrs when cropped).
    markers : xarray.Dataset or (ids, x)
        Marker centres from DIC: ``x(marker, component)`` in mm with the
        marker IDs as coordinate (:func:`irdic.io.read_markers`), or a pair
        of arrays (ids (M,), x (M, 3)).
    seeds : mapping, optional
        ``{marker_id: (u, v)}`` approximate pixel positions of >= 6 markers;
        without seeds the correspondence is found automatically (grid
        targets) or a CalibrationError says which seeds to add.
    polarity : {"auto", "dark", "bright"}
        Markers colder or warmer than the target body (see
        :func:`irdic.calibration.detect_markers`).
    distortion : {"none", "k1", "k1k2"}
        Radial distortion coefficients to refine (needs ``refine``).
    refine : bool
        Levenberg-Marquardt refinement of the reprojection error after the DLT.
    correct_bias : bool
        Correct the perspective bias of the imaged circle centres.
    marker_radius_mm : float, optional
        Marker radius for the bias correction, mm; estimated from the image
        when not given, checked against the image when given.
    min_radius_px, max_radius_px, min_contrast_k : float
        Detection limits (px, px, K).
    outlier_factor : float
        A marker whose leave-one-out residual exceeds ``outlier_factor`` x the
        median (and ``outlier_min_px``) is an outlier and left out of the fit.
    outlier_min_px : float
        Smallest leave-one-out residual called an outlier, px.
    max_outliers : int, optional
        At most this many markers are removed (default: a quarter of them).
    detections : xarray.Dataset, optional
        Result of :func:`~irdic.calibration.detect_markers` (skips detection).

    Returns
    -------
    xarray.Dataset
        See :func:`calibration_dataset`.

    Raises
    ------
    CalibrationError
        No usable markers, fewer than 6 usable, coplanar markers, an uncertain
        correspondence, or ``marker_radius_mm`` contradicts the image.
    ConfigError
        Invalid arguments, unknown or contradictory seeds.
    DataError
        Duplicate marker IDs.
    """
    opts = FitOptions(refine, distortion, correct_bias, marker_radius_mm, outlier_factor, outlier_min_px,
                      max_outliers)
    _check_options(opts)
    table = _marker_table(markers)
    sensor = _sensor_size(target_image)
    limits = dict(min_radius_px=min_radius_px, max_radius_px=max_radius_px, min_contrast_k=min_contrast_k)
    det = detections if detections is not None else detect_markers(target_image, polarity=polarity, **limits)
    D = np.column_stack([det["u"].values, det["v"].values])
    if len(D) < 6:
        raise CalibrationError(f"only {len(D)} markers were detected in the target image; the calibration needs 6")
    det, sol = _solve_and_rematch(target_image, det, *_match(target_image, det, table, seeds, marker_radius_mm, limits),
                                  table, opts, marker_radius_mm, limits)
    warn_seeds_off(sol.model, table.x[table.measured], table.ids[table.measured], seeds, sol.info["rms_px"])
    settings = dict(polarity=det.attrs.get("polarity", polarity), distortion=distortion, refine=refine,
                    correct_bias=correct_bias, marker_radius_mm=marker_radius_mm, **limits,
                    outlier_factor=outlier_factor, outlier_min_px=outlier_min_px,
                    seeds={str(k): list(map(float, v)) for k, v in (seeds or {}).items()})
    ds = calibration_dataset(table, det, sol, sensor, settings)
    report(ds)
    return ds


def _match(target_image, det: xr.Dataset, table: MarkerTable, seeds: Mapping | None, radius_mm, limits: dict):
    """Detections (with the markers found at their predicted positions added), matched (measured marker,
    detection) index pairs, from seeds or automatically, and which way."""
    X = table.x[table.measured]
    D = np.column_stack([det["u"].values, det["v"].values])
    pending = None
    if seeds:
        mi, di, model, pending = match_seeds_deferred(D, X, table.ids[table.measured], seeds)
        how = "seeds"
    else:
        mi, di, model = match_lattice(D, X)
        how = "automatic"
    # faint markers on a steep wing escape the detector: the first camera says where to look
    det, mi, di, _ = find_missing(target_image, det, X, mi, di, model, radius_mm=radius_mm, **limits)
    # a seed that the camera of the other seeds misses is judged by that of every matched marker
    judge_pending(pending, X, np.column_stack([det["u"].values, det["v"].values]), mi, di)
    log.info("correspondence (%s): %d of %d markers matched to %d detections", how, len(mi), len(X),
             det.sizes["detection"])
    return det, mi, di, how


def _solve_and_rematch(target_image, raw: xr.Dataset, det: xr.Dataset, mi, di, how: str, table: MarkerTable,
                       opts: FitOptions, radius_mm, limits: dict) -> tuple[xr.Dataset, Solution]:
    """The fit of the matched pairs (:func:`_solve`) and, where more than 2 (and 5 %) of the markers are
    outliers or unmatched in the image, the fit of the correspondence grown again from its camera over the
    ``raw`` detections, when that uses more markers.

    The first correspondence grows from the camera of a few seeds (or of a
    lattice guess); a slip there on a steep, faint wing leaves wrong pairs,
    which the fit drops as outliers, and markers that the guided search did
    not find with that camera. The fitted camera predicts every marker far
    better (noise field 49 of the calibration benchmark, oblique,
    contrast/noise 6, 4 K: 65 of 84 matched, 11 outliers, 0.134 px from the
    true camera; grown again from the fit, 84 matched, no outlier, 0.047 px).
    """
    X, ids = table.x[table.measured], table.ids[table.measured]
    sol = _solve(X, np.column_stack([det["u"].values, det["v"].values]), det, mi, di, how, opts, ids)
    img, u0, v0 = image_array(target_image)
    uv = sol.model.project(X) - [u0, v0]
    unmatched = np.isin(np.arange(len(X)), mi, invert=True) & (uv >= 0).all(axis=1) & (uv < img.shape[::-1]).all(1)
    # a few outliers or unfound markers are bad markers (the same again, at ~1 s); a slip leaves many
    if len(sol.outliers) + unmatched.sum() <= max(2, len(X) // 20):
        return det, sol
    D = np.column_stack([raw["u"].values, raw["v"].values])
    try:
        mi2, di2, model = propagate(sol.model, X, D)
        det2, mi2, di2, _ = find_missing(target_image, raw, X, mi2, di2, model, radius_mm=radius_mm, **limits)
        sol2 = _solve(X, np.column_stack([det2["u"].values, det2["v"].values]), det2, mi2, di2, how, opts, ids)
    except CalibrationError:
        return det, sol
    if len(sol2.marker_index) - len(sol2.outliers) <= len(sol.marker_index) - len(sol.outliers):
        return det, sol
    log.info("correspondence grown again from the fitted camera: %d markers used instead of %d",
             len(sol2.marker_index) - len(sol2.outliers), len(sol.marker_index) - len(sol.outliers))
    return det2, sol2


def _solve(X: np.ndarray, D: np.ndarray, det: xr.Dataset, mi: np.ndarray, di: np.ndarray, how: str,
           opts: FitOptions, ids: np.ndarray) -> Solution:
    """Fit the camera to the matched pairs, correct the bias and remove outliers one at a time.

    ``X`` (n, 3) mm are the measured markers with IDs ``ids``, ``D`` (d, 2)
    px the detections, ``mi``/``di`` the matched pairs.
    """
    normals = plane_normals(X) if opts.correct_bias else None
    radius = opts.marker_radius_mm
    bias = np.zeros((len(X), 2))
    outliers: list[int] = []  # indices into X
    limit = opts.max_outliers if opts.max_outliers is not None else max(1, len(mi) // 4)
    loo = np.full(len(X), np.nan)
    wdet, cdet = centre_weights(det), centre_covariances(det)
    for _ in range(limit + 1):
        use = np.array([m for m in mi if m not in outliers])
        duse = np.array([d for m, d in zip(mi, di) if m not in outliers])
        w = None if wdet is None else wdet[duse]
        c = None if cdet is None else cdet[duse]
        if len(use) < 6:
            raise CalibrationError(f"only {len(use)} markers are left after removing outliers; the calibration needs 6")
        model, info = _fit(X[use], D[duse] - bias[use], opts, weights=w, cov=c)
        if opts.correct_bias:
            if radius is None:
                radius = estimate_radius(model, X[use], det, duse)
                log.info("marker radius estimated from the image: %.3f mm", radius)
            # the bias depends on the camera only weakly: two rounds converge
            for _ in range(2):
                bias = perspective_bias(model, X, normals, radius)
                model, info = _fit(X[use], D[duse] - bias[use], opts, start=model, weights=w, cov=c)
        loo[:] = np.nan
        # the DLT's leave-one-out residuals (a fraction of the refined fits' cost) settle a clear outlier
        clear = _clear_outlier(X[use], D[duse] - bias[use], w, opts) if opts.refine and len(use) > 7 else None
        if clear is not None and len(outliers) < limit:
            worst = use[clear]
            outliers.append(int(worst))
            log.info("marker %s is an outlier (the DLT's leave-one-out residual over %g x its threshold); refitting "
                     "without it", ids[worst], CLEAR_OUTLIER)
            continue
        loo[use] = leave_one_out(X[use], D[duse] - bias[use], method="refine" if opts.refine else "dlt",
                                 distortion=opts.distortion, start=model if opts.refine else None, weights=w)
        thr = max(opts.outlier_factor * float(np.nanmedian(loo[use])), opts.outlier_min_px)
        worst = use[int(np.nanargmax(loo[use]))]
        if not loo[worst] > thr or len(outliers) >= limit or len(use) <= 7:
            break
        outliers.append(int(worst))
        log.info("marker %s is an outlier (leave-one-out %.3f px > %.3f px); refitting without it",
                 ids[worst], loo[worst], thr)
    # an outlier is not in the final fit: its residual there is its leave-one-out residual
    for m, d in zip(mi, di):
        if m in outliers:
            loo[m] = float(np.hypot(*(D[d] - bias[m] - model.project(X[m]))))
    return Solution(model=model, info=info, marker_index=mi, detection_index=di, how=how, outliers=outliers,
                    bias=bias, loo=loo, radius_mm=radius)


#: a DLT leave-one-out residual this many times the outlier threshold marks an outlier without the refined fits
CLEAR_OUTLIER = 1.5


def _clear_outlier(x, uv, w, opts: FitOptions) -> int | None:
    """Index of the pair whose leave-one-out residual of the DLT exceeds :data:`CLEAR_OUTLIER` x the outlier
    threshold on those residuals, or None (then the refined fits' leave-one-out residuals decide).

    Each refined leave-one-out fit is a Levenberg-Marquardt run, and the
    outliers are removed one at a time: a correspondence that slipped on a
    steep wing (11 wrong pairs of 65) took 4.6 s of CPU in them. The DLT's
    leave-one-out residuals are SVDs; a pair far beyond the threshold on
    them is an outlier on the refined ones too, and the last, borderline
    decision and the stored residuals stay the refined fits'.
    """
    loo = leave_one_out(x, uv, method="dlt", weights=w)
    if not np.isfinite(loo).any():
        return None
    i = int(np.nanargmax(loo))
    return i if loo[i] > CLEAR_OUTLIER * max(opts.outlier_factor * float(np.nanmedian(loo)), opts.outlier_min_px) else None


def calibrate_from_files(markers_path: str | os.PathLike, target_path: str | os.PathLike,
                         store: str | os.PathLike, figure: str | os.PathLike | None = None, *,
                         target_format: str = "auto", seeds: Mapping | None = None, **settings) -> Path:
    """Read the marker export and the target image, calibrate, write the store and the figure.

    When the calibration fails after the detection (correspondence), the
    figure shows the detections with their pixel positions, so that seeds can
    be read off it, and the error is raised again.

    Parameters
    ----------
    markers_path, target_path : path-like
        Marker centres export and IR image of the target.
    store : path-like
        ``calibration.zarr`` to write.
    figure : path-like, optional
        PNG (see :func:`irdic.plot.plot_calibration`).
    target_format : str
        Format of the target image (see :func:`irdic.io.read_ir`).
    seeds : mapping, optional
    **settings
        Keyword arguments of :func:`calibrate`.

    Returns
    -------
    pathlib.Path
        ``store``.
    """
    from ..io import read_ir, read_markers
    from ..store import write_dataset

    mk = read_markers(markers_path)
    image = read_ir(target_path, format=target_format)
    if "time" in image.dims and image.sizes["time"] > 1:
        log.info("target image has %d frames: calibrating on their mean", image.sizes["time"])
    # the frames of a still target average its noise down; a moving one is refused
    image = mean_frame(image, where=f"{target_path}: ")
    kw = {k: v for k, v in settings.items() if k in ("min_radius_px", "max_radius_px", "min_contrast_k")}
    det = detect_markers(image, polarity=settings.get("polarity", "auto"), **kw)
    try:
        cal = calibrate(image, mk, seeds=seeds or None, detections=det, **settings)
    except (CalibrationError, ConfigError):
        if figure is not None:
            # plot draws calibrations, so it is imported here, not at module level (no import cycle)
            from ..plot import plot_detections

            plot_detections(det, image, figure)
            log.error("calibration failed; the detections are drawn in %s (read seed positions off it)", figure)
        raise
    params = dict(settings, seeds={str(k): v for k, v in (seeds or {}).items()}, target_format=target_format)
    write_dataset(cal, store, stage="calibrate", params=params, inputs=[markers_path, target_path])
    if figure is not None:
        from ..plot import plot_calibration

        plot_calibration(cal, image, figure)
    return Path(store)
