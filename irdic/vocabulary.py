"""Names shared by the stages, the figures and the export: dimensions, CF attributes, point status.

The stores are the contract between the stages (see ``docs/results.md``):
a variable keeps its name, dimensions, units and ``long_name`` wherever it
is written, and readers (figures, export, ``irdic info``) rely on them.
"""

from __future__ import annotations

import enum

__all__ = ["TIME", "POINT", "COMPONENT", "AXIS", "I", "J", "PRINCIPAL", "PARAM", "COMPONENTS", "PIXEL_AXES",
           "Status", "STATUS_MEANINGS", "status_attrs", "POINTS_ATTRS", "FIELDS_ATTRS", "HEAT_ATTRS", "cf_attrs",
           "COORD_ATTRS", "SERIES_ATTRS", "DATASET_ATTRS", "series_attrs", "allowed_dataset_attr"]

#: dimension names of the stores
TIME, POINT, COMPONENT, AXIS = "time", "point", "component", "axis"
I, J, PRINCIPAL, PARAM = "i", "j", "principal", "param"

#: labels of the ``component`` (DIC frame, mm) and ``axis`` (image, px) coordinates
COMPONENTS = ("x", "y", "z")
PIXEL_AXES = ("u", "v")


class Status(enum.IntEnum):
    """Why a point has or lacks a temperature at a time (``points.status``, int8).

    Notes
    -----
    The integer values are stored in ``points.zarr`` and must not change;
    ``visible`` is ``status <= EXTRAPOLATED_FROM_EDGE``.
    """

    #: interpolated inside the specimen mask
    INTERPOLATED = 0
    #: extrapolated from the mask edge (at most max_extrapolation_px)
    EXTRAPOLATED_FROM_EDGE = 1
    #: DIC point missing at this time
    DIC_POINT_MISSING = 2
    #: behind the IR camera or outside the IR frame
    OUTSIDE_IR_FRAME = 3
    #: surface facing away from the IR camera
    FACING_AWAY = 4
    #: outside the specimen mask, farther than max_extrapolation_px
    OUTSIDE_SPECIMEN_MASK = 5
    #: DIC time outside the IR time span, or in a gap of the IR record (no IR frame within the temporal reach)
    TIME_OUTSIDE_IR_SPAN = 6


#: CF ``flag_meanings`` of ``status``: the member names, lower case, in value order
STATUS_MEANINGS = " ".join(s.name.lower() for s in Status)


def status_attrs() -> dict:
    """CF attributes of ``points.status`` (``flag_values``/``flag_meanings``)."""
    return {"long_name": "why a point has or lacks a temperature",
            "flag_values": [int(s) for s in Status], "flag_meanings": STATUS_MEANINGS}


#: units and long names of the variables of ``points.zarr`` (couple stage)
POINTS_ATTRS: dict[str, dict[str, str]] = {
    "temperature": {"units": "degC", "long_name": "temperature at the material point"},
    "temperature_footprint": {"units": "degC", "long_name": "temperature at the material point from the plane "
                              "fitted to the specimen pixels of a footprint_px box about each pixel (the fields "
                              "stage regresses it for the gradient and rate)"},
    "temperature_footprint_noise_factor": {"units": "1", "long_name": "noise of temperature_footprint relative "
                                           "to that of a whole footprint_px box (box cut by the mask edge, "
                                           "extrapolation from the edge)"},
    "pixel": {"units": "px", "long_name": "projected position in the IR image (full sensor, u = column, v = row)"},
    "pixel_std": {"units": "px", "long_name": "standard uncertainty of the projected position from the "
                  "calibration covariance (radial RMS)"},
    "temperature_pixel_gradient": {"units": "K/px", "long_name": "temperature gradient in the IR image plane"},
    "temperature_local_rate": {"units": "K/s",
                               "long_name": "local time derivative of the IR temperature at the fixed pixel"},
    "visible": {"long_name": "the point has a temperature (status 0 or 1)"},
    "edge_distance": {"units": "px", "long_name": "distance to the specimen mask edge (negative: extrapolated)"},
    "x": {"units": "mm", "long_name": "current coordinates (from dic.zarr)"},
    "mask_pixels": {"long_name": "number of IR pixels on the specimen mask"},
    "time": {"units": "s", "long_name": "DIC time"},
}

