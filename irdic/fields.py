"""Fields stage: in-plane temperature gradient, temperature rate and strain on the surface.

Input: ``points.zarr`` (temperatures, pixel gradients and local rates at the
DIC points, plus their coordinates) and the setup's ``calibration.zarr``.
The surface ``x(Ψ, t)`` is interpolated from the DIC points
(:func:`irdic.surface.fit_surface`: IMQ RBF in the surface parameters Ψ,
tensor product with time). With the tangents ``a_α`` and the projection
Jacobian ``J`` (px/mm) the paper's relations give

- ``grad Θ = (∂Θ/∂Ψ^α) a^α`` with ``∂Θ/∂Ψ^α = ∇_pix Θ · J a_α`` (eq. tempGrad),
- ``Θ̇ = ∂Θ/∂t + (Jᵀ ∇_pix Θ) · ∂x/∂t`` (eq. tempVeloc), local and convective
  parts stored separately,
- the in-plane Green-Lagrange strain on the reference tangent plane, its
  principal values and directions, and an equivalent strain.

Beyond the paper (its own outlook for noisy IR data): with
``temperature_smoothing`` ("gcv" or a number) the material rate is the time
derivative of each point's temperature series after IMQ regression in time
(the series is Lagrangian, so this is the material rate without pixel
derivatives); the local part is then the difference of that rate and the
convective part. ``surface_smoothing``/``surface_smoothing_time`` do the same
for the coordinates. Interpolation (None) stays the default.
"""

from __future__ import annotations

import logging
import os
import time as _time
from pathlib import Path

import numpy as np
import xarray as xr

from .camera import load_camera
from .errors import ConfigError, DataError
from .store import open_store, write_dataset
from .strain import strain
from .surface import fit_surface, surface_geometry
from .noise import auto_smoothing
from .gradient import material_rate, rate_from_series, surface_gradient

__all__ = ["fields", "fields_stores"]

log = logging.getLogger(__name__)


def _smoothing(name, value):
    if value is None or value == "gcv" or value == "auto":
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 1:
        return float(value)
    raise ConfigError(f"fields.{name} must be null (interpolation), 'gcv', 'auto' or a number >= 1, got {value!r}")


def _method_of(info) -> str:
    return str(info.get("method")) if isinstance(info, dict) else str(info)


