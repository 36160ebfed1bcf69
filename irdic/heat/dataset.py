"""``heat.zarr`` from ``fields.zarr`` and ``points.zarr``: the heat source and the balance's terms at the points.

The storage term takes the material rate of the fields stage and its std;
the losses take the fields' temperature (regressed where the fields stage
regresses it) against the reference temperature; the conduction takes the
Laplace–Beltrami operator of the point temperatures of ``points.zarr`` (white
noise in space, which the Laplacian's regression and its std assume), on
the fields' surface.
"""

from __future__ import annotations

import logging
import time as _time

import numpy as np
import xarray as xr

from ..errors import ConfigError, DataError
from ..surface.parametrisation import median_spacing
from ..vocabulary import cf_attrs
from .balance import MM2_PER_M2, heat_balance, loss_time_constant
from .bias import laplacian_bias, with_bias
from .laplacian import JUDGED_MARGIN, judging_weights, smooth_in_time, surface_laplacian

__all__ = ["heat_dataset", "HEAT_VARIABLES"]

log = logging.getLogger(__name__)

#: the variables of ``heat.zarr`` besides their ``_std`` and ``_bias_dominated``
HEAT_VARIABLES = ("heat_source", "temperature_laplacian", "heat_storage", "heat_losses", "heat_conduction")

_NEEDED = ("surface_parameter", "x", "temperature", "temperature_rate", "surface_edge_distance")


def _aligned_points(fields: xr.Dataset, points: xr.Dataset) -> np.ndarray:
    """The point temperatures of ``points`` (T, N) at the fields' times and points."""
    if "temperature" not in points:
        raise DataError("points store lacks temperature: is it the output of the couple stage?")
    try:
        th = points["temperature"].sel(time=fields["time"].values, point=fields["point"].values)
    except KeyError:
        raise DataError("points.zarr and fields.zarr do not share their times and points: is fields.zarr computed "
                        "from this points.zarr?") from None
    return th.transpose("time", "point").values.astype(float)


def _flag(ds, name):
    v = f"{name}_bias_dominated"
    return ds[v].values.astype(bool) if v in ds else None


def _std(ds, name):
    v = f"{name}_std"
    return ds[v].values.astype(float) if v in ds else 0.0


def _reference(fields, material):
    """Θ0 (N,) degC and its std: ``reference_temperature`` or each point's temperature at the first DIC time."""
    ref = material.get("reference_temperature")
    theta = fields["temperature"].values.astype(float)
    if ref is not None:
        return np.full(theta.shape[1], float(ref)), 0.0
    std = _std(fields, "temperature")
    return theta[0], (std[0] if np.ndim(std) else 0.0)


def _tau(material, t, rate, theta, theta0, lap, inner):
    """``(tau, tau_std, how)``: the configured τ, None (no face losses), or the least squares of ``cooling``."""
    tau = material.get("loss_time_constant")
    if tau != "auto":
        return (None if tau is None else float(tau)), None, "configured"
    window = material.get("cooling")
    if window is None:
        raise ConfigError("material.loss_time_constant: auto needs material.cooling: [t0, t1], a window of DIC "
                          "times (s) without heat sources (e.g. a natural cooling after unloading)")
    diff = material["conductivity"] / (material["density"] * material["specific_heat"]) * MM2_PER_M2
    tau, std = loss_time_constant(t, rate, theta, theta0, lap, diffusivity=diff, window=window, points=inner)
    log.info("heat: loss_time_constant %.4g ± %.2g s from the cooling window %s", tau, std, list(window))
    return tau, std, f"auto: least squares over the cooling window {list(window)} s"


