"""The calibration store's dataset: camera, per-marker status, residuals and detections (:func:`calibration_dataset`)."""

from __future__ import annotations

import json
import numpy as np
import xarray as xr

from .detection import centre_covariances

__all__ = ["calibration_dataset", "STATUSES"]

#: Values of the ``status(marker)`` variable.
STATUSES = ("used", "not_detected", "outlier", "outside_image", "not_measured")


def _marker_status(table, sol, reproj: np.ndarray, sensor: tuple[int, int]):
    """``(status (M,) of :data:`STATUSES`, detection index (M,), -1 if none)``."""
    n, vidx = len(table.ids), table.measured
    status = np.array(["not_measured"] * n, dtype=object)
    status[vidx] = "not_detected"
    det_index = np.full(n, -1, dtype=np.int64)
    for m, d in zip(sol.marker_index, sol.detection_index):
        g = vidx[m]
        det_index[g] = d
        status[g] = "outlier" if m in sol.outliers else "used"
    width, height = sensor
    inside = np.isfinite(reproj).all(axis=1)
    inside[inside] = ((reproj[inside] >= -0.5) & (reproj[inside] <= [width - 0.5, height - 0.5])).all(axis=1)
    status[(status == "not_detected") & ~inside] = "outside_image"
    return status, det_index


def _per_marker(values: np.ndarray, index: np.ndarray, fill=np.nan) -> np.ndarray:
    """``values`` of the measured or detected markers spread onto all markers (``fill`` elsewhere)."""
    out = np.full((len(index),) + values.shape[1:], fill, dtype=np.float64)
    has = index >= 0
    out[has] = values[index[has]]
    return out


def calibration_dataset(table, det: xr.Dataset, sol, sensor: tuple[int, int],
                        settings: dict) -> xr.Dataset:
    """The content of ``calibration.zarr`` from a solved calibration.

    Parameters
    ----------
    table : irdic.calibration.solve.MarkerTable
    det : xarray.Dataset
        :func:`~irdic.calibration.detect_markers` output.
    sol : irdic.calibration.solve.Solution
    sensor : (int, int)
        Sensor width and height, px.
    settings : dict
        Settings of :func:`calibrate` (stored as JSON).

    Returns
    -------
    xarray.Dataset
        Camera (see :meth:`irdic.camera.CameraModel.to_dataset`). Markers
        (dim ``marker``): ``marker_x(marker, component)``,
        ``detected(marker, axis)`` (raw detection, NaN if none),
        ``bias_correction(marker, axis)`` (subtracted from ``detected``),
        ``reprojected``, ``residual`` (= detected - bias_correction -
        reprojected), ``residual_norm``, ``loo_residual``,
        ``projection_uncertainty``, ``status``, ``detection_index``,
        ``marker_radius_px``, ``marker_contrast_k``, ``marker_snr`` (contrast /
        pixel noise), ``centre_covariance(marker, axis, axis_2)`` (px^2, NaN
        where unknown; stores written before it lack it). Detections without a marker: ``unassigned_uv(unassigned,
        axis)``. Scalars ``rms_px``, ``max_px`` over the used markers.
        Attributes: ``method``, ``settings`` (JSON), ``sensor_width``,
        ``sensor_height``, counts and the IDs of flagged markers.
    """
    n, vidx, model = len(table.ids), table.measured, sol.model
    D = np.column_stack([det["u"].values, det["v"].values])
    measured_index = np.full(n, -1, dtype=np.int64)
    measured_index[vidx] = np.arange(len(vidx))
    reproj = _per_marker(model.project(table.x[vidx]), measured_index)
    status, det_index = _marker_status(table, sol, reproj, sensor)
    detected = _per_marker(D, det_index)
    bias_all = _per_marker(sol.bias, measured_index, fill=0.0)
    residual = detected - bias_all - reproj
    rnorm = np.hypot(residual[:, 0], residual[:, 1])
    used = status == "used"
    snr = _per_marker(det["snr"].values, det_index) if "snr" in det else np.full(n, np.nan)
    unassigned = np.setdiff1d(np.arange(len(D)), sol.detection_index)
    px = {"units": "px"}
    ds = model.to_dataset().assign_coords(marker=np.asarray(table.ids), axis_2=["u", "v"],
                                          detection_unassigned=("unassigned", unassigned))
    ds["marker_x"] = (("marker", "component"), table.x, {"units": "mm", "long_name": "marker centre (DIC frame)"})
    ds["detected"] = (("marker", "axis"), detected, {**px, "long_name": "detected marker centre (raw)"})
    ds["bias_correction"] = (("marker", "axis"), bias_all,
                             {**px, "long_name": "perspective bias subtracted from the detected centre"})
    ds["reprojected"] = (("marker", "axis"), reproj, {**px, "long_name": "projection of the marker centre"})
    ds["residual"] = (("marker", "axis"), residual,
                      {**px, "long_name": "detected - bias_correction - reprojected"})
    ds["residual_norm"] = (("marker",), rnorm, {**px, "long_name": "length of the residual"})
    ds["loo_residual"] = (("marker",), _per_marker(sol.loo, measured_index),
                          {**px, "long_name": "residual when left out of the fit"})
    ds["projection_uncertainty"] = (("marker",), _per_marker(model.projection_uncertainty(table.x[vidx]),
                                                             measured_index),
                                    {**px, "long_name": "standard uncertainty of the projection (from covariance)"})
    ds["status"] = (("marker",), status.astype(str), {"long_name": "used / not_detected / outlier / "
                                                                    "outside_image / not_measured"})
    ds["detection_index"] = (("marker",), det_index, {"long_name": "index into the detections (-1: none)"})
    ds["marker_radius_px"] = (("marker",), _per_marker(det["radius_px"].values, det_index),
                              {**px, "long_name": "detected radius"})
    ds["marker_contrast_k"] = (("marker",), _per_marker(det["contrast_k"].values, det_index),
                               {"units": "K", "long_name": "detected contrast"})
    ds["marker_snr"] = (("marker",), snr, {"units": "1", "long_name": "detected contrast / pixel noise"})
    cdet = centre_covariances(det)
    ds["centre_covariance"] = (("marker", "axis", "axis_2"), np.full((n, 2, 2), np.nan) if cdet is None else
                               _per_marker(cdet, det_index), {"units": "px^2", "long_name": "covariance of the "
                                                              "detected centre (pixel noise, floor included)"})
    ds["unassigned_uv"] = (("unassigned", "axis"), D[unassigned].reshape(-1, 2),
                           {**px, "long_name": "detections not assigned to any marker"})
    ds["rms_px"] = ((), float(np.sqrt(np.mean(rnorm[used] ** 2))),
                    {**px, "long_name": "RMS reprojection residual of the used markers"})
    ds["max_px"] = ((), float(rnorm[used].max()), {**px, "long_name": "largest reprojection residual (used)"})
    ds.attrs.update(_attributes(table, det, sol, sensor, settings, status, len(unassigned)))
    return ds