def fields(
    points: xr.Dataset,
    calibration: xr.Dataset,
    *,
    c_space: float = 0.95,
    R0_space: float = 1.0,
    c_time: float = 1.0,
    R0_time: float = 1.0,
    parametrisation: str = "auto",
    solver: str = "auto",
    surface_smoothing="auto",
    surface_smoothing_time=None,
    temperature_smoothing="auto",
    temperature_smoothing_space="auto",
) -> xr.Dataset:
    """Gradient, rate and strain fields at the DIC points.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr`` of the experiment.
    calibration : xarray.Dataset
        ``calibration.zarr`` of its setup.
    c_space, R0_space : float
        IMQ shape factor and distance normalisation (mm) in the surface
        parameters (the paper: 0.969 / 0.9328, 1 mm).
    c_time, R0_time : float
        IMQ shape factor and normalisation (s) in time (the paper: 1, 1 s).
    parametrisation : {"auto", "plane", "cylinder"}
        Surface parameters: best-fit plane (the paper) or cylindrical
        unwrapping; "auto" takes the cylinder where the plane would fold.
    solver : {"auto", "global", "local"}
        Spatial solver of the surface interpolation.
    surface_smoothing, surface_smoothing_time : None, "gcv", "auto" or float >= 1
        Regression instead of interpolation for the coordinates ("auto",
        only in space: :func:`irdic.noise.auto_smoothing` decides from the
        estimated DIC noise).
    temperature_smoothing : None, "gcv", "auto" or float >= 1
        Regression in time of the point temperatures for the material rate.
    temperature_smoothing_space : None, "gcv", "auto" or float >= 1
        Regression in space (surface parameters) of the point temperatures of
        each time for the in-plane gradient, ``grad Θ = (∂Θ/∂Ψ^α) a^α`` with
        ``∂Θ/∂Ψ^α`` from the regressed field instead of the pixel gradients.

    Returns
    -------
    xarray.Dataset
        The content of ``fields.zarr`` (see README).
    """
    for name, v in (("surface_smoothing", surface_smoothing), ("surface_smoothing_time", surface_smoothing_time),
                    ("temperature_smoothing", temperature_smoothing),
                    ("temperature_smoothing_space", temperature_smoothing_space)):
        _smoothing(name, v)
    missing = [v for v in ("x", "temperature", "temperature_pixel_gradient", "temperature_local_rate")
               if v not in points]
    if missing:
        raise DataError(f"points store lacks {missing}: is it the output of the couple stage?")
    started = _time.perf_counter()
    t = points["time"].values.astype(float)
    x = points["x"].transpose("time", "point", "component").values.astype(float)
    # --- issue 15: "auto" -> regression where the estimated noise matters, else the paper's interpolation
    chosen, noise_attrs = auto_smoothing(points, x, {"surface_smoothing": surface_smoothing,
                                                     "temperature_smoothing": temperature_smoothing,
                                                     "temperature_smoothing_space": temperature_smoothing_space})
    surface_smoothing = chosen["surface_smoothing"]
    temperature_smoothing = chosen["temperature_smoothing"]
    temperature_smoothing_space = chosen["temperature_smoothing_space"]
    # --- end issue 15
    sf = fit_surface(x, t, c=c_space, R0=R0_space, c_t=c_time, R0_t=R0_time, smoothing=surface_smoothing,
                     smoothing_t=surface_smoothing_time, solver=solver, parametrisation=parametrisation)
    T, N = sf.x.shape[:2]
    geo = surface_geometry(sf.tangents)
    camera = load_camera(calibration)
    flat = sf.x.reshape(-1, 3)
    ok = np.isfinite(flat).all(axis=1)
    J = np.full((T * N, 2, 3), np.nan)
    J[ok] = camera.jacobian(flat[ok])
    J = J.reshape(T, N, 2, 3)
    g_pix = points["temperature_pixel_gradient"].transpose("time", "point", "axis").values.astype(float)
    local = points["temperature_local_rate"].values.astype(float)
    theta = points["temperature"].values.astype(float)
    grad = surface_gradient(g_pix, J, sf.tangents)
    rate = material_rate(local, g_pix, J, sf.velocity)
    total, loc = rate.rate, rate.local
    visible = np.isfinite(theta)
    best = theta  # issue 15: the best estimate of the temperature, denoised where smoothing is on
    if temperature_smoothing is not None:
        smoothed_rate, smoothed = rate_from_series(theta, t, smoothing=temperature_smoothing, c=c_time, R0=R0_time)
        total = np.where(visible, smoothed_rate, np.nan)
        loc = total - rate.convective
        best = np.where(visible, smoothed, np.nan)
    if temperature_smoothing_space is not None:
        grad, value = _regressed_gradient(theta, sf.psi, geo.dual, temperature_smoothing_space, c=c_space, R0=R0_space)
        if temperature_smoothing is not None:
            # space-time regression: the spatial regression of the temporally regressed series
            _, value = _regressed_gradient(best, sf.psi, geo.dual, temperature_smoothing_space, c=c_space, R0=R0_space)
        best = value
    st = strain(sf.tangents, sf.ref_tangents, tensors=False)
    log.info("fields: %d times x %d points in %.1f s (parametrisation %s, solver %s)", T, N,
             _time.perf_counter() - started, _method_of(sf.info.get("parametrisation")), sf.info.get("solver"))

    comp = np.array(["x", "y", "z"], dtype=object)
    ds = xr.Dataset(
        {
            "temperature_gradient": (("time", "point", "component"), grad,
                                     {"units": "K/mm", "long_name": "in-plane temperature gradient (current configuration)"}),
            "temperature_rate": (("time", "point"), total,
                                 {"units": "K/s", "long_name": "material temperature rate"}),
            "temperature_rate_local": (("time", "point"), loc,
                                       {"units": "K/s", "long_name": "local part of the temperature rate (at the fixed pixel)"}),
            "temperature_rate_convective": (("time", "point"), rate.convective,
                                            {"units": "K/s", "long_name": "convective part of the temperature rate (motion of the point)"}),
            "temperature": (("time", "point"), best,
                            {"units": "degC", "long_name": "temperature at the material point, regressed in time and/or "
                             "space where the smoothing options are on (points.zarr keeps the interpolated value)"}),
            "x": (("time", "point", "component"), sf.x, {"units": "mm", "long_name": "position on the interpolated surface"}),
            "velocity": (("time", "point", "component"), sf.velocity, {"units": "mm/s", "long_name": "velocity of the material point"}),
            "normal": (("time", "point", "component"), geo.normal, {"units": "1", "long_name": "unit surface normal"}),
            "strain": (("time", "point", "i", "j"), st.E2,
                       {"units": "1", "long_name": "Green-Lagrange strain components in the reference basis (E_1, E_2)"}),
            "reference_basis": (("point", "i", "component"), st.basis,
                                {"units": "1", "long_name": "orthonormal reference tangent basis E_1 = A_1/|A_1|, E_2 = N x E_1"}),
            "max_principal_strain": (("time", "point"), st.e_max, {"units": "1", "long_name": "maximum in-plane principal Green-Lagrange strain"}),
            "min_principal_strain": (("time", "point"), st.e_min, {"units": "1", "long_name": "minimum in-plane principal Green-Lagrange strain"}),
            "principal_direction": (("time", "point", "principal", "component"),
                                    np.stack([st.direction_max, st.direction_min], axis=2),
                                    {"units": "1", "long_name": "principal strain directions (reference configuration)"}),
            "principal_direction_current": (("time", "point", "principal", "component"),
                                            np.stack([st.direction_max_current, st.direction_min_current], axis=2),
                                            {"units": "1", "long_name": "principal strain directions mapped to the current configuration"}),
            "equivalent_strain": (("time", "point"), st.equivalent,
                                  {"units": "1", "long_name": "equivalent (von Mises) logarithmic strain, plane, isochoric"}),
            "surface_parameter": (("point", "param"), sf.psi, {"units": "mm", "long_name": "surface parameters Psi"}),
            "surface_edge_distance": (("point",), sf.edge_distance,
                                      {"units": "mm", "long_name": "distance to the edge of the point cloud in Psi"}),
            "filled": (("time", "point"), sf.filled,
                       {"long_name": "point missing in this DIC stage, position filled by the surface interpolant"}),
        },
        coords={"time": ("time", t, {"units": "s"}), "point": points["point"].values, "component": comp,
                "i": np.array(["1", "2"], dtype=object), "j": np.array(["1", "2"], dtype=object),
                "principal": np.array(["max", "min"], dtype=object), "param": np.array(["psi1", "psi2"], dtype=object)},
        attrs={"parametrisation": _method_of(sf.info.get("parametrisation")), "surface_solver": str(sf.info.get("solver")),
               "temperature_smoothing": str(temperature_smoothing), **noise_attrs},
    )
    return ds


