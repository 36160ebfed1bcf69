"""The noise probes' shared settings and their times.

The per-point uncertainties (:mod:`irdic.uncertainty.model`,
:mod:`irdic.uncertainty.strain`) run random noise probes through the
fields stage's operators with the smoothing frozen; a long record's probes
are evaluated at at most :data:`PROBE_TIMES` times, every other time taking
the nearest probed time's result (the noise propagated by a fixed operator
follows the geometry, which changes slowly from stage to stage).
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["PROBES", "PROBE_GROUP", "BIAS_PROBES", "PROBE_TIMES", "probe_times", "spread"]

#: random probes of the operators propagated by Monte Carlo
PROBES = 16
#: probes run through the spatial regressions together (their memory is PROBE_GROUP x times x points)
PROBE_GROUP = 4
#: the first BIAS_PROBES probes also run through the exact interpolation, for the noise variance of a
#: regression's difference to it (the costliest operator; the variance is averaged locally anyway)
BIAS_PROBES = 4
#: the noise probes are evaluated at at most this many times spread over the record; each other time takes
#: the nearest probed time's standard deviation (the noise follows the slowly changing geometry)
PROBE_TIMES = 32


def probe_times(T):
    """The probed times of ``T`` (at most :data:`PROBE_TIMES`, spread evenly, first and last included; all
    when there are no more) and, for each of the ``T`` times, the position of the nearest probed one."""
    sub = np.unique(np.linspace(0, T - 1, min(T, PROBE_TIMES)).round().astype(int))
    return sub, np.searchsorted((sub[1:] + sub[:-1]) / 2, np.arange(T))


def spread(a, near):
    """Per-time values ``a`` (S, N, ...) at the probed times -> (T, N, ...): the nearest probed time's; a
    point without a value there (hidden then) takes its median over the probed times."""
    out = a[near]
    if a.shape[0] == near.size:  # every time probed
        return out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # points never seen: all NaN
        med = np.nanmedian(a, axis=0)
    return np.where(np.isfinite(out), out, med)