def _attributes(table, det: xr.Dataset, sol, sensor: tuple[int, int], settings: dict,
                status: np.ndarray, n_unassigned: int) -> dict:
    """Method, settings, counts and flagged marker IDs of a calibration dataset."""

    def id_list(mask):
        return json.dumps([str(i) for i in np.asarray(table.ids)[mask]])

    method = "Hartley-normalised DLT (SVD)"
    if settings["refine"]:
        method += (" + Levenberg-Marquardt refinement of the reprojection error "
                   f"(distortion: {settings['distortion']})")
    if settings["correct_bias"]:
        method += " + perspective bias correction of the circle centres"
    counts = {f"n_{s}": int((status == s).sum()) for s in ("used", "not_detected", "outside_image", "not_measured")}
    return dict(
        method=method,
        correspondence=sol.how,
        settings=json.dumps(settings, sort_keys=True),
        sensor_width=int(sensor[0]),
        sensor_height=int(sensor[1]),
        n_markers=int(len(table.ids)),
        n_detections=int(det.sizes["detection"]),
        **counts,
        n_outliers=int((status == "outlier").sum()),
        n_unassigned=int(n_unassigned),
        not_detected_ids=id_list(status == "not_detected"),
        outlier_ids=id_list(status == "outlier"),
        outside_image_ids=id_list(status == "outside_image"),
        not_measured_ids=id_list(status == "not_measured"),
        polarity=str(det.attrs.get("polarity", settings["polarity"])),
        noise_k=float(det.attrs.get("noise_k", np.nan)),
        marker_radius_mm=float(sol.radius_mm) if sol.radius_mm is not None else float("nan"),
        dlt_rms_px=float(sol.info.get("dlt_rms_px", np.nan)),
        sigma_px=float(sol.info.get("sigma_px", np.nan)),
    )
