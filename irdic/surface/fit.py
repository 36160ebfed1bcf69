"""The surface stage: ``x(Psi, t)``, tangents, velocities and reference tangents at the DIC points."""

from __future__ import annotations

import logging
import time as _time
import warnings
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ConfigError, DataError, IrdicWarning
from ..numerics.series import cardinal_weights, valid_neighbours
from ..numerics.temporal import TemporalInterpolant, temporal_window
from ..numerics.temporal_choice import gcv_temporal
from ..validation import as_int, choice, float_array, increasing_times, psi_array, smoothing_factor
from .geometry import edge_distance
from .interpolation import shared_interpolant
from .parametrisation import MIN_POINTS, surface_parameters
from .regression import SURFACE_CANDIDATES, gcv_spatial

__all__ = ["SurfaceFields", "fit_surface", "fit_stages"]

log = logging.getLogger(__name__)


def _temporal_fill(X, valid, times, c, R0, max_gap, window=8):
    """Fill short gaps from each point's own valid stages.

    A missing stage is filled when it lies in a run of at most ``max_gap``
    missing stages with valid stages on both sides; the temporal IMQ
    interpolant (with {1, t}) of up to ``window`` valid stages on each side
    gives the value.

    Returns the filled array and the (M, N) mask of entries filled.
    """
    M = X.shape[0]
    prev, nxt = valid_neighbours(valid)
    todo = ~valid & (prev >= 0) & (nxt < M) & (nxt - prev - 1 <= max_gap)
    out = X.copy()
    # the weights depend only on the valid times relative to t_k: with regular
    # stages a handful of patterns serve all gaps
    cache = {}
    valid_of = {}
    for k, i in zip(*np.nonzero(todo)):
        ok = valid_of.get(i)
        if ok is None:
            ok = valid_of[i] = np.flatnonzero(valid[:, i])
        j = np.searchsorted(ok, k)
        sel = ok[max(0, j - window):j + window]
        s = (times[sel] - times[k]) / R0
        key = tuple(np.round(s, 9))
        w = cache.get(key)
        if w is None:
            w = cache[key] = cardinal_weights(s, c)
        out[k, i] = w @ X[sel, i]
    return out, todo


def _duplicates(psi):
    """Indices of points closer than 1e-9 of the median spacing to an earlier point."""
    if psi.shape[0] < 2:
        return np.zeros(0, np.int64)
    tree = cKDTree(psi)
    d, _ = tree.query(psi, k=2)
    tol = 1e-9 * max(float(np.median(d[:, 1])), 1e-300) + 1e-12
    pairs = tree.query_pairs(tol, output_type="ndarray")
    return np.unique(pairs.max(axis=1)) if pairs.size else np.zeros(0, np.int64)


class SurfaceFields(NamedTuple):
    """Result of :func:`fit_surface`; ``T`` evaluation times, ``N`` points.

    Points without any valid stage (and duplicates left out) are NaN throughout.
    """

    psi: np.ndarray
    """(N, 2) surface parameters (mm)."""
    times: np.ndarray
    """(T,) evaluation times (s)."""
    x: np.ndarray
    """(T, N, 3) position on the continuous surface (mm)."""
    tangents: np.ndarray
    """(T, N, 2, 3) ``a_alpha = dx/dPsi^alpha`` (dimensionless)."""
    velocity: np.ndarray
    """(T, N, 3) ``dx/dt`` at fixed Psi (mm/s)."""
    ref_x: np.ndarray
    """(N, 3) reference position ``x(Psi, t_0)`` (mm), t_0 the first stage."""
    ref_tangents: np.ndarray
    """(N, 2, 3) reference tangents ``A_alpha``."""
    filled: np.ndarray
    """(M, N) bool: the point was missing in the stage and filled (see ``fill``)."""
    stage_used: np.ndarray
    """(M,) bool: the stage entered the temporal fit."""
    edge_distance: np.ndarray
    """(N,) distance to the edge of the point cloud in Psi (mm)."""
    info: dict
    """Solver, smoothing, GCV tables, parametrisation, timings."""


