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

__all__ = ["PROBES", "PROBE_GROUP", "BIAS_PROBES", "PROBE_TIMES", "probe_times", "spread", "SpreadStack"]

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


class SpreadStack:
    """``K`` per-probe arrays at the probed times, read as their :func:`spread` to every time on demand.

    The probes' squared differences (``K`` x (T, N[, C])) are needed at a few
    times only (:func:`~irdic.uncertainty.regression_bias.local_bias` pools
    their scatter over a subset of the times): held at the probed times they
    take ``S / T`` of the memory (at paper scale 32 of 300 times, ~0.9 GB less
    at 13,000 points).

    Parameters
    ----------
    a : ndarray, shape (K, S, N, ...)
        The arrays at the ``S`` probed times.
    near : ndarray of int, shape (T,)
        The nearest probed time of each time (:func:`probe_times`).
    """

    def __init__(self, a, near):
        self._a = np.asarray(a, dtype=float)
        self._near = np.asarray(near)
        self._medians = None  # each array's median over the probed times, once (rows() is called per block)

    def __len__(self):
        return self._a.shape[0]

    @property
    def shape(self):
        return (self._a.shape[0], self._near.size) + self._a.shape[2:]

    def rows(self, times):
        """The spread arrays at ``times`` (array of time indices): (K, len(times), N, ...)."""
        out = self._a[:, self._near[times]]
        if self._a.shape[1] == self._near.size:  # every time probed: spread() fills nothing
            return out
        if self._medians is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # points never seen: all NaN
                self._medians = np.array([np.nanmedian(a, axis=0) for a in self._a])
        return np.where(np.isfinite(out), out, self._medians[:, None])

    def __imul__(self, k):
        self._a *= k
        self._medians = None
        return self

    def __array__(self, dtype=None, copy=None):
        out = np.array([spread(a, self._near) for a in self._a])
        return out if dtype is None else out.astype(dtype)
