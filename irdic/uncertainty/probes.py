"""The noise probes' shared settings, their times, and a block of the IR probes' regressions.

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

from .regression_bias import half_means, reference_spacing
from .ring import ring_scatter

__all__ = ["PROBES", "PROBE_GROUP", "BIAS_PROBES", "PROBE_TIMES", "probe_times", "spread", "SpreadStack", "probe_block"]

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


def probe_block(noise, regress_space, geo, visible, ks, W, sub, off, bias, ref_k, ring=None, halves=None):
    """A block of the noise probes of the spatial (and temporal) regression of the temperatures
    (:func:`irdic.uncertainty.model.uncertainties`; its probe groups run a block per thread).

    ``noise`` (b, T_w, N) K, the hidden points NaN (made 0 here) at the window's ``T_w`` times of which the
    ``T`` of ``visible`` (T, N) start at ``off``; ``sub``: the probed times among the ``T``; ``W`` the temporal
    weights (gradient, rate, their exact interpolation's, the rate's reference, the value: the gradient's array
    itself where it is the same regression) or None; ``ks`` the spatial spacing; ``bias``: with the noise of the
    regressions' differences; ``ref_k``: the spacing of the gradient's reference (1: the exact
    interpolation) these probes also run through, or None; ``ring``: the mean over each point's nearest that the
    value's difference takes before it is squared (:func:`~irdic.uncertainty.ring.ring_mean`), or None;
    ``halves`` (2, N): the patch's halves whose mean rate differences' product each probe gives (``rt_common``,
    :func:`~irdic.uncertainty.regression_bias.common_bias`'s null), or None.

    Returns the sums over the ``b`` probes of the squares the uncertainty averages (``v``, ``g``, ``res``;
    ``r`` with ``W``; with ``bias`` ``v_var``, ``rt_var``, ``rs_var``, ``vt_var``, and ``v_spread`` with
    ``ring``; with ``ref_k``
    ``g_var``), and with ``ref_k`` each probe's squared differences (the bias estimates' nulls).
    """
    T, N = visible.shape
    b = noise.shape[0]
    m = b * sub.size
    W0, W1, I0, I1, Wv = W if W is not None else (None,) * 5
    sums, squares = {}, {k: [] for k in ("v_var", "g_var", "rt_var", "rs_var", "vt_var", "rt_common")}
    noise_c = noise[:, off:off + T][:, sub]
    if W0 is None:
        g, v = regress_space(noise_c.reshape(m, N), geo.dual[sub], ks)
        value_in = noise_c
        res = noise_c - v.reshape(noise_c.shape)
    else:
        # in space at each time first, then in time (irdic.fields.space_time.space_time)
        s = np.nan_to_num(regress_space(noise.reshape(-1, N), None, ks)[1].reshape(noise.shape), copy=False)
        res = noise_c - s[:, off:off + T][:, sub]
        k_ref = reference_spacing(ks) if bias else None  # the rate's spatial reference (space_time._bias_inputs)
        s_ref = None if k_ref is None else np.nan_to_num(
            regress_space(noise.reshape(-1, N), None, k_ref)[1].reshape(noise.shape), copy=False)
        np.nan_to_num(noise, copy=False)  # the hidden points count as 0 from here on, as in the data's differences
        sums["r"] = np.sum((W1[sub] @ s) ** 2, axis=0)  # (S, T_w) @ (b, T_w, N): one BLAS call per probe
        smoothed = W0[sub] @ s
        smoothed[:, ~visible[sub]] = np.nan
        g, v = regress_space(smoothed.reshape(m, N), geo.dual[sub], ks)
        if Wv is not W0:  # the value's own, lighter regression in time (irdic.fields.space_time.space_time)
            smoothed = Wv[sub] @ s
            smoothed[:, ~visible[sub]] = np.nan
            v_own = regress_space(smoothed.reshape(m, N), None, ks)[1]
        del smoothed
        # the bias is judged against the temporal regression of the points' own series
        value_in = W0[sub] @ noise
        if bias:  # the noise in the space-time regression's differences (model._space_time_bias)
            for key, Wd, x in (("rt_var", W1 - I1, s), ("rs_var", W1, s - (noise if s_ref is None else s_ref)),
                               ("vt_var", Wv - I0, s)):
                dx = Wd[sub] @ x
                if key == "rt_var" and halves is not None:  # every probe: the product's scatter is wide
                    squares["rt_common"] += list(np.prod(half_means(dx, halves, visible[sub]), axis=-1))
                sq = dx ** 2
                sums[key] = np.sum(sq, axis=0)
                squares[key] += list(sq) if ref_k is not None else []
    g, v = g.reshape(b, sub.size, N, 3), v.reshape(b, sub.size, N)
    # the value's spatial bias is judged on the gradient's field (model._bias_terms), its noise is its own
    sums["v"] = np.sum((v if W0 is None or Wv is W0 else v_own.reshape(v.shape)) ** 2, axis=0)
    sums["res"] = np.sum(res ** 2, axis=0)  # (noise - S noise): see noise_scale
    sums["g"] = np.sum(g ** 2, axis=0)
    if bias:
        if ring is None:
            dv = (v - value_in) ** 2
        else:  # the data's difference is NaN at the hidden points: the mean leaves them out there as well
            mean, scatter = ring_scatter(ring, np.where(visible[sub], v - value_in, np.nan))
            dv = mean ** 2
            # the scatter within each mean, which calibrates the probes to the data (ring_noise_scale)
            sums["v_spread"] = np.sum(scatter, axis=0)
        sums["v_var"] = np.sum(dv, axis=0)
        squares["v_var"] += list(dv) if ref_k is not None else []
    if ref_k is not None:
        # the same probes through the exact interpolation (k = 1): the noise expected in the
        # difference regression - interpolation, which is subtracted from the data's difference
        g_int = regress_space(value_in.reshape(m, N), geo.dual[sub], ref_k)[0].reshape(
            b, sub.size, N, 3)
        sums["g_var"] = np.sum((g - g_int) ** 2, axis=0)
        squares["g_var"] += list((g - g_int) ** 2)
    return sums, squares