def fit_surface(x, times, psi=None, *, t_eval=None, c=0.95, R0=1.0, c_t=1.0, R0_t=1.0, smoothing=None,
                smoothing_t=None, solver="auto", halo=None, parametrisation="auto", min_stage_fraction=0.5,
                fill="both", max_gap=3, record_times=None, shape_stage=None, operators=None, choose_only=False):
    """The continuous surface ``x(Psi, t)`` of DIC stages, evaluated at the points.

    Parameters
    ----------
    x : array_like, shape (M, N, 3)
        Point coordinates per stage (mm); NaN rows are missing points.
    times : array_like, shape (M,)
        Stage times (s), strictly increasing; stage 0 is the reference.
    psi : array_like, shape (N, 2), optional
        Surface parameters; default from :func:`surface_parameters` (``parametrisation``).
    t_eval : array_like, shape (T,), optional
        Evaluation times (s); default ``times``. Outside the stage span: NaN.
    c, R0 : float
        Spatial IMQ shape factor, distance normalisation (mm); the paper: 0.969 / 0.9328, 1 mm.
    c_t, R0_t : float
        Temporal shape factor and normalisation (s); the paper: 1, 1 s.
    smoothing, smoothing_t : None, float >= 1 or "gcv"
        Spatial / temporal regression (:mod:`irdic.surface` Notes); None = interpolation.
        ``"gcv"`` chooses a spacing for the shape (the first stage) and one for
        the motion (the displacements, :func:`gcv_displacement`); ``smoothing``
        may be such a pair, as ``info`` records it (``smoothing_shape``, ``smoothing``).
    solver : {"auto", "global", "local"}
        Spatial interpolation solver (:mod:`irdic.surface` Notes).
    halo : float, optional
        Halo of the local tiles (mm).
    parametrisation : {"auto", "plane", "cylinder"}
        Used when ``psi`` is None.
    min_stage_fraction : float
        Stages with fewer valid points are left out (warned); not the reference.
    fill : {"both", "space", "time"}
        Missing points filled in space, in time (gaps of at most ``max_gap``
        stages) or both: positions and tangents in space, velocities in time
        (:mod:`irdic.surface` Notes, Missing points).
    max_gap : int
    record_times, shape_stage : array_like, optional
        For a time chunk's window of stages: the whole record's stage times
        (M_rec,) s, whose :func:`~irdic.numerics.temporal.temporal_window`
        the temporal operator uses, and the record's stage 0 (N, 3) mm, on
        which the shape is fitted when ``smoothing`` is a pair. Default
        ``times`` and the first stage of ``x``.
    operators : dict, optional
        Cache of the spatial factorisations, shared by calls on the same
        points and missing pattern (noise probes): the same dict each call.
    choose_only : bool
        Return only ``info``, the smoothing chosen as the fit records it, no surface evaluated.

    Returns
    -------
    SurfaceFields
        Duplicate DIC points (the surface parameters of an earlier point) are
        left out, warned about and listed in ``info["duplicates"]``: NaN.

    Raises
    ------
    DataError
        Fewer than 2 usable stages, too few points, non-increasing times,
        reference stage unusable.
    GeometryError
        Folded parametrisation.
    """
    t0 = _time.perf_counter()
    X, t, ks, kt, info, psi, valid, nodes, used = _checked(x, times, psi, smoothing, smoothing_t, parametrisation,
                                                            fill, max_gap, min_stage_fraction)
    M, N, _ = X.shape
    ops = {} if operators is None else operators
    sp = shared_interpolant(ops, psi[nodes], c=c, R0=R0, solver=solver, halo=halo)
    te = t if t_eval is None else np.atleast_1d(float_array(t_eval, "t_eval"))
    Xu, Vu = X[:, nodes][used], valid[:, nodes][used]
    Xs, Xt = _fill_missing(sp, Xu, Vu, t[used], te.size, ks, fill, c_t, R0_t, max_gap, info)
    record = t if record_times is None else float_array(record_times, "record_times")
    x0 = None if shape_stage is None else _shape_stage(sp, shape_stage, nodes, N)
    fields = _fit_stages(sp, psi[nodes], Xs, Xt, Vu, t[used], te, t[:1], ks, kt, c, R0, c_t, R0_t, info, record,
                         x0, ops, choose_only)
    return info if choose_only else _assemble(fields, psi, te, nodes, used, ~Vu, edge_distance(psi[nodes]), (M, N),
                                              info, (c, R0, c_t, R0_t), t0)


