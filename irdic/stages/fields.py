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

Beyond the paper (its outlook for noisy IR data): regression in space and
time where the estimated noise matters ("auto", the default; ``null`` is the
paper's interpolation), the rate then the time derivative of each point's
Lagrangian series (:func:`_space_time`), and per-point uncertainties
(:mod:`irdic.stages.uncertainty`).
"""

from __future__ import annotations

import logging
import os
import time as _time
from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from ..camera import load_camera
from ..errors import ConfigError, DataError
from ..store import open_store, write_dataset
from ..strain import strain
from ..surface import fit_surface, surface_geometry, surface_parameters
from ..surface.parametrisation import median_spacing
from ..chunks import chunk_slice, gathered, window
from ..numerics.series import fill_series, smooth_series
from ..numerics.temporal import RATE_MAX_FRACTION, rate_reference_weights, temporal_window
from ..gradient import material_rate, surface_gradient
from ..noise import auto_smoothing
from ..vocabulary import COMPONENTS, cf_attrs
from .common import optional_path, paths, stage_context
from .identity import fields_inputs
from .footprint_fields import footprint_temperatures, paper_value, pixel_pitch, window_extras
from .parameters import settings
from .uncertainty import Window, uncertainties, uncertainty_notes

__all__ = ["run", "run_gather", "fields"]

log = logging.getLogger(__name__)

#: Smoothing chosen by GCV is chosen on the record's first stages (at most this many), by every time chunk
#: and by the whole-record run alike, so that all of them regress with the same smoothing.
GCV_STAGES = 256

#: The temperature regression's spacing is judged on points more than this many point spacings inside the
#: cloud's edge (:func:`_space_gcv_filled`).
JUDGED_MARGIN = 3.0

_SMOOTHING = ("surface_smoothing", "surface_smoothing_time", "temperature_smoothing", "temperature_smoothing_space")


def _smoothing(name, value):
    number = isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 1
    if not (value is None or value in ("gcv", "auto") or number):
        raise ConfigError(f"fields.{name} must be null (interpolation), 'gcv', 'auto' or a number >= 1, got {value!r}")


def _method_of(info) -> str:
    return str(info.get("method")) if isinstance(info, dict) else str(info)


def fields(points: xr.Dataset, calibration: xr.Dataset, *, chunk: tuple[int, int] | None = None,
           **params) -> xr.Dataset:
    """Gradient, rate and strain fields at the DIC points.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr`` of the experiment.
    calibration : xarray.Dataset
        ``calibration.zarr`` of its setup.
    chunk : (index, count), optional
        Only the DIC times of this time chunk (:mod:`irdic.chunks`), from the
        stages within the temporal kernel's reach of them (see Notes).
    **params
        The ``fields`` section of the configuration; absent keys take the
        schema's defaults:

        - ``c_space``, ``R0_space`` (mm): IMQ shape factor and distance
          normalisation in the surface parameters (the paper: 0.969 /
          0.9328, 1 mm);
        - ``c_time``, ``R0_time`` (s): the same in time (the paper: 1, 1 s);
        - ``parametrisation`` {"auto", "plane", "cylinder"}: best-fit plane
          (the paper) or cylindrical unwrapping; "auto" takes the cylinder
          where the plane would fold;
        - ``solver`` {"auto", "global", "local"}: spatial solver of the
          surface interpolation;
        - ``surface_smoothing``, ``surface_smoothing_time`` (None, "gcv",
          "auto" or float >= 1): regression instead of interpolation for the
          coordinates ("auto", only in space: :func:`irdic.noise.auto_smoothing`
          decides from the estimated DIC noise);
        - ``temperature_smoothing`` (same values): regression in time of the
          point temperatures for the material rate;
        - ``temperature_smoothing_space`` (same values): regression in space
          (surface parameters) of the point temperatures of each time for
          the in-plane gradient, ``grad Θ = (∂Θ/∂Ψ^α) a^α`` with
          ``∂Θ/∂Ψ^α`` from the regressed field instead of the pixel gradients.

    Returns
    -------
    xarray.Dataset
        The content of ``fields.zarr`` (see README).

    Notes
    -----
    A time chunk reads the coordinates of every stage (the surface
    parameters come from each point's first valid stage, the strain from the
    reference stage 0) but fits the surface and the temperature series only
    over its own stages plus the temporal operators' reach on each side
    (:func:`irdic.numerics.temporal.temporal_window`). In a record longer
    than that reach every temporal operator is the windowed one, in the
    whole-record run too, so a chunk reproduces the whole-record result to
    rounding, at the record's ends included. Smoothing chosen by GCV is
    chosen on the record's first :data:`GCV_STAGES` stages, identically in
    every chunk and in the whole-record run.
    """
    p = _checked_settings(points, params)
    started = _time.perf_counter()
    t = points["time"].values.astype(float)
    x = points["x"].transpose("time", "point", "component").values.astype(float)
    # "auto": regression where the estimated noise matters, else the paper's interpolation; resolved once on
    # the whole record (before chunking), so every chunk makes the same choice
    chosen, noise_attrs = auto_smoothing(points, x, {k: p[k] for k in _SMOOTHING if k != "surface_smoothing_time"})
    p.update(chosen)
    points = footprint_temperatures(points) if p["temperature_smoothing_space"] is not None else points
    configured = p["temperature_smoothing"]
    ops = _fill_operators(points, x, p)
    points, sf, p, series = _surface(points, x, t, chunk, p, ops)
    t = points["time"].values.astype(float)
    T, N = sf.x.shape[:2]
    geo = surface_geometry(sf.tangents)
    grad, total, loc, convective, best, unc = _temperature_fields(points, calibration, sf, geo, t, p, noise_attrs,
                                                                  series, ops)
    ops.clear()  # the factorisations (GBs at paper scale) go before the output dataset is built
    st = strain(sf.tangents, sf.ref_tangents, tensors=False)
    log.info("fields: %d times x %d points in %.1f s (parametrisation %s, solver %s)", T, N,
             _time.perf_counter() - started, _method_of(sf.info.get("parametrisation")), sf.info.get("solver"))
    ds = _fields_dataset(points, t, sf, geo, st, grad, total, loc, convective, best, configured, noise_attrs)
    return _with_uncertainty(ds, unc)


def _checked_settings(points, params) -> dict:
    """The ``fields`` settings with defaults; ConfigError/DataError for bad smoothing values or a wrong store."""
    p = settings("fields", params)
    for name in _SMOOTHING:
        _smoothing(name, p[name])
    missing = [v for v in ("x", "temperature", "temperature_pixel_gradient", "temperature_local_rate")
               if v not in points]
    if missing:
        raise DataError(f"points store lacks {missing}: is it the output of the couple stage?")
    return p


def _fill_operators(points, x, p) -> dict:
    """The stage's cache of spatial operators (:func:`irdic.surface.shared_interpolant`), its fill rows built.

    The surface fit, the GCV trials, the temperature regressions and their
    noise probes all fill missing points with the same interpolant (the
    kernel of ``c_space``, ``R0_space`` on the surface parameters). Its rows
    of ``G`` come from one pass over the local tiles, for every point that
    lacks a position or a temperature anywhere in the record, so no later
    fill factorises the tiles again; the same pass gives the interpolant's
    derivative weights (:meth:`~irdic.surface.SpatialInterpolant.local_pass`),
    so its evaluations (the exact interpolation, and the reference of the
    regressions' bias estimates) are one product per tile.
    """
    from ..surface import shared_interpolant

    ops = {}
    psi = surface_parameters(x, p["parametrisation"])[0]
    have = np.isfinite(psi).all(axis=1)
    theta = points["temperature"].values
    gaps = (~np.isfinite(x).all(axis=2) | ~np.isfinite(theta)).any(axis=0)[have]
    if gaps.any() and have.sum() >= 6:
        shared_interpolant(ops, psi[have], c=p["c_space"], R0=p["R0_space"],
                           solver=p["solver"]).local_pass(np.flatnonzero(gaps))
    return ops


def _surface(points, x, t, chunk, p, ops=None):
    """``(points, surface, p, window)`` of the whole record, or of a time chunk (:func:`_chunk_surface`)."""
    if chunk is not None:
        return _chunk_surface(points, x, t, chunk, p, ops)
    if t.size > GCV_STAGES:
        p = _resolve_gcv(points, x, t, surface_parameters(x, p["parametrisation"])[0], p, ops)
    sf = fit_surface(x, t, c=p["c_space"], R0=p["R0_space"], c_t=p["c_time"], R0_t=p["R0_time"],
                     smoothing=p["surface_smoothing"], smoothing_t=p["surface_smoothing_time"],
                     solver=p["solver"], parametrisation=p["parametrisation"], operators=ops)
    return points, sf, p, None


def _surface_kw(p):
    return dict(c=p["c_space"], R0=p["R0_space"], c_t=p["c_time"], R0_t=p["R0_time"], solver=p["solver"])


def _record_reach(t, p):
    """Stages each side a time needs (:func:`~irdic.numerics.temporal.temporal_window`): the widest of the
    temporal operators in use; None for the whole record."""
    ks = [None] + [p.get(k) for k in ("temperature_smoothing", "temperature_smoothing_rate", "surface_smoothing_time")
                   if p.get(k) is not None]
    reach = [temporal_window(t, c=p["c_time"], R0=p["R0_time"], smoothing=k) for k in ks]
    return None if any(r is None for r in reach) else max(reach)


def _chunk_surface(points, x, t, chunk, p, ops=None):
    """Points of the chunk's window, the surface at the chunk's times, and ``p`` with GCV choices resolved."""
    sl = chunk_slice(t.size, *chunk)
    psi, how = surface_parameters(x, p["parametrisation"])
    p = _resolve_gcv(points, x, t, psi, p, ops)
    reach = _record_reach(t, p)
    w = window(t, t[sl.start], t[sl.stop - 1], reach)
    log.info("fields: chunk %d of %d, DIC times %d..%d, stages %d..%d (kernel reach %s stages)", chunk[0] + 1,
             chunk[1], sl.start, sl.stop - 1, w.start, w.stop - 1, "all" if reach is None else reach)
    kw = {**_surface_kw(p), "operators": ops}
    sf = fit_surface(x[w], t[w], psi, t_eval=t[sl], smoothing=p["surface_smoothing"],
                     smoothing_t=p["surface_smoothing_time"], record_times=t, shape_stage=x[0], **kw)
    if w.start > 0:
        # the strain's reference is stage 0 of the record; at a sample time the temporal
        # operator is the identity, so stages 0 and 1 alone give its tangents
        ref = fit_surface(x[:2], t[:2], psi, t_eval=t[:1], smoothing=p["surface_smoothing"], smoothing_t=None, **kw)
        sf = sf._replace(ref_x=ref.ref_x, ref_tangents=ref.ref_tangents)
    filled = np.asarray(sf.filled)[sl.start - w.start:sl.stop - w.start]
    sf = sf._replace(filled=filled)
    sf.info["parametrisation"] = how
    # the window's temperature series and coordinates: the regression in time and the uncertainty probes need them
    series = Window(theta=points["temperature"].isel(time=w).values.astype(float), t=t[w], x=x[w], x_ref=x[:2],
                    t_ref=t[:2], first=sl.start == 0, last=sl.stop == t.size, record=t, **window_extras(points, w))
    return points.isel(time=sl), sf, p, series


def _resolve_gcv(points, x, t, psi, p, ops=None):
    """``p`` with every "gcv" smoothing replaced by the number GCV picks on the record's first
    :data:`GCV_STAGES` stages: the same in every chunk and in the whole-record run."""
    gcv = [k for k in _SMOOTHING if p[k] == "gcv"]
    if not gcv:
        return p
    w = slice(0, min(t.size, GCV_STAGES))
    p = dict(p)
    if "surface_smoothing" in gcv or "surface_smoothing_time" in gcv:
        info = fit_surface(x[w], t[w], psi, smoothing=p["surface_smoothing"], smoothing_t=p["surface_smoothing_time"],
                           operators=ops, **_surface_kw(p)).info
        p["surface_smoothing"] = info["smoothing"] if p["surface_smoothing"] is not None else None
        if p["surface_smoothing"] is not None and "smoothing_shape" in info:
            # GCV chose a spacing for the shape and one for the motion (irdic.surface.fit_surface): keep both
            p["surface_smoothing"] = (info["smoothing_shape"], info["smoothing"])
        p["surface_smoothing_time"] = info["smoothing_t"] if p["surface_smoothing_time"] is not None else None
    theta = points["temperature"].isel(time=w).values.astype(float)
    if p["temperature_smoothing_space"] == "gcv":
        k = _space_gcv(theta, psi, c=p["c_space"], R0=p["R0_space"], ops=ops, separation=pixel_pitch(points, psi))
        if k is not None:  # no time with 6 visible points among them: each chunk chooses its own
            p["temperature_smoothing_space"] = k
    if p["temperature_smoothing"] == "gcv":
        if p["temperature_smoothing_space"] not in (None, "gcv"):
            # judged on the spatially regressed series, as the fields regress them (see _space_time)
            theta = _regressed_gradient(theta, psi, None, p["temperature_smoothing_space"], c=p["c_space"],
                                        R0=p["R0_space"], ops=ops)[1]
        theta = fill_series([theta], t[w], c=p["c_time"], R0=p["R0_time"])[0]  # once for both GCVs below
        p["temperature_smoothing"] = smooth_series(theta, t[w], smoothing="gcv", c=p["c_time"], R0=p["R0_time"]).smoothing
        if p["temperature_smoothing_space"] is not None:  # the rate's own spacing (see _rate_series)
            p["temperature_smoothing_rate"] = smooth_series(theta, t[w], c=p["c_time"], R0=p["R0_time"],
                                                            gcv_max_fraction=RATE_MAX_FRACTION).smoothing
    log.info("fields: smoothing chosen once on DIC times %d..%d: %s", w.start, w.stop - 1,
             ", ".join(f"{k} {p[k]}" for k in gcv))
    return p


def _temperature_fields(points, calibration, sf, geo, t, p, noise_attrs, series=None, ops=None):
    """In-plane gradient (T, N, 3) K/mm, material rate with its local and convective parts (T, N) K/s,
    and the best estimate of the temperature (T, N) degC (denoised where smoothing is on); last the
    uncertainties of :func:`irdic.stages.uncertainty.uncertainties`.

    The projection Jacobian of the calibrated camera at the surface points
    turns pixel gradients into surface ones (see the module docstring).
    ``series`` (:class:`Window`): a time chunk's window around the times
    ``t``, for the regression in time and the uncertainty probes.
    """
    T, N = sf.x.shape[:2]
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
    best = theta
    chosen_k = {"temperature_smoothing": None, "temperature_smoothing_space": None}
    spatial = None
    ops = {} if ops is None else ops  # the spatial operators of the regressions and their probes, factorised once
    if p["temperature_smoothing_space"] is not None:
        def space_time(th, ser, q=p):
            return _space_time(th, t, sf, geo, q, ser, rate.convective, visible, (total, loc), ops)
        grad, total, loc, best, spatial, chosen_k = space_time(theta, series)
        if "temperature_paper" in points:  # footprint temperatures: the value from the paper's, same spacings
            best, spatial = paper_value(points, series, lambda th, ser: space_time(th, ser, {**p, **chosen_k}), spatial)
    elif p["temperature_smoothing"] is not None:
        # a chunk regresses its window's series and evaluates it at its own times
        th, ts = (series.theta, series.t) if series is not None else (theta, t)
        fit = smooth_series(th, ts, t if series is not None else None, smoothing=p["temperature_smoothing"],
                            c=p["c_time"], R0=p["R0_time"], record_times=t if series is None else series.record)
        chosen_k["temperature_smoothing"] = fit.smoothing
        total = np.where(visible, fit.rate, np.nan)
        loc = total - rate.convective
        best = np.where(visible, fit.value, np.nan)

    def regress_space(th, dual, k):
        return _regressed_gradient(th, sf.psi, dual, k, c=p["c_space"], R0=p["R0_space"], ops=ops)[:2]

    unc = uncertainties(points.assign_attrs(dic_noise_mm=noise_attrs.get("dic_noise_mm", np.nan)), sf, geo, J,
                        g_pix, t, p, chosen_k, regress_space, window=series, spatial=spatial, ops=ops)
    return grad, total, loc, rate.convective, best, unc


def _space_time(theta, t, sf, geo, p, series, convective, visible, paper_rate, ops=None):
    """Gradient, rate (material, local) and value of the space-time regression of the point temperatures.

    Parameters
    ----------
    theta : ndarray, shape (T, N)
        Point temperatures (degC) at the DIC times ``t`` (s).
    sf, geo
        The fitted surface and its geometry (surface parameters, dual basis).
    p : dict
        The fields settings; ``temperature_smoothing_space`` is set.
    series : Window or None
        A time chunk's window (its regressions run over the window).
    convective : ndarray, shape (T, N)
        Convective part of the rate (K/s).
    visible : ndarray of bool, shape (T, N)
    paper_rate : (total, local)
        The paper's rate and local part, kept when there is no regression in time.
    ops : dict, optional
        Cache of the spatial operators (:func:`irdic.surface.shared_interpolant`).

    Returns
    -------
    grad (T, N, 3) K/mm, total (T, N) K/s, local (T, N) K/s, value (T, N) degC,
    spatial (the inputs of the regression's bias estimate, see
    :func:`irdic.stages.uncertainty.uncertainties`), chosen (the spacings used).

    Notes
    -----
    Space first, then time. The tube's temperature is smooth in space (a
    quadratic axial profile) but changes within a few DIC stages in time, so
    a point's own series, with the full 0.05 K noise, makes GCV in time
    choose centres every 4 stages, whose bias alone is 7 % of the rate. The
    spatial regression of each stage removes most of the noise first
    (GCV over the points, whose noise is white in space); GCV of the
    regressed series in time then judges a nearly noise-free signal and
    chooses the light smoothing the signal needs. The gradient is the spatial
    regression's derivative of the temporally regressed values (the regressed
    field's own gradient), the rate the temporal derivative of the spatially
    regressed series, by a lighter regression in time (:func:`_rate_series`).
    """
    kw = dict(c=p["c_space"], R0=p["R0_space"], ops=ops)
    chosen = {"temperature_smoothing": None, "temperature_smoothing_space": None}
    grad, value, ks = _regressed_gradient(theta, sf.psi, geo.dual, p["temperature_smoothing_space"], **kw)
    chosen["temperature_smoothing_space"] = ks
    total, loc = paper_rate
    if p["temperature_smoothing"] is None:
        return grad, total, loc, value, (theta, grad, theta, value, theta), chosen
    # a chunk regresses its window's series (in space at each stage, then in time) and evaluates at its own times
    if series is not None:
        th_in, ts_in, t_eval, record = series.theta, series.t, t, series.record
        _, th_s, _ = _regressed_gradient(th_in, sf.psi, None, ks, **kw)
    else:
        th_in, ts_in, t_eval, record, th_s = theta, t, None, t, value
    # the regressions in time below fill the same gaps: once, together
    th_s, th_in = fill_series([th_s, th_in], ts_in, c=p["c_time"], R0=p["R0_time"], record_times=record)
    tkw = dict(c=p["c_time"], R0=p["R0_time"], record_times=record)
    fit = smooth_series(th_s, ts_in, t_eval, smoothing=p["temperature_smoothing"], **tkw)
    rate_fit = _rate_series(th_s, ts_in, t_eval, p, fit, tkw)
    chosen["temperature_smoothing"], chosen["temperature_smoothing_rate"] = fit.smoothing, rate_fit.smoothing
    total = np.where(visible, rate_fit.rate, np.nan)
    smoothed = np.where(visible, fit.value, np.nan)
    grad, value, _ = _regressed_gradient(smoothed, sf.psi, geo.dual, ks, **kw)
    # the spatial regression's bias is judged against the temporal regression of the points' own series
    own = smooth_series(th_in, ts_in, t_eval, smoothing=fit.smoothing, **tkw)
    own_rate = own.rate if rate_fit.smoothing == fit.smoothing else \
        smooth_series(th_in, ts_in, t_eval, smoothing=rate_fit.smoothing, **tkw).rate
    # the temporal regressions' bias: against the same (regressed) series, whose noise is small (against the
    # points' own series the estimate drowned in their noise): the rate's against a local polynomial in time
    exact = smooth_series(th_s, ts_in, t_eval, smoothing=None, **tkw)
    bias_inputs = (theta, grad, (own_v := np.where(visible, own.value, np.nan)), value, total - rate_reference_weights(
        ts_in, t_eval, smoothing=rate_fit.smoothing) @ th_s, total - own_rate, smoothed - exact.value, own_v)
    return grad, total, total - convective, value, bias_inputs, chosen


def _rate_series(th_s, ts_in, t_eval, p, fit, tkw):
    """The temporal regression of the spatially regressed series ``th_s`` whose derivative is the rate.

    With ``temperature_smoothing`` "gcv": GCV's spacing among candidates with up to
    :data:`~irdic.numerics.temporal.RATE_MAX_FRACTION` parameters per stage (the value's: 1/2), or that
    resolved for the record (``p["temperature_smoothing_rate"]``); a configured number serves both (``fit``).

    Notes
    -----
    The value and gradient stay one field, ``S_x S_t2 S_x Θ``; the rate is ``∂_t S_t1 S_x Θ``, ``S_t1`` at
    most as smooth; they differ by the heavier one's temporal bias, which the value's std holds. A fast
    transient's rate at 2 Hz is bias-limited, the gradient noise-limited (benchmarks/README.md, issue 15).
    """
    k = p.get("temperature_smoothing_rate") or ("gcv" if p["temperature_smoothing"] == "gcv" else None)
    if k is None:
        return fit
    return smooth_series(th_s, ts_in, t_eval, smoothing=k, gcv_max_fraction=RATE_MAX_FRACTION, **tkw)


def _fields_dataset(points, t, sf, geo, st, grad, total, loc, convective, best, temperature_smoothing,
                    noise_attrs) -> xr.Dataset:
    """The content of ``fields.zarr``: variables with their CF attributes (:mod:`irdic.vocabulary`)."""
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
            "normal": (tpc, geo.normal, a("normal")),
            "strain": (("time", "point", "i", "j"), st.E2, a("strain")),
            "reference_basis": (("point", "i", "component"), st.basis, a("reference_basis")),
            "max_principal_strain": (tp, st.e_max, a("max_principal_strain")),
            "min_principal_strain": (tp, st.e_min, a("min_principal_strain")),
            "principal_direction": (tppc, np.stack([st.direction_max, st.direction_min], axis=2),
                                    a("principal_direction")),
            "principal_direction_current": (tppc, np.stack([st.direction_max_current, st.direction_min_current],
                                                           axis=2), a("principal_direction_current")),
            "equivalent_strain": (tp, st.equivalent, a("equivalent_strain")),
            "surface_parameter": (("point", "param"), sf.psi, a("surface_parameter")),
            "surface_edge_distance": (("point",), sf.edge_distance, a("surface_edge_distance")),
            "filled": (tp, sf.filled, a("filled")),
        },
        coords={"time": ("time", t, a("time")), "point": points["point"].values,
                "component": np.array(COMPONENTS, dtype=object),
                "i": np.array(["1", "2"], dtype=object), "j": np.array(["1", "2"], dtype=object),
                "principal": np.array(["max", "min"], dtype=object), "param": np.array(["psi1", "psi2"], dtype=object)},
        attrs={"parametrisation": _method_of(sf.info.get("parametrisation")), "surface_solver": str(sf.info.get("solver")),
               "temperature_smoothing": str(temperature_smoothing), **noise_attrs},
    )


def _with_uncertainty(ds: xr.Dataset, unc: dict) -> xr.Dataset:
    """``<field>_std`` and ``<field>_bias_dominated`` beside each field (see :mod:`irdic.stages.uncertainty`)."""
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


def _space_gcv_filled(filled, p, *, c, R0, separation=None):
    """Centre spacing of the spatial regression from up to 8 filled times (rows of ``filled``).

    Chosen by the estimated risk of the gradient
    (:func:`irdic.surface.regression.gradient_risk_spatial`), not by GCV of
    the values: the gradient is what this regression is for, and GCV's curve
    is flat where the gradient's error still halves. ``separation`` (mm): one IR pixel (see there).
    """
    from ..surface import edge_distance
    from ..surface.regression import gradient_risk_spatial

    sample = filled[np.linspace(0, filled.shape[0] - 1, min(filled.shape[0], 8)).astype(int)].T
    # the rim's data carry more than noise (mixed edge pixels, extrapolation), which the least smoothed
    # pilot follows: judged inside it, all points fitted
    judged = edge_distance(p) >= JUDGED_MARGIN * median_spacing(p)
    k, _ = gradient_risk_spatial(p, sample, c=c, R0=R0, judged=judged if judged.sum() >= 6 else None,
                                 separation=separation)
    log.info("temperature_smoothing_space: the gradient's estimated risk chose %.1f point spacings", k)
    return k


def _space_gcv(theta, psi, *, c, R0, ops=None, separation=None):
    """:func:`_space_gcv_filled` of the times of ``theta`` (T, N) with 6 or more visible points."""
    from ..surface import shared_interpolant

    have = np.isfinite(psi).all(axis=1)
    visible = np.isfinite(theta) & have
    times = np.flatnonzero(visible.sum(axis=1) >= 6)
    if times.size == 0:
        return None
    filled, _ = shared_interpolant({} if ops is None else ops, psi[have], c=c, R0=R0).fill(
        theta[np.ix_(times, have)], visible[np.ix_(times, have)])
    return _space_gcv_filled(filled, psi[have], c=c, R0=R0, separation=separation)


def _regressed_gradient(theta, psi, dual, smoothing, *, c, R0, ops=None):
    """In-plane gradient and value from a spatial regression of the point temperatures of each time.

    Missing values of a time are filled from that time's visible points first;
    times with fewer than 6 visible points stay NaN. Returns ``(grad (T, N, 3)
    K/mm, value (T, N) degC, the centre spacing factor used)``; ``dual`` None:
    the values only (``grad`` None, no derivatives computed). ``dual`` (T_d, N, 2, 3) may hold
    fewer times than ``theta``: row ``m`` of ``theta`` then uses the dual basis
    of time ``m % T_d`` (noise probes stacked along time). ``ops``: a cache of
    the spatial operators (:func:`irdic.surface.shared_interpolant`) shared by
    the calls of one stage run.
    """
    from ..surface import shared_interpolant

    ops = {} if ops is None else ops
    T, N = theta.shape
    grad = None if dual is None else np.full((T, N, 3), np.nan)
    val = np.full((T, N), np.nan)
    have = np.isfinite(psi).all(axis=1)
    visible = np.isfinite(theta) & have
    times = np.flatnonzero(visible.sum(axis=1) >= 6)
    if times.size == 0:
        log.warning("temperature_smoothing_space: no time with 6 or more visible points; gradient left NaN")
        return grad, val, smoothing
    p = psi[have]
    filled, _ = shared_interpolant(ops, p, c=c, R0=R0, smoothing=1.0).fill(theta[np.ix_(times, have)], visible[np.ix_(times, have)])
    if smoothing == "gcv":
        k = _space_gcv_filled(filled, p, c=c, R0=R0)
    else:
        k = float(smoothing)
    v0, d1, d2 = shared_interpolant(ops, p, c=c, R0=R0, smoothing=k).evaluate(filled.T, derivatives=dual is not None)
    del filled
    cols = np.flatnonzero(have)
    if dual is not None:
        step = max(1, (1 << 24) // max(1, 6 * cols.size))  # rows per block: ~128 MB of dual basis
        for s in range(0, times.size, step):
            tt = times[s:s + step]
            D = dual[tt % dual.shape[0]][:, cols]
            g = d1[:, s:s + step].T[..., None] * D[:, :, 0]
            g += d2[:, s:s + step].T[..., None] * D[:, :, 1]
            grad[tt[:, None], cols] = g
        grad[~visible] = np.nan
    val[times[:, None], cols] = v0.T
    val[~visible] = np.nan
    return grad, val, k


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, chunk: tuple[int, int] | None = None,
        **params) -> None:
    """Stage entry: ``inputs`` points, calibration (and dic, machine) -> ``outputs["store"]`` (fields.zarr).

    ``dic`` (``dic.zarr``) and ``machine`` (``machine.zarr``), when given,
    add the testing machine signals at the DIC times:
    ``signal_value(time, signal)`` with the signal coordinates (see
    :func:`irdic.signals.signals_at`; machine signals prefixed ``machine_``).
    ``params``: the ``fields`` section of the configuration (see
    :func:`fields`); ``log`` a log file (Snakemake), ``threads`` the CPU
    threads of the stage (default all cores); ``chunk`` (index, count):
    write only that time chunk (``results/<experiment>/chunks/fields-<i>.zarr``,
    gathered by :func:`run_gather`).
    """
    from ..signals import signals_at

    i = paths(inputs, "fields", "inputs", ("points", "calibration"), ("dic", "machine"))
    o = paths(outputs, "fields", "outputs", ("store",), against=i)
    dic, machine = optional_path(i, "dic"), optional_path(i, "machine")
    with stage_context("fields", log, threads):
        points, calibration, dic_ds, machine_ds = fields_inputs(i["points"], i["calibration"], dic, machine)
        ds = fields(points, calibration, chunk=chunk, **params)
        sig = signals_at(ds["time"].values, dic=dic_ds, machine=machine_ds)
        if sig is not None:
            ds = ds.merge(sig.drop_vars("time"))
        inputs_used = [os.fspath(i["points"]), os.fspath(i["calibration"])]
        inputs_used += [os.fspath(q) for q in (dic, machine) if q is not None]
        write_dataset(ds, o["store"], stage="fields", params=params, inputs=inputs_used)


def run_gather(inputs: Mapping[str, Sequence[str | os.PathLike]], outputs: Mapping[str, str | os.PathLike], *,
               log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Gather entry: ``inputs["chunks"]`` (chunk stores in time order) -> ``outputs["store"]`` (fields.zarr)."""
    o = paths(outputs, "fields", "outputs", ("store",))
    parts = [os.fspath(q) for q in paths(inputs, "fields-gather", "inputs", ("chunks",))["chunks"]]
    with stage_context("fields-gather", log, threads):
        first, rest = gathered([open_store(q, "fields") for q in parts])
        write_dataset(first, o["store"], stage="fields", params=params, append=rest, inputs=parts)
