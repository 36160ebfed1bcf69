"""Local estimates of a regression's bias, and whether they resolve it.

A regression's error is noise plus bias. Its difference ``d`` to a reference
of the same input (the exact interpolation; the regression at half the
spacing, :func:`reference_spacing`; for the rate a local polynomial in time)
has ``E d² = b² + b_ref² + v``, ``v`` the noise variance of ``d`` from noise
probes through both operators, ``b_ref`` the reference's own bias (0 for
the interpolation, as large as ``b`` for the half spacing). :func:`local_bias`
averages ``d² - v`` over a neighbourhood and keeps it only where it exceeds
the scatter this average has on pure noise, measured on the probes
themselves (:func:`_null_scale`). Before that, the probes' noise level is
scaled to the data's own (:func:`noise_scale`): an error of the noise
model passes for a bias in ``d² - v`` otherwise.
"""

from __future__ import annotations

import logging
import threading

import numpy as np

from ..numerics.threads import parallel_map, worker_slices, workers

__all__ = ["local_bias", "common_bias", "first_mode_bias", "patch_halves", "half_means", "reference_spacing",
           "reference_options", "strain_reference_options", "noise_scale", "scaled_probes", "BIAS_NEIGHBOURS", "BIAS_Z",
           "REFERENCE_SHARE", "REFERENCE_Z"]

log = logging.getLogger(__name__)

#: nearest points (surface parameters) over which a regression's bias is averaged, at each time and its neighbours
BIAS_NEIGHBOURS = 32
#: a local bias estimate counts where it exceeds this many of its own standard errors on pure noise
BIAS_Z = 1.0
#: times (each with its neighbours) over which the estimate's scatter on pure noise is pooled
NULL_TIMES = 16
#: the most points of the wider neighbourhood (its sparse sums cost that many per point, time and component;
#: a paper-density cloud's 24 point spacings would ask for 1,809)
WIDE_MAX = 512
#: the share of the difference to the half-spacing reference that is the regression's own bias (see
#: :func:`reference_spacing`): the reference's bias is as large and uncorrelated
REFERENCE_SHARE = 0.5
#: the significance (standard errors) of a bias estimate against the half-spacing reference
REFERENCE_Z = 2.0
#: times on each side of a time whose cross products :func:`common_bias` averages with its own
COMMON_TIMES = 1


def patch_halves(psi):
    """The two halves (2, N) of the points with surface parameters ``psi`` (N, 2), cut at the median of the longer
    parameter (:func:`common_bias`); None with fewer than ``2`` :data:`BIAS_NEIGHBOURS` such points."""
    ok = np.isfinite(psi).all(axis=1)
    if ok.sum() < 2 * BIAS_NEIGHBOURS:
        return None
    along = int(np.argmax(np.ptp(psi[ok], axis=0)))
    cut = np.median(psi[ok, along])
    x = np.where(ok, psi[:, along], cut)
    return np.stack([ok & (x < cut), ok & (x >= cut)])


def half_means(d, halves, use):
    """Means (..., 2) of ``d`` (..., N) over each of the ``halves`` (2, N) where ``use`` (..., N, broadcast); NaN
    where a half has fewer than :data:`BIAS_NEIGHBOURS` points."""
    out = []
    for half in halves:
        m = use & half
        n = m.sum(axis=-1)
        out.append(np.where(n >= BIAS_NEIGHBOURS, np.where(m, d, 0.0).sum(axis=-1) / np.maximum(n, 1), np.nan))
    return np.stack(out, axis=-1)


