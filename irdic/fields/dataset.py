"""The content of ``fields.zarr``: the fields with their CF attributes, their std and bias flags."""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..uncertainty.model import uncertainty_notes
from ..vocabulary import COMPONENTS, cf_attrs

__all__ = ["fields_dataset", "method_of", "stacked_directions", "with_uncertainty"]


def method_of(info) -> str:
    return str(info.get("method")) if isinstance(info, dict) else str(info)


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