#: units and long names of the variables of ``fields.zarr`` (fields stage)
FIELDS_ATTRS: dict[str, dict[str, str]] = {
    "temperature_gradient": {"units": "K/mm", "long_name": "in-plane temperature gradient (current configuration)"},
    "temperature_rate": {"units": "K/s", "long_name": "material temperature rate"},
    "temperature_rate_local": {"units": "K/s", "long_name": "local part of the temperature rate (at the fixed pixel)"},
    "temperature_rate_convective": {"units": "K/s",
                                    "long_name": "convective part of the temperature rate (motion of the point)"},
    "temperature": {"units": "degC", "long_name": "temperature at the material point, regressed in time and/or "
                    "space where the smoothing options are on (points.zarr keeps the interpolated value)"},
    "x": {"units": "mm", "long_name": "position on the interpolated surface"},
    "velocity": {"units": "mm/s", "long_name": "velocity of the material point"},
    "normal": {"units": "1", "long_name": "unit surface normal"},
    "strain": {"units": "1", "long_name": "Green-Lagrange strain components in the reference basis (E_1, E_2)"},
    "reference_basis": {"units": "1",
                        "long_name": "orthonormal reference tangent basis E_1 = A_1/|A_1|, E_2 = N x E_1"},
    "max_principal_strain": {"units": "1", "long_name": "maximum in-plane principal Green-Lagrange strain"},
    "min_principal_strain": {"units": "1", "long_name": "minimum in-plane principal Green-Lagrange strain"},
    "principal_direction": {"units": "1", "long_name": "principal strain directions (reference configuration)"},
    "principal_direction_current": {"units": "1",
                                    "long_name": "principal strain directions mapped to the current configuration"},
    "equivalent_strain": {"units": "1",
                          "long_name": "equivalent (von Mises) logarithmic strain, plane, isochoric"},
    "surface_parameter": {"units": "mm", "long_name": "surface parameters Psi"},
    "surface_edge_distance": {"units": "mm", "long_name": "distance to the edge of the point cloud in Psi"},
    "filled": {"long_name": "point missing in this DIC stage, position filled by the surface interpolant"},
    "time": {"units": "s"},
}

#: units and long names of the variables of ``heat.zarr`` (heat stage; the balance of docs/heat.md)
HEAT_ATTRS: dict[str, dict[str, str]] = {
    "heat_source": {"units": "W/m3", "long_name": "heat source s = heat_storage + heat_losses - heat_conduction, "
                    "averaged through the wall's thickness (plastic dissipation plus thermoelastic coupling)"},
    "temperature_laplacian": {"units": "K/mm2", "long_name": "Laplace-Beltrami operator of the temperature on the "
                              "current surface"},
    "heat_storage": {"units": "W/m3", "long_name": "heat stored, rho c times the material temperature rate"},
    "heat_losses": {"units": "W/m3", "long_name": "face losses, rho c (temperature - reference temperature) / "
                    "loss_time_constant"},
    "heat_conduction": {"units": "W/m3", "long_name": "heat brought in by in-plane conduction, k times the "
                        "temperature Laplacian"},
}

_STORES = {"points": POINTS_ATTRS, "fields": FIELDS_ATTRS, "heat": HEAT_ATTRS}


def cf_attrs(store: str, name: str) -> dict:
    """A copy of the CF attributes of variable ``name`` of ``store`` (``"points"``, ``"fields"`` or ``"heat"``)."""
    return dict(_STORES[store][name])


#: CF attributes of the coordinates of every store; :func:`irdic.store.write_dataset` adds them to a
#: coordinate that has none, so ``irdic info`` and xarray users see what each index means
COORD_ATTRS: dict[str, dict[str, str]] = {
    TIME: {"units": "s", "long_name": "time"},
    POINT: {"long_name": "point ID of the DIC software"},
    COMPONENT: {"long_name": "Cartesian component in the DIC frame (x, y, z)"},
    AXIS: {"long_name": "IR image axis (u = column, v = row)"},
    I: {"long_name": "first index of the strain tensor in the reference tangent basis (E_1, E_2)"},
    J: {"long_name": "second index of the strain tensor in the reference tangent basis (E_1, E_2)"},
    PRINCIPAL: {"long_name": "principal strain (max, min)"},
    PARAM: {"long_name": "surface parameter (Psi_1, Psi_2)"},
    "u": {"units": "px", "long_name": "pixel column (full-sensor, 0-based)"},
    "v": {"units": "px", "long_name": "pixel row (full-sensor, 0-based)"},
    "signal": {"long_name": "testing machine signal name as written in the export"},
    "signal_kind": {"long_name": "kind of signal (value_element, analog_input, machine)"},
    "signal_unit": {"long_name": "unit of the signal ('' if unknown)"},
    "signal_standard_name": {"long_name": "standard name of the signal (force, displacement, torque, angle, "
                             "cycles, time or '')"},
    "marker": {"long_name": "marker ID of the calibration target"},
    "row": {"long_name": "row of the 3 x 4 projection matrix"},
    "col": {"long_name": "column of the 3 x 4 projection matrix"},
    "row3": {"long_name": "row of a 3 x 3 matrix"},
    "col3": {"long_name": "column of a 3 x 3 matrix"},
    "coefficient": {"long_name": "lens distortion coefficient"},
    "parameter": {"long_name": "parameter of the refined camera model"},
    "parameter_2": {"long_name": "parameter of the refined camera model (second covariance index)"},
    "axis_2": {"long_name": "image axis (u, v) of a 2 x 2 covariance's second index"},
    "unassigned": {"long_name": "detection without a marker"},
    "detection_unassigned": {"long_name": "index of a detection without a marker"},
}