def heat_dataset(fields: xr.Dataset, points: xr.Dataset, material: dict, *, c=0.95, R0=1.0, c_t=1.0, R0_t=1.0,
                 separation=None) -> xr.Dataset:
    """The content of ``heat.zarr``.

    Parameters
    ----------
    fields, points : xarray.Dataset
        ``fields.zarr`` and ``points.zarr`` of the experiment.
    material : dict
        ``experiments.<name>.material`` with its defaults: ``density``
        (kg/m³), ``specific_heat`` (J/(kg K)), ``conductivity`` (W/(m K)),
        ``loss_time_constant`` (s, None or "auto"), ``reference_temperature``
        (degC or None), ``cooling`` ([t0, t1] s or None),
        ``laplacian_smoothing`` ("auto" or a spacing factor > 1),
        ``laplacian_smoothing_time`` ("gcv", None or a spacing in stages >= 1).
    c, R0 : float
        IMQ kernel of the surface parameters (the fields' ``c_space``, ``R0_space``).
    c_t, R0_t : float
        IMQ kernel in time (the fields' ``c_time``, ``R0_time``).
    separation : float, optional
        One IR pixel on the surface (mm), below which the temperature noise is correlated.

    Returns
    -------
    xarray.Dataset
        ``heat_source``, ``temperature_laplacian``, ``heat_storage``,
        ``heat_losses``, ``heat_conduction`` (time, point), each with
        ``_std`` and ``_bias_dominated``; the material and the choices in
        the attributes.
    """
    missing = [v for v in _NEEDED if v not in fields]
    if missing:
        raise DataError(f"fields store lacks {missing}: is it the output of the fields stage?")
    started = _time.perf_counter()
    psi = fields["surface_parameter"].transpose("point", "param").values.astype(float)
    x = fields["x"].transpose("time", "point", "component").values.astype(float)
    raw = _aligned_points(fields, points)
    ops = {}
    t = fields["time"].values.astype(float)
    judge = judging_weights(t, material.get("laplacian_smoothing_time"), c=c_t, R0=R0_t)
    lap = surface_laplacian(psi, raw, x, spacing=material["laplacian_smoothing"], c=c, R0=R0,
                            separation=separation, ops=ops, time_weights=judge)
    lap, k_t = smooth_in_time(lap, t, material.get("laplacian_smoothing_time"), c=c_t, R0=R0_t)
    bias = laplacian_bias(psi, raw, x, lap, c=c, R0=R0, ops=ops)
    noise_std, lap = lap.std, with_bias(lap, bias)
    theta = fields["temperature"].values.astype(float)
    rate = fields["temperature_rate"].values.astype(float)
    theta0, theta0_std = _reference(fields, material)
    edge = fields["surface_edge_distance"].values.astype(float)
    h = median_spacing(psi[np.isfinite(psi).all(axis=1)])
    tau, tau_std, how = _tau(material, t, rate, theta, theta0, lap.laplacian, edge >= JUDGED_MARGIN * h)
    terms = heat_balance(rate, theta, theta0[None, :], lap.laplacian, density=material["density"],
                         specific_heat=material["specific_heat"], conductivity=material["conductivity"], tau=tau,
                         rate_std=_std(fields, "temperature_rate"), theta_std=_std(fields, "temperature"),
                         theta0_std=theta0_std, laplacian_std=lap.std)
    flags = _bias_flags(fields, terms, material["conductivity"] * MM2_PER_M2 * bias, noise_std, bias,
                        tau is not None, theta.shape)
    log.info("heat: %d times x %d points in %.1f s (Laplacian spacing %.3g x %.3g mm)", t.size, psi.shape[0],
             _time.perf_counter() - started, lap.spacing, h)
    values = {"heat_source": (terms.source, terms.source_std), "temperature_laplacian": (lap.laplacian, lap.std),
              "heat_storage": (terms.storage, terms.storage_std), "heat_losses": (terms.losses, terms.losses_std),
              "heat_conduction": (terms.conduction, terms.conduction_std)}
    attrs = _attrs(material, tau, tau_std, how, lap, h)
    attrs["laplacian_smoothing_time_chosen"] = "none" if k_t <= 1.0 else f"centres every {k_t:.3g} DIC times"
    return _assemble(fields, values, flags, attrs)


def _bias_flags(fields, terms, conduction_bias, laplacian_noise, laplacian_bias, with_losses, shape):
    """``_bias_dominated`` of each variable: where its estimated bias exceeds its noise std.

    The Laplacian and the conduction: :func:`~irdic.heat.bias.laplacian_bias` against the noise std.
    The storage and the losses: the fields' flags of the rate and the temperature (whose stds hold their bias
    where flagged). The source: its bias, the conduction's and, where flagged, the storage's and the losses'
    stds, against the rest of its variance.
    """
    lap = np.nan_to_num(laplacian_bias) > laplacian_noise
    rate = _flag(fields, "temperature_rate")
    temp = _flag(fields, "temperature")
    rate = np.zeros(shape, bool) if rate is None else rate
    temp = np.zeros(shape, bool) if (temp is None or not with_losses) else temp
    b2 = (np.square(np.nan_to_num(conduction_bias)) + np.where(rate, terms.storage_std, 0.0) ** 2
          + np.where(temp, terms.losses_std, 0.0) ** 2)
    source = b2 > np.square(terms.source_std) - b2
    return {"temperature_laplacian": lap, "heat_conduction": lap, "heat_storage": rate, "heat_losses": temp,
            "heat_source": source}


def _attrs(material, tau, tau_std, how, lap, h):
    a = {f"material_{k}": float(material[k]) for k in ("density", "specific_heat", "conductivity")}
    a["material_reference_temperature"] = ("first DIC time" if material.get("reference_temperature") is None
                                           else float(material["reference_temperature"]))
    a["loss_time_constant_s"] = "none (no face losses)" if tau is None else float(tau)
    if tau_std is not None:
        a["loss_time_constant_std_s"] = float(tau_std)
    a["loss_time_constant_chosen"] = how
    a["laplacian_spacing_chosen"] = (f"{lap.spacing:.3g} point spacings ({lap.spacing * h:.3g} mm)"
                                     + (", by the Laplacian's estimated risk" if lap.table else ", configured"))
    a["laplacian_noise_k"] = float(np.nanmedian(lap.noise)) if np.isfinite(lap.noise).any() else float("nan")
    return a


def _assemble(fields, values, flags, attrs) -> xr.Dataset:
    tp = ("time", "point")
    data = {}
    for name, (value, std) in values.items():
        base = cf_attrs("heat", name)
        data[name] = (tp, value, base)
        data[f"{name}_std"] = (tp, std, {"units": base["units"], "long_name": f"standard uncertainty of {name} "
                                         "(IR noise through the regressions and the fields' stds; see docs/heat.md)"})
        data[f"{name}_bias_dominated"] = (tp, np.asarray(flags[name], bool), {
            "long_name": f"the method's estimated bias exceeds the noise: there {name}_std is mostly that "
                         "estimate (a local or regional RMS), not a Gaussian width"})
    return xr.Dataset(data, coords={"time": fields["time"], "point": fields["point"]}, attrs=attrs)
