"""The fields at the DIC points: in-plane temperature gradient, temperature rate and strain on the surface.

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
Lagrangian series (:func:`irdic.fields.space_time.space_time`), and per-point
uncertainties (:mod:`irdic.uncertainty.model`).
"""

from __future__ import annotations

import logging
import time as _time

import numpy as np
import xarray as xr

from ..chunks import chunk_slice, window
from ..logs import StageProgress, report, reweigh
from ..threads import thread_budget
from ..footprint.fields import footprint_temperatures, window_extras
from ..noise import auto_smoothing
from ..numerics.memory import release
from ..numerics.temporal import temporal_window
from ..strain import strain
from ..surface import fit_surface, surface_geometry, surface_parameters
from ..uncertainty.model import Window, with_strain_std
from .dataset import fields_dataset, method_of, spacing_attrs, stacked_directions, with_uncertainty
from .smoothing import GCV_STAGES, SMOOTHING, checked_settings, resolve_gcv, surface_kw
from .space_time import temperature_fields

__all__ = ["fields"]

log = logging.getLogger(__name__)


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
    chosen on the record's first :data:`~irdic.fields.smoothing.GCV_STAGES` stages, identically in
    every chunk and in the whole-record run.
    """
    p = checked_settings(points, params)
    n_t = points.sizes["time"] if chunk is None else chunk_slice(points.sizes["time"], *chunk).stop - \
        chunk_slice(points.sizes["time"], *chunk).start
    sizes = dict(n_t=n_t, n_points=points.sizes["point"], n_record=points.sizes["time"], chunked=chunk is not None)
    with StageProgress("fields", stage_costs(**sizes, gcv=_chooses(p)), threads=thread_budget(),
                       shares=STAGE_SHARES, logger=log):
        ds, unc = _fields(points, calibration, chunk, p, sizes)
        out = with_uncertainty(ds, unc)
        report("rest", 1.0)
    return out


#: The cost model of the stage's progress lines (:class:`irdic.logs.StageProgress`): seconds of one core per
#: DIC time and point of each part with the default settings (regressions, their noise probes and bias
#: estimates); the ETA rests on their ratios. Fitted on the benchmarks' moving tube at 6,552, 13,104 and 26,180
#: points and the sweep tube's still and 2 px/frame rows (13,104 points), 300 DIC times, 2 threads
#: (benchmarks/README.md); the surface's the fit alone (the choice of the smoothing: :data:`GCV_COST`).
#: ``write`` is the stage's store, written after :func:`fields` returns (never reported: the ETA includes it)
STAGE_COSTS = {"setup": 4.1e-7, "fill": 1.9e-6, "surface": 2.4e-6, "regression": 1.9e-6, "uncertainty": 1.0e-5,
               "rest": 2.2e-7, "write": 6.6e-7}
#: parts whose cost per point grows with the number of points, as ``(n_points / GROWTH_POINTS) ** g``: the fill's
#: local tiles overlap more where the points are denser next to the kernel, and the bias estimates' reference
#: regressions have centres in proportion to the points (their cost per point grows with them); the exponents
#: from the fitted tubes (the fill 2.5 / 6.0 / 14.1 s at 6,552 / 13,104 / 26,180 points, the uncertainty 12.8 /
#: 23.5 / 57.0 s)
GROWTH = {"fill": 0.25, "uncertainty": 0.2}
GROWTH_POINTS = 13104
#: seconds of one core per stage judged of the choice of the smoothing (GCV, the gradient's risk; on the record's
#: first GCV_STAGES stages): per stage and point of the patch judged (at most
#: irdic.surface.regression.GCV_MAX_POINTS) and per stage and point of the record (the candidates' fills and
#: regressions of every point); 8, 10-12 and 15 s of wall time on 2 threads at 6,552, 13,104 and 26,180 points.
#: A record longer than GCV_STAGES, or a time chunk, chooses all of it before the surface is fitted (the
#: surface part); a shorter whole record chooses the surface's in its fit and the temperature's (all but
#: :data:`GCV_SURFACE_SHARE`) in the regression part
GCV_COST = (1.0e-5, 2.5e-6)
#: the surface's share of the choice (the static half-shell of 9,875 points: its GCV 2 s, the temperature's 6 s)
GCV_SURFACE_SHARE = 0.25
#: the part of each that runs on the stage's threads (from wall and CPU seconds on 2 threads; the surface's and
#: the uncertainty's from their wall times on the sweep tube since the smoothing's candidates and the noise
#: probes run on the threads: x 0.835 and x 0.864)
STAGE_SHARES = {"setup": 0.4, "fill": 0.38, "surface": 0.89, "regression": 0.34, "uncertainty": 0.81, "rest": 0.0,
                "write": 0.0}


def stage_costs(n_t: int, n_points: int, *, n_record: int | None = None, gcv: bool = True,
                chunked: bool = False) -> dict:
    """Expected seconds of one core of the stage's parts for ``n_t`` DIC times (of the chunk) and ``n_points``
    points; ``n_record`` DIC times of the whole record (default ``n_t``), ``gcv``: a smoothing is chosen by GCV
    (:data:`GCV_COST`, in every chunk), ``chunked``: a time chunk's run."""
    from ..surface.regression import GCV_MAX_POINTS

    out = {k: c * float(n_t) * n_points * (n_points / GROWTH_POINTS) ** GROWTH.get(k, 0.0)
           for k, c in STAGE_COSTS.items()}
    if gcv:
        record = n_t if n_record is None else n_record
        choice = float(min(record, GCV_STAGES)) * (GCV_COST[0] * min(n_points, GCV_MAX_POINTS) + GCV_COST[1] * n_points)
        before = chunked or record > GCV_STAGES  # all chosen before the surface is fitted (_surface)
        out["surface"] += choice if before else GCV_SURFACE_SHARE * choice
        out["regression"] += 0.0 if before else (1.0 - GCV_SURFACE_SHARE) * choice
    return out