#: dataset attributes an ingest stage keeps from the first file: settings of the whole series (camera,
#: export, DIC project); per-file values (frame or stage index, stage name and date, counts) are not kept
SERIES_ATTRS: dict[str, tuple[str, ...]] = {
    "ir": ("sensor_width", "sensor_height", "emissivity", "distance", "transmission", "env_temp", "path_temp",
           "recording_file", "irbis_version", "source_unit", "camera", "lens",
           # FLIR object parameters (after the configuration's overrides) and Planck constants
           "reflected_temp", "relative_humidity", "ir_window_temp", "ir_window_transmission",
           "planck_r1", "planck_r2", "planck_b", "planck_f", "planck_o"),
    "dic": ("point_id_source", "point_key", "reference_stage_index", "rbm_compensation"),
}

#: dataset attributes a store may hold besides provenance (``irdic_*``): the series settings above,
#: the machine record's columns, the calibration's summary, the coupling's summary (points.status counts)
#: and the fields stage's choices
DATASET_ATTRS: frozenset[str] = frozenset(
    [a for v in SERIES_ATTRS.values() for a in v]
    + ["source_columns", "experiment", "method", "time_offset", "ir_time_offset", "ir_time_offset_std",
       "ir_time_offset_source", "ir_time_offset_estimate", "ir_time_offset_estimate_std", "correspondence",
       "settings", "n_markers", "n_detections",
       "n_used", "n_not_detected", "n_outside_image", "n_not_measured", "n_outliers", "n_unassigned",
       "not_detected_ids", "outlier_ids", "outside_image_ids", "not_measured_ids", "polarity", "noise_k",
       "marker_radius_mm", "dlt_rms_px", "sigma_px", "parametrisation", "surface_solver", "temperature_smoothing",
       "n_source_files", "calibration_rms_px", "calibration_projection_matrix", "calibration_camera_centre_mm",
       "calibration_focal_length_px", "ir_time_span_s", "ir_frames",
       # noise estimates, the smoothing "auto" chose and why, uncertainty notes (irdic.noise, fields)
       "ir_noise_k", "ir_noise_temporal_k", "ir_noise_spatial_k", "ir_quantisation_k",
       "ir_noise_gain_temperature", "ir_noise_gain_gradient_per_px", "ir_noise_gain_rate_per_s", "dic_noise_mm",
       "footprint_px", "ir_noise_gain_temperature_footprint",
       "uncertainty_notes",
       # the heat stage's material and choices (irdic.heat)
       "material_density", "material_specific_heat", "material_conductivity", "material_reference_temperature",
       "loss_time_constant_s", "loss_time_constant_std_s", "loss_time_constant_chosen", "laplacian_spacing_chosen",
       "laplacian_smoothing_time_chosen",
       "laplacian_noise_k"]
    + [f"{o}_{w}" for o in ("temperature_smoothing", "temperature_smoothing_space", "surface_smoothing")
       for w in ("chosen", "reason")]
    # the centre spacings the fields' regressions used (irdic.fields.dataset.SPACINGS)
    + [f"{o}_spacing" for o in ("temperature_smoothing", "temperature_smoothing_space", "temperature_smoothing_rate",
                                "temperature_smoothing_value", "surface_smoothing", "surface_smoothing_shape",
                                "surface_smoothing_time")]
    + [f"count_{s.name.lower()}" for s in Status])


def series_attrs(kind: str, first: dict) -> dict:
    """The series-level attributes of ``kind`` (``"ir"``, ``"dic"``) among a first file's ``attrs``.

    Only scalars and strings are kept (zarr attributes); a value of the first
    file stands for the series, which is why per-file values are left out.
    """
    return {k: v for k, v in first.items() if k in SERIES_ATTRS[kind] and isinstance(v, (str, int, float, bool))}


def allowed_dataset_attr(name: str) -> bool:
    """Whether a dataset attribute ``name`` belongs in a store (provenance ``irdic_*`` or :data:`DATASET_ATTRS`)."""
    return name.startswith("irdic_") or name in DATASET_ATTRS
