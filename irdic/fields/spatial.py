"""The spatial regression of the point temperatures of each time, and the choice of its centre spacing.

The regressed field's own derivatives on the surface parameters give the
in-plane gradient (:func:`regressed_gradient`); its spacing is chosen by the
estimated risk of that gradient (:func:`space_gcv_filled`).
"""

from __future__ import annotations

import logging

import numpy as np

from ..surface.parametrisation import median_spacing
from ..threads import thread_budget

__all__ = ["AFTER_TIME_SHARE", "JUDGED_MARGIN", "RISK_DESIGNS", "judged_points", "regressed_gradient", "space_gcv",
           "space_gcv_filled"]

log = logging.getLogger(__name__)


#: Runs of five consecutive times at most whose fourth differences measure the noise of the spatial regression's
#: candidates (:func:`space_gcv_filled`): the tiny demo tube's 273 points need more than 8 (gradient 10.8 % with 32
#: and with the white model, 15.8 % with 8: its choice followed the measured covariance's scatter).
QUINTETS = 32

#: The temperature regression's spacing is judged on points more than this many point spacings inside the
#: cloud's edge (:func:`space_gcv_filled`).
JUDGED_MARGIN = 3.0


def judged_points(p):
    """Which points (surface parameters ``p``, (N, 2), all finite) lie more than :data:`JUDGED_MARGIN` point
    spacings inside the cloud's edge: those the smoothing choices judge by."""
    from ..surface import edge_distance

    return edge_distance(p) >= JUDGED_MARGIN * median_spacing(p)


def space_gcv_filled(filled, p, *, c, R0, separation=None, after=None, designs=None):
    """Centre spacing of the spatial regression from up to 8 filled times (rows of ``filled``).

    Chosen by the estimated risk of the gradient
    (:func:`irdic.surface.regression.gradient_risk_spatial`), not by GCV of
    the values: the gradient is what this regression is for, and GCV's curve
    is flat where the gradient's error still halves. ``separation`` (mm): one IR pixel (see there).
    ``after``: ``(t, k, c_t, R0_t, single)``, the rows' times (s), the regression in time that follows
    (its spacing ``k``, kernel) and the spacing chosen on single times: judged on what the fields deliver
    (:func:`_after_time`), at most ``single`` (:func:`_narrower`). ``designs``: a dict
    that keeps the candidates' designs for the next call on the same points (see there).
    """
    from ..surface.regression import gradient_risk_spatial

    if after is None:
        sample, noise = filled[np.linspace(0, filled.shape[0] - 1, min(filled.shape[0], 8)).astype(int)], 1.0
    else:
        sample, noise = _after_time(filled, *after[:4])
    quintets = None
    runs = min(QUINTETS, filled.shape[0] - 4)
    if runs > 0:
        # runs of five consecutive times over the record (overlapping where it is short): their fourth differences
        # measure the noise of each candidate, correlated in space as it is (shared pixels, the DIC surface),
        # white in time
        first = np.round(np.linspace(0, filled.shape[0] - 5, runs)).astype(int)
        quintets = np.stack([filled[f:f + 5] for f in first], axis=0).transpose(2, 0, 1) * np.sqrt(noise)
    # the rim's data carry more than noise (mixed edge pixels, extrapolation), which the least smoothed
    # pilot follows: judged inside it, all points fitted
    judged = judged_points(p)
    k, table = gradient_risk_spatial(p, sample.T, c=c, R0=R0, judged=judged if judged.sum() >= 6 else None,
                                     separation=separation, quintets=quintets, designs=designs)
    if after is not None:
        k = _narrower(table, after[4] if len(after) > 4 else None)
    log.info("temperature_smoothing_space: the gradient's estimated risk chose %.1f point spacings%s", k,
             "" if after is None else " (judged after the regression in time)")
    return k


#: The key of ``ops`` under which :func:`regressed_gradient` keeps the gradient risk's designs
#: (:func:`~irdic.surface.regression.gradient_risk_spatial`) for the spacing judged again after the regression in time
RISK_DESIGNS = "gradient_risk_designs"

#: Times whose regression in time keeps at most this multiple of the median time's share of the noise are
#: sampled by :func:`_after_time` (the record's ends keep several times more)
AFTER_TIME_SHARE = 1.25


def _after_time(filled, t, k, c_t, R0_t):
    """``(sample, noise)``: ``filled`` (T, N) at the times ``t`` regressed in time with spacing ``k``, at up to 8
    of those times to judge by (8, N), and the share of white noise's variance the regression keeps there.

    Notes
    -----
    The fields' gradient is that of the spatial regression of the series
    regressed in time. The spatial regression's bias (a pattern that varies
    smoothly in time) passes the regression in time; its noise, white in
    time, keeps ``Σ_j w_ij²`` of its variance (``w``: the regression in time's
    weights). Judged on single times, a noise that the regression in time
    divides by 2.6-7 hid the bias of wide spacings: the twisted tube's risk
    chose 24 spacings and a gradient 4.0 % off, 2.2 % at the 12 chosen here
    (benchmarks/README.md). Times near the record's ends, whose regression
    keeps several times the median share, are not sampled: the noise the
    quintets measure is scaled by that median.
    """
    from ..numerics.temporal import TemporalInterpolant, temporal_window

    reg = TemporalInterpolant(t, c=c_t, R0=R0_t, smoothing=k, window=temporal_window(t, c=c_t, R0=R0_t, smoothing=k))
    weights = reg.weights(t, 0)
    share = np.sum(np.square(weights), axis=1)
    noise = float(np.median(share))
    usable = np.flatnonzero(share <= AFTER_TIME_SHARE * noise)
    rows = usable[np.linspace(0, usable.size - 1, min(usable.size, 8)).astype(int)]
    # only the sampled times regressed (``filled`` has no gaps: the regression is its weights' product)
    return weights[rows] @ filled, noise