def _checked(x, times, psi, smoothing, smoothing_t, parametrisation, fill, max_gap, min_stage_fraction):
    """:func:`fit_surface`'s checked inputs: stages (M, N, 3) mm and times (M,) s, the spacings, ``info``, the
    parameters (N, 2), valid (M, N), the nodes fitted on and the stages used."""
    X, t, frac = _check_stages(x, times, fill, max_gap, min_stage_fraction)
    ks, kt = _smoothings(smoothing, smoothing_t)
    info = {}
    psi = _parameters(X, psi, parametrisation, info)
    valid = np.isfinite(X).all(axis=2)
    nodes = _nodes(psi, valid, info)
    return X, t, ks, kt, info, psi, valid, nodes, _used_stages(valid[:, nodes].sum(axis=1), frac, nodes.size)


def fit_stages(x, psi, *, shape_stage=None, nodes=None, c=0.95, R0=1.0, smoothing=None, solver="auto",
               operators=None, values=True):
    """Position and tangents of each stage's own surface, without the temporal operator.

    At a stage's own time :func:`fit_surface` interpolating in time
    (``smoothing_t`` None) gives exactly this: the exact temporal interpolant
    reproduces its samples, so the surface there is the spatial operator
    applied to that stage alone. Stages from different sources (noise
    probes) may be stacked; each is filled from its own valid points.

    Parameters
    ----------
    x : array_like, shape (S, N, 3)
        Stage coordinates (mm); NaN rows are missing points.
    psi : array_like, shape (N, 2)
        Surface parameters (mm).
    shape_stage : array_like, shape (N, 3) or (S, N, 3), optional
        The stage the shape is fitted on when ``smoothing`` is a (shape,
        motion) pair (:func:`fit_surface`), for all stages or one per
        stage; default ``x[0]``.
    nodes : array_like of int, optional
        The points the surface is fitted on (those of the :func:`fit_surface`
        this reproduces); default those with parameters and data in ``x``.
    c, R0, smoothing, solver, operators
        As :func:`fit_surface` (``smoothing`` a number >= 1, a (shape,
        motion) pair or None; not "gcv").
    values : bool
        Also the positions (False: ``x_fit`` None, the tangents alone at
        two thirds of the cost, as the strain's noise probes need them).

    Returns
    -------
    x_fit : ndarray, shape (S, N, 3) or None
        Position on each stage's surface (mm); NaN off the nodes.
    tangents : ndarray, shape (S, N, 2, 3)
        ``a_alpha = dx/dPsi^alpha`` (dimensionless).
    """
    X = float_array(x, "x")
    if X.ndim != 3 or X.shape[2] != 3:
        raise ConfigError(f"x must have shape (stages, points, 3), got {X.shape}")
    if np.isinf(X).any():
        raise DataError("x: infinite coordinate; missing points must be NaN")
    S, N, _ = X.shape
    psi = _parameters(X, psi, "auto", {})
    if isinstance(smoothing, tuple):
        kg, ks = _smoothings(smoothing, None)[0]
    else:
        kg, ks = None, smoothing_factor(smoothing, "smoothing", allow_gcv=False)
    nodes = _nodes(psi, np.isfinite(X).all(axis=2), {}) if nodes is None else np.asarray(nodes, dtype=np.int64)
    n = nodes.size
    sp = shared_interpolant({} if operators is None else operators, psi[nodes], c=c, R0=R0, solver=solver)
    Xn = X[:, nodes]
    Xs = sp.fill(Xn, np.isfinite(Xn).all(axis=2))[0]
    x0 = Xs[:1] if shape_stage is None else float_array(shape_stage, "shape_stage").reshape(-1, N, 3)[:, nodes]
    if x0.shape[0] not in (1, S):
        raise ConfigError(f"shape_stage must have shape ({N}, 3) or ({S}, {N}, 3), got {np.shape(shape_stage)}")
    # stacked probes repeat one shape stage for all their stages: each distinct one is filled and fitted once
    changed = np.r_[True, np.any((x0[1:] != x0[:-1]) & ~(np.isnan(x0[1:]) & np.isnan(x0[:-1])), axis=(1, 2))]
    shape_of = np.cumsum(changed) - 1 if x0.shape[0] > 1 else None
    x0 = x0[changed]
    if shape_stage is not None:
        x0 = sp.fill(x0, np.isfinite(x0).all(axis=2))[0]
    val, d1, d2, _ = _spatial_fields(sp, psi[nodes], Xs.transpose(1, 0, 2).reshape(n, 3 * S),
                                     x0.transpose(1, 0, 2).reshape(n, -1), ks, kg, c, R0, operators, shape_of,
                                     values)
    x_fit = None
    if values:
        x_fit = np.full((S, N, 3), np.nan)
        x_fit[:, nodes] = val.reshape(n, S, 3).transpose(1, 0, 2)
    tangents = np.full((S, N, 2, 3), np.nan)
    tangents[:, nodes, 0] = d1.reshape(n, S, 3).transpose(1, 0, 2)
    tangents[:, nodes, 1] = d2.reshape(n, S, 3).transpose(1, 0, 2)
    return x_fit, tangents


