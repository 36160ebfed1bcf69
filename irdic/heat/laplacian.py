"""Laplace–Beltrami operator of the temperature on the current surface, with its uncertainty.

The temperature of each time is regressed in the surface parameters Ψ
(IMQ centres on a subset of the points, :func:`irdic.surface.regression.ls_design`),
the surface positions of the same time by the same design, and the operator

    Δ_s Θ = a^{αβ} (∂²Θ/∂Ψ^α∂Ψ^β − Γ^γ_{αβ} ∂Θ/∂Ψ^γ),   Γ^γ_{αβ} = a^γ · ∂²x/∂Ψ^α∂Ψ^β,

is evaluated from the closed-form first and second derivatives of the two
regressions. The Ψ are Lagrangian, so one QR factorisation serves every time
and both fields. The centre spacing is chosen by the estimated risk of the
Laplacian (:func:`irdic.surface.regression.laplacian_risk_spatial`); the
temperatures a time lacks are the fit of the others (:func:`refit_missing`), a
point's few-frame spikes are left out (:func:`_noise`), the noise is
propagated with each point's own level (a mixed pixel on the rim carries
several times the IR noise), and each point's series is regressed in time
(:func:`smooth_in_time`). The regression's bias: :mod:`irdic.heat.bias`.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from ..errors import DataError
from ..surface import edge_distance, shared_interpolant
from ..surface.parametrisation import MIN_POINTS, median_spacing
from ..surface.regression import hessian_operator, laplacian_risk_spatial, ls_design
from ..validation import float_array, psi_array

__all__ = ["Laplacian", "laplace_beltrami", "surface_laplacian", "smooth_in_time", "judging_weights",
           "temporal_modes", "fill_missing",
           "refit_missing", "noise_gram", "laplacian_difference", "JUDGED_MARGIN", "TIME_CANDIDATES"]

log = logging.getLogger(__name__)

#: The noise level and the spacing are judged on points more than this many point spacings inside the cloud's
#: edge: the rim's data carry more than noise (mixed edge pixels, extrapolated temperatures).
JUDGED_MARGIN = 3.0


#: Points the Laplacian's risk criterion judges at most (:func:`~irdic.surface.regression.laplacian_risk_spatial`;
#: the gradient's 4,000 is a round patch too small for the wide spacings a noise-dominated Laplacian needs: 63 points
#: across on the paper-scale moving tube, 0.25 mm apart, where the widest candidate, 32 spacings, is 8 mm).
RISK_MAX_POINTS = 16000


#: A temporal mode is kept where its singular value exceeds this many times white noise's largest
#: (:func:`temporal_modes`).
MODE_EDGE = 1.5

#: Times a point's residual series needs off the data's temporal modes for its noise level to be read there
#: (:func:`_noise`); fewer: the whole residual.
PROFILE_MIN_DOF = 3

#: A point temperature whose residual exceeds this many times the point's own robust noise level is a spike
#: (:func:`_noise`): about one in two million Gaussian ones.
SPIKE_Z = 5.0

#: Rounds of :func:`_noise`'s spike search, each on the data without the spikes found before.
SPIKE_PASSES = 3

#: Leverage ``1 − H_ii`` below which a point's residual no longer tells its noise level (:func:`_noise`): the
#: regression nearly interpolates it.
PROFILE_MIN_LEVER = 0.2


#: Centre spacings (DIC times) GCV tries for the Laplacian's regression in time (:func:`smooth_in_time`). The
#: per-time Laplacian is noise-dominated, so GCV of the series alone goes to the widest spacing it may (12-16
#: DIC times on the demo tube and half-shell), where the temporal bias outgrows the std that the regression
#: shrinks: on the realistic half-shell the source's std covered 0.27 / 0.49 of its errors within 1 / 2 std at
#: 16, 0.35 / 0.62 at 4, for the same accuracy (tube Laplacian 10.7 % at 12, 10.1 % at 4).
TIME_CANDIDATES = (1.5, 2.0, 3.0, 4.0)

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
    profile: np.ndarray
    """Each point's noise variance relative to ``noise²`` (N,): 1 inside on average, larger where the data carry
    more than the IR noise (mixed pixels on the rim); NaN without parameters."""


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


def _nearest_filled(p, values, valid):
    """``values`` (T, n) with each missing entry taken from the nearest point visible at that time: a start
    for :func:`refit_missing` (which replaces them by the fit of the rest) and for the spacing's choice, where
    a few per cent of entries carry about the noise more (the interpolant costs 8 s of the paper-scale tube's
    42)."""
    if valid.all():
        return values
    from scipy.spatial import cKDTree

    out = values.copy()
    for t in np.flatnonzero(~valid.all(axis=1)):
        ok = valid[t]
        if ok.any():
            out[t, ~ok] = values[t, ok][cKDTree(p[ok]).query(p[~ok])[1]]
    return out


def refit_missing(theta, visible, Q):
    """``theta`` (T, n) with its missing entries replaced by the least-squares fit of the visible ones alone
    (design ``Q``, orthonormal columns).

    The interpolant's fill extrapolates the noise of the visible neighbours into the gap (at a moving
    specimen's silhouette, where points drop out and come back, up to several times the noise), and the
    regression took those values for data: the moving tube's per-time Laplacian noise was 1.25 times its std
    at the times with a gap, 0.91 at the others.

    Notes
    -----
    The fit of the visible rows ``v`` has coefficients ``(Q_vᵀ Q_v)⁻¹ Q_vᵀ θ_v``
    with ``Q_vᵀ Q_v = I − Q_mᵀ Q_m`` (``m`` the missing rows); by the Woodbury
    identity ``(I − Q_mᵀ Q_m)⁻¹ = I + Q_mᵀ (I − Q_m Q_mᵀ)⁻¹ Q_m``, an ``m × m``
    system per time (the pseudo-inverse: a combination of centres that only
    missing points support gets no coefficient).
    """
    miss = ~visible
    if not miss.any():
        return theta
    th = theta.copy()
    rows = np.flatnonzero(miss.any(axis=1))
    full = theta[rows] @ Q  # Qᵀ θ of every point, less the missing ones' below
    for t, qt in zip(rows, full):
        m = miss[t]
        Qm = Q[m]
        rhs = qt - theta[t, m] @ Qm
        evals, evecs = np.linalg.eigh(np.eye(Qm.shape[0]) - Qm @ Qm.T)
        keep = evals > 1e-10
        y = evecs[:, keep] @ ((evecs[:, keep].T @ (Qm @ rhs)) / evals[keep])
        th[t, m] = Qm @ (rhs + Qm.T @ y)
    return th


def _clean_data(theta, seen, Q, judged):
    """``(theta, sigma, profile)``: the temperatures (T, n) with the missing entries and the spikes refitted
    (:func:`refit_missing`), and the noise level (T,) and profile (n,) of :func:`_noise` without the spikes."""
    theta = refit_missing(theta, seen, Q)
    sigma, profile, spikes = _noise(theta, Q, seen, judged)
    left_out = 0
    for _ in range(SPIKE_PASSES):
        if not spikes.any():
            break
        # a few frames' errors are left out and refitted, the level read again without them (the largest
        # spikes first: many in one frame make a temporal mode of their own, which hides the others)
        left_out += int(spikes.sum())
        seen = seen & ~spikes
        theta = refit_missing(theta, seen, Q)
        sigma, profile, spikes = _noise(theta, Q, seen, judged, profile)
    if left_out:
        log.info("temperature Laplacian: %d point temperatures (%.2g %%) left out as spikes", left_out,
                 100.0 * left_out / max(seen.sum() + left_out, 1))
    return theta, sigma, profile


def _judged(p):
    judged = edge_distance(p) >= JUDGED_MARGIN * median_spacing(p)
    return judged if judged.sum() >= MIN_POINTS else np.ones(p.shape[0], bool)


def _choose_spacing(p, theta, judged, c, R0, separation):
    sample = theta[np.linspace(0, theta.shape[0] - 1, min(theta.shape[0], 8)).astype(int)].T
    k, table = laplacian_risk_spatial(p, sample, c=c, R0=R0, judged=judged, separation=separation,
                                      max_points=RISK_MAX_POINTS)
    log.info("temperature Laplacian: the estimated risk chose %.1f point spacings", k)
    return k, table


def _floored(sigma):
    """``sigma`` with its zeros (noise-free times: the first of a record heated from uniform) raised to a
    millionth of its largest (1 when all are zero), so that dividing by it stays finite."""
    top = float(np.max(sigma, initial=0.0))
    return np.maximum(sigma, 1e-6 * top) if top > 0 else np.ones_like(sigma)


def temporal_modes(theta, sigma, Q, profile=None, *, edge=MODE_EDGE):
    """The projection of each point's series on the data's leading temporal modes, as two factors.

    Parameters
    ----------
    theta : ndarray, shape (T, n)
        Point temperatures (filled), K.
    sigma : ndarray, shape (T,)
        Their noise level at each time (K).
    Q : ndarray, shape (n, p)
        The spatial regression's orthonormal design (:func:`~irdic.surface.regression.ls_design`).
    profile : ndarray, shape (n,), optional
        Each point's noise variance relative to ``sigma²`` (default 1).
    edge : float
        A mode is kept where its singular value exceeds ``edge`` times the
        largest one white noise would give, ``√T + √p``.

    Returns
    -------
    (B, C)
        ``B`` (T, r) and ``C`` (r, T): the projection is ``P = B C``; ``C θ``
        holds a series' ``r`` mode coefficients, ``B`` makes them times again.

    Notes
    -----
    The temperature of a heating pattern that evolves smoothly is a sum of a
    few products ``a_m(t) φ_m(Ψ)`` (one amplitude history per pattern), and
    so is everything linear in it that the regressions do not change from
    time to time: the regression's bias, its residual's bias. White noise
    spreads evenly over all ``T`` temporal directions, so projecting a
    point's series on the ``r`` leading ones keeps its persistent part and
    ``r/T`` of its noise, and ``I − P`` keeps noise alone. The modes are the
    left singular vectors of the regression's coefficients ``(θ / √profile) Q``
    scaled to unit noise at each time (white noise there: ``Q`` has
    orthonormal columns): a spatial linear map leaves the temporal modes as
    they are, and a point's few-frame spike, which would make a mode of its
    own frame, weighs only its leverage in the coefficients.
    """
    T = theta.shape[0]
    if T < 2:
        return np.eye(T), np.eye(T)
    sigma = _floored(sigma)
    w = theta if profile is None else theta / np.sqrt(profile)
    U, sv, _ = np.linalg.svd((w @ Q) / sigma[:, None], full_matrices=False)
    r = int(np.clip(np.sum(sv > edge * (np.sqrt(T) + np.sqrt(Q.shape[1]))), 1, T))
    Ur = U[:, :r]
    return sigma[:, None] * Ur, Ur.T / sigma[None, :]


def _noise(theta, Q, visible, judged, profile=None):
    """The data's noise: ``(sigma, profile, spikes)``.

    ``sigma`` (T,): each time's level from its residual over the visible judged points (K). ``profile`` (n,):
    each point's variance relative to it, from the part of its residual series off the data's temporal modes
    (:func:`temporal_modes`, weighed by a previous ``profile`` if given; 1 where never seen). ``spikes``
    (T, n): entries whose residual there exceeds
    :data:`SPIKE_Z` times the point's own robust level (its median absolute value, at least ``sigma``): errors
    of a few frames (a mixed pixel at a moving silhouette) that no Gaussian level describes.
    """
    resid = theta - (theta @ Q) @ Q.T
    use = visible & judged
    lever = np.maximum(1.0 - np.sum(Q * Q, axis=1), PROFILE_MIN_LEVER)
    dof = np.maximum((use * lever).sum(axis=1), 1.0)
    sigma = np.sqrt(np.sum(np.where(use, resid, 0.0) ** 2, axis=1) / dof)
    T = theta.shape[0]
    seen = visible.sum(axis=0)
    B, C = temporal_modes(theta, sigma, Q, profile)
    P, r = B @ C, B.shape[1]
    sigma_f = _floored(sigma)
    if T - r >= PROFILE_MIN_DOF:
        # the residual's bias is persistent (in the modes), its noise white: the rest is noise alone
        hp = np.eye(T) - P
        resid = hp @ np.where(visible, resid, 0.0)
        expect = (hp ** 2) @ sigma_f ** 2  # per unit profile and leverage, at each time
    else:
        expect = sigma_f ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(visible, resid / np.sqrt(expect[:, None] * lever), np.nan)
        profile = np.where(seen > 0, np.nanmean(z ** 2, axis=0), 1.0)
        level = 1.4826 * np.nanmedian(np.abs(z), axis=0)
    # judged against the point's own level, and at least the common one (noise-free data have none)
    level = np.maximum(np.nan_to_num(level, nan=np.inf), 1.0)
    spikes = visible & (np.abs(np.nan_to_num(z)) > SPIKE_Z * level) if T - r >= PROFILE_MIN_DOF \
        else np.zeros_like(visible)
    return sigma, np.nan_to_num(profile, nan=1.0), spikes


def noise_gram(Q, profile, Q2=None):
    """``Qᵀ diag(profile) Q2`` (p, p2): the noise covariance of the regression coefficients per unit ``noise²``."""
    return Q.T @ (profile[:, None] * (Q if Q2 is None else Q2))


def _rows_times(M, coef):
    """``M`` (5, n, p) times ``coef`` (p, ...) -> (..., n, 5): the derivatives at the points, by one matrix
    product (einsum's loop over the five rows costs the paper-scale tube's bias estimate 6 of its 12 s)."""
    k, n, p = M.shape
    out = (M.reshape(k * n, p) @ coef.reshape(p, -1)).reshape((k, n) + coef.shape[1:])
    return np.moveaxis(out, (0, 1), (-1, -2))


def _surface_coefficients(Q, x):
    """``Qᵀ x`` (p, T, 3) of the positions ``x`` (T, n, 3), by one matrix product."""
    T, n, _ = x.shape
    return (Q.T @ np.moveaxis(x, 1, 0).reshape(n, T * 3)).reshape(-1, T, 3)


def _pair_gram(A, B):
    """``A[:, i] B[:, i]ᵀ`` (n, 5, 5) of two (5, n, p) row stacks, per point, by batched products."""
    return np.matmul(A.transpose(1, 0, 2), B.transpose(1, 2, 0))


def _block_laplacian(M, Mx, coef, coef_x, noise, gram):
    """Laplacian and std (T, nb) of one block of points; ``M``, ``Mx`` (5, nb, p) the derivative rows of the
    temperature's and the surface's designs, their coefficients (p, T) and (p, T, 3); ``gram`` (p, p) the
    coefficients' noise covariance per unit ``noise²`` (:func:`noise_gram`)."""
    nb = M.shape[1]
    dth = _rows_times(M, coef)
    dx = np.moveaxis(_rows_times(Mx, coef_x), 1, -1)  # (T, n, 5, 3)
    lap, w = laplace_beltrami(dth[..., :2], dth[..., 2:], dx[:, :, :2], dx[:, :, 2:])
    cov = _pair_gram(M @ gram, M)
    var = np.einsum("tnk,nkl,tnl->tn", w, cov, w)
    return lap, noise[:, None] * np.sqrt(np.maximum(var, 0.0)), nb


