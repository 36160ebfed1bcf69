"""The value's bias estimate over a mean of nearby points: which points, and the probes' scale to the data.

The denoised temperature's bias is estimated from its difference to its
input (:func:`~irdic.uncertainty.regression_bias.local_bias`), whose noise
is the input's own. Averaged over a point and its nearest before it is
squared (:func:`ring_mean`), the noise weighs less against the bias, and so
does an error of the noise model; the mean's members are far enough apart in
the image for their noise to be independent (:func:`ring_apart`), close
enough to keep the regression's bias (:func:`value_ring`), and the probes'
variance of the mean is scaled to the data's (:func:`ring_noise_scale`).
"""

from __future__ import annotations

import logging

import numpy as np

__all__ = ["ring_mean", "ring_scatter", "ring_apart", "ring_noise_scale", "value_ring", "RING_POINTS", "RING_APART_PX",
           "RING_RADIUS_SHARE"]

log = logging.getLogger(__name__)

#: points (each with its nearest) over which the value's difference is averaged before it is squared
RING_POINTS = 7
#: the largest radius of such a mean in centre spacings of the regression (larger, it averages the bias away)
RING_RADIUS_SHARE = 0.5
#: the least distance (px in the IR image) between the points of such a mean: closer, the point temperatures'
#: noise is correlated by the image interpolation (-0.13 to -0.19 at 1-2 px on two dense family members,
#: within +-0.05 from 2 px on), which the probes do not draw
RING_APART_PX = 2.0
#: nearest points among which :func:`ring_mean` looks for its members
RING_CANDIDATES = 48


def ring_mean(psi, n=RING_POINTS, apart=0.0):
    """The mean over each point and its nearest, ``n`` in all (by surface parameters ``psi``, (N, 2)), as a
    function of ``a`` (..., N): over the finite values; NaN where the point's own value or parameters are not.
    The members are taken nearest first, each at least ``apart`` (mm of ``psi``) from those taken before
    (:func:`ring_apart`); fewer than ``n`` where the nearest :data:`RING_CANDIDATES` hold no more.

    Notes
    -----
    The value's bias is estimated from its difference ``d`` to the input
    (:func:`~irdic.uncertainty.regression_bias.local_bias`), whose noise is
    nearly all the input's own: ``E d² = b² + v`` with ``b²`` a hundredth of
    ``v`` on the family's band members. Squared, each value's noise sits in
    the estimate, and ``v`` must be
    known to about 1 % (the probes' scaled noise was 7 % off on two smooth
    members, 0.3 % on a band member: the threshold at one standard error
    then hid the band's bias with the misfit). The bias varies on the
    regression's centre spacing, the noise from point to point: averaged over
    a point and its six nearest before it is squared, the difference keeps
    70 % of ``b²`` on strip-band (centres 4 spacings apart) and 12 % of the
    noise variance, so the same misfit weighs 6 x less against the bias.
    The probes' differences take the same mean
    (:func:`~irdic.uncertainty.probes.probe_block`): its noise variance is
    theirs only where the members' noise is as correlated as the probes'
    (white), hence ``apart``.
    """
    from scipy import sparse

    psi = np.asarray(psi, dtype=float)
    have = np.flatnonzero(np.isfinite(psi).all(axis=1))
    rows, cols = _ring_members(psi[have], int(n), float(apart))
    S = sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(have.size, have.size))
    reach = np.linalg.norm(psi[have][rows] - psi[have][cols], axis=1)
    far = np.zeros(have.size)
    np.maximum.at(far, rows, reach)

    def mean(a):
        a = np.asarray(a, dtype=float)
        out = np.full(a.shape, np.nan)
        X = np.moveaxis(a[..., have], -1, 0).reshape(have.size, -1)
        ok = np.isfinite(X)
        total, count = S @ np.where(ok, X, 0.0), S @ ok.astype(float)
        m = np.divide(total, count, out=np.full(total.shape, np.nan), where=ok & (count > 0))
        out[..., have] = np.moveaxis(m.reshape((have.size,) + a.shape[:-1]), 0, -1)
        return out

    mean.radius = float(np.median(far)) if far.size else 0.0  # mm: the farthest member, median over the points
    return mean


def ring_scatter(ring, d):
    """``(ring(d), ring(d²) - ring(d)²)``: the :func:`ring_mean` of ``d`` and the scatter of ``d`` within each
    mean (the probes' and the data's alike, :func:`ring_noise_scale`)."""
    m = ring(d)
    return m, ring(np.square(d)) - np.square(m)