def _smoothings(smoothing, smoothing_t):
    """Checked spatial smoothing (a number, "gcv" or a (shape, motion) pair) and temporal smoothing."""
    if isinstance(smoothing, tuple) and len(smoothing) == 2:
        # (shape, motion): the spacings GCV chose for the reference and the displacement, frozen
        ks = tuple(smoothing_factor(k, "smoothing", allow_gcv=False) for k in smoothing)
    else:
        ks = smoothing_factor(smoothing, "smoothing")
    return ks, smoothing_factor(smoothing_t, "smoothing_t")


def _parameters(X, psi, parametrisation, info):
    """The surface parameters (N, 2): given (checked) or from the stages ``X`` (M, N, 3)."""
    if psi is None:
        psi, info["parametrisation"] = surface_parameters(X, parametrisation)
        return psi
    psi = psi_array(psi, "psi")
    if psi.shape[0] != X.shape[1]:
        raise ConfigError(f"psi has {psi.shape[0]} rows but x has {X.shape[1]} points")
    return psi


def _shape_stage(sp, shape_stage, nodes, N):
    """The stage the shape is fitted on, at the nodes, missing points filled in space (n, 3)."""
    s0 = float_array(shape_stage, "shape_stage")
    if s0.shape != (N, 3):
        raise ConfigError(f"shape_stage must have shape (points, 3) = ({N}, 3), got {s0.shape}")
    s0 = s0[nodes]
    return sp.fill(s0[None], np.isfinite(s0).all(axis=1)[None])[0][0]


