"""Names shared by the stages, the figures and the export: dimensions, CF attributes, point status.

The stores are the contract between the stages (see ``docs/results.md``):
a variable keeps its name, dimensions, units and ``long_name`` wherever it
is written, and readers (figures, export, ``irdic info``) rely on them.
"""

from __future__ import annotations

import enum

__all__ = ["TIME", "POINT", "COMPONENT", "AXIS", "I", "J", "PRINCIPAL", "PARAM", "COMPONENTS", "PIXEL_AXES",
           "Status", "STATUS_MEANINGS", "status_attrs", "POINTS_ATTRS", "FIELDS_ATTRS", "cf_attrs"]

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
    #: DIC time outside the IR time span
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

_STORES = {"points": POINTS_ATTRS, "fields": FIELDS_ATTRS}


def cf_attrs(store: str, name: str) -> dict:
    """A copy of the CF attributes of variable ``name`` of ``store`` (``"points"`` or ``"fields"``)."""
    return dict(_STORES[store][name])
