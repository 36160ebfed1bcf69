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

__all__ = ["JUDGED_MARGIN", "judged_points", "regressed_gradient", "space_gcv", "space_gcv_filled"]

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


def space_gcv_filled(filled, p, *, c, R0, separation=None):
    """Centre spacing of the spatial regression from up to 8 filled times (rows of ``filled``).

    Chosen by the estimated risk of the gradient
    (:func:`irdic.surface.regression.gradient_risk_spatial`), not by GCV of
    the values: the gradient is what this regression is for, and GCV's curve
    is flat where the gradient's error still halves. ``separation`` (mm): one IR pixel (see there).
    """
    from ..surface.regression import gradient_risk_spatial

    rows = np.linspace(0, filled.shape[0] - 1, min(filled.shape[0], 8)).astype(int)
    sample = filled[rows].T
    quintets = None
    runs = min(QUINTETS, filled.shape[0] - 4)
    if runs > 0:
        # runs of five consecutive times over the record (overlapping where it is short): their fourth differences
        # measure the noise of each candidate, correlated in space as it is (shared pixels, the DIC surface),
        # white in time
        first = np.round(np.linspace(0, filled.shape[0] - 5, runs)).astype(int)
        quintets = np.stack([filled[f:f + 5] for f in first], axis=0).transpose(2, 0, 1)
    # the rim's data carry more than noise (mixed edge pixels, extrapolation), which the least smoothed
    # pilot follows: judged inside it, all points fitted
    judged = judged_points(p)
    k, _ = gradient_risk_spatial(p, sample, c=c, R0=R0, judged=judged if judged.sum() >= 6 else None,
                                 separation=separation, quintets=quintets)
    log.info("temperature_smoothing_space: the gradient's estimated risk chose %.1f point spacings", k)
    return k


def space_gcv(theta, psi, *, c, R0, ops=None, separation=None):
    """:func:`space_gcv_filled` of the times of ``theta`` (T, N) with 6 or more visible points."""
    from ..surface import shared_interpolant

    have = np.isfinite(psi).all(axis=1)
    visible = np.isfinite(theta) & have
    times = np.flatnonzero(visible.sum(axis=1) >= 6)
    if times.size == 0:
        return None
    filled, _ = shared_interpolant({} if ops is None else ops, psi[have], c=c, R0=R0).fill(
        theta[np.ix_(times, have)], visible[np.ix_(times, have)])
    return space_gcv_filled(filled, psi[have], c=c, R0=R0, separation=separation)


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
    if smoothing == "gcv":
        k = space_gcv_filled(filled, p, c=c, R0=R0)
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
