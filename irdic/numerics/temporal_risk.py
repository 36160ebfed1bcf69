"""Whether a temporal regression beats the interpolation: Mallows' C_p with the noise known.

GCV (:func:`~irdic.numerics.temporal_choice.gcv_temporal`) compares
regressions only; :func:`bias_ratio` tells whether the one it picked is
better than no regression at all.
"""

from __future__ import annotations

import numpy as np

from ..validation import float_array, increasing_times
from .temporal import TemporalInterpolant

__all__ = ["CP_LIMIT", "bias_ratio"]

#: the regression is kept while its residual is at most this many times what noise alone would leave
#: (:func:`bias_ratio`): Mallows' C_p of the regression and of the interpolation are equal there
CP_LIMIT = 2.0


def bias_ratio(times, series, smoothing, noise_var, *, c=1.0, R0=1.0):
    """The temporal regression's residual over what the series' white noise alone would leave.

    Parameters
    ----------
    times : array_like, shape (M,)
        Sample times (s).
    series : array_like, shape (M, n)
        Complete series (finite), one per column.
    smoothing : float
        The regression's centre spacing factor (> 1).
    noise_var : float
        The columns' mean white-noise variance (their unit squared).
    c, R0 : float
        Kernel (as :class:`~irdic.numerics.temporal.TemporalInterpolant`).

    Returns
    -------
    float
        ``RSS / (n (M - p) noise_var)``, ``p`` the regression's parameters;
        NaN where ``noise_var`` is not positive or there is no column.

    Notes
    -----
    With the noise known, Mallows' ``C_p`` estimates each series' summed
    squared error: ``RSS - (M - 2p) σ²`` for the regression, ``M σ²`` for the
    interpolation (which reproduces the samples, noise and all). The
    regression is the better estimate while ``RSS < 2 (M - p) σ²``, i.e. a
    ratio below :data:`CP_LIMIT`. GCV cannot make this comparison (its
    denominator vanishes at ``p = M``): where a signal changes within a few
    samples (a narrow band passing a point in two DIC times), every candidate
    leaves a residual of bias and GCV picks the least bad of them.
    """
    t = increasing_times(times, "times", "n_times")
    F = float_array(series, "series").reshape(t.size, -1)
    if not (np.isfinite(noise_var) and noise_var > 0) or F.shape[1] == 0:
        return float("nan")
    ts = TemporalInterpolant(t, c=c, R0=R0, smoothing=float(smoothing))
    return ts.residual_ss(F) / (F.shape[1] * (t.size - ts.n_parameters) * float(noise_var))