def gcv_displacement(psi, X, valid=None, *, c=0.95, R0=1.0):
    """GCV centre spacing of the surface regression, judged on the displacements from the first stage.

    Parameters
    ----------
    psi : ndarray, shape (n, 2)
        Surface parameters of the points (mm).
    X : ndarray, shape (M, n, 3)
        Filled stage coordinates (mm), M >= 2.
    valid : ndarray of bool, shape (M, n), optional
        Entries measured (not filled). GCV is judged on the points measured
        in the first and in every pooled stage when they are at least half of
        the points: a filled value is the interpolant of its noisy
        neighbours, not a noisy sample, and would bias GCV towards narrow
        spacings (tube, 1 % failed points per stage: 3.5 spacings instead of 5).
    c, R0 : float
        Spatial kernel.

    Returns
    -------
    k : float
    table : list of (k, n_parameters, gcv)
        As :func:`gcv_spatial`, over :data:`SURFACE_CANDIDATES`.

    Notes
    -----
    The strain depends on the tangents only through ``a_ab - A_ab``; with one
    linear operator for all stages that is the operator applied to the
    displacement ``u = x - x_0`` (plus products with the reference tangents),
    so the displacement's approximation error is what matters. The positions
    themselves carry the specimen's curvature, which flat regression kernels
    with few centres cannot follow: GCV on positions stops at a spacing where
    that geometric residual equals the noise and leaves the strain noisy. On
    the tube (R 15 mm, 0.8 mm grid, 0.003 mm noise) GCV on positions chose
    2.5 spacings (strain error 1.5e-3 RMS), on displacements 5 (3.9e-4); on a
    static specimen the displacement is noise only and GCV takes the widest
    spacing, so the strain stays at its noise floor. Up to 8 stages after the
    first, spread over the record, are pooled.
    """
    M, n = X.shape[:2]
    pick = np.unique(np.linspace(1, M - 1, min(M - 1, 8)).astype(int))
    rows = np.arange(n)
    if valid is not None:
        measured = np.flatnonzero(valid[0] & valid[pick].all(axis=0))
        if measured.size >= max(n // 2, MIN_POINTS):
            rows = measured
    U = (X[pick][:, rows] - X[0][rows]).transpose(1, 0, 2).reshape(rows.size, -1)
    return gcv_spatial(psi[rows], U, c=c, R0=R0, candidates=SURFACE_CANDIDATES)


def _fit_stages(sp, psi_n, Xs, Xt, Vu, tu, te, t_ref, ks, kt, c, R0, c_t, R0_t, info, record, x0=None, ops=None,
                choose_only=False):
    """Temporal then spatial operator on the filled stage data: value, d1, d2 (n, 3 T_ok + 3), velocity, ok times
    (``choose_only``: None, the smoothing chosen in ``info``)."""
    n = psi_n.shape[0]
    # --- the smoothing
    if kt == "gcv":
        kt, info["gcv_t"] = gcv_temporal(tu, Xt.reshape(tu.size, -1), c=c_t, R0=R0_t)
    kg = None
    if ks == "gcv":
        pick = np.linspace(0, tu.size - 1, min(tu.size, 8)).astype(int)
        kg, info["gcv_shape"] = gcv_spatial(psi_n, Xs[pick].transpose(1, 0, 2).reshape(n, -1), c=c, R0=R0)
        ks, info["gcv"] = gcv_displacement(psi_n, Xs, Vu, c=c, R0=R0)
    elif isinstance(ks, tuple):
        kg, ks = ks
    if choose_only:
        info.update(smoothing=float(ks), smoothing_t=float(kt))
        if kg is not None:
            info["smoothing_shape"] = float(kg)
        return None
    # --- temporal
    ts = TemporalInterpolant(tu, c=c_t, R0=R0_t, smoothing=kt,
                             window=temporal_window(record, c=c_t, R0=R0_t, smoothing=kt))
    Y0, Y1, Yr, ok_t = _temporal_columns(ts, te, t_ref, Xs, Xt)
    # --- spatial
    cols = np.flatnonzero(np.repeat(ok_t, 3))
    Yall = np.concatenate([Y0[:, cols], Yr], axis=1)
    del Y0  # the stage data of many times are large: free each as soon as it is used
    x0 = Xs[0] if x0 is None else x0
    val, d1, d2, sp_motion = _spatial_fields(sp, psi_n, Yall, x0, ks, kg, c, R0, ops)
    del Yall
    # the velocity's temporal weights sum to 0: it is a displacement rate, the motion's operator alone
    vel = sp_motion.evaluate(Y1[:, cols], derivatives=False)[0]
    del Y1
    info.update(sp_motion.info)
    info.update(smoothing=float(ks), smoothing_t=float(kt))
    if kg is not None:
        info["smoothing_shape"] = float(kg)
    return val, d1, d2, vel, np.flatnonzero(ok_t)


def _spatial_fields(sp, psi_n, Y, x0, ks, kg, c, R0, ops, shape_of=None, values=True):
    """Value and ``d/dPsi^alpha`` (n, 3 m) of stage columns ``Y`` (n, 3 m: x, y, z of m stages side by side).

    ``ks``: the spacing of the spatial operator (1: ``sp``, the
    interpolation); with a shape spacing ``kg`` other than ``ks`` the shape
    and the motion are regressed apart, ``x = S_shape x0 + S_motion (x -
    x0)``, ``x0`` (n, 3) the shape stage of all, or (n, 3 u) ``u`` shape
    stages with ``shape_of`` (m,) int the one of each stage (None: one per
    stage, in order). ``Y`` is overwritten. Returns ``val, d1, d2`` (``val``
    None without ``values``) and the motion's operator.
    """
    ops = {} if ops is None else ops
    sp_motion = shared_interpolant(ops, psi_n, c=c, R0=R0, smoothing=ks) if ks > 1.0 else sp
    split = kg is not None and kg != ks
    m = Y.shape[1] // 3
    if shape_of is None:
        shape_of = np.zeros(m, int) if np.shape(x0)[1] == 3 else np.arange(m)

    def per_stage(a):  # (n, 3 u) -> (n, 3 m), each stage's shape stage
        return a.reshape(a.shape[0], -1, 3)[:, shape_of].reshape(a.shape[0], -1)

    if split:
        # the temporal weights of a value sum to 1 ({1, t} are reproduced), so columns minus x0 are displacements
        Y -= per_stage(x0)
    val, d1, d2 = sp_motion.evaluate(Y, value=values)
    if split:
        sp_shape = shared_interpolant(ops, psi_n, c=c, R0=R0, smoothing=kg) if kg > 1.0 else sp
        for a, b in zip((val, d1, d2), sp_shape.evaluate(x0, value=values)):
            if a is not None:
                a += per_stage(b)
    return val, d1, d2, sp_motion


def _assemble(fields, psi, te, nodes, used, was_filled, ed_nodes, shape, info, kernel, t0):
    """The :class:`SurfaceFields` of all N points from the results at the nodes."""
    M, N = shape
    c, R0, c_t, R0_t = kernel
    val, d1, d2, vel, tk = fields
    x_out, tang, v_out, ref_x, ref_t = _place_fields(val, d1, d2, vel, tk, nodes, te.size, N)
    filled = np.zeros((M, N), bool)
    filled[np.ix_(np.flatnonzero(used), nodes)] = was_filled
    ed = np.full(N, np.nan)
    ed[nodes] = ed_nodes
    info.update(
        c=float(c), R0=float(R0), c_t=float(c_t), R0_t=float(R0_t),
        n_nodes=int(nodes.size), n_filled=int(was_filled.sum()), stages_used=int(used.sum()),
        seconds=_time.perf_counter() - t0,
    )
    log.info("surface: %d points x %d times in %.1f s", nodes.size, te.size, info["seconds"])
    return SurfaceFields(psi, te, x_out, tang, v_out, ref_x, ref_t, filled, used, ed, info)


def _check_stages(x, times, fill, max_gap, min_stage_fraction):
    """Checked stage coordinates (M, N, 3), stage times (M,) and the stage fraction."""
    X = float_array(x, "x")
    if X.ndim != 3 or X.shape[2] != 3:
        raise ConfigError(f"x must have shape (stages, points, 3), got {X.shape}")
    M = X.shape[0]
    t = increasing_times(times, "times", "stages")
    if t.size != M:
        raise ConfigError(f"times has {t.size} entries but x has {M} stages")
    if M < 2:
        raise DataError(f"x: {M} stage(s); the space-time surface needs at least 2 (monomials {{1, t}})")
    if np.isinf(X).any():
        m, n, _ = np.argwhere(np.isinf(X))[0]
        raise DataError(f"x: infinite coordinate at stage {m}, point {n}; missing points must be NaN")
    choice(fill, "fill", ("both", "space", "time"))
    as_int(max_gap, "max_gap", 1)
    frac = float(min_stage_fraction)
    if not 0 <= frac <= 1:
        raise ConfigError(f"min_stage_fraction must be in [0, 1], got {min_stage_fraction!r}")
    return X, t, frac


def _nodes(psi, valid, info):
    """Points with parameters and data, duplicates left out (listed in ``info``)."""
    nodes = np.flatnonzero(np.isfinite(psi).all(axis=1) & valid.any(axis=0))
    dup = _duplicates(psi[nodes])
    if dup.size:
        log.warning(
            "%d point(s) have the same surface parameters as an earlier point (duplicate DIC points?) "
            "and are left out (NaN): %s%s", dup.size, nodes[dup][:10].tolist(), " ..." if dup.size > 10 else "",
        )
        info["duplicates"] = nodes[dup].tolist()
        nodes = np.delete(nodes, dup)
    if nodes.size < MIN_POINTS:
        raise DataError(f"x: {nodes.size} point(s) with data and parameters; the surface needs {MIN_POINTS}")
    return nodes


def _used_stages(counts, frac, n):
    """Stages with enough valid points for the temporal fit (warned about the others)."""
    used = counts >= max(frac * n, MIN_POINTS)
    if not used[0]:
        raise DataError(
            f"stage 0 (the reference) has only {counts[0]} of {n} valid points "
            f"(min_stage_fraction = {frac:g})"
        )
    if not used.all():
        bad = np.flatnonzero(~used)
        warnings.warn(
            f"{bad.size} stage(s) with fewer than {frac:.0%} valid points left out of the temporal fit: "
            f"{bad[:10].tolist()}{' ...' if bad.size > 10 else ''}",
            IrdicWarning,
            stacklevel=3,
        )
    if used.sum() < 2:
        raise DataError("fewer than 2 usable stages")
    return used


def _fill_missing(sp, Xu, Vu, tu, T, ks, fill, c_t, R0_t, max_gap, info):
    """Space-filled and time-filled stage data: each derivative sees the fill that is smooth along it."""
    if ks == 1.0:
        # one pass over the tiles gives the fill rows of G and the derivative weights
        chosen, tiles = sp.resolve(Xu.shape[1], 3 * T + 3, 2, sp.psi)
        sp.info["solver"] = chosen
        if chosen == "local":
            sp.local_pass(np.flatnonzero((~Vu).any(axis=0)), tiles=tiles)
    Xs = sp.fill(Xu, Vu)[0] if fill != "time" else None
    by_time = np.zeros_like(Vu)
    Xt = Xs
    if fill != "space":
        Xt, by_time = _temporal_fill(Xu, Vu, tu, c_t, R0_t, max_gap)
        if (~(Vu | by_time)).any():
            Xt = sp.fill(Xt, Vu | by_time)[0]
    if fill == "time":
        Xs = Xt
    info["filled_in_time"] = int(by_time.sum())
    info["filled_in_space"] = int((~Vu).sum() - (by_time.sum() if fill == "time" else 0))
    return Xs, Xt


def _temporal_columns(ts, te, t_ref, Xs, Xt):
    """Stage data combined in time, (points, 3 T) per functional: value, d/dt, reference; times in span."""
    W0 = ts.weights(te, 0)
    W1 = ts.weights(te, 1)
    Wr = ts.weights(t_ref, 0)
    M, n, _ = Xs.shape
    T = te.size
    # (stages, points, 3) -> (points, 3 * T): one spatial operator for all columns
    flat = Xs.reshape(M, n * 3)
    with np.errstate(invalid="ignore"):
        Y0 = (W0 @ flat).reshape(T, n, 3).transpose(1, 0, 2).reshape(n, T * 3)
        Y1 = (W1 @ Xt.reshape(M, n * 3)).reshape(T, n, 3).transpose(1, 0, 2).reshape(n, T * 3)
    Yr = (Wr @ flat).reshape(n, 3)
    return Y0, Y1, Yr, np.isfinite(W0).all(axis=1)


def _place_fields(val, d1, d2, vel, tk, nodes, T, N):
    """Spatial results (n, 3 T_ok [+ 3 reference]) into the (T, N, ...) output arrays."""
    n = nodes.size

    def place(arr, out=None, sub=None):
        block = arr.reshape(n, tk.size, 3).transpose(1, 0, 2)
        if out is None:
            out = np.full((T, N, 3), np.nan)
            out[np.ix_(tk, nodes)] = block
        else:
            out[np.ix_(tk, nodes, [sub])] = block[:, :, None, :]
        return out

    x_out = place(val[:, :-3])
    v_out = place(vel)
    tang = np.full((T, N, 2, 3), np.nan)
    place(d1[:, :-3], tang, 0)
    place(d2[:, :-3], tang, 1)
    ref_x = np.full((N, 3), np.nan)
    ref_x[nodes] = val[:, -3:]
    ref_t = np.full((N, 2, 3), np.nan)
    ref_t[nodes, 0] = d1[:, -3:]
    ref_t[nodes, 1] = d2[:, -3:]
    return x_out, tang, v_out, ref_x, ref_t
