"""Laplace–Beltrami operator of the temperature on the current surface, with its uncertainty.

The temperature of each time is regressed in the surface parameters Ψ
(IMQ centres on a subset of the points, :func:`irdic.surface.regression.ls_design`),
the surface positions of the same time by the same design, and the operator

    Δ_s Θ = a^{αβ} (∂²Θ/∂Ψ^α∂Ψ^β − Γ^γ_{αβ} ∂Θ/∂Ψ^γ),   Γ^γ_{αβ} = a^γ · ∂²x/∂Ψ^α∂Ψ^β,

is evaluated from the closed-form first and second derivatives of the two
regressions. The Ψ are Lagrangian, so one QR factorisation serves every time
and both fields. The centre spacing is chosen by the estimated risk of the
Laplacian (:func:`irdic.surface.regression.laplacian_risk_spatial`), each
point's series is regressed in time (:func:`smooth_in_time`), and the
regression's bias is estimated from its differences to the regressions at
nearby spacings (:func:`laplacian_bias`) and added to the std
(:func:`with_bias`).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from ..errors import DataError, GeometryError
from ..surface import edge_distance, shared_interpolant
from ..surface.parametrisation import MIN_POINTS, median_spacing
from ..surface.regression import hessian_operator, laplacian_risk_spatial, ls_design
from ..validation import float_array, psi_array

__all__ = ["Laplacian", "laplace_beltrami", "surface_laplacian", "smooth_in_time", "laplacian_bias",
           "with_bias", "JUDGED_MARGIN", "TIME_CANDIDATES", "REFERENCE_RATIO", "BIAS_REACH"]

log = logging.getLogger(__name__)

#: The noise level and the spacing are judged on points more than this many point spacings inside the cloud's
#: edge: the rim's data carry more than noise (mixed edge pixels, extrapolated temperatures).
JUDGED_MARGIN = 3.0


#: Points the Laplacian's risk criterion judges at most (:func:`~irdic.surface.regression.laplacian_risk_spatial`;
#: the gradient's 4,000 is a round patch too small for the wide spacings a noise-dominated Laplacian needs: 63 points
#: across on the paper-scale moving tube, 0.25 mm apart, where the widest candidate, 32 spacings, is 8 mm).
RISK_MAX_POINTS = 16000


#: Centre spacings (DIC times) GCV tries for the Laplacian's regression in time (:func:`smooth_in_time`). The
#: per-time Laplacian is noise-dominated, so GCV of the series alone goes to the widest spacing it may (12-16
#: DIC times on the demo tube and half-shell), where the temporal bias outgrows the std that the regression
#: shrinks: on the realistic half-shell the source's std covered 0.27 / 0.49 of its errors within 1 / 2 std at
#: 16, 0.35 / 0.62 at 4, for the same accuracy (tube Laplacian 10.7 % at 12, 10.1 % at 4).
TIME_CANDIDATES = (1.5, 2.0, 3.0, 4.0)

#: The references of the Laplacian's bias estimate (:func:`laplacian_bias`): the regressions at these fractions of
#: the chosen centre spacing. At the spacings the risk criterion picks, the Laplacian's approximation error is a
#: ripple of the centres whose size hardly changes with the spacing, uncorrelated from one spacing to another (on
#: the true temperatures of the demo half-shell R 65 mm: 2.2e-3, 2.0e-3 and 2.2e-3 K/mm² RMS at 5, 4 and 2.5
#: spacings; the difference at 5 and 2.5, 1.6 times either). Spacings near the chosen one keep the difference's
#: noise close to the regression's own, so a bias of the order of the noise is resolved; half the spacing (8 times
#: the noise in its Laplacian) also passes more of the data's persistent errors, the coupling's and the mixed
#: pixels': the half-shells' estimates were twice the error, the tube's four times. Two references, the smaller
#: estimate: a reference whose ripple happens to be the larger doubles the other's (the sphere cap and the moving
#: tube of the benchmark's point clouds, 10 spacings: 0.81 and 0.86 of the errors within 1 std with 0.8 alone,
#: 0.70 and 0.68 with both); within one centre spacing of the edge the larger (the paper-scale R 65 mm
#: half-shell: 0.57 / 0.85 of the errors within 1 / 2 std with the smaller there, 0.64 / 0.89 with the larger).
REFERENCE_RATIO = (0.8, 1.25)

#: Where a point's neighbours do not resolve the bias, :func:`laplacian_bias` averages over the points within this
#: many centre spacings (at most :data:`irdic.uncertainty.regression_bias.WIDE_MAX`), not over the whole specimen:
#: a hot feature's bias stays on the feature, and the specimen's average spread it where there was none (the
#: demo's 4 mm hot band: 0.84 of the source's errors within 1 std, 0.72 so; the other scenes within 0.03).
BIAS_REACH = 3.0


class Laplacian(NamedTuple):
    """Result of :func:`surface_laplacian`."""

    laplacian: np.ndarray
    """``Δ_s Θ`` (T, N), K/mm²; NaN where the temperature is missing."""
    std: np.ndarray
    """Its standard uncertainty from the temperature noise (T, N), K/mm²."""
    spacing: float
    """The centre spacing used, in median point spacings."""
    noise: np.ndarray
    """The temperature noise estimated from each time's regression residual (T,), K."""
    table: list
    """The risk criterion's ``(spacing, parameters, risk K²/mm⁴)`` rows; empty for a given spacing."""


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def laplace_beltrami(d_theta, h_theta, tangents, second):
    """The Laplace–Beltrami operator from the parameter derivatives of the temperature and the surface.

    Parameters
    ----------
    d_theta : array_like, shape (..., 2)
        ``∂Θ/∂Ψ^1``, ``∂Θ/∂Ψ^2`` (K/mm).
    h_theta : array_like, shape (..., 3)
        ``∂²Θ/∂Ψ1²``, ``∂²Θ/∂Ψ1∂Ψ2``, ``∂²Θ/∂Ψ2²`` (K/mm²).
    tangents : array_like, shape (..., 2, 3)
        ``a_α = ∂x/∂Ψ^α`` (dimensionless).
    second : array_like, shape (..., 3, 3)
        ``∂²x/∂Ψ1²``, ``∂²x/∂Ψ1∂Ψ2``, ``∂²x/∂Ψ2²`` (1/mm), each a 3-vector.

    Returns
    -------
    laplacian : ndarray, shape (...)
        ``Δ_s Θ`` (K/mm²); NaN where the tangents are degenerate.
    weights : ndarray, shape (..., 5)
        ``w`` with ``Δ_s Θ = w · (Θ_1, Θ_2, Θ_11, Θ_12, Θ_22)``: the operator's
        coefficients, for propagating the derivatives' covariance.

    Notes
    -----
    With the metric ``a_αβ = a_α · a_β``, its inverse ``a^{αβ}`` and the dual
    vectors ``a^γ = a^{γδ} a_δ``, the contraction
    ``C^γ = a^{αβ} Γ^γ_{αβ} = a^γ · (a^{αβ} ∂²x/∂Ψ^α∂Ψ^β)`` gives
    ``w = (−C^1, −C^2, a^{11}, 2 a^{12}, a^{22})``.
    """
    t = float_array(tangents, "tangents")
    x2 = float_array(second, "second")
    a1, a2 = t[..., 0, :], t[..., 1, :]
    g11, g12, g22 = _dot(a1, a1), _dot(a1, a2), _dot(a2, a2)
    with np.errstate(invalid="ignore", divide="ignore"):
        det = g11 * g22 - g12 * g12
        det = np.where(det > 1e-12 * g11 * g22, det, np.nan)
        i11, i12, i22 = g22 / det, -g12 / det, g11 / det
    d1 = i11[..., None] * a1 + i12[..., None] * a2  # dual vectors a^1, a^2
    d2 = i12[..., None] * a1 + i22[..., None] * a2
    contracted = i11[..., None] * x2[..., 0, :] + 2.0 * i12[..., None] * x2[..., 1, :] + i22[..., None] * x2[..., 2, :]
    w = np.stack([-_dot(d1, contracted), -_dot(d2, contracted), i11, 2.0 * i12, i22], axis=-1)
    derivs = np.concatenate([float_array(d_theta, "d_theta"), float_array(h_theta, "h_theta")], axis=-1)
    return _dot(w, derivs), w