def first_mode_bias(series, difference):
    """The rate's temporal bias on the first temporal mode of the series, (T, N), in ``difference``'s units.

    Parameters
    ----------
    series : ndarray, shape (M, N)
        The spatially regressed series at the samples (degC), NaN-free where complete.
    difference : ndarray, shape (T, M)
        The weights of the regression's rate minus its reference's (1/s): ``difference @ X`` (K/s).

    Returns
    -------
    ndarray, shape (T, N)
        The estimate ``sqrt(max(0, (Δu)_t² - v_t) max(0, a_x² - σ²))``: 0 for a series with a gap, and where the
        mode or the point's amplitude is noise.

    Notes
    -----
    A patch heated with one history holds series ``a(x) φ(t)`` plus noise of variance ``σ²``: the
    regression's rate bias is ``a(x) Δφ`` everywhere, ``Δ`` the regression's rate minus the truth's, here
    the reference's (:func:`~irdic.numerics.temporal.rate_reference_weights`). ``u`` (unit) is the leading
    eigenvector of the centred series' Gram matrix in time (M x M, eigenvalues ``λ_1 >= λ_2 ...``), ``a = uᵀ
    X`` the amplitudes. Their noise is subtracted from the squares: ``σ² = (Σ λ - λ_1) / (N (M - 2))``
    (larger where the series hold a second pattern: the more cautious); ``a_x`` holds ``σ²``; ``u``'s noise
    (first-order perturbation, ``δu = Σ_j u_j u_jᵀ N a / (λ_1 - λ_j)``) gives ``(Δ δu)_t`` a variance of at
    most ``v_t = σ² λ_1 q_t / (λ_1 - λ_2)²``, ``q_t = Σ_{j>1} (Δ u_j)_t²``: on noise alone the gap closes and
    nothing counts. Point by point the bias drowned in the reference's noise (drawn-202: the difference's
    mean square 4.25e-4 against the probes' 4.42e-4, the error a patch-wide ripple of 0.01 K/s); the mode
    averages the patch. The noisy family's smooth members are of rank one to 0.2-2 % of the first singular
    value (drawn-202: 1, 0.007, 0.006, ...); a narrow band is not (drawn-101: 1, 0.90, 0.75, ...): there the
    local estimates decide (:func:`local_bias`).
    """
    X = np.asarray(series, dtype=float)
    M = X.shape[0]
    D = np.asarray(difference, dtype=float)  # constants give 0
    out = np.zeros((D.shape[0], X.shape[1]))
    live = np.isfinite(X).all(axis=0)
    n = int(live.sum())
    if n < 2 or M < 4:
        return out
    Xc = X[:, live] - X[:, live].mean(axis=0)
    lam, V = np.linalg.eigh(Xc @ Xc.T)
    gap = lam[-1] - lam[-2]
    if not gap > 0:
        return out
    u = V[:, -1]
    a = u @ Xc
    var = max(float(np.sum(lam) - lam[-1]), 0.0) / (n * (M - 2))
    du = D @ u
    q = np.maximum(np.sum(D * D, axis=1) - du * du, 0.0)
    profile = np.maximum(du * du - var * lam[-1] * q / gap ** 2, 0.0)
    out[:, live] = np.sqrt(profile[:, None] * np.maximum(a * a - var, 0.0)[None, :])
    return out


def common_bias(d, psi, trusted=None, null=None):
    """RMS (T,) of the part of a difference ``d`` (T, N) that the whole patch shares at each time.

    Parameters
    ----------
    d : ndarray, shape (T, N)
        A regression minus its reference (the rate's: K/s).
    psi : ndarray, shape (N, 2)
        Surface parameters (mm).
    trusted : ndarray of bool, shape (T, N), optional
        The points that enter the means (:func:`local_bias`).
    null : ndarray or SpreadStack, shape (K, T), optional
        The same products of ``K`` noise probes' differences (:func:`half_means` over :func:`patch_halves`):
        the estimate counts where it exceeds :data:`BIAS_Z` of their scatter.

    Returns
    -------
    ndarray, shape (T,)
        ``sqrt(<m_1 m_2>)`` where it counts, else 0; same units as ``d``.

    Notes
    -----
    The patch is cut at the median of its longer parameter into two halves
    (:func:`patch_halves`) with means ``m_1``, ``m_2`` of ``d``. Their noises
    are independent (the halves are apart but for the points along the cut,
    whose correlation the regression's kernel carries), so ``E m_1 m_2 =
    b_1 b_2`` with no noise term to subtract: the square of a bias both halves
    share, and 0 for one that only one half has. The product is averaged over
    the time and its :data:`COMMON_TIMES` neighbours on each side (a ripple of
    the regression in time changes sign from stage to stage; its square does
    not). On pure noise the average scatters about 0 by the probes' own
    (``null``): on the tiny demo half-shell (273 points, 3 inner times) one
    time of two seeds came out at half the rate's noise without that test.
    Such a bias is the temporal regression's on a heating whose time profile
    is the whole patch's: on the noisy family's smooth members its mean over
    the patch followed the rate's mean error (correlation 0.74 and 0.82 over
    the times of drawn-707 and drawn-202, ripples of 0.01 K/s against a noise
    of 0.005 K/s), while each point's local estimate was drowned by the
    reference's noise (0.017 K/s) and kept at 0.
    """
    d = np.asarray(d, dtype=float)
    T = d.shape[0]
    out = np.zeros(T)
    halves = patch_halves(psi)
    if halves is None:
        return out
    use = np.isfinite(d) & (True if trusted is None else np.asarray(trusted, dtype=bool))
    m = half_means(d, halves, use)

    def average(p):  # over each time and its neighbours with a product (last axis: times, any number)
        have = np.isfinite(p)
        v, c = np.where(have, p, 0.0), have.astype(float)
        total, count = v.copy(), c.copy()
        for s in range(1, COMMON_TIMES + 1):
            total[..., s:] += v[..., :-s]
            total[..., :-s] += v[..., s:]
            count[..., s:] += c[..., :-s]
            count[..., :-s] += c[..., s:]
        return np.where(count > 0, total / np.maximum(count, 1.0), np.nan)

    mean = average(m[:, 0] * m[:, 1])
    keep = np.isfinite(mean) & (mean > 0)
    if null is not None and len(null) >= 2:
        rows = null.rows(np.arange(T)) if hasattr(null, "rows") else np.asarray(null, dtype=float)
        with np.errstate(invalid="ignore"):
            se = np.sqrt(np.nanmean(np.square(average(rows)), axis=0))  # about 0: the products' mean on noise
        keep &= ~(mean <= BIAS_Z * se)  # a time no probe reached (se NaN) keeps the estimate untested
    out[keep] = np.sqrt(mean[keep])
    return out