def _narrower(table, single):
    """The spacing of least risk after the regression in time among the candidates of ``table``
    (:func:`~irdic.surface.regression.gradient_risk_spatial`) up to ``single``, the choice on single times.

    Less noise moves the least risk ``|b_k|² + γ N_k`` to narrower spacings, never to wider ones (where
    ``|b_k|² + N_k`` was least at ``k*``, a wider ``k`` has ``|b_k|² - |b_k*|² >= N_k* - N_k >= γ (N_k* - N_k)``):
    a wider choice is the estimate's scatter. The pilot (the first row, the least smoothed) only where it was
    the choice on single times: the risk is estimated up to the pilot's own bias, and the pilot's is its noise
    alone, which after the regression in time no longer outweighs that bias (the demo half-shell: its 2
    spacings chosen over the 3 of single times, the gradient 0.0048 K/mm off against 0.0030)."""
    fit = [r for r in table if single is None or r[0] <= single * (1.0 + 1e-9)] or table[:1]
    return float(min(fit[1:] or fit, key=lambda r: r[2])[0])


def space_gcv(theta, psi, *, c, R0, ops=None, separation=None, after=None, designs=None):
    """:func:`space_gcv_filled` of the times of ``theta`` (T, N) with 6 or more visible points; ``after``: ``(t,
    k, c_t, R0_t, single)`` with ``t`` the times of ``theta`` (see there)."""
    from ..surface import shared_interpolant

    have = np.isfinite(psi).all(axis=1)
    visible = np.isfinite(theta) & have
    times = np.flatnonzero(visible.sum(axis=1) >= 6)
    if times.size == 0:
        return None
    filled, _ = shared_interpolant({} if ops is None else ops, psi[have], c=c, R0=R0).fill(
        theta[np.ix_(times, have)], visible[np.ix_(times, have)])
    if after is not None:
        after = (np.asarray(after[0], dtype=float)[times], *after[1:])
    return space_gcv_filled(filled, psi[have], c=c, R0=R0, separation=separation, after=after, designs=designs)


def regressed_gradient(theta, psi, dual, smoothing, *, c, R0, ops=None, everywhere=False):
    """In-plane gradient and value from a spatial regression of the point temperatures of each time.

    Missing values of a time are filled from that time's visible points first;
    times with fewer than 6 visible points stay NaN. Returns ``(grad (T, N, 3)
    K/mm, value (T, N) degC, the centre spacing factor used)``, both NaN where
    the input is, or with ``everywhere`` the value also at the points without
    one (the regressed field there, from the time's other points); ``dual`` None:
    the values only (``grad`` None, no derivatives computed). ``dual`` (T_d, N, 2, 3) may hold
    fewer times than ``theta``: row ``m`` of ``theta`` then uses the dual basis
    of time ``m % T_d`` (noise probes stacked along time). ``ops``: a cache of
    the spatial operators (:func:`irdic.surface.shared_interpolant`) shared by
    the calls of one stage run.
    """
    from ..surface import shared_interpolant

    ops = {} if ops is None else ops
    T, N = theta.shape
    have = np.isfinite(psi).all(axis=1)
    visible = np.isfinite(theta) & have
    times = np.flatnonzero(visible.sum(axis=1) >= 6)
    if times.size == 0:
        log.warning("temperature_smoothing_space: no time with 6 or more visible points; gradient left NaN")
        return None if dual is None else np.full((T, N, 3), np.nan), np.full((T, N), np.nan), smoothing
    p = psi[have]
    # every time and point (the usual case): the input itself, not a gathered copy (the fill copies it anyway)
    whole = times.size == T and bool(have.all())
    filled, _ = shared_interpolant(ops, p, c=c, R0=R0, smoothing=1.0).fill(
        theta if whole else theta[np.ix_(times, have)], visible if whole else visible[np.ix_(times, have)])
    if smoothing == "gcv":  # the candidates' designs kept in ops for the choice judged again after time
        k = space_gcv_filled(filled, p, c=c, R0=R0, designs=ops.setdefault(RISK_DESIGNS, {}))
    else:
        k = float(smoothing)
    v0, d1, d2 = shared_interpolant(ops, p, c=c, R0=R0, smoothing=k).evaluate(filled.T, derivatives=dual is not None)
    del filled
    # the outputs once the fill's and the evaluation's work arrays are gone (each GBs for stacked noise probes)
    grad = None if dual is None else np.full((T, N, 3), np.nan)
    val = np.full((T, N), np.nan)
    cols = np.flatnonzero(have)
    if dual is not None:
        # rows per block: ~128 MB of dual basis over the stage's threads (the noise probes' blocks run on each)
        step = max(1, (1 << 24) // max(1, 6 * cols.size) // thread_budget())
        every = cols.size == N  # all points: slices, not gathers (GBs of dual basis at paper scale)
        for s in range(0, times.size, step):
            tt = times[s:s + step]
            D = dual[tt % dual.shape[0]]
            D = D if every else D[:, cols]
            g = d1[:, s:s + step].T[..., None] * D[:, :, 0]
            g += d2[:, s:s + step].T[..., None] * D[:, :, 1]
            if every:
                grad[tt] = g
            else:
                grad[tt[:, None], cols] = g
        grad[~visible] = np.nan
    val[times[:, None], cols] = v0.T
    if not everywhere:
        val[~visible] = np.nan
    return grad, val, k
