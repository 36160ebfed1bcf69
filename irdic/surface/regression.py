"""Spatial regression with fewer centres, and the choice of their spacing by GCV.

Centres on a subset of the points spaced ``k`` times the median spacing, a
kernel six centre spacings wide (``c R0_eff = 6 H``, see
:data:`irdic.numerics.imq.REGRESSION_RATIO`), least squares over all data (QR).
The hat matrix ``Q Q^T`` has trace ``p`` = number of parameters, so
generalised cross-validation, ``GCV(k) = n RSS / (n - p)^2`` pooled over all
series, is exact and cheap.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg

from ..errors import ConfigError, DataError, GeometryError
from ..numerics.imq import imq_matrix, imq_planar, regression_R0
from ..numerics.threads import parallel_map
from ..validation import float_array, positive, psi_array
from .parametrisation import MIN_POINTS, median_spacing

__all__ = ["monomials", "grid_subset", "ls_design", "gcv_spatial", "gradient_risk_spatial", "SURFACE_CANDIDATES",
           "GRADIENT_CANDIDATES", "GRADIENT_MIN_PARAMETERS", "LAPLACIAN_CANDIDATES", "laplacian_risk_spatial",
           "hessian_operator"]

#: Centre spacing factors GCV tries for the DIC surface. Wider than the default of
#: :func:`gcv_spatial`: the displacement of a static or uniformly strained specimen
#: is best fitted by very few centres (a static half-shell at 0.003 mm noise: strain
#: noise 1.2e-4 RMS at 8 spacings, 4.4e-5 at 16).
SURFACE_CANDIDATES = (2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0, 16.0)

#: Centre spacing factors the gradient-risk criterion tries for the temperature (:func:`gradient_risk_spatial`).
#: Wider than GCV's: a smooth temperature field's gradient keeps falling in error up to 12 spacings at
#: 0.05 K (tube demo: 7.8 % at GCV's 5-8, 4.7 % at 12), which GCV, judging values, does not see; a cloud of
#: paper density (9,821 points, 4 times the demo's per mm) needs the wider ones (paper tube: 61 parameters at 12
#: spacings, the risk still falling, 11.5 %).
GRADIENT_CANDIDATES = (2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 16.0, 20.0, 24.0, 32.0)
#: The fewest parameters (centres and the 3 monomials) of a candidate beyond 12 spacings that the
#: gradient-risk criterion judges. With the noise of the white model the risk of 9-12 parameters did not resolve
#: the bias (tube demo: it chose 20 spacings, 5.6 % against 4.7 % at 12; the model's noise of a wide candidate
#: was 2.4 x too low); with the noise measured in time (``quintets``) 10 gains on six smooth members of the
#: noisy family against 16 (drawn-202 7.5 -> 5.4 %, drawn-707 6.3 -> 3.9 %) and loses on tube-twist (2.2 ->
#: 4.0 %: its risk flat from 8 to 24 spacings, the bias of 11 parameters not resolved); 12 as 10 elsewhere.
GRADIENT_MIN_PARAMETERS = 10

#: The fewest fourth differences in time (runs of five times x judged points) that measure the gradient's noise
#: for :func:`gradient_risk_spatial`; fewer: the white model. The tiny demo tube (7 times, 1 run, ~150 judged
#: points) chose 3 spacings on the measured covariance's scatter (gradient 15.8 % against 10.8 %); the noisy
#: family's members (17-31 stages, 3-6 runs of ~1,500 points) are measured.
QUINTET_MIN_SAMPLES = 1000

#: Centre spacing factors the Laplacian-risk criterion tries (:func:`laplacian_risk_spatial`): a second
#: derivative's noise grows like σ / H², so its best spacing is wider than the gradient's. 4 is the pilot: a narrow
#: hot band (4 mm Gaussian, points 0.93 mm apart) needs it (Laplacian error 4.6 % at 5, the smallest spacing tried
#: before, 0.7 % at 4 on clean data, 1.2 % realistic); a pilot at 3 is so noisy that the risk's minimum wanders
#: on noise-dominated data (a noisy tube: 8 spacings and 3.2 % against 16 and 1.0 % with the pilot at 4).
LAPLACIAN_CANDIDATES = (4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 16.0, 20.0, 24.0, 32.0)

log = logging.getLogger(__name__)


def monomials(pts, centre, R0, kind):
    """Rows of the monomials ``[1, (xi - centre) / R0]`` (kind 0) or of their d/dPsi^kind (1, 2).

    Parameters
    ----------
    pts : ndarray, shape (n, 2)
        Points (mm).
    centre : ndarray, shape (2,)
        Origin of the monomials (mm).
    R0 : float
        Normalisation (mm).
    kind : {0, 1, 2}
        Value, d/dPsi1, d/dPsi2.

    Returns
    -------
    ndarray, shape (n, 3)
    """
    n = pts.shape[0]
    if kind == 0:
        return np.c_[np.ones(n), (pts - centre) / R0]
    out = np.zeros((n, 3))
    out[:, kind] = 1.0 / R0
    return out


def _cells(psi, H):
    """Each point's square cell of side H from the points' lower corner: ``(cell (n, 2), key (n,))``, the key
    one integer per cell."""
    cell = np.floor((psi - psi.min(axis=0)) / H).astype(np.int64)
    return cell, cell[:, 0] * (cell[:, 1].max() + 1) + cell[:, 1]


def grid_subset(psi, H):
    """Indices of a subset of points, about one per square cell of side H (nearest to the cell centre)."""
    cell, key = _cells(psi, H)
    d = np.linalg.norm(psi - (psi.min(axis=0) + (cell + 0.5) * H), axis=1)
    order = np.lexsort((d, key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return np.sort(order[first])


def ls_design(psi, k, h, c, R0):
    """QR of the regression design matrix: centres spaced k h, kernel width c R0_eff = 6 k h."""
    centres, R0k, ctr, E = _design(psi, k, h, c, R0)
    Qm, Rm = scipy.linalg.qr(E, mode="economic", overwrite_a=True, check_finite=False)
    _check_rank(Rm, k)
    return centres, R0k, ctr, Qm, Rm


def _design(psi, k, h, c, R0):
    """``(centres, R0k, ctr, E)``: the regression's centres spaced ``k h``, its kernel's width, the monomials'
    centre and the design matrix (N, centres + 3) at the points ``psi``."""
    centres = psi[grid_subset(psi, k * h)]
    R0k = regression_R0(c, k * h)
    ctr = psi.mean(axis=0)
    return centres, R0k, ctr, np.concatenate([imq_matrix(psi, centres, c * R0k), monomials(psi, ctr, R0, 0)], axis=1)


def _check_rank(Rm, k):
    dg = np.abs(np.diag(Rm))
    if dg.min() < 1e-12 * dg.max():
        raise GeometryError(
            f"the regression with centres every {k:g} spacings is rank deficient "
            f"(condition > 1e12); use a larger smoothing factor"
        )


def _residual_ss(p, k, h, c, R0, F):
    """``(parameters, RSS)`` of the regression with spacing ``k`` of the samples ``F`` (n, m) at ``p``: the
    triangular factor of the design with the samples beside it, ``[E F] = Q [[R, Qᵀ F], [0, S]]``, holds the
    residual's sum of squares as ``‖S‖²`` (half the cost of a QR that forms ``Q``). GeometryError as
    :func:`_fit_design`."""
    _check_judged(p, k, h)
    E = _design(p, k, h, c, R0)[3]
    pp = E.shape[1]
    R = scipy.linalg.qr(np.concatenate([E, F], axis=1), mode="r", overwrite_a=True, check_finite=False)[0]
    _check_rank(R[:pp, :pp], k)
    return pp, float(np.sum(R[pp:, pp:] ** 2))


#: Points GCV judges at most: a larger cloud is judged on the round patch of this many points about its
#: middle (a QR of the design is O(N p²) per candidate, minutes at 13k points and spacing 2)
GCV_MAX_POINTS = 4000


def _judged_patch(p, F, max_points, judged=None):
    """``(psi, samples, h, judged)`` of the round patch of ``max_points`` points about the middle of the
    parameter box (all points of a smaller cloud); ``h`` the median spacing of the whole cloud."""
    h = median_spacing(p)
    if p.shape[0] > max_points:
        from scipy.spatial import cKDTree

        mid = 0.5 * (p.min(axis=0) + p.max(axis=0))
        near = np.sort(cKDTree(p).query(mid, k=int(max_points))[1])
        p, F = p[near], F[near]
        judged = None if judged is None else judged[near]
    return p, F, h, judged


def _candidates(candidates):
    ks = sorted(set(float(x) for x in candidates))
    for k in ks:
        if k <= 1:
            raise ConfigError(f"candidates must be > 1 (1 is interpolation, GCV undefined), got {k}")
    return ks


def _fit_design(p, k, h, c, R0):
    """:func:`ls_design`, or GeometryError when spacing ``k`` leaves too few or too many centres for
    a regression judged on ``p`` (fewer than 6, or more than half the points)."""
    _check_judged(p, k, h)
    return ls_design(p, k, h, c, R0)


def _check_judged(p, k, h):
    """GeometryError where spacing ``k`` leaves fewer than 6 centres, or more than half the points ``p``."""
    n = p.shape[0]
    nc = grid_subset(p, k * h).size
    if nc + 3 > n // 2 or nc < MIN_POINTS:
        raise GeometryError(f"{nc} centres for {n} points")


def gcv_spatial(psi, samples, *, c=0.95, R0=1.0, candidates=(2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0),
                max_points=GCV_MAX_POINTS):
    """Choose the spatial regression's centre spacing by generalised cross-validation.

    Parameters
    ----------
    psi : array_like, shape (N, 2)
        Surface parameters (mm).
    samples : array_like, shape (N, n_series)
        Data to judge by (e.g. the three coordinates of a few stages, filled).
    c, R0 : float
        Kernel (as :class:`SpatialInterpolant`).
    candidates : sequence of float
        Centre spacing factors to try (> 1).
    max_points : int
        Larger clouds are judged on the ``max_points`` points nearest to the
        middle of their parameter box.

    Returns
    -------
    k : float
        The factor with the least ``GCV = n RSS / (n - p)^2`` (pooled over the series).
    table : list of (k, n_parameters, gcv)

    Notes
    -----
    The spacing is a multiple of the median point spacing ``h``, and what
    GCV weighs (the noise against the signal's curvature on the scale of a
    few spacings) is local, so a round patch of a few thousand points with
    the cloud's density chooses as the whole cloud does, at a fraction of
    the cost.
    """
    p = psi_array(psi, "psi")
    F = float_array(samples, "samples").reshape(p.shape[0], -1)
    c, R0 = positive(c, "c"), positive(R0, "R0")
    p, F, h, _ = _judged_patch(p, F, max_points)
    n = p.shape[0]

    def gcv(k):  # (k, parameters, GCV) of spacing k, or None where it does not fit
        try:
            pp, rss = _residual_ss(p, k, h, c, R0, F)
        except GeometryError:
            return None
        return k, pp, n * rss / F.shape[1] / (n - pp) ** 2

    # each candidate a QR: on the stage's threads
    table = [r for r in parallel_map(gcv, _candidates(candidates)) if r is not None]
    if not table:
        raise DataError(f"gcv_spatial: no candidate spacing fits {n} points (too few points)")
    best = min(table, key=lambda r: r[2])
    log.info("spatial GCV: centre spacing %.3g x %.3g mm (%d parameters)", best[0], h, best[1])
    return best[0], table


def _gradient_risks(p, F, h, c, R0, rows, nj, candidates, operator=None, per_row=None, quintets=0, designs=None):
    """``(k, n_parameters, risk, noise)`` of each candidate that fits (Notes of :func:`gradient_risk_spatial`);
    ``operator(p, design, c, R0)`` the derivative whose risk counts (default the gradient's). ``per_row``: a
    list that gets each candidate's terms of the risk per judged row (their sum over ``nj`` is ``risk``).
    ``quintets``: the last ``5 quintets`` columns of ``F`` are that many runs of five consecutive times, whose
    fourth differences measure the noise (else the white-noise model gives it).

    The pilot (the first candidate that fits) is fitted first; the others, each a QR and a few products
    against the pilot's, run on the stage's threads. ``designs``: a dict that keeps each candidate's ``(Q, M)``
    for a later call on the same points (the same choice judged on other samples); emptied where it held
    another set's."""
    operator = _gradient_operator if operator is None else operator
    n, ns = p.shape[0], F.shape[1] - 5 * quintets
    stencil = np.array([1.0, -4.0, 6.0, -4.0, 1.0]) / np.sqrt(70.0)  # unit variance for white noise in time
    if designs is not None and not _same_set(designs.get("set"), (p, rows, h, c, R0, operator)):
        designs.clear()
        designs["set"] = (p, rows, h, c, R0, operator)

    def fitted(k):  # (Q, M, g, fourth differences) of spacing k, or None where it does not fit
        entry = None if designs is None else designs.get(k)
        if entry is None:
            try:
                design = _fit_design(p, k, h, c, R0)
                entry = (design[3], operator(p, design, c, R0)[rows])
            except GeometryError:
                entry = ()
            if designs is not None:
                designs[k] = entry
        if not entry:
            return None
        Qm, M = entry
        g = M @ (Qm.T @ F)
        return Qm, M, g[:, :ns], g[:, ns:].reshape(g.shape[0], quintets, 5) @ stencil

    def risk(k, fit=None):  # (k, n_parameters, risk, noise, terms per judged row) against the pilot, or None
        fit = fitted(k) if fit is None else fit
        if fit is None:
            return None
        Qm, M, g, q = fit
        MQ = M @ (Qm.T @ Q0)
        cross = float(np.sum(MQ * M0))
        d = np.sum((g - g0) ** 2, axis=1) / ns
        if quintets:  # the noise and the pilot's covariance with it as measured in time (correlated in space)
            noise, cross_noise = float(np.sum(q * q)) / quintets / nj, float(np.sum(q * q0)) / quintets / nj
        else:
            noise, cross_noise = var * float(np.sum(M * M)) / nj, var * cross / nj
        return (k, Qm.shape[1], float(np.sum(d)) / nj - var * norm0 / nj + 2.0 * cross_noise, noise,
                d - var * np.sum(M0 * (M0 - 2.0 * MQ), axis=1))

    ks = _widths(p, h, _candidates(candidates))
    pilot = None
    while ks and pilot is None:
        k = ks.pop(0)
        fit = fitted(k)
        if fit is None:
            continue
        Q0, M0, g0, q0 = fit
        # the residual r_i has variance σ² (1 - H_ii), H = Q Qᵀ; summed over the judged points
        jr = rows[:n]
        rss = float(np.sum((F[:, :ns] - Q0 @ (Q0.T @ F[:, :ns]))[jr] ** 2))
        var = rss / ns / (nj - float(np.sum(Q0[jr] ** 2)))
        norm0 = float(np.sum(M0 ** 2))
        pilot = risk(k, fit)

    if pilot is None:
        return []
    out = [pilot] + [r for r in parallel_map(risk, ks) if r is not None]
    if per_row is not None:
        per_row += [r[4] for r in out]
    return [r[:4] for r in out]


def _same_set(a, b):
    """Whether the point sets and settings ``(p, rows, h, c, R0, operator)`` ``a`` and ``b`` are the same."""
    return a is not None and all(np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y for x, y in zip(a, b))


def _widths(p, h, ks):
    """The candidate spacings ``ks`` (factors of ``h``) :func:`_gradient_risks` tries on the points ``p``: beyond
    12 spacings only those with at least :data:`GRADIENT_MIN_PARAMETERS` parameters (wider ones have fewer
    still)."""
    out = []
    for k in ks:
        n_par = grid_subset(p, k * h).size + 3
        if k > 12.0 and n_par < GRADIENT_MIN_PARAMETERS:
            break
        out.append(k)
    return out


def _widest_within_one_se(table, terms, pj, h):
    """The index in ``table`` of the widest candidate whose estimated risk exceeds the least one by at most the
    standard error of that difference (the one-standard-error rule).

    ``terms`` are the candidates' risk terms per judged point at ``pj`` (nj, 2) mm (:func:`_gradient_risks`,
    one row block), ``h`` the spacing the factors are in (mm). A regression's outputs are correlated over
    its centre spacing, so the difference's standard error is that of its sums over square tiles of twice the
    wider candidate's spacing, taken as independent."""
    best = min(range(len(table)), key=lambda i: table[i][2])
    out = best
    nj = pj.shape[0]
    for i in range(best + 1, len(table)):
        d = terms[i] - terms[best]
        tile = np.unique(_cells(pj, 2.0 * table[i][0] * h)[1], return_inverse=True)[1].ravel()
        n_t = np.bincount(tile)
        if n_t.size < 4:
            break  # too few tiles to say how well the difference is known
        mean = float(d.mean())
        se = float(np.sqrt(np.sum((np.bincount(tile, d) - n_t * mean) ** 2) * n_t.size / (n_t.size - 1))) / nj
        if mean <= se:
            out = i
    return out


def _gradient_operator(p, design, c, R0):
    """``M`` (2n, p) with ``M Qᵀ F`` the regression's derivatives d/dPsi1 (rows :n) and d/dPsi2 (rows n:)
    at the points ``p`` (1/mm), from the QR ``design`` of :func:`ls_design`."""
    centres, R0k, ctr, _, Rm = design
    _, m1, m2 = imq_planar(p[:, None, 0] - centres[None, :, 0], p[:, None, 1] - centres[None, :, 1], c, R0k, True)
    B = np.concatenate([np.concatenate([m1, monomials(p, ctr, R0, 1)], axis=1),
                        np.concatenate([m2, monomials(p, ctr, R0, 2)], axis=1)], axis=0)
    # B R^-1, i.e. solve R^T X^T = B^T
    return scipy.linalg.solve_triangular(Rm, B.T, trans="T", check_finite=False).T


def _one_per_separation(p, F, judged, separation, h):
    """``(p, F, judged)`` of about one point per ``separation`` square when the points (spacing ``h``) are
    denser; all of them otherwise.

    Points closer than an IR pixel share its noise, and the least smoothed
    pilot of :func:`gradient_risk_spatial` then follows that correlated
    noise: its residual underestimates σ² and the risk no longer falls with
    the spacing (moving tube, 25,960 points 0.64 px apart: 2 spacings
    chosen, the risk rising from 0.030 to 0.068 K²/mm² at 12). Judged on
    about one point per pixel the curve falls again and the choice is made
    in millimetres, as on a sparser grid of the same specimen (12 spacings
    of the subset: 2.1 mm; 13,104 points: 2.8 mm).
    """
    if separation is None or positive(separation, "separation") <= h:
        return p, F, judged
    sub = grid_subset(p, separation)
    return p[sub], F[sub], None if judged is None else judged[sub]


def gradient_risk_spatial(psi, samples, *, c=0.95, R0=1.0, candidates=GRADIENT_CANDIDATES,
                          max_points=GCV_MAX_POINTS, judged=None, separation=None, quintets=None, designs=None):
    """Choose the spatial regression's centre spacing by the estimated mean squared error of its gradient.

    Parameters
    ----------
    psi : array_like, shape (N, 2)
        Surface parameters (mm).
    samples : array_like, shape (N, n_series)
        Data (e.g. the point temperatures of a few times, filled), each
        series with white noise of one unknown standard deviation.
    c, R0 : float
        Kernel (as :class:`SpatialInterpolant`).
    candidates : sequence of float
        Centre spacing factors to try (> 1); the smallest that fits is the
        pilot (see Notes).
    max_points : int
        As :func:`gcv_spatial`.
    judged : array_like of bool, shape (N,), optional
        The points whose gradient error counts (all fit the regressions);
        default all. Points whose data carry an error that is not noise
        (mixed pixels at the IR mask's edge, the cloud's rim, where the
        least smoothed pilot follows the data's own error) belong outside.
    separation : float, optional
        Distance (mm) below which the data's noise is correlated (one IR
        pixel): denser points are judged on a subset (:func:`_one_per_separation`).
    designs : dict, optional
        Keeps the candidates' QR and derivative operators for a later call on
        the same points and settings (the same choice judged on other
        samples, :func:`irdic.fields.spatial.space_gcv_filled`).

    Returns
    -------
    k : float
        The factor with the least estimated gradient risk, in units of the
        median spacing of all points.
    table : list of (k, n_parameters, risk, noise)
        ``risk``: the estimated mean squared error of ``∂f/∂Ψ`` per point
        and series (data units² / mm²); ``noise``: its noise part
        ``σ² ‖D_k‖²_F`` per point.

    Notes
    -----
    The regression's derivatives are linear in the data, ``g_k = D_k f`` with
    ``D_k = B_k R_k⁻¹ Q_kᵀ`` (``B_k``: the derivatives of the design's
    columns at the points). For white noise of variance σ² and the truth
    ``g``, the risk ``E |g_k - g|²`` is ``|b_k|² + σ² ‖D_k‖²_F`` (``b_k``:
    the bias). With the least smoothed candidate as an (almost) unbiased
    pilot ``g_0 = D_0 f``,

    ``E |g_k - g_0|² = |b_k - b_0|² + σ² ‖D_k - D_0‖²_F``,

    so ``R_k = |g_k - g_0|² - σ² (‖D_0‖²_F - 2 tr(D_k D_0ᵀ))`` estimates the
    risk without bias up to the pilot's own bias (a Mallows-type criterion
    aimed at the derivative). σ² is the pilot's residual variance,
    ``RSS_0 / Σ (1 - H_ii)`` over the judged points (``H = Q_0 Q_0ᵀ``). ``tr(D_k D_0ᵀ) = Σ (M_k Q_kᵀ Q_0) ∘ M_0`` with
    ``M = B R⁻¹``: ``p × p`` products only.

    GCV (:func:`gcv_spatial`) judges the values, whose error a smooth field
    leaves flat over a wide range of spacings; the derivative weighs the
    noise by the square of its wavenumber, so its risk keeps falling with
    wider spacings until the bias sets in. On the tube demo (0.05 K IR
    noise, 2-decimal exports) GCV's flat curve chose 5-8 spacings and a
    7.8 % gradient error; see benchmarks/README.md.
    """
    return _risk_choice(psi, samples, c, R0, candidates, max_points, judged, separation, "gradient",
                        _gradient_operator, 2, quintets=quintets, designs=designs)


def _risk_choice(psi, samples, c, R0, candidates, max_points, judged, separation, what, operator, copies,
                 one_se=False, quintets=None, designs=None):
    """The spacing of least estimated risk of the derivative ``operator`` (its ``copies`` row blocks per point)
    and the table of :func:`gradient_risk_spatial` / :func:`laplacian_risk_spatial`; ``one_se`` (one row block):
    the widest within one standard error of it (:func:`_widest_within_one_se`)."""
    p = psi_array(psi, "psi")
    F = float_array(samples, "samples").reshape(p.shape[0], -1)
    nq = 0
    if quintets is not None:  # runs of five times beside the samples (the same rows: subsets below take both)
        Fq = float_array(quintets, "quintets").reshape(p.shape[0], -1, 5)
        nq = Fq.shape[1]
        F = np.concatenate([F, Fq.reshape(p.shape[0], -1)], axis=1)
    c, R0 = positive(c, "c"), positive(R0, "R0")
    judged = None if judged is None else np.asarray(judged, dtype=bool).reshape(p.shape[0])
    h_all = median_spacing(p)
    p, F, judged = _one_per_separation(p, F, judged, separation, h_all)
    p, F, h, judged = _judged_patch(p, F, max_points, judged)
    n = p.shape[0]
    rows = np.ones(copies * n, bool) if judged is None else np.tile(judged, copies)
    nj = int(rows.sum()) // copies
    if nj == 0:
        raise DataError(f"{what}_risk_spatial: no point is judged (judged is all False)")
    terms = [] if one_se else None
    if nq and nq * nj < QUINTET_MIN_SAMPLES:
        F, nq = F[:, :F.shape[1] - 5 * nq], 0  # too few to measure the noise better than the white model
    table = _gradient_risks(p, F, h, c, R0, rows, nj, candidates, operator, terms, nq, designs)
    if not table:
        raise DataError(f"{what}_risk_spatial: no candidate spacing fits {n} points (too few points)")
    chosen = _widest_within_one_se(table, terms, p[rows[:n]], h) if one_se else None
    table = [(k * h / h_all, n_par, r, noise) for k, n_par, r, noise in table]
    least = min(table, key=lambda r: r[2])
    best = least if chosen is None else table[chosen]
    log.info("spatial %s risk: centre spacing %.3g x %.3g mm (%d parameters, judged on %d points %.3g mm "
             "apart%s); %s", what, best[0], h_all, best[1], n, h,
             "" if best is least else f"; the widest within one standard error of the least, {least[0]:.3g}",
             ", ".join(f"{k:.3g}: {r:.3g}" for k, _, r, _ in table))
    return best[0], table


def hessian_operator(pts, design, c, R0):
    """``M`` (5, n, p): ``M[j] Qᵀ F`` is the regression's d/dΨ1, d/dΨ2, d²/dΨ1², d²/dΨ1dΨ2, d²/dΨ2²
    (rows ``j`` = 0..4, units of ``F`` per mm or mm²) at the points ``pts`` (n, 2), from the QR ``design``
    of :func:`ls_design`."""
    from ..numerics.imq import imq_planar_hessian

    centres, R0k, ctr, _, Rm = design
    dx, dy = pts[:, None, 0] - centres[None, :, 0], pts[:, None, 1] - centres[None, :, 1]
    _, m1, m2 = imq_planar(dx, dy, c, R0k, True)
    zero = np.zeros((pts.shape[0], 3))
    cols = [np.concatenate([m1, monomials(pts, ctr, R0, 1)], axis=1),
            np.concatenate([m2, monomials(pts, ctr, R0, 2)], axis=1)]
    cols += [np.concatenate([m, zero], axis=1) for m in imq_planar_hessian(dx, dy, c, R0k)]
    B = np.stack(cols)
    return np.stack([scipy.linalg.solve_triangular(Rm, b.T, trans="T", check_finite=False).T for b in B])


def _laplacian_operator(p, design, c, R0):
    """``M`` (n, p) with ``M Qᵀ F`` the regression's parameter Laplacian ``∂²/∂Ψ1² + ∂²/∂Ψ2²`` (1/mm²)."""
    from ..numerics.imq import imq_planar_hessian

    centres, R0k, _, _, Rm = design
    m11, _, m22 = imq_planar_hessian(p[:, None, 0] - centres[None, :, 0], p[:, None, 1] - centres[None, :, 1], c, R0k)
    B = np.concatenate([m11 + m22, np.zeros((p.shape[0], 3))], axis=1)
    return scipy.linalg.solve_triangular(Rm, B.T, trans="T", check_finite=False).T


def laplacian_risk_spatial(psi, samples, *, c=0.95, R0=1.0, candidates=LAPLACIAN_CANDIDATES,
                           max_points=GCV_MAX_POINTS, judged=None, separation=None):
    """Choose the spatial regression's centre spacing by the estimated mean squared error of its Laplacian.

    The criterion of :func:`gradient_risk_spatial` (same parameters and
    returns, ``risk`` in data units² / mm⁴) with the derivative ``∂²f/∂Ψ1² +
    ∂²f/∂Ψ2²`` in place of the gradient.

    Notes
    -----
    The surface Laplacian differs from the parameter one by the metric and
    the Christoffel terms, which on a specimen of nearly isometric
    parameters (the best-fit plane of a shallow patch, the unwrapped
    cylinder) change the operator by a factor close to one and add a small
    first-derivative term: the spacing that minimises the parameter
    Laplacian's risk minimises the surface one's. A second derivative weighs
    noise by the fourth power of its wavenumber, so the risk keeps falling
    to wider spacings than the gradient's (:data:`LAPLACIAN_CANDIDATES`).

    Of the candidates wider than the least estimated risk's, the widest whose
    estimate exceeds it by at most the standard error of the difference is
    taken (the one-standard-error rule, :func:`_widest_within_one_se`): at the
    wide end of a noise-dominated Laplacian the estimates differ by less than
    the pilot's scatter lets them be told apart, while the true noise still
    falls like ``H^-3`` (the paper-scale moving tube: 12 to 32 spacings within
    1 % of the pilot's scatter, the least at 16 with four times the error of
    32). A wider spacing whose bias stands out of that scatter is not taken.
    """
    return _risk_choice(psi, samples, c, R0, candidates, max_points, judged, separation, "Laplacian",
                        _laplacian_operator, 1, one_se=True)