def noise_scale(theta, acc, regress_space, ks, trusted):
    """``κ²``: the data's noise variance over the probes', from the residual of each time's spatial regression.

    The probes draw the noise the data's estimates predict (IR noise level,
    interpolation gains, one white level per point); what they leave out
    (the noise estimate's own error, the DIC noise the points are sampled
    with, the mixed pixels) is all point-to-point noise, which the residual
    ``Θ - S Θ`` holds (the regression's bias is a small part of it: 3 mK
    against 17-46 mK). ``κ² = Σ r² / Σ E r_probe²`` over the ``trusted``
    points; 1 when it cannot be formed. Demo barrel: the probes' noise was
    10 % low in std (estimated 0.0485 K against the true 0.0501 K, the
    rest mostly the sampling's), and the bias estimates took that excess
    for a bias.
    """
    res = acc.get("res")
    if theta is None or not np.ndim(res):
        return 1.0
    r = theta - regress_space(theta, None, ks)[1]
    ok = np.isfinite(r) & np.isfinite(res) & (res > 0) & (True if trusted is None else trusted)
    if ok.sum() < 10:
        return 1.0
    k2 = float(np.sum(np.square(r[ok])) / np.sum(res[ok]))
    log.info("fields: the data's noise is %.3g x the probes' (std, spatial-regression residual)", np.sqrt(k2))
    return k2


def scaled_probes(acc, k2):
    """The probes' mean squares ``acc`` (:func:`irdic.uncertainty.model._spatial_probes`) with the noise variance
    scaled by ``k2``, arrays in place (at paper scale they are GBs)."""
    for k, a in acc.items():
        if isinstance(a, np.ndarray) or hasattr(a, "rows"):
            a *= k2
        elif a is not None:
            acc[k] = a * k2
    return acc


def reference_spacing(k):
    """The reference regression of a spatial regression with centre spacing(s) ``k`` (None: none): half the
    spacing, None (the exact interpolation) from 2 down.

    Notes
    -----
    The exact interpolation, as a reference, carries the full
    noise of the data: against it a bias below a few per cent of that
    noise is not resolved at all (the demo barrel's gradient: the
    interpolation's noise ~0.2 K/mm, the regression's bias 1.3e-3 K/mm).
    Half the spacing has a small fraction of the interpolation's noise.
    Its bias is not smaller, though: the kernel is as many centre spacings
    wide at every spacing (:data:`irdic.numerics.imq.REGRESSION_RATIO`), so
    the approximation error of a smooth field does not shrink with the
    spacing (it saturates), and the two regressions' ripples sit on different
    centres. With the true temperatures of the noisy demo scenes the
    gradient's bias at the chosen spacing and at half of it were 1.47e-3 and
    1.41e-3 K/mm RMS, correlated 0.02 (barrel), 9.1e-5 and 4.1e-5, -0.10
    (tube). The difference then holds both biases: ``E d² - v = b² + b_ref²``,
    and its local value says little about where ``b`` is large: from 2 point
    spacings on the callers take :data:`REFERENCE_SHARE` of it, averaged over
    all points where the neighbourhood does not resolve it
    (:func:`reference_options`).
    """
    if k is None:
        return None
    if np.ndim(k):
        ref = tuple(reference_spacing(float(v)) for v in k)
        return None if all(r is None for r in ref) else tuple(1.0 if r is None else r for r in ref)
    return None if k < 2.0 else k / 2.0