def _filled(ops, p, values, valid, c, R0):
    """``values`` (T, n, ...) with the missing entries of each time filled by that time's interpolant."""
    if valid.all():
        return values
    return shared_interpolant(ops, p, c=c, R0=R0).fill(values, valid)[0]


def _judged(p):
    judged = edge_distance(p) >= JUDGED_MARGIN * median_spacing(p)
    return judged if judged.sum() >= MIN_POINTS else np.ones(p.shape[0], bool)


def _choose_spacing(p, theta, judged, c, R0, separation):
    sample = theta[np.linspace(0, theta.shape[0] - 1, min(theta.shape[0], 8)).astype(int)].T
    k, table = laplacian_risk_spatial(p, sample, c=c, R0=R0, judged=judged, separation=separation,
                                      max_points=RISK_MAX_POINTS)
    log.info("temperature Laplacian: the estimated risk chose %.1f point spacings", k)
    return k, table


def _noise(theta, Q, visible, judged):
    """Noise (T,) from each time's residual over its visible judged points (K)."""
    resid = theta - (theta @ Q) @ Q.T
    use = visible & judged
    lever = 1.0 - np.sum(Q * Q, axis=1)
    dof = np.maximum((use * lever).sum(axis=1), 1.0)
    return np.sqrt(np.sum(np.where(use, resid, 0.0) ** 2, axis=1) / dof)


