"""The temporal regression's centre spacing chosen from the data: by GCV on the values, by the estimated risk
of the rate.

GCV (:func:`gcv_temporal`) judges how well a regression predicts the
series' values, without knowing the noise; :func:`rate_risk_temporal`
estimates the mean squared error of the regression's time derivative (a
Mallows-type criterion against the least smoothed candidate), which a
spacing that fits the values well can still bias. Both try the candidates of
:func:`regression_candidates`.
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import ConfigError, DataError, GeometryError
from ..validation import float_array, increasing_times
from .temporal import TemporalInterpolant

__all__ = ["gcv_temporal", "rate_risk_temporal", "regression_candidates", "judged_columns", "TEMPORAL_CANDIDATES",
           "GCV_MAX_SERIES", "RATE_MAX_FRACTION"]

log = logging.getLogger(__name__)

#: Most parameters per sample of the regression the material rate is taken from (:func:`rate_risk_temporal`'s
#: ``max_fraction``; the value's GCV has 1/2; the figures below are GCV's, which chose the rate's spacing before
#: the rate's risk did). The rate of a fast transient sampled at a few stages per time constant is limited by the
#: regression's bias, not by the noise left after the spatial regression: on the tube (demo, 21 stages at 2 Hz,
#: 0.05 K) GCV's curve has its minimum at centres every 2 stages (13 parameters of 21), which the cap of 1/2
#: excluded (it took 3: rate error 3.5 %, against 2.7 % at 2). Not more: with 17 parameters of 21 (spacing 1.5)
#: the GCV denominator is 0.04 and its choice scatters.
RATE_MAX_FRACTION = 2.0 / 3.0


#: Series (columns) :func:`gcv_temporal` pools at most, evenly spaced among those given: its choice is a
#: property of the record's signal and noise, which a few thousand points judge as well as all of them.
GCV_MAX_SERIES = 4096


def gcv_temporal(times, series, *, c=1.0, R0=1.0, candidates=None, max_series=GCV_MAX_SERIES,
                 max_fraction=0.5):
    """Choose the temporal regression's centre spacing by generalised cross-validation.

    Parameters
    ----------
    times : array_like, shape (M,)
        Sample times (s).
    series : array_like, shape (M, ...)
        Time series (finite) to judge by, pooled: every column counts.
    c, R0 : float
        Kernel (as :class:`TemporalInterpolant`).
    candidates : sequence of float, optional
        Centre spacing factors (> 1); default :data:`TEMPORAL_CANDIDATES`, as many as ``M`` allows
        (:func:`regression_candidates`).
    max_series : int
        At most this many columns (evenly spaced) enter the pooled GCV.
    max_fraction : float
        Candidates with more than ``max_fraction M`` parameters are left out
        (GCV's denominator ``(1 - p/M)²`` becomes unreliable as ``p`` nears
        ``M``); the value's default 1/2, the rate's
        :data:`RATE_MAX_FRACTION`.

    Returns
    -------
    k : float
        Factor with the least ``GCV = n RSS / (n - p)^2``; 1.0 (interpolation)
        when no candidate fits (at most ``max_fraction M`` parameters: fewer
        than ~10 times).
    table : list of (k, n_parameters, gcv)

    Notes
    -----
    The hat matrix of the regression is ``Q Q^T`` with trace ``p``, the number
    of parameters, so GCV is exact and cheap.
    """
    t = increasing_times(times, "times", "n_times")
    F = float_array(series, "series")
    if F.shape[0] != t.size:
        raise ConfigError(f"series must have M = {t.size} rows, got shape {F.shape}")
    F = F.reshape(t.size, -1)
    if not np.isfinite(F).all():
        raise DataError("series contain NaN or inf; GCV needs complete series")
    if F.shape[1] > max_series:
        F = F[:, judged_columns(F.shape[1], max_series)]
    M = t.size
    table = []
    for k, ts in regression_candidates(t, c=c, R0=R0, candidates=candidates, max_fraction=max_fraction):
        p = ts.n_parameters
        rss = ts.residual_ss(F)
        table.append((k, p, M * rss / F.shape[1] / (M - p) ** 2))
    if not table:
        log.warning("temporal GCV: %d times are too few for a regression; interpolating", M)
        return 1.0, table
    best = min(table, key=lambda r: r[2])
    log.info("temporal GCV: centres every %.3g times (%d parameters of %d)", best[0], best[1], M)
    return best[0], table


#: the temporal regressions' centre spacing factors a choice from the data tries (:func:`regression_candidates`)
TEMPORAL_CANDIDATES = (1.5, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64)


def regression_candidates(times, *, c=1.0, R0=1.0, candidates=None, max_fraction=0.5):
    """``[(k, TemporalInterpolant)]``: the regressions of the spacings ``candidates`` (> 1; default
    :data:`TEMPORAL_CANDIDATES`) on ``times`` that fit, in increasing ``k``: at least 3 centres, at most
    ``max_fraction`` parameters per sample, each number of parameters once (the least spacing that gives it)."""
    t = increasing_times(times, "times", "n_times")
    out, seen = [], set()
    for k in sorted(float(x) for x in (TEMPORAL_CANDIDATES if candidates is None else candidates)):
        if k <= 1:
            raise ConfigError(f"candidates must be > 1 (1 is interpolation, GCV undefined), got {k}")
        try:
            ts = TemporalInterpolant(t, c=c, R0=R0, smoothing=k)
        except (DataError, GeometryError):
            continue
        p = ts.n_parameters
        if p in seen or p > int(max_fraction * t.size) or ts.centre_index.size < 3:
            continue
        seen.add(p)
        out.append((k, ts))
    return out


def judged_columns(n, max_series=GCV_MAX_SERIES):
    """Indices of the columns of ``n`` that :func:`gcv_temporal` pools: all, or ``max_series`` evenly spaced."""
    return np.arange(n) if n <= max_series else np.linspace(0, n - 1, max_series).astype(int)


def rate_risk_temporal(times, series, *, c=1.0, R0=1.0, candidates=None, max_series=GCV_MAX_SERIES,
                       max_fraction=RATE_MAX_FRACTION):
    """Choose the temporal regression's centre spacing by the estimated mean squared error of its rate.

    Parameters
    ----------
    times : array_like, shape (M,)
        Sample times (s), at least 3.
    series : array_like, shape (M, ...)
        Time series (finite) with white noise of one unknown standard
        deviation, pooled: every column counts.
    c, R0 : float
        Kernel (as :class:`~irdic.numerics.temporal.TemporalInterpolant`).
    candidates : sequence of float, optional
        Centre spacing factors (> 1), as :func:`gcv_temporal`'s.
    max_series : int
        At most this many columns (evenly spaced) are judged.
    max_fraction : float
        Candidates with more than ``max_fraction M`` parameters are left out
        (:func:`regression_candidates`); the least
        smoothed of the others is the pilot.

    Returns
    -------
    k : float
        The factor of least estimated risk; 1.0 (interpolation) where fewer
        than two candidates fit.
    table : list of (k, n_parameters, risk)
        ``risk``: the estimated mean squared error of the rate per series and
        judged time (units²/s²).

    Notes
    -----
    The regression's rate at the samples is ``r_k = D_k f`` (``D_k``: the
    weights of the derivative, M x M). For white noise of variance σ² the
    risk ``E |r_k - r|²`` is ``|b_k|² + σ² ‖D_k‖²_F``; with the least
    smoothed candidate as an (almost) unbiased pilot ``r_0``,
    ``R_k = |r_k - r_0|² - σ² (‖D_0‖²_F - 2 tr(D_k D_0ᵀ))`` estimates it up
    to the pilot's own bias, as :func:`~irdic.surface.regression.gradient_risk_spatial`
    does for the gradient in space; σ² is the pilot's residual variance
    ``RSS_0 / (n (M - p_0))``. Judged at the samples inside the series (the
    first and last are one-sided). GCV judges the values, which a regression
    fits well over a wider range of spacings than it fits their derivative:
    on the noisy family's twisting tube (21 stages at 2 Hz) GCV took centres
    every 3 stages and the rate erred by 3.1 % (95 % of it flagged
    bias-dominated); the rate's risk takes 2 (2.3 %, 70 %).
    """
    t = increasing_times(times, "times", "n_times")
    F = float_array(series, "series").reshape(t.size, -1)
    if not np.isfinite(F).all():
        raise DataError("series contain NaN or inf; the rate's risk needs complete series")
    F = F[:, judged_columns(F.shape[1], max_series)]
    M, n = F.shape
    fits = regression_candidates(t, c=c, R0=R0, candidates=candidates, max_fraction=max_fraction)
    if len(fits) < 2 or n == 0 or M < 3:
        return 1.0, []
    inner = slice(1, M - 1)
    k0, pilot = fits[0]
    var = pilot.residual_ss(F) / (n * (M - pilot.n_parameters))
    D0 = pilot.weights(t, 1)[inner]
    r0, norm0 = D0 @ F, float(np.sum(D0 ** 2))
    table = []
    for k, ts in fits:
        D = ts.weights(t, 1)[inner]
        d = float(np.sum((D @ F - r0) ** 2)) / n
        table.append((k, ts.n_parameters, (d - var * (norm0 - 2.0 * float(np.sum(D * D0)))) / (M - 2)))
    best = min(table, key=lambda r: r[2])
    log.info("temporal rate risk: centres every %.3g times (%d parameters of %d); %s", best[0], best[1], M,
             ", ".join(f"{k:.3g}: {r:.3g}" for k, _, r in table))
    return best[0], table