def _chooses(p) -> bool:
    """Whether a smoothing of the settings ``p`` is chosen from the data (GCV, or "auto" that may choose it)."""
    return any(p.get(k) in ("gcv", "auto") for k in SMOOTHING)


def _fields(points, calibration, chunk, p, sizes):
    """:func:`fields` without its progress lines: the dataset and the uncertainties."""
    started = _time.perf_counter()
    t = points["time"].values.astype(float)
    x = points["x"].transpose("time", "point", "component").values.astype(float)
    # "auto": regression where the estimated noise matters, else the paper's interpolation; resolved once on
    # the whole record (before chunking), so every chunk makes the same choice
    chosen, noise_attrs = auto_smoothing(points, x, {k: p[k] for k in SMOOTHING if k != "surface_smoothing_time"})
    p.update(chosen)
    reweigh(stage_costs(**sizes, gcv=_chooses(p)))  # "auto" resolved: whether GCV runs
    points = footprint_temperatures(points) if p["temperature_smoothing_space"] is not None else points
    configured = p["temperature_smoothing"]
    report("setup", 1.0)
    ops = _fill_operators(points, x, p)
    report("fill", 1.0)
    report("surface", 0.0)
    points, sf, p, series = _surface(points, x, t, chunk, p, ops)
    del x  # each (time, point) array is 31 MB at 13,000 points x 300 times: what is done with goes
    release()
    report("surface", 1.0)
    t = points["time"].values.astype(float)
    T, N = sf.x.shape[:2]
    # the fields use the dual basis (gradients) and the normal of the geometry, not its metrics
    geo = surface_geometry(sf.tangents)._replace(metric=None, inverse_metric=None, area_ratio=None, degenerate=None)
    grad, total, loc, convective, best, unc, chosen = temperature_fields(points, calibration, sf, geo, t, p,
                                                                          noise_attrs, series, ops)
    noise_attrs = {**noise_attrs, **spacing_attrs(chosen, sf.info)}
    # the strain's noise probes refit the surface: after the IR terms' inputs and the dual basis are gone
    geo = geo._replace(dual=None)
    release()
    unc = with_strain_std(unc)
    report("uncertainty", 1.0)
    report("rest", 0.0)
    ops.clear()  # the factorisations (GBs at paper scale) go before the output dataset is built
    st = strain(sf.tangents, sf.ref_tangents, tensors=False)
    sf = sf._replace(tangents=None, ref_tangents=None)
    st, directions = stacked_directions(st)
    release()
    log.info("fields: %d times x %d points in %.1f s (parametrisation %s, solver %s)", T, N,
             _time.perf_counter() - started, method_of(sf.info.get("parametrisation")), sf.info.get("solver"))
    report("rest", 0.5)
    return fields_dataset(points, t, sf, geo.normal, st, directions, grad, total, loc, convective, best, configured,
                          noise_attrs), unc


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
    report("fill", 0.0)
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
        p = resolve_gcv(points, x, t, surface_parameters(x, p["parametrisation"])[0], p, ops)
    sf = fit_surface(x, t, c=p["c_space"], R0=p["R0_space"], c_t=p["c_time"], R0_t=p["R0_time"],
                     smoothing=p["surface_smoothing"], smoothing_t=p["surface_smoothing_time"],
                     solver=p["solver"], parametrisation=p["parametrisation"], operators=ops)
    return points, sf, p, None


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
    p = resolve_gcv(points, x, t, psi, p, ops)
    reach = _record_reach(t, p)
    w = window(t, t[sl.start], t[sl.stop - 1], reach)
    log.info("fields: chunk %d of %d, DIC times %d..%d, stages %d..%d (kernel reach %s stages)", chunk[0] + 1,
             chunk[1], sl.start, sl.stop - 1, w.start, w.stop - 1, "all" if reach is None else reach)
    kw = {**surface_kw(p), "operators": ops}
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