def _block_laplacian(M, Mx, coef, coef_x, noise):
    """Laplacian and std (T, nb) of one block of points; ``M``, ``Mx`` (5, nb, p) the derivative rows of the
    temperature's and the surface's designs, their coefficients (p, T) and (p, T, 3)."""
    nb = M.shape[1]
    dth = np.einsum("knp,pt->tnk", M, coef)
    dx = np.einsum("knp,ptc->tnkc", Mx, coef_x)
    lap, w = laplace_beltrami(dth[..., :2], dth[..., 2:], dx[:, :, :2], dx[:, :, 2:])
    gram = np.einsum("knp,lnp->nkl", M, M)
    var = np.einsum("tnk,nkl,tnl->tn", w, gram, w)
    return lap, noise[:, None] * np.sqrt(np.maximum(var, 0.0)), nb


def _evaluate(p, design, design_x, theta, x, noise, c, R0):
    """Laplacian and std (T, n) at the points ``p`` of the regressions of ``theta`` (T, n) with the QR
    ``design`` and of ``x`` (T, n, 3) with ``design_x``, in blocks of points."""
    coef = design[3].T @ theta.T  # (p, T); the rows of hessian_operator hold R⁻¹
    coef_x = np.einsum("np,tnc->ptc", design_x[3], x)
    T, n = theta.shape
    lap, std = np.empty((T, n)), np.empty((T, n))
    nb = int(np.clip((1 << 21) // (20 * T), 1, 2048))  # points per block: ~16 MB of derivatives
    for s in range(0, n, nb):
        M = hessian_operator(p[s:s + nb], design, c, R0)
        Mx = M if design_x is design else hessian_operator(p[s:s + nb], design_x, c, R0)
        lap[:, s:s + nb], std[:, s:s + nb], _ = _block_laplacian(M, Mx, coef, coef_x, noise)
    return lap, std


def surface_laplacian(psi, theta, x, *, spacing="auto", c=0.95, R0=1.0, separation=None, ops=None) -> Laplacian:
    """Δ_s Θ of the point temperatures on the current surface, with its standard uncertainty.

    Parameters
    ----------
    psi : array_like, shape (N, 2)
        Surface parameters (mm); NaN rows give NaN.
    theta : array_like, shape (T, N)
        Point temperatures (degC; NaN where not seen), white noise in space.
    x : array_like, shape (T, N, 3)
        Current positions of the points (mm), e.g. the fitted surface of the fields stage.
    spacing : "auto" or float > 1
        Centre spacing of the regression in median point spacings; "auto":
        :func:`~irdic.surface.regression.laplacian_risk_spatial` on up to 8 times.
    c, R0 : float
        IMQ kernel (as the fields stage's ``c_space``, ``R0_space``).
    separation : float, optional
        Distance (mm) below which the temperature noise is correlated (one IR pixel).
    ops : dict, optional
        A cache of spatial operators (:func:`irdic.surface.shared_interpolant`).

    Returns
    -------
    Laplacian

    Notes
    -----
    The regression is linear in the data: ``Δ_s Θ_i = w_i · M_i R⁻¹ Qᵀ Θ``
    with ``M_i`` the five derivative rows of the design at point ``i``.
    White noise of variance σ² gives ``var = σ² w_iᵀ (M_i M_iᵀ) w_i``
    (``Q`` has orthonormal columns); σ comes from each time's residual over
    the points inside the rim, corrected for the hat matrix's leverage.
    The surface's own noise (DIC, through the metric and the Christoffel
    symbols) is left out: with first derivatives of the temperature of
    order 1 K/mm it is orders of magnitude below the temperature's.
    Missing temperatures of a time are filled by that time's interpolant
    before the regression; their Laplacian is NaN.
    """
    p_all = psi_array(psi, "psi")
    th = float_array(theta, "theta")
    xx = float_array(x, "x")
    T, N = th.shape
    if p_all.shape[0] != N or xx.shape != (T, N, 3):
        raise DataError(f"psi {p_all.shape}, theta {th.shape} and x {xx.shape} disagree on (T, N)")
    ops = {} if ops is None else ops
    have = np.isfinite(p_all).all(axis=1)
    p = p_all[have]
    visible = np.isfinite(th[:, have])
    good = visible.sum(axis=1) >= MIN_POINTS
    lap = np.full((T, N), np.nan)
    std = np.full((T, N), np.nan)
    noise = np.full(T, np.nan)
    if p.shape[0] < 2 * MIN_POINTS or not good.any():
        log.warning("temperature Laplacian: too few points with a temperature; left NaN")
        return Laplacian(lap, std, float("nan"), noise, [])
    tt = np.flatnonzero(good)
    th_f = _filled(ops, p, th[np.ix_(tt, have)], visible[tt], c, R0)
    x_in = xx[tt][:, have]
    x_ok = np.isfinite(x_in).all(axis=2)
    x_f = _filled(ops, p, x_in, x_ok, c, R0)
    judged = _judged(p)
    table = []
    if spacing == "auto":
        k, table = _choose_spacing(p, th_f, judged, c, R0, separation)
    else:
        k = float(spacing)
    h = median_spacing(p)
    design = ls_design(p, k, h, c, R0)
    noise[tt] = _noise(th_f, design[3], visible[tt], judged)
    lb, sb = _evaluate(p, design, design, th_f, x_f, noise[tt], c, R0)
    cols = np.flatnonzero(have)
    lap[tt[:, None], cols], std[tt[:, None], cols] = lb, sb
    lap[~np.isfinite(th)] = np.nan
    std[~np.isfinite(lap)] = np.nan
    return Laplacian(lap, std, k, noise, table)


def smooth_in_time(result: Laplacian, times, smoothing="gcv", *, c=1.0, R0=1.0) -> tuple[Laplacian, float]:
    """The Laplacian regressed in time along each point's series, its std propagated.

    Parameters
    ----------
    result : Laplacian
        Of :func:`surface_laplacian`.
    times : array_like, shape (T,)
        DIC times (s).
    smoothing : "gcv", None or float >= 1
        Centre spacing in time (stages); "gcv": :func:`irdic.numerics.temporal.gcv_temporal` among
        :data:`TIME_CANDIDATES` on the series of the points that have a Laplacian at every time; None: unchanged.
    c, R0 : float
        Temporal IMQ kernel (the fields stage's ``c_time``, ``R0_time``).

    Returns
    -------
    (Laplacian, k)
        ``k`` the spacing used (1.0: unchanged). Points without a Laplacian at
        some time keep their per-time values.

    Notes
    -----
    The IR noise is white in time, so the per-time Laplacians' errors are
    independent between times and the regression ``W`` (T, T) gives
    ``var_t = Σ_j W_tj² var_j``. Second derivatives in space carry the
    noise amplified by ``1/H²``; the temperature changes slowly against the
    DIC rate on most tests, so the time regression removes most of that
    noise at a small temporal bias.
    """
    from ..numerics.temporal import TemporalInterpolant, gcv_temporal

    t = float_array(times, "times")
    lap, std = result.laplacian, result.std
    full = np.isfinite(lap).all(axis=0) & np.isfinite(std).all(axis=0)
    if smoothing is None or t.size < 4 or not full.any():
        return result, 1.0
    k = gcv_temporal(t, lap[:, full], c=c, R0=R0, candidates=TIME_CANDIDATES)[0] if smoothing == "gcv" \
        else float(smoothing)
    if k <= 1.0:
        return result, 1.0
    W = TemporalInterpolant(t, c=c, R0=R0, smoothing=k).weights(t)
    lap, std = lap.copy(), std.copy()
    lap[:, full] = W @ result.laplacian[:, full]
    std[:, full] = np.sqrt((W ** 2) @ result.std[:, full] ** 2)
    log.info("temperature Laplacian: regressed in time, centres every %.3g stages", k)
    return result._replace(laplacian=lap, std=std), k


def _difference(p, design, ref, th, x, c, R0):
    """The Laplacian of the regression ``design`` minus that of ``ref``, both on ``design``'s surface.

    ``th`` (S, T, n): S series of T times (the data, then noise probes); ``x`` (T, n, 3). Returns the
    difference (S, T, n) and its variance per unit white noise (T, n), ``‖r_k − r_ref‖²`` of the two rows.
    """
    S, T, n = th.shape
    flat = th.reshape(S * T, n).T
    coef, coef_r = design[3].T @ flat, ref[3].T @ flat
    coef_x = np.einsum("np,tnc->ptc", design[3], x)
    cross = design[3].T @ ref[3]
    diff, var = np.empty((S, T, n)), np.empty((T, n))
    nb = int(np.clip((1 << 21) // (20 * S * T), 1, 1024))
    for s in range(0, n, nb):
        pb = p[s:s + nb]
        M, Mr = hessian_operator(pb, design, c, R0), hessian_operator(pb, ref, c, R0)
        dx = np.einsum("knp,ptc->tnkc", M, coef_x)
        dth = np.einsum("knp,pt->tnk", M, coef).reshape(S, T, -1, 5)
        dth_r = np.einsum("knp,pt->tnk", Mr, coef_r).reshape(S, T, -1, 5)
        _, w = laplace_beltrami(dth[0, ..., :2], dth[0, ..., 2:], dx[:, :, :2], dx[:, :, 2:])
        diff[:, :, s:s + nb] = _dot(w[None], dth - dth_r)
        X = np.einsum("knq,lnq->nkl", np.einsum("knp,pq->knq", M, cross), Mr)
        G = np.einsum("knp,lnp->nkl", M, M) + np.einsum("knp,lnp->nkl", Mr, Mr) - X - np.swapaxes(X, 1, 2)
        var[:, s:s + nb] = np.maximum(np.einsum("tnk,nkl,tnl->tn", w, G, w), 0.0)
    return diff, var


def laplacian_bias(psi, theta, x, result: Laplacian, times, k_time=1.0, *, c=0.95, R0=1.0, c_t=1.0, R0_t=1.0,
                   ops=None, seed=0):
    """Local RMS of the spatial regression's bias in the Laplacian of :func:`surface_laplacian` (after the
    regression in time of :func:`smooth_in_time`, spacing ``k_time``), K/mm².

    Parameters
    ----------
    psi, theta, x, c, R0, ops
        As :func:`surface_laplacian`; ``result`` its result (the spacing and the noise level); ``seed`` the probes'.
    times : array_like, shape (T,)
        DIC times (s); ``k_time`` the regression in time's spacing (1: none), ``c_t``, ``R0_t`` its kernel.

    Returns
    -------
    ndarray, shape (T, N)
        The bias estimate; 0 where not resolved, NaN where the Laplacian is NaN.

    Notes
    -----
    The references are the same regression at :data:`REFERENCE_RATIO` times
    the spacing, on the same surface; their centres are other subsets of the
    points, so a difference ``d`` holds both regressions' approximation
    errors (at the chosen spacings a ripple of the centres, alike in size
    and uncorrelated from one spacing to another) and the part of both
    noises that differs. As for the gradient
    (:func:`irdic.uncertainty.regression_bias.reference_options`) the bias
    squared is :data:`~irdic.uncertainty.regression_bias.REFERENCE_SHARE` of
    ``<d² − var d>``; of the two references the smaller estimate counts,
    except within one centre spacing of the cloud's edge, where the
    one-sided fit's bias grows with the spacing and the references share it:
    there the larger. ``d`` is regressed in time as the Laplacian is (the
    bias persists, the noise does not), then
    :func:`~irdic.uncertainty.regression_bias.local_bias` averages
    ``d² − var d`` locally, keeps it where it exceeds its scatter on
    :data:`~irdic.uncertainty.probes.BIAS_PROBES` noise probes through the
    same operators, and where no neighbourhood resolves it averages over the
    points within :data:`BIAS_REACH` centre spacings. ``var d = σ² ‖r_k −
    r_ref‖²`` of the two regressions' rows, exact.
    """
    from ..numerics.temporal import TemporalInterpolant
    from ..uncertainty.probes import BIAS_PROBES

    p_all = psi_array(psi, "psi")
    th = float_array(theta, "theta")
    T, N = th.shape
    out = np.full((T, N), np.nan)
    have = np.isfinite(p_all).all(axis=1)
    tt = np.flatnonzero(np.isfinite(result.noise))
    refs = [r * result.spacing for r in REFERENCE_RATIO if r * result.spacing > 1.0] \
        if np.isfinite(result.spacing) else []
    if not refs or tt.size == 0:
        return out
    p = p_all[have]
    th_f, x_f = _inputs({} if ops is None else ops, p, th[np.ix_(tt, have)], float_array(x, "x")[tt][:, have], c, R0)
    h = median_spacing(p)
    design = ls_design(p, result.spacing, h, c, R0)
    rng = np.random.default_rng(seed)
    sigma = result.noise[tt]
    probes = sigma[None, :, None] * rng.standard_normal((BIAS_PROBES, tt.size, p.shape[0]))
    series = np.concatenate([th_f[None], probes])
    full = np.isfinite(result.laplacian[np.ix_(tt, np.flatnonzero(have))]).all(axis=0)
    W = TemporalInterpolant(float_array(times, "times")[tt], c=c_t, R0=R0_t, smoothing=k_time).weights() \
        if k_time > 1.0 and full.any() else None
    b = None
    rim = edge_distance(p) < result.spacing * h
    for k_ref in refs:
        try:
            ref = ls_design(p, k_ref, h, c, R0)
        except GeometryError:
            log.info("temperature Laplacian: the bias reference at %.3g spacings does not fit", k_ref)
            continue
        bk = _reference_bias(p, design, ref, series, x_f, sigma, W, full, result.spacing, c, R0)
        b = bk if b is None else np.where(rim, np.maximum(b, bk), np.minimum(b, bk))
    if b is None:
        log.warning("temperature Laplacian: no bias estimate (no reference regression fits the points)")
        return np.where(np.isfinite(result.laplacian), 0.0, np.nan)
    out[tt[:, None], np.flatnonzero(have)] = b
    out[~np.isfinite(result.laplacian)] = np.nan
    return out


def _inputs(ops, p, th, x, c, R0):
    """The temperatures (T, n) and positions (T, n, 3) with their missing entries filled by each time's
    interpolant (:func:`_filled`)."""
    return _filled(ops, p, th, np.isfinite(th), c, R0), _filled(ops, p, x, np.isfinite(x).all(axis=2), c, R0)


def _reference_bias(p, design, ref, series, x, sigma, W, full, spacing, c, R0):
    """:func:`~irdic.uncertainty.regression_bias.local_bias` (T, n) of the difference of ``design`` to ``ref``
    (:func:`_difference` of ``series``: the data, then the probes), regressed in time by ``W`` (T, T; None: not)
    at the points ``full`` that have every time; ``sigma`` (T,) the noise."""
    from ..uncertainty.regression_bias import BIAS_Z, REFERENCE_SHARE, local_bias

    diff, var = _difference(p, design, ref, series, x, c, R0)
    var = var * sigma[:, None] ** 2
    if W is not None:
        diff[:, :, full] = np.einsum("ts,ksn->ktn", W, diff[:, :, full])
        var[:, full] = (W ** 2) @ var[:, full]
    return local_bias(diff[0], var, p, null=np.square(diff[1:]), spacing=BIAS_REACH * spacing, z=BIAS_Z,
                      share=REFERENCE_SHARE)


def with_bias(result: Laplacian, bias) -> Laplacian:
    """``result`` with the bias estimate of :func:`laplacian_bias` added to its std in quadrature."""
    b = np.where(np.isfinite(bias), bias, 0.0)
    return result._replace(std=np.sqrt(result.std ** 2 + b ** 2))