def _evaluate(p, design, design_x, theta, x, noise, profile, c, R0):
    """Laplacian and std (T, n) at the points ``p`` of the regressions of ``theta`` (T, n) with the QR
    ``design`` and of ``x`` (T, n, 3) with ``design_x``, in blocks of points; ``noise`` (T,) and ``profile``
    (n,) the data's noise (:func:`_noise`)."""
    coef = design[3].T @ theta.T  # (p, T); the rows of hessian_operator hold R⁻¹
    coef_x = _surface_coefficients(design_x[3], x)
    gram = noise_gram(design[3], profile)
    T, n = theta.shape
    lap, std = np.empty((T, n)), np.empty((T, n))
    nb = int(np.clip((1 << 21) // (20 * T), 1, 2048))  # points per block: ~16 MB of derivatives
    for s in range(0, n, nb):
        M = hessian_operator(p[s:s + nb], design, c, R0)
        Mx = M if design_x is design else hessian_operator(p[s:s + nb], design_x, c, R0)
        lap[:, s:s + nb], std[:, s:s + nb], _ = _block_laplacian(M, Mx, coef, coef_x, noise, gram)
    return lap, std


def surface_laplacian(psi, theta, x, *, spacing="auto", c=0.95, R0=1.0, separation=None, ops=None,
                      time_weights=None) -> Laplacian:
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
    time_weights : ndarray, shape (T, T), optional
        The regression in time the Laplacian will get (:func:`judging_weights`): "auto" judges the spacing on
        the temperatures so regressed, whose noise is the one left in the result.

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
    profile = np.full(N, np.nan)
    if p.shape[0] < 2 * MIN_POINTS or not good.any():
        log.warning("temperature Laplacian: too few points with a temperature; left NaN")
        return Laplacian(lap, std, float("nan"), noise, [], profile)
    tt = np.flatnonzero(good)
    th_f, x_f = fill_missing(ops, p, th[np.ix_(tt, have)], xx[tt][:, have], c, R0)
    judged = _judged(p)
    table = []
    if spacing == "auto":
        # (a time without enough temperatures leaves the regression in time undefined: each time's own then)
        k, table = _choose_spacing(p, th_f if time_weights is None or tt.size < T else time_weights @ th_f,
                                   judged, c, R0, separation)
    else:
        k = float(spacing)
    h = median_spacing(p)
    design = ls_design(p, k, h, c, R0)
    th_f, noise[tt], profile[have] = _clean_data(th_f, visible[tt], design[3], judged)
    lb, sb = _evaluate(p, design, design, th_f, x_f, noise[tt], profile[have], c, R0)
    cols = np.flatnonzero(have)
    lap[tt[:, None], cols], std[tt[:, None], cols] = lb, sb
    lap[~np.isfinite(th)] = np.nan
    std[~np.isfinite(lap)] = np.nan
    return Laplacian(lap, std, k, noise, table, profile)


def judging_weights(times, smoothing="gcv", *, c=1.0, R0=1.0):
    """The regression in time (T, T) on whose result :func:`surface_laplacian` judges its spacing, for
    :func:`smooth_in_time`'s ``smoothing``; None where there is none.

    Notes
    -----
    The risk criterion balances the regression's bias against its noise,
    and the regression in time removes much of the noise but none of the
    spatial bias: judged on each time's noise, the spacing was too wide for
    the result (the demo's R 40 and 30 mm half-shells: 6 and 8 point
    spacings, the bias twice the noise left after the regression in time;
    judged on the regressed temperatures, 5 and 6, the bias 0.6 and 0.8 of
    it). GCV chooses the regression in time from the Laplacian's own series,
    after the spacing; the widest of its candidates, which it takes for a
    noise-dominated Laplacian, stands in for it.
    """
    from ..numerics.temporal import TemporalInterpolant

    t = float_array(times, "times")
    k = max(TIME_CANDIDATES) if smoothing == "gcv" else (None if smoothing is None else float(smoothing))
    if k is None or k <= 1.0 or t.size < 4:
        return None
    return TemporalInterpolant(t, c=c, R0=R0, smoothing=k).weights(t)


def smooth_in_time(result: Laplacian, times, smoothing="gcv", *, c=1.0, R0=1.0) -> tuple[Laplacian, float]:
    """The Laplacian regressed in time along each point's series, its std propagated.

    Parameters
    ----------
    result : Laplacian
        Of :func:`surface_laplacian`.
    times : array_like, shape (T,)
        DIC times (s).
    smoothing : "gcv", None or float >= 1
        Centre spacing in time (stages); "gcv": :func:`irdic.numerics.temporal_choice.gcv_temporal` among
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
    from ..numerics.temporal import TemporalInterpolant
    from ..numerics.temporal_choice import gcv_temporal

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


def fill_missing(ops, p, th, x, c, R0):
    """The temperatures (T, n) and positions (T, n, 3) with their missing entries filled: the temperatures by
    the nearest visible point (to be refitted: :func:`refit_missing`), the positions by each time's
    interpolant (:func:`_filled`)."""
    return _nearest_filled(p, th, np.isfinite(th)), _filled(ops, p, x, np.isfinite(x).all(axis=2), c, R0)


def laplacian_difference(p, design, ref, th, x, profile, c, R0, basis=None):
    """The Laplacian of the regression ``design`` minus that of ``ref`` (QRs of
    :func:`~irdic.surface.regression.ls_design`), both on ``design``'s surface.

    ``th`` (S, T, n): S series of T times (the data, then noise probes), or with ``basis`` (T, r) their ``r``
    temporal mode coefficients (S, r, n), the series being ``basis @ th[s]`` (:func:`temporal_modes`: the
    regressions run on ``r`` instead of ``T`` columns); ``x`` (T, n, 3); ``profile`` (n,) the points' relative
    noise variance. Returns the difference (S, T, n) and its variance per unit noise variance (T, n),
    ``(r_k − r_ref) diag(profile) (r_k − r_ref)ᵀ`` of the two rows.
    """
    S, R, n = th.shape
    T = x.shape[0]
    flat = th.reshape(S * R, n).T
    coef, coef_r = design[3].T @ flat, ref[3].T @ flat
    coef_x = _surface_coefficients(design[3], x)
    g_kk, g_rr = noise_gram(design[3], profile), noise_gram(ref[3], profile)
    g_kr = noise_gram(design[3], profile, ref[3])
    diff, var = np.empty((S, T, n)), np.empty((T, n))
    nb = int(np.clip((1 << 22) // (5 * S * T), 16, 1024))  # points per block: ~32 MB of differences
    for s in range(0, n, nb):
        pb = p[s:s + nb]
        M, Mr = hessian_operator(pb, design, c, R0), hessian_operator(pb, ref, c, R0)
        dx = np.moveaxis(_rows_times(M, coef_x), 1, -1)
        delta = _rows_times(M, coef.reshape(-1, S, R)) - _rows_times(Mr, coef_r.reshape(-1, S, R))
        if basis is not None:
            delta = np.moveaxis(np.tensordot(basis, delta, axes=(1, 1)), 0, 1)  # (S, T, nb, 5)
        zero = np.zeros(dx.shape[:2] + (5,))
        _, w = laplace_beltrami(zero[..., :2], zero[..., 2:], dx[:, :, :2], dx[:, :, 2:])
        diff[:, :, s:s + nb] = _dot(w[None], delta)
        X = _pair_gram(M @ g_kr, Mr)
        G = _pair_gram(M @ g_kk, M) + _pair_gram(Mr @ g_rr, Mr) - X - np.swapaxes(X, 1, 2)
        var[:, s:s + nb] = np.maximum(np.einsum("tnk,nkl,tnl->tn", w, G, w), 0.0)
    return diff, var
