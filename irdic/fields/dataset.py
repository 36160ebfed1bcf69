"""The content of ``fields.zarr``: the fields with their CF attributes, their std and bias flags."""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..uncertainty.model import uncertainty_notes
from ..vocabulary import COMPONENTS, cf_attrs

__all__ = ["fields_dataset", "method_of", "spacing_attrs", "stacked_directions", "with_uncertainty"]


def method_of(info) -> str:
    return str(info.get("method")) if isinstance(info, dict) else str(info)


#: the spacings a run used, by the store's attribute: the key of the temperature's choice or of the surface fit's
#: ``info`` it is read from
SPACINGS = {"temperature_smoothing_space_spacing": "temperature_smoothing_space",
            "temperature_smoothing_spacing": "temperature_smoothing",
            "temperature_smoothing_rate_spacing": "temperature_smoothing_rate",
            "temperature_smoothing_value_spacing": "temperature_smoothing_value",
            "surface_smoothing_spacing": "smoothing", "surface_smoothing_shape_spacing": "smoothing_shape",
            "surface_smoothing_time_spacing": "smoothing_t"}


def spacing_attrs(chosen, surface_info) -> dict:
    """The centre spacings the regressions used, as ``fields.zarr`` records them: whatever ``gcv`` or ``auto``
    chose, so that a series can be re-processed with the smoothing fixed.

    Parameters
    ----------
    chosen : dict
        The temperature's spacings (:func:`irdic.fields.space_time.space_time`'s ``chosen``): in space in point
        spacings, in time (the gradient's and value's regression, the rate's, the value's own) in DIC stages;
        None where that regression is off.
    surface_info : dict
        The surface fit's ``info`` (:func:`irdic.surface.fit_surface`): ``smoothing`` (the motion's spacing in
        point spacings), ``smoothing_shape`` (the shape's, where regressed apart), ``smoothing_t`` (DIC stages).

    Returns
    -------
    dict
        ``<option>_spacing`` -> float, or None (no regression; 1 in time is a centre at every stage); an
        option that is not there (no regression in space: no temperature spacings in time apart from the
        first) is left out.
    """
    out = {}
    for attr, key in SPACINGS.items():
        src = surface_info if attr.startswith("surface") else chosen
        if key in src:
            v = src[key]
            out[attr] = None if v is None else float(v)
    return out


def stacked_directions(st):
    """The principal directions of the strain ``st`` (:func:`irdic.strain.strain`) as the store holds them,
    ``(reference, current)`` each (T, N, 2, 3) (max, min), and ``st`` without its directions and stretches
    (the store's dataset would otherwise hold them twice while it is built)."""
    directions = (np.stack([st.direction_max, st.direction_min], axis=2),
                  np.stack([st.direction_max_current, st.direction_min_current], axis=2))
    return st._replace(direction_max=None, direction_min=None, direction_max_current=None, direction_min_current=None,
                       stretch_max=None, stretch_min=None), directions


def fields_dataset(points, t, sf, normal, st, directions, grad, total, loc, convective, best, temperature_smoothing,
                   noise_attrs) -> xr.Dataset:
    """The content of ``fields.zarr``: variables with their CF attributes (:mod:`irdic.vocabulary`); ``normal``
    (T, N, 3) the surface's unit normal, ``directions`` :func:`stacked_directions`'s."""
    a = lambda name: cf_attrs("fields", name)  # noqa: E731
    tp, tpc = ("time", "point"), ("time", "point", "component")
    tppc = ("time", "point", "principal", "component")
    return xr.Dataset(
        {
            "temperature_gradient": (tpc, grad, a("temperature_gradient")),
            "temperature_rate": (tp, total, a("temperature_rate")),
            "temperature_rate_local": (tp, loc, a("temperature_rate_local")),
            "temperature_rate_convective": (tp, convective, a("temperature_rate_convective")),
            "temperature": (tp, best, a("temperature")),
            "x": (tpc, sf.x, a("x")),
            "velocity": (tpc, sf.velocity, a("velocity")),
            "normal": (tpc, normal, a("normal")),
            "strain": (("time", "point", "i", "j"), st.E2, a("strain")),
            "reference_basis": (("point", "i", "component"), st.basis, a("reference_basis")),
            "max_principal_strain": (tp, st.e_max, a("max_principal_strain")),
            "min_principal_strain": (tp, st.e_min, a("min_principal_strain")),
            "principal_direction": (tppc, directions[0], a("principal_direction")),
            "principal_direction_current": (tppc, directions[1], a("principal_direction_current")),
            "equivalent_strain": (tp, st.equivalent, a("equivalent_strain")),
            "surface_parameter": (("point", "param"), sf.psi, a("surface_parameter")),
            "surface_edge_distance": (("point",), sf.edge_distance, a("surface_edge_distance")),
            "filled": (tp, sf.filled, a("filled")),
        },
        coords={"time": ("time", t, a("time")), "point": points["point"].values,
                "component": np.array(COMPONENTS, dtype=object),
                "i": np.array(["1", "2"], dtype=object), "j": np.array(["1", "2"], dtype=object),
                "principal": np.array(["max", "min"], dtype=object), "param": np.array(["psi1", "psi2"], dtype=object)},
        attrs={"parametrisation": method_of(sf.info.get("parametrisation")), "surface_solver": str(sf.info.get("solver")),
               "temperature_smoothing": str(temperature_smoothing), **noise_attrs},
    )


def with_uncertainty(ds: xr.Dataset, unc: dict) -> xr.Dataset:
    """``<field>_std`` and ``<field>_bias_dominated`` beside each field (see :mod:`irdic.uncertainty.model`)."""
    for name in ("temperature", "temperature_gradient", "temperature_rate", "max_principal_strain"):
        std, bias = unc[name]
        dims = ds[name].dims
        units = ds[name].attrs.get("units", "1")
        ds[f"{name}_std"] = (dims, std, {"units": units, "long_name": f"standard uncertainty of {name} (IR and DIC "
                                         "noise and calibration, propagated; see docs/method.md, Uncertainty)"})
        ds[f"{name}_bias_dominated"] = (dims, np.asarray(bias, dtype=bool),
                                        {"long_name": f"the method's bias (mask edge, extrapolation, series end, "
                                         f"export rounding) dominates the noise: {name}_std does not bound the error"})
    ds.attrs["uncertainty_notes"] = uncertainty_notes(unc, ds["max_principal_strain"].values)
    return ds