def value_ring(psi, ks, apart):
    """The :func:`ring_mean` of the value's bias estimate for the regression with centre spacing ``ks`` (point
    spacings; None: none), members ``apart`` mm: None where its median radius exceeds :data:`RING_RADIUS_SHARE`
    of the centre spacing.

    Notes
    -----
    A regression's bias ripples with its centres at worst: a mean over a
    disc of radius ``r`` keeps ``(2 J1(k r) / (k r))²`` of a ripple of
    wavelength ``2 π / k``, 3 % at half the wavelength. Measured, the
    denoised temperature's RMS of error/std without / with the mean: where
    the radius is 0.17-0.40 of the centre spacing it helped or held (over
    noise seeds 11-14: drawn-606, 0.17, 1.44 / 0.89; plate-fine-twist, 0.20,
    0.83 / 0.79; strip-band, 0.36, 1.49 / 1.17, keeping 70 % of the bias' ``b²``;
    plate-band-2mm, 0.40, 1.43 / 1.06), at 0.57-0.71 it did not (the tiny
    demo half-shell, centres 2 spacings apart, 0.71: 1.37 / 1.56 over seeds
    1-4; one draw each of drawn-101 1.25 / 1.28, drawn-303 1.05 / 1.08,
    wide-shell-spot 1.02 / 1.05, thin-tube-band 0.82 / 0.80).
    """
    from ..surface.parametrisation import median_spacing

    if ks is None:
        return None
    ring = ring_mean(psi, apart=apart)
    h = median_spacing(np.asarray(psi, dtype=float)[np.isfinite(psi).all(axis=1)])
    return ring if ring.radius <= RING_RADIUS_SHARE * float(np.min(ks)) * h else None


def _ring_members(p, n, apart):
    """``(rows, cols)``: each point (row) and its ring's members (cols), nearest first, each at least ``apart``
    from the members before it (the point itself first)."""
    from scipy.spatial import cKDTree

    N = p.shape[0]
    if N == 0 or n < 1:
        return np.zeros(0, int), np.zeros(0, int)
    k = min(RING_CANDIDATES if apart > 0 else n, N)
    nb = cKDTree(p).query(p, k=k)[1].reshape(N, k)
    taken = np.full((N, n), -1)
    taken[:, 0] = nb[:, 0]
    count = np.ones(N, int)
    for j in range(1, k):  # nearest first: a candidate joins where it is far enough from every member so far
        c = nb[:, j]
        far = np.ones(N, bool)
        for m in range(n):
            has = taken[:, m] >= 0
            dist = np.linalg.norm(p[c] - p[np.maximum(taken[:, m], 0)], axis=1)
            far &= ~has | (dist >= apart)
        join = far & (count < n)
        taken[join, count[join]] = c[join]
        count += join
        if (count >= n).all():
            break
    rows = np.repeat(np.arange(N), n).reshape(N, n)
    return rows[taken >= 0], taken[taken >= 0]


def ring_apart(pixel, psi):
    """The :data:`RING_APART_PX` in mm of the surface parameters ``psi`` (N, 2): over the points' nearest
    neighbours at up to 8 times of ``pixel`` (T, N, 2, px; NaN: none), the image's scale (px per mm) at its
    10th percentile, so that nine in ten neighbour pairs are that far apart in the image; 0 where none."""
    from scipy.spatial import cKDTree

    psi = np.asarray(psi, dtype=float)
    pixel = np.asarray(pixel, dtype=float)
    ok = np.isfinite(psi).all(axis=1)
    if ok.sum() < 2 or pixel.ndim != 3:
        return 0.0
    idx = np.flatnonzero(ok)
    d, nb = cKDTree(psi[idx]).query(psi[idx], k=2)
    a, b = idx, idx[nb[:, 1]]
    scales = []
    for t in np.unique(np.linspace(0, pixel.shape[0] - 1, min(8, pixel.shape[0])).round().astype(int)):
        px = np.linalg.norm(pixel[t, a] - pixel[t, b], axis=1)
        good = np.isfinite(px) & (d[:, 1] > 0)
        scales.append(px[good] / d[good, 1])
    scales = np.concatenate(scales) if scales else np.zeros(0)
    scales = scales[scales > 0]
    return float(RING_APART_PX / np.percentile(scales, 10)) if scales.size else 0.0


def ring_noise_scale(own, spread, trusted):
    """``κ_r²``: the data's noise variance over the probes' in the value's :func:`ring_mean`, from the scatter
    within each mean (:func:`ring_scatter`): the data's ``own`` and the probes' mean ``spread``, (T, N) each (None
    or a number: no ring); 1 where it cannot be formed.

    Notes
    -----
    The members of a mean are at least :data:`RING_APART_PX` apart, their
    noise independent, while the bias varies on the regression's centre
    spacing: their scatter ``ring(d²) - ring(d)²`` is the noise's, and it
    scales the probes' variance of the mean without taking in the bias.
    :func:`~irdic.uncertainty.regression_bias.noise_scale` scales all the probes
    from the regression's residual; on the smooth, dense family members the value's difference was
    still 7 % above the probes' in variance, and the bias estimate took it
    for a bias (plate-fine-twist: ``κ_r²`` 1.03-1.05 over four noise seeds,
    the RMS of error/std 0.79 -> 0.84; strip-band 1.00-1.02, unchanged).
    """
    if own is None or not np.ndim(spread):
        return 1.0
    ok = np.isfinite(own) & np.isfinite(spread) & (True if trusted is None else trusted)
    if ok.sum() < 10 or not np.sum(spread[ok]) > 0:
        return 1.0
    k2 = float(np.sum(own[ok]) / np.sum(spread[ok]))
    log.info("fields: the data's noise in the value's ring mean is %.3g x the probes' (variance, scatter within "
             "the means)", k2)
    return k2
