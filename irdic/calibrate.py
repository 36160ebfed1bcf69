"""Calibration stage: the IR camera in the DIC frame from one IR image of a 3-D target.

:func:`calibrate` detects the markers, pairs them with the marker IDs of the
DIC export (from seeds or automatically), fits the projection matrix (DLT,
then optionally a Levenberg-Marquardt refinement with radial distortion),
corrects the perspective bias of the imaged circle centres, flags outliers
by leave-one-out residuals and returns everything as one Dataset: the
content of ``results/setups/{setup}/calibration.zarr``. Later stages rebuild
the camera with :func:`load_camera`.
"""

from __future__ import annotations

import json
import logging
import os
import warnings
from pathlib import Path
from typing import Mapping

import numpy as np
import xarray as xr

from . import camera as _camera
from .camera import CameraModel, degeneracy, fit_dlt, leave_one_out, planarity
from .errors import CalibrationError, ConfigError, IrdicWarning
from .markers import (check_ids, detect_markers, image_array, match_lattice, match_seeds, perspective_bias,
                      plane_normals)

__all__ = ["calibrate", "load_camera", "summarize", "calibrate_from_files", "STATUSES"]

log = logging.getLogger(__name__)

#: Values of the ``status(marker)`` variable.
STATUSES = ("used", "not_detected", "outlier", "outside_image", "not_measured")


def _marker_table(markers) -> tuple[np.ndarray, np.ndarray]:
    """(ids (M,), x (M, 3) mm) from a marker Dataset or an ``(ids, x)`` pair."""
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
    return ids, x


def _sensor_size(target_image, img_shape, u0, v0) -> tuple[int, int]:
    attrs = getattr(target_image, "attrs", {}) or {}
    w = attrs.get("sensor_width")
    h = attrs.get("sensor_height")
    if w is None or h is None:
        return int(u0 + img_shape[1]), int(v0 + img_shape[0])
    return int(w), int(h)


def _fit(x, uv, *, refine: bool, distortion: str, start: CameraModel | None = None):
    model, info = fit_dlt(x, uv)
    dlt_rms = info["rms_px"]
    if refine:
        model, info = _camera.refine(start if start is not None else model, x, uv, distortion=distortion)
    info["dlt_rms_px"] = dlt_rms
    return model, info