def reference_options(k):
    """The :func:`local_bias` options for a difference to the half-spacing reference of spacing(s) ``k``.

    From a reference of 2 point spacings on (``k >= 4``) the reference is a
    regression whose bias is as large as the regression's own and
    uncorrelated with it (:func:`reference_spacing`): :data:`REFERENCE_SHARE`
    of the difference, at :data:`REFERENCE_Z` standard errors, pooled over
    all points where no neighbourhood resolves it. Below, the reference is
    an almost exact interpolation whose own error dominates the difference
    (the noise of the points' positions through a nearly interpolating fit;
    demo half-shell, ``k = 3``: 3.1e-3 K/mm against the regression's bias of
    1.4e-3): there the halved, pooled estimate put 0.87-0.89 of the
    gradient's errors within 1 std, the local one at one standard error
    0.70-0.72 / 0.90-0.91 (seeds 1, 3, 5), and the local one is kept. From
    2 spacings on (the demo barrel and tube) the gradient's coverage went
    from 0.59-0.81 / 0.84-0.97 within 1 / 2 std to 0.67-0.79 / 0.93-0.97.
    """
    k_min = None if k is None else float(np.min(k))
    if k_min is None or k_min < 4.0:
        return {}
    return dict(z=REFERENCE_Z, share=REFERENCE_SHARE, pooled=True)


def strain_reference_options(k):
    """The :func:`local_bias` options for the strain's difference to the half-spacing reference of the surface
    regression with spacing(s) ``k`` (a number or the (shape, motion) pair; None: no regression in space).

    Notes
    -----
    Where the reference is itself a regression (:func:`reference_spacing`),
    its strain is as biased as the regression's and uncorrelated with it:
    on the noise-free coordinates of the demo tube (spacings 2.5 and 5)
    4.32e-4 against 4.36e-4 RMS, correlation -0.08. So, as for the gradient
    (:func:`reference_options`), :data:`REFERENCE_SHARE` of ``<d² - v>``,
    averaged over all points where no neighbourhood resolves it; but at
    :data:`BIAS_Z` standard errors. The strain's noise is shared by the
    stages (every stage's displacement is taken from the same reference
    stage's coordinates: the error at two stages of the tube correlates
    0.6-0.76 from point to point), so a record's estimate holds few
    independent draws and two standard errors discarded a real bias (tube:
    0.55 / 0.85 within 1 / 2 std on seed 7). With the exact interpolation as
    the reference (``b_ref`` 0) the local estimate alone.
    """
    if reference_spacing(k) is None:
        return {}
    return dict(z=BIAS_Z, share=REFERENCE_SHARE, pooled=True)