def _regressed_gradient(theta, psi, dual, smoothing, *, c, R0):
    """In-plane gradient and value from a spatial regression of the point temperatures of each time.

    Missing values of a time are filled from that time's visible points first;
    times with fewer than 6 visible points stay NaN. Returns ``(grad (T, N, 3)
    K/mm, value (T, N) degC)``.
    """
    from .surface import SpatialInterpolant, gcv_spatial

    T, N = theta.shape
    grad = np.full((T, N, 3), np.nan)
    val = np.full((T, N), np.nan)
    have = np.isfinite(psi).all(axis=1)
    visible = np.isfinite(theta) & have
    times = np.flatnonzero(visible.sum(axis=1) >= 6)
    if times.size == 0:
        log.warning("temperature_smoothing_space: no time with 6 or more visible points; gradient left NaN")
        return grad, val
    p = psi[have]
    filled, _ = SpatialInterpolant(p, c=c, R0=R0).fill(theta[np.ix_(times, have)], visible[np.ix_(times, have)])
    if smoothing == "gcv":
        sample = filled[np.linspace(0, times.size - 1, min(times.size, 8)).astype(int)].T
        k, _ = gcv_spatial(p, sample, c=c, R0=R0)
        log.info("temperature_smoothing_space: GCV chose a centre spacing of %.1f point spacings", k)
    else:
        k = float(smoothing)
    v0, d1, d2 = SpatialInterpolant(p, c=c, R0=R0, smoothing=k).evaluate(filled.T, value=True)
    g = d1.T[..., None] * dual[np.ix_(times, have)][:, :, 0] + d2.T[..., None] * dual[np.ix_(times, have)][:, :, 1]
    out = np.full((times.size, N, 3), np.nan)
    out[:, have] = g
    grad[times] = out
    grad[~visible] = np.nan
    vt = np.full((times.size, N), np.nan)
    vt[:, have] = v0.T
    val[times] = vt
    val[~visible] = np.nan
    return grad, val


def fields_stores(points_path, calibration_path, out, *, dic=None, machine=None, **params) -> Path:
    """Run :func:`fields` on stores and write ``fields.zarr`` atomically.

    ``dic`` (``dic.zarr``) and ``machine`` (``machine.zarr``), when given,
    add the testing machine signals at the DIC times:
    ``signal_value(time, signal)`` with the signal coordinates (see
    :func:`irdic.signals.signals_at`; machine signals prefixed ``machine_``).
    """
    from .signals import signals_at

    ds = fields(open_store(points_path), open_store(calibration_path), **params)
    sig = signals_at(ds["time"].values, dic=open_store(dic) if dic is not None else None,
                     machine=open_store(machine) if machine is not None else None)
    if sig is not None:
        ds = ds.merge(sig.drop_vars("time"))
    inputs = [os.fspath(points_path), os.fspath(calibration_path)]
    inputs += [os.fspath(q) for q in (dic, machine) if q is not None]
    write_dataset(ds, out, stage="fields", params=params, inputs=inputs)
    return Path(out)
