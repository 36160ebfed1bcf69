"""The regression bias of the temperature Laplacian, estimated from the data, and added to its std.

A Laplacian from a regression at the spacing that minimises its risk is as
biased as it is noisy, often more (the smoothing of narrow features, a
ripple of the centres, the one-sided fit at the cloud's edge).
:func:`laplacian_bias` estimates the local RMS of that bias from the
Laplacian's differences to the same regression at finer spacings
(:data:`REFERENCE_RATIO`), after projecting every point's temperature series
on the data's temporal modes (the bias persists, the noise does not:
:func:`~irdic.heat.laplacian.temporal_modes`), with the noise part of the
differences known exactly and its scatter measured on noise probes; the
squared differences are averaged locally by empirical-Bayes shrinkage from
the specimen's mean down to half a centre spacing (:func:`_shrunk_means`).
:func:`with_bias` adds the estimate to the std in quadrature.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy import ndimage, sparse

from ..errors import GeometryError
from ..surface import edge_distance
from ..surface.parametrisation import median_spacing
from ..surface.regression import ls_design
from ..uncertainty.probes import BIAS_PROBES, probe_times
from ..validation import float_array, psi_array
from .laplacian import Laplacian, fill_missing, laplacian_difference, refit_missing, temporal_modes

__all__ = ["laplacian_bias", "with_bias", "REFERENCE_RATIO", "BIAS_SHARE", "BIAS_SCALES"]

log = logging.getLogger(__name__)

#: The references of :func:`laplacian_bias`: the same regression at these fractions of the chosen spacing.
#: Finer, because the bias of a feature the regression smooths grows steeply with the spacing: against wider
#: references the difference is theirs (the demo's 4 mm hot band at 1.25 times the spacing: 5 times the bias
#: of the chosen one). Not much finer: the difference's noise is the reference's (3.4 and 2 times the Laplacian's
#: variance at 0.67 and 0.8; 8 times at 0.5). Two of them, averaged: where the bias is a ripple of the centres
#: rather than a smoothing, a reference's own ripple is as large as the regression's and erratic from one
#: spacing to the next (the R 30 mm half-shell at 8 spacings: 3.0e-3 K/mm²; at 6.4, 4.3e-3).
REFERENCE_RATIO = (0.67, 0.8)

#: The part of the references' mean squared difference that counts as the regression's own bias. Where the
#: finer references resolve what the regression smooths (narrow hot features), the difference is the bias
#: (share 1); where the bias is a ripple whose size hardly changes with the spacing, the references' own ripple
#: doubles it (share 1/2). On the noise-free scenes of the heat benchmark (half-shells of three radii, a hot band
#: and a hot spot, the moving tube; a plane, a sphere cap, cylinders and a stretched and twisted tube as point
#: clouds) the RMS of the difference was 0.8 to 1.4 times the bias: 3/4 of its square puts the estimate within
#: 0.7-1.2 of it.
BIAS_SHARE = 0.75

#: The specimen's mean of the squared differences counts where it exceeds this many of its standard errors on
#: pure noise (:func:`_shrunk_means`); below, the local averages start from zero.
POOLED_Z = 2.0

#: The bands of distance to the cloud's edge (in centre spacings) that :func:`laplacian_bias` averages apart: the
#: one-sided fit's bias within a spacing of the edge is several times the bias inside (the stretched and twisted
#: tube at 10 spacings: 1.8e-3 K/mm² within half a spacing, 4e-4 beyond two), and averaged with it the inside's
#: estimate was 1.6 times its bias.
EDGE_BANDS = (0.5, 1.0, 2.0)

#: The neighbourhoods (half-widths in centre spacings) of :func:`_shrunk_means`, from the widest down: the bias
#: varies on the scale of the spacing, and the specimen's mean would spread a hot feature's bias over it.
BIAS_SCALES = (4.0, 2.0, 1.0, 0.5)


def laplacian_bias(psi, theta, x, result: Laplacian, *, c=0.95, R0=1.0, ops=None, seed=0):
    """Local RMS of the spatial regression's bias in the Laplacian of :func:`~irdic.heat.surface_laplacian`
    (K/mm²).

    Parameters
    ----------
    psi, theta, x, c, R0, ops
        As :func:`~irdic.heat.surface_laplacian`; ``result`` its result (the spacing, the noise level and
        profile).
    seed : int
        Of the noise probes.

    Returns
    -------
    ndarray, shape (T, N)
        The bias estimate; 0 where not resolved, NaN where the Laplacian is NaN.

    Notes
    -----
    ``d_j`` is the Laplacian at the chosen spacing minus that at
    :data:`REFERENCE_RATIO` times it (same surface, same data), the data's
    series first projected on their temporal modes ``P``
    (:func:`~irdic.heat.laplacian.temporal_modes`): the bias, linear in the
    temperature field, keeps its whole size, the noise ``r/T`` of its variance.
    ``E d_j² = (b − b_j)² + v_j`` with ``v_j = Σ_s P_ts² σ_s² (r_k − r_j)
    diag(profile) (r_k − r_j)ᵀ`` the exact noise variance of the two rows, so
    ``a = mean_j (d_j² − v_j)`` estimates the squared bias differences; the
    estimate is :data:`BIAS_SHARE` of ``a`` averaged locally. The local
    average of a noisy ``a`` is only as good as the points it holds, so it is
    shrunk toward the next wider one by the ratio of the spread of the true
    local values to the average's own noise (:func:`_shrunk_means`): where the
    bias stands out of the noise its own neighbourhood counts, elsewhere the
    wider one. The noise of each average is measured on
    :data:`~irdic.uncertainty.probes.BIAS_PROBES` noise probes of the data's
    level and profile through the same projection and operators.
    """
    p_all = psi_array(psi, "psi")
    th = float_array(theta, "theta")
    T, N = th.shape
    out = np.full((T, N), np.nan)
    have = np.isfinite(p_all).all(axis=1)
    tt = np.flatnonzero(np.isfinite(result.noise))
    if not np.isfinite(result.spacing) or tt.size == 0:
        return out
    p = p_all[have]
    seen = np.isfinite(th[np.ix_(tt, have)])
    th_f, x_f = fill_missing({} if ops is None else ops, p, th[np.ix_(tt, have)],
                             float_array(x, "x")[tt][:, have], c, R0)
    h = median_spacing(p)
    design = ls_design(p, result.spacing, h, c, R0)
    th_f = refit_missing(th_f, seen, design[3])
    sigma = result.noise[tt]
    profile = np.nan_to_num(result.profile[have], nan=1.0)
    B, C = temporal_modes(th_f, sigma, design[3], profile)
    rank = B.shape[1]
    rng = np.random.default_rng(seed)
    probes = sigma[None, :, None] * np.sqrt(profile) * rng.standard_normal((BIAS_PROBES, tt.size, p.shape[0]))
    modes = np.einsum("mt,stn->smn", C, np.concatenate([th_f[None], probes]))  # the series are B @ modes
    gain = ((B @ C) ** 2) @ sigma ** 2  # the projected series' noise variance per unit profile
    # the projected differences vary as slowly as the modes and the surface: evaluated at PROBE_TIMES times,
    # the estimate is interpolated between them
    sub = probe_times(tt.size)[0]
    a, v = _squared_differences(p, design, modes, x_f[sub], profile, gain[sub], result.spacing, h, c, R0, B[sub])
    if a is None:
        log.warning("temperature Laplacian: no bias estimate (no reference regression fits the points)")
        return np.where(np.isfinite(result.laplacian), 0.0, np.nan)
    H = result.spacing * h
    # the one-sided fit's bias near the cloud's edge is of another kind and size than inside: each band of
    # distance to the edge is averaged on its own
    band = np.searchsorted(np.asarray(EDGE_BANDS) * H, edge_distance(p), side="right")
    est = np.zeros(a.shape[1:])
    for j in np.unique(band):
        on = band == j
        est[:, on] = _shrunk_means(a[..., on], v[..., on], p[on], H)
    log.info("temperature Laplacian: bias estimated on %d temporal mode(s) of %d times", rank, tt.size)
    out[tt[:, None], np.flatnonzero(have)] = _between(np.sqrt(BIAS_SHARE * est), sub, tt.size)
    out[~np.isfinite(result.laplacian)] = np.nan
    return out


def _between(values, sub, T):
    """``values`` (len(sub), n) at the times ``sub`` (increasing, first and last included) -> (T, n), linearly
    between them."""
    if sub.size == T:
        return values
    i = np.clip(np.searchsorted(sub, np.arange(T), side="right") - 1, 0, sub.size - 2)
    w = ((np.arange(T) - sub[i]) / (sub[i + 1] - sub[i]))[:, None]
    return (1.0 - w) * values[i] + w * values[i + 1]


def _squared_differences(p, design, modes, x, profile, gain, spacing, h, c, R0, basis):
    """``(a, v)``: the mean over the :data:`REFERENCE_RATIO` references of the squared differences of the
    Laplacians of the series ``basis @ modes[s]`` (``modes`` (S, r, n), ``basis`` (T, r)) less their noise
    variance, (S, T, n), and that variance (T, n), for noise of variance ``gain`` (T,) times ``profile`` (n,);
    (None, None) when no reference fits."""
    a, v, k = None, None, 0
    for ratio in REFERENCE_RATIO:
        try:
            ref = ls_design(p, ratio * spacing, h, c, R0)
        except GeometryError:
            log.info("temperature Laplacian: the bias reference at %.3g spacings does not fit", ratio * spacing)
            continue
        d, var = laplacian_difference(p, design, ref, modes, x, profile, c, R0, basis)
        var = var * gain[:, None]
        a = d ** 2 - var if a is None else a + d ** 2 - var
        v = var if v is None else v + var
        k += 1
    return (None, None) if a is None else (a / k, v / k)


def _box_means(values, p, half):
    """Means of ``values`` (..., n) over the points in the 3 x 3 cells of side ``2 half / 3`` about each point's
    cell (a square of half-width about ``half``, mm, in the parameters ``p`` (n, 2)); the cost does not grow
    with ``half``."""
    n = p.shape[0]
    width = 2.0 * half / 3.0
    ij = np.floor((p - p.min(axis=0)) / width).astype(np.int64)
    nx, ny = (int(v) for v in ij.max(axis=0) + 1)
    cell = ij[:, 0] * ny + ij[:, 1]
    onehot = sparse.csr_matrix((np.ones(n), (cell, np.arange(n))), shape=(nx * ny, n))
    lead = values.shape[:-1]
    sums = (onehot @ values.reshape(-1, n).T).T.reshape(-1, nx, ny)
    count = np.asarray(onehot.sum(axis=1)).reshape(nx, ny)
    sums = ndimage.uniform_filter(sums, size=(1, 3, 3), mode="constant")
    count = ndimage.uniform_filter(count, size=3, mode="constant")
    return (sums[:, ij[:, 0], ij[:, 1]] / count[ij[:, 0], ij[:, 1]]).reshape(lead + (n,))


def _shrunk_means(a, v, p, H):
    """Local means (T, n) of ``a[0]`` (the data's ``d² − v``; ``a[1:]`` the probes'), shrunk from the specimen's
    mean (0 unless it exceeds :data:`POOLED_Z` standard errors) through the neighbourhoods of
    :data:`BIAS_SCALES` centre spacings ``H`` (mm); 0 where negative.

    Notes
    -----
    At each scale the box mean ``L(a)`` of the data has a noise variance
    ``s² L(v)²`` whose factor ``s²`` the probes' own box means give (pooled
    over the specimen and the times); the spread of the true local values
    about the wider estimate ``A`` is ``τ² = W[(L(a) − A)²] − W[s² L(v)²]``
    over the wider box ``W``, and the estimate becomes ``A + τ²/(τ² + s²
    L(v)²) (L(a) − A)``: a linear combination, so the noise's positive and
    negative excursions stay balanced until the last clip at zero.
    """
    K = a.shape[0] - 1
    # the specimen's mean, where it stands out of its noise (measured by the probes' own means)
    mean, vmean = a.mean(axis=-1, keepdims=True), v.mean(axis=-1, keepdims=True)
    s2 = float(np.sum(mean[1:] ** 2) / max(K * np.sum(vmean ** 2), 1e-300)) * (1.0 + 1.0 / K)
    A = np.broadcast_to(np.where(mean[0] > POOLED_Z * np.sqrt(s2) * vmean, mean[0], 0.0), a[0].shape)
    prev = None
    for q in BIAS_SCALES:
        La, Lv = _box_means(a, p, q * H), _box_means(v, p, q * H)
        s2 = float(np.sum(La[1:] ** 2) / max(K * np.sum(Lv ** 2), 1e-300)) * (1.0 + 1.0 / K)
        se2 = s2 * Lv ** 2
        dev = (La[0] - A) ** 2
        spread = dev.mean(axis=-1, keepdims=True) - se2.mean(axis=-1, keepdims=True) if prev is None \
            else _box_means(dev, p, prev * H) - _box_means(se2, p, prev * H)
        tau2 = np.maximum(spread, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(tau2 + se2 > 0, tau2 / (tau2 + se2), 0.0)
        A = A + w * (La[0] - A)
        prev = q
    return np.maximum(A, 0.0)


def with_bias(result: Laplacian, bias) -> Laplacian:
    """``result`` with the bias estimate of :func:`laplacian_bias` added to its std in quadrature."""
    b = np.where(np.isfinite(bias), bias, 0.0)
    return result._replace(std=np.sqrt(result.std ** 2 + b ** 2))