def local_bias(d, noise_var, psi, trusted=None, null=None, spacing=None, neighbourhoods=None, *, z=BIAS_Z, share=1.0,
               pooled=False):
    """Local RMS of a regression's bias from its difference ``d`` to a reference.

    Parameters
    ----------
    d : ndarray, shape (T, N) or (T, N, C)
        The regression minus the reference (the data's).
    noise_var : ndarray, same shape, or SpreadStack of one
        The noise variance of ``d`` (probes through both operators); a
        :class:`~irdic.uncertainty.probes.SpreadStack` of one array at the
        probed times is read a block of times at a time.
    psi : ndarray, shape (N, 2)
        Surface parameters (the neighbourhoods).
    trusted : ndarray of bool, shape (T, N), optional
        Points whose reference is itself accurate; only they enter the
        averages (at the mask's and the point cloud's edges the
        interpolation's own error is large: those points are flagged).
    null : ndarray, shape (K, T, N[, C]), optional
        ``K >= 2`` probes' own squared differences (``noise_var`` is, or
        estimates, their mean): the noise-only scatter of the estimate.
    spacing : float, optional
        The regression's centre spacing in point spacings: where the
        neighbourhood's estimate is not resolved, the points within that
        spacing (``π spacing²`` nearest) are averaged instead (the bias
        varies on that scale; at most :data:`WIDE_MAX`).
    neighbourhoods : dict, optional
        Cache of the neighbourhoods of ``psi`` by their size, shared by the
        calls on the same points (each is a k-d tree query and a sparse matrix).
    z, share, pooled
        Significance (standard errors on pure noise), the part of ``d²`` that
        is the regression's own bias, and whether all trusted points are
        averaged last (:func:`reference_options`).

    Returns
    -------
    ndarray, same shape as ``d``
        ``sqrt(share b²)``; 0 where nothing is known or not resolved.

    Notes
    -----
    ``b² = <d² - v>``, averaged over the :data:`BIAS_NEIGHBOURS` nearest
    points at the same and the adjacent times (the bias varies on the scale
    of the regression's centre spacing, the noise from point to point).
    That average is itself noisy: ``d`` holds the reference's noise, for an
    exact interpolation many times the regression's. Kept at its full size
    wherever it came out positive, that noise was added to the std in place
    of a bias (demo barrel: the strain's bias estimate 2.5e-3 against a
    true 1e-5, the temperature's 0.011 K against 0.003 K). The estimate's
    standard error on pure noise is ``s L(v)`` (``L``: the local mean),
    ``s`` pooled over the points from the probes' own estimates
    ``L(d_j² - v̄)``; ``b²`` counts where it exceeds ``z`` such errors,
    else 0.
    """
    d = np.asarray(d)
    T = d.shape[0]
    step = max(1, _BIAS_BLOCK // max(1, int(np.prod(d.shape[1:]))))
    noise_rows = _rows_of(noise_var, d.shape)
    ok = _finite(d, noise_rows, step)
    if trusted is not None:
        ok &= np.asarray(trusted, dtype=bool).reshape(trusted.shape + (1,) * (d.ndim - 2))
    if not np.isfinite(psi).all(axis=1).any():
        return np.zeros(d.shape)
    nbs = _neighbourhoods(psi, spacing, pooled, neighbourhoods)
    simple = null is None or len(null) < 2
    if simple:
        nbs = nbs[:1]
        scales = [None]
    else:  # the pooled scatter on noise, one number per neighbourhood
        null = null if hasattr(null, "rows") else np.asarray(null)
        scales = [_null_scale(null, ok, nb) for nb in nbs]
    # block by block of times (each with its neighbouring times, which the local means include): the work
    # arrays of a block, not of the record (at paper scale ~10 arrays of 100 MB per call otherwise)
    out = np.empty(d.shape)
    for t0 in range(0, T, step):
        t1 = min(T, t0 + step)
        e0, e1 = max(0, t0 - 1), min(T, t1 + 1)
        res = _local_estimate(d[e0:e1], noise_rows(e0, e1), ok[e0:e1], nbs, scales, z)
        out[t0:t1] = np.sqrt(share * res[t0 - e0:t1 - e0])
    return out


def _rows_of(a, shape):
    """``(e0, e1) -> a[e0:e1]`` of an array broadcast to ``shape``, or of a
    :class:`~irdic.uncertainty.probes.SpreadStack` of one array (spread to those times only)."""
    if hasattr(a, "rows"):
        return lambda e0, e1: a.rows(np.arange(e0, e1))[0]
    a = np.broadcast_to(a, shape)
    return lambda e0, e1: a[e0:e1]


def _finite(d, noise_rows, step):
    """Where ``d² - noise_var`` is finite (T, N[, C]), ``step`` times at a time (``noise_rows``: :func:`_rows_of`)."""
    ok = np.empty(d.shape, dtype=bool)
    for t0 in range(0, d.shape[0], step):
        ok[t0:t0 + step] = np.isfinite(np.square(d[t0:t0 + step]) - noise_rows(t0, min(d.shape[0], t0 + step)))
    return ok


def _neighbourhoods(psi, spacing, pooled, cache):
    """The neighbourhoods :func:`local_bias` averages over, in order: the :data:`BIAS_NEIGHBOURS` nearest
    points, then a wider one where the bias is below their resolution, then (``pooled``) all points (None);
    from ``cache`` by size where built before."""
    wide = [] if spacing is None else [min(WIDE_MAX, int(np.pi * float(np.max(spacing)) ** 2))]
    nbs = []
    for k in [BIAS_NEIGHBOURS] + [n for n in wide if n > BIAS_NEIGHBOURS] + ([None] if pooled else []):
        # the estimates that share a cache run side by side (parallel_map): one builds, the other waits for it
        with _CACHE_LOCK:
            nb = None if cache is None or k is None else cache.get(k)
            if nb is None and k is not None:
                nb = _neighbours(psi, k)
                if cache is not None:
                    cache[k] = nb
        nbs.append(nb)
    return nbs


_CACHE_LOCK = threading.Lock()


def _local_estimate(d, noise_var, ok, nbs, scales, z):
    """``b²`` of :func:`local_bias` on a block of times: the first neighbourhood's estimate where it exceeds
    ``z`` standard errors (``scales``: their factors; None: no null, the estimate as it is), else the next's."""
    a = np.where(ok, np.square(d) - noise_var, 0.0)
    res = None
    for nb, scale in zip(nbs, scales):
        count = _local_count(_one_mask(ok), nb)
        est = _local_mean(a, ok, nb, count)
        if scale is None:
            return np.maximum(est, 0.0)
        se = scale * _local_mean(np.where(ok, noise_var, 0.0), ok, nb, count)
        est = np.where(est > z * se, est, 0.0)
        res = est if res is None else np.where(res > 0, res, est)
    return res


#: Values per time block of :func:`local_bias` (its work arrays are a few of this size)
_BIAS_BLOCK = 1 << 21


def _null_scale(null, ok, nb):
    """Standard error of the local bias estimate on pure noise relative to the local noise variance, pooled.

    ``null`` (K, T, N[, C], or a :class:`~irdic.uncertainty.probes.SpreadStack`):
    the probes' squared differences. Each probe's estimate ``L(null_j - v̄)``
    scatters about 0 as the data's does under no bias; the data's ``v`` is the
    mean of the probes, whose own error adds ``1/K`` of that variance.
    """
    K = null.shape[0]
    # a pooled ratio: the times of at most NULL_TIMES windows (each time with its neighbours) hold enough
    # points, at a fraction of the sparse products over every time and probe (43 of 163 s of the fields stage
    # on the moving tube, 300 times x 13,104 points, 452 neighbours)
    T = ok.shape[0]
    if T > NULL_TIMES + 2:
        mid = np.linspace(1, T - 2, NULL_TIMES).round().astype(int)
        sel = np.unique(np.clip(mid[:, None] + [-1, 0, 1], 0, T - 1))
        null = null.rows(sel) if hasattr(null, "rows") else null[:, sel]
        ok = ok[sel]
        centre = np.isin(sel, mid)
    else:
        null = np.asarray(null)
        centre = np.ones(T, bool)
    ok = ok & np.isfinite(null).all(axis=0)
    mean = np.where(ok, null.mean(axis=0), 0.0)
    count = _local_count(_one_mask(ok), nb)
    lv = _local_mean(mean, ok, nb, count)
    dev2 = sum(np.square(_local_mean(np.where(ok, n, 0.0) - mean, ok, nb, count)) for n in null) / (K - 1)
    ok, lv, dev2 = ok[centre], lv[centre], dev2[centre]
    use = ok & (lv > 0)
    if not use.any():
        return 0.0
    return float(np.sqrt(np.sum(dev2[use]) / np.sum(np.square(lv[use])) * (1.0 + 1.0 / K)))


def _neighbours(psi, k=BIAS_NEIGHBOURS):
    """``(have, S, chain)``: the points with parameters, the sparse (n_have x n_have) sum over each one's ``k``
    nearest, and that sum as differences along a path through the points where it is cheaper
    (:func:`_chain_sums`; None where not). None stands for all points (:func:`_window_sum`), not built here."""
    from scipy import sparse
    from scipy.spatial import cKDTree

    have = np.flatnonzero(np.isfinite(psi).all(axis=1))
    k = min(k, have.size)
    nb = cKDTree(psi[have]).query(psi[have], k=k, workers=workers())[1].reshape(have.size, k)
    # the sum over each point's neighbours is one sparse product over all times and components
    # (a[:, nb] at once would hold T x N x k (x 3) values: GBs at paper scale)
    S = sparse.csr_matrix((np.ones(nb.size), (np.repeat(np.arange(have.size), k), nb.ravel())),
                          shape=(have.size, have.size))
    return have, S, _chain_sums(psi[have], S)


def _chain_sums(psi, S):
    """``(order, D)``: the points in a path ``order`` through the cloud and ``D`` whose row ``j`` is the
    neighbourhood of point ``order[j]`` minus that of ``order[j - 1]`` (the first: its own); None where ``D``
    is not at most half as large as ``S``.

    Notes
    -----
    The sums ``S X`` are then ``cumsum(D X)`` along the path, exactly up to
    rounding (each partial sum is a point's window sum, so the rounding does
    not grow with the path's length beyond a random walk: 1e-14 of the
    sums' scale at 13,104 points). Consecutive points of the path are one
    spacing apart (rows of one spacing, each run in the opposite direction
    of the one before), so two neighbourhoods of ``k`` points differ by about
    ``4 sqrt(k / π)`` points: 56 against 512 (the wide neighbourhood at paper
    scale, 4.4 x faster), 16 against 32 (no gain: the cumulative sum costs
    more than it saves).
    """
    from ..surface.parametrisation import median_spacing

    n = psi.shape[0]
    if n < 3:
        return None
    h = median_spacing(psi)
    if not h > 0:
        return None
    # rows along the parameters' wider extent, one spacing high
    along, across = (0, 1) if np.ptp(psi[:, 0]) >= np.ptp(psi[:, 1]) else (1, 0)
    row = np.floor((psi[:, across] - psi[:, across].min()) / h).astype(np.int64)
    order = np.lexsort((np.where(row % 2 == 0, psi[:, along], -psi[:, along]), row))
    A = S[order]
    D = (A - _shifted(A)).tocsr()
    D.eliminate_zeros()
    return (order, D) if 2 * D.nnz <= S.nnz else None


def _shifted(A):
    """``A`` (CSR) with its rows moved down by one, the first row empty."""
    from scipy import sparse

    indptr = np.concatenate([[0], A.indptr[:-1]])
    return sparse.csr_matrix((A.data[:A.indptr[-2]], A.indices[:A.indptr[-2]], indptr), shape=A.shape)


def _local_mean(a, ok, nb, count=None):
    """Mean of ``a`` (T, N[, C]; 0 where not ``ok``) over the ``ok`` neighbours ``nb`` (:func:`_neighbours`) at
    the time and the adjacent ones; 0 where none. ``count``: :func:`_local_count` of ``ok``, when known."""
    n2 = _local_count(ok, nb) if count is None else count
    out = np.zeros(a.shape)
    np.divide(_window_sum(a, nb), n2, out=out, where=np.broadcast_to(n2 > 0, a.shape))
    return out


def _local_count(ok, nb):
    """The number of ``ok`` neighbours that :func:`_local_mean` averages, in ``ok``'s own shape (a mask that
    broadcasts over components is counted once)."""
    return _window_sum(np.asarray(ok, dtype=float), nb)


def _one_mask(ok):
    """``ok`` (T, N[, C]) as (T, N, 1) where every component has the same mask (counted once), else as it is."""
    if ok.ndim == 3 and ok.shape[2] > 1 and (ok == ok[..., :1]).all():
        return ok[..., :1]
    return ok


def _window_sum(v, nb):
    """Sum of ``v`` (T, N[, C]) over the neighbours ``nb`` of each point at its time and the adjacent ones
    (``nb`` None: over all points)."""
    if nb is None:
        s = np.broadcast_to(v.sum(axis=1, keepdims=True), v.shape).astype(float)
    else:
        have, S, chain = nb
        s = np.zeros(v.shape)
        vh = np.moveaxis(v[:, have], 1, 0)
        X = vh.reshape(have.size, -1)
        Y = np.empty(X.shape)
        # a value that is not finite would reach every later point of the path, not only its neighbours
        chain = chain if chain is not None and np.isfinite(X).all() else None

        def part(cols):  # each column's sums on their own: blocks of columns on the stage's threads
            if chain is None:
                Y[:, cols] = S @ X[:, cols]
            else:
                order, D = chain
                Y[order, cols] = np.cumsum(D @ X[:, cols], axis=0)

        parallel_map(part, worker_slices(X.shape[1]))
        s[:, have] = np.moveaxis(Y.reshape(vh.shape), 0, 1)
    s2 = s.copy()
    s2[1:] += s[:-1]
    s2[:-1] += s[1:]
    return s2