def _estimate_radius(model: CameraModel, x: np.ndarray, det: xr.Dataset, di: np.ndarray) -> float:
    """Marker radius (mm) from the detected size: half-contrast radius / sqrt(axis ratio) x depth / f."""
    q = np.clip(det["semi_minor_px"].values[di] / det["semi_major_px"].values[di], 0.2, 1.0)
    a_px = det["radius_px"].values[di] / np.sqrt(q)
    f = model.decompose().focal_length_px
    return float(np.median(a_px * model.depth(x) / f))


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
        :func:`irdic.markers.detect_markers`).
    distortion : {"none", "k1", "k1k2"}
        Radial distortion coefficients to refine (needs ``refine``).
    refine : bool
        Levenberg-Marquardt refinement of the reprojection error after the DLT.
    correct_bias : bool
        Correct the perspective bias of the imaged circle centres.
    marker_radius_mm : float, optional
        Marker radius for the bias correction, mm; estimated from the image
        when not given.
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
        Result of :func:`~irdic.markers.detect_markers` (skips detection).

    Returns
    -------
    xarray.Dataset
        Camera: ``projection_matrix(row, col)``, ``K``, ``R`` (``row3, col3``),
        ``camera_centre(component)``, ``viewing_direction``,
        ``principal_point(axis)``, ``focal_length_px``, ``ifov_mrad``,
        ``distortion(coefficient)``, ``covariance(parameter, parameter_2)``.
        Markers (dim ``marker``): ``marker_x(marker, component)``,
        ``detected(marker, axis)`` (raw detection, NaN if none),
        ``bias_correction(marker, axis)`` (subtracted from ``detected``),
        ``reprojected``, ``residual`` (= detected - bias_correction -
        reprojected), ``residual_norm``, ``loo_residual``,
        ``projection_uncertainty``, ``status``, ``detection_index``,
        ``marker_radius_px``, ``marker_contrast_k``, ``marker_snr`` (contrast /
        pixel noise). Detections without a
        marker: ``unassigned_uv(unassigned, axis)``. Scalars ``rms_px``,
        ``max_px`` over the used markers. Attributes: ``method``,
        ``settings`` (JSON), ``sensor_width``, ``sensor_height``, counts and
        the IDs of flagged markers.

    Raises
    ------
    CalibrationError
        The image shows no usable markers, fewer than 6 markers can be used,
        the markers are coplanar, or the correspondence is uncertain.
    ConfigError
        Invalid arguments, unknown or contradictory seeds.
    DataError
        Duplicate marker IDs.
    """
    if distortion not in ("none", "k1", "k1k2"):
        raise ConfigError(f"`distortion` must be 'none', 'k1' or 'k1k2', got {distortion!r}")
    if distortion != "none" and not refine:
        raise ConfigError("`distortion` needs `refine=True` (the DLT is a pinhole model)")
    if marker_radius_mm is not None and not (np.isfinite(marker_radius_mm) and marker_radius_mm > 0):
        raise ConfigError(f"`marker_radius_mm` must be a positive number (mm), got {marker_radius_mm!r}")
    if not outlier_factor > 1:
        raise ConfigError(f"`outlier_factor` must be > 1, got {outlier_factor!r}")
    ids, X_all = _marker_table(markers)
    measured = np.isfinite(X_all).all(axis=1)
    if measured.sum() < 6:
        raise CalibrationError(f"only {measured.sum()} markers have finite coordinates; the calibration needs 6")
    thick = planarity(X_all[measured])
    line = degeneracy(X_all[measured], "markers")
    if line is not None and "coplanar" not in line:
        raise CalibrationError(f"{line}: markers on a line do not determine a camera. Use a 3-D target (open "
                               "book) and export the markers of both wings")
    if thick < 1e-3:
        raise CalibrationError(
            f"the {measured.sum()} markers are coplanar (thickness ratio s3/s1 = {thick:.1e} of the centred marker "
            "cloud): one image of a planar target cannot calibrate a projection matrix. Use a 3-D target (open "
            "book) and export the markers of both wings"
        )
    img, u0, v0 = image_array(target_image)
    width, height = _sensor_size(target_image, img.shape, u0, v0)
    det = detections if detections is not None else detect_markers(
        target_image, polarity=polarity, min_radius_px=min_radius_px, max_radius_px=max_radius_px,
        min_contrast_k=min_contrast_k)
    D = np.column_stack([det["u"].values, det["v"].values])
    if len(D) < 6:
        raise CalibrationError(f"only {len(D)} markers were detected in the target image; the calibration needs 6")

    # correspondence on the measured markers
    vidx = np.flatnonzero(measured)
    X = X_all[vidx]
    if seeds:
        mi, di, model = match_seeds(D, X, ids[vidx], seeds)
        how = "seeds"
    else:
        mi, di, model = match_lattice(D, X)
        how = "automatic"
    log.info("correspondence (%s): %d of %d markers matched to %d detections", how, len(mi), len(X), len(D))

    normals = plane_normals(X) if correct_bias else None
    radius = marker_radius_mm
    bias = np.zeros((len(X), 2))
    outliers: list[int] = []  # indices into X
    limit = max_outliers if max_outliers is not None else max(1, len(mi) // 4)
    loo = np.full(len(X), np.nan)
    start = None
    for _ in range(limit + 1):
        use = np.array([m for m in mi if m not in outliers])
        duse = np.array([d for m, d in zip(mi, di) if m not in outliers])
        if len(use) < 6:
            raise CalibrationError(f"only {len(use)} markers are left after removing outliers; the calibration needs 6")
        model, info = _fit(X[use], D[duse] - bias[use], refine=refine, distortion=distortion)
        if correct_bias:
            if radius is None:
                radius = _estimate_radius(model, X[use], det, duse)
                log.info("marker radius estimated from the image: %.3f mm", radius)
            # the bias depends on the camera only weakly: two rounds converge
            for _ in range(2):
                bias = perspective_bias(model, X, normals, radius)
                model, info = _fit(X[use], D[duse] - bias[use], refine=refine, distortion=distortion, start=model)
        method = "refine" if refine else "dlt"
        loo[:] = np.nan
        loo[use] = leave_one_out(X[use], D[duse] - bias[use], method=method, distortion=distortion,
                                 start=model if refine else None)
        med = float(np.nanmedian(loo[use]))
        thr = max(outlier_factor * med, outlier_min_px)
        worst = use[int(np.nanargmax(loo[use]))]
        if not loo[worst] > thr or len(outliers) >= limit or len(use) <= 7:
            break
        outliers.append(int(worst))
        log.info("marker %s is an outlier (leave-one-out %.3f px > %.3f px); refitting without it",
                 ids[vidx][worst], loo[worst], thr)
    # an outlier is not in the final fit: its residual there is its leave-one-out residual
    for m, d in zip(mi, di):
        if m in outliers:
            loo[m] = float(np.hypot(*(D[d] - bias[m] - model.project(X[m]))))
    return _result(target_image, ids, X_all, vidx, D, det, mi, di, outliers, model, info, bias, loo,
                   width=width, height=height, how=how, radius=radius,
                   settings=dict(polarity=det.attrs.get("polarity", polarity), distortion=distortion, refine=refine,
                                 correct_bias=correct_bias, marker_radius_mm=marker_radius_mm,
                                 min_radius_px=min_radius_px, max_radius_px=max_radius_px,
                                 min_contrast_k=min_contrast_k, outlier_factor=outlier_factor,
                                 outlier_min_px=outlier_min_px,
                                 seeds={str(k): list(map(float, v)) for k, v in (seeds or {}).items()}))


def _result(target_image, ids, X_all, vidx, D, det, mi, di, outliers, model, info, bias, loo, *,
            width, height, how, radius, settings) -> xr.Dataset:
    n = len(ids)
    status = np.array(["not_measured"] * n, dtype=object)
    status[vidx] = "not_detected"
    detected = np.full((n, 2), np.nan)
    det_index = np.full(n, -1, dtype=np.int64)
    bias_all = np.zeros((n, 2))
    bias_all[vidx] = bias
    loo_all = np.full(n, np.nan)
    loo_all[vidx] = loo
    for m, d in zip(mi, di):
        g = vidx[m]
        detected[g] = D[d]
        det_index[g] = d
        status[g] = "outlier" if m in outliers else "used"
    reproj = np.full((n, 2), np.nan)
    reproj[vidx] = model.project(X_all[vidx])
    inside = np.isfinite(reproj).all(axis=1)
    inside[inside] = ((reproj[inside] >= -0.5) & (reproj[inside] <= [width - 0.5, height - 0.5])).all(axis=1)
    status[(status == "not_detected") & ~inside] = "outside_image"
    residual = detected - bias_all - reproj
    rnorm = np.hypot(residual[:, 0], residual[:, 1])
    used = status == "used"
    unc = np.full(n, np.nan)
    unc[vidx] = model.projection_uncertainty(X_all[vidx])
    radius_px = np.full(n, np.nan)
    contrast = np.full(n, np.nan)
    has = det_index >= 0
    radius_px[has] = det["radius_px"].values[det_index[has]]
    contrast[has] = det["contrast_k"].values[det_index[has]]
    snr = np.full(n, np.nan)
    if "snr" in det:
        snr[has] = det["snr"].values[det_index[has]]
    unassigned = np.setdiff1d(np.arange(len(D)), di)
    ds = model.to_dataset()
    px = {"units": "px"}
    ds = ds.assign_coords(marker=np.asarray(ids), detection_unassigned=("unassigned", unassigned))
    ds["marker_x"] = (("marker", "component"), X_all, {"units": "mm", "long_name": "marker centre (DIC frame)"})
    ds["detected"] = (("marker", "axis"), detected, {**px, "long_name": "detected marker centre (raw)"})
    ds["bias_correction"] = (("marker", "axis"), bias_all,
                             {**px, "long_name": "perspective bias subtracted from the detected centre"})
    ds["reprojected"] = (("marker", "axis"), reproj, {**px, "long_name": "projection of the marker centre"})
    ds["residual"] = (("marker", "axis"), residual,
                      {**px, "long_name": "detected - bias_correction - reprojected"})
    ds["residual_norm"] = (("marker",), rnorm, {**px, "long_name": "length of the residual"})
    ds["loo_residual"] = (("marker",), loo_all, {**px, "long_name": "residual when left out of the fit"})
    ds["projection_uncertainty"] = (("marker",), unc,
                                    {**px, "long_name": "standard uncertainty of the projection (from covariance)"})
    ds["status"] = (("marker",), status.astype(str), {"long_name": "used / not_detected / outlier / "
                                                                    "outside_image / not_measured"})
    ds["detection_index"] = (("marker",), det_index, {"long_name": "index into the detections (-1: none)"})
    ds["marker_radius_px"] = (("marker",), radius_px, {**px, "long_name": "detected radius"})
    ds["marker_contrast_k"] = (("marker",), contrast, {"units": "K", "long_name": "detected contrast"})
    ds["marker_snr"] = (("marker",), snr, {"units": "1", "long_name": "detected contrast / pixel noise"})
    ds["unassigned_uv"] = (("unassigned", "axis"), D[unassigned].reshape(-1, 2),
                           {**px, "long_name": "detections not assigned to any marker"})
    rms = float(np.sqrt(np.mean(rnorm[used] ** 2)))
    ds["rms_px"] = ((), rms, {**px, "long_name": "RMS reprojection residual of the used markers"})
    ds["max_px"] = ((), float(rnorm[used].max()), {**px, "long_name": "largest reprojection residual (used)"})

    def id_list(mask):
        return json.dumps([str(i) for i in np.asarray(ids)[mask]])

    refine, distortion = settings["refine"], settings["distortion"]
    method = "Hartley-normalised DLT (SVD)"
    if refine:
        method += f" + Levenberg-Marquardt refinement of the reprojection error (distortion: {distortion})"
    if settings["correct_bias"]:
        method += " + perspective bias correction of the circle centres"
    ds.attrs.update(
        method=method,
        correspondence=how,
        settings=json.dumps(settings, sort_keys=True),
        sensor_width=int(width),
        sensor_height=int(height),
        n_markers=int(n),
        n_detections=int(len(D)),
        n_used=int(used.sum()),
        n_not_detected=int((status == "not_detected").sum()),
        n_outside_image=int((status == "outside_image").sum()),
        n_not_measured=int((status == "not_measured").sum()),
        n_outliers=int((status == "outlier").sum()),
        n_unassigned=int(len(unassigned)),
        not_detected_ids=id_list(status == "not_detected"),
        outlier_ids=id_list(status == "outlier"),
        outside_image_ids=id_list(status == "outside_image"),
        not_measured_ids=id_list(status == "not_measured"),
        polarity=str(det.attrs.get("polarity", settings["polarity"])),
        noise_k=float(det.attrs.get("noise_k", np.nan)),
        marker_radius_mm=float(radius) if radius is not None else float("nan"),
        dlt_rms_px=float(info.get("dlt_rms_px", np.nan)),
        sigma_px=float(info.get("sigma_px", np.nan)),
    )
    if (status == "outlier").any():
        flagged = ", ".join(json.loads(ds.attrs["outlier_ids"]))
        warnings.warn(f"calibration: markers {flagged} are outliers (large leave-one-out residual) "
                      "and were left out of the fit; check them in the calibration figure", IrdicWarning,
                      stacklevel=3)
    if (status == "not_detected").any():
        log.warning("calibration: markers %s are in the image but were not detected",
                    ", ".join(json.loads(ds.attrs["not_detected_ids"])))
    if len(unassigned):
        log.info("calibration: %d detections have no marker", len(unassigned))
    log.info("%s", summarize(ds))
    return ds


def load_camera(cal_ds: xr.Dataset) -> CameraModel:
    """The calibrated :class:`~irdic.camera.CameraModel` from a calibration dataset/store."""
    return CameraModel.from_dataset(cal_ds)


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
    from .io import read_ir, read_markers
    from .store import write_dataset

    mk = read_markers(markers_path)
    image = read_ir(target_path, format=target_format)
    if "time" in image.dims:
        if image.sizes["time"] > 1:
            log.info("target image has %d frames: calibrating on their mean", image.sizes["time"])
        image = image.mean("time", keep_attrs=True)
    kw = {k: v for k, v in settings.items() if k in ("min_radius_px", "max_radius_px", "min_contrast_k")}
    det = detect_markers(image, polarity=settings.get("polarity", "auto"), **kw)
    try:
        cal = calibrate(image, mk, seeds=seeds or None, detections=det, **settings)
    except (CalibrationError, ConfigError):
        if figure is not None:
            from .plot import plot_detections

            plot_detections(det, image, figure)
            log.error("calibration failed; the detections are drawn in %s (read seed positions off it)", figure)
        raise
    params = dict(settings, seeds={str(k): v for k, v in (seeds or {}).items()}, target_format=target_format)
    write_dataset(cal, store, stage="calibrate", params=params, inputs=[markers_path, target_path])
    if figure is not None:
        from .plot import plot_calibration

        plot_calibration(cal, image, figure)
    return Path(store)
