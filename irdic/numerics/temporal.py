"""The one temporal operator: IMQ interpolation or regression over sample times.

Frame times of the IR series (:mod:`irdic.image_rbf`) and stage times of the
DIC series (:mod:`irdic.surface`) are treated alike: an IMQ kernel
``m(r) = c / sqrt(c^2 + r^2)``, ``r = (t - t_j) / R0``, on every time plus the
monomials {1, t} (the paper's interpolant; c = 1, R0 = 1 s), or, for noisy
series, a least-squares regression with fewer centres whose spacing
generalised cross-validation can choose
(:func:`~irdic.numerics.temporal_choice.gcv_temporal`).
:func:`irdic.numerics.series.smooth_series` applies the operator to any per-point series.
"""

from __future__ import annotations

import functools
import logging
import math

import numpy as np
import scipy.linalg

from ..errors import ConfigError, DataError, GeometryError
from ..validation import as_int, float_array, increasing_times, positive, smoothing_factor
from .imq import imq, imq_dr, regression_R0
from .saddle import SaddleFactor

__all__ = ["TIME_SNAP", "TemporalInterpolant", "temporal_reach", "temporal_window", "REACH_TOL", "REGRESSION_SPACINGS",
           "local_rate_weights", "LOCAL_RATE_SAMPLES", "rate_reference_stencil", "rate_reference_weights",
           "RATE_REFERENCE_MIN_SPACING", "RATE_REFERENCE_DEGREE", "FLAT_KERNEL_SPACINGS", "kernel_R0"]

log = logging.getLogger(__name__)

#: Sample times closer than this (in units of R0) to an evaluation time are
#: taken as equal: the interpolation weights are then the identity row.
TIME_SNAP = 1e-9



#: Samples of the local polynomial (degree one less) whose derivative is the reference of a temporal
#: regression's rate bias (:func:`local_rate_weights`).
LOCAL_RATE_SAMPLES = 5

#: From this rate-regression spacing (samples) on, the rate bias reference is a least-squares polynomial of
#: :data:`RATE_REFERENCE_DEGREE` over two spacings (:func:`rate_reference_stencil`).
RATE_REFERENCE_MIN_SPACING = 6.0
RATE_REFERENCE_DEGREE = 6


#: The interpolation kernel is never flatter than this many median sample spacings (``c R0 <= n h``): the
#: saddle system of a flatter IMQ kernel loses the digits its weights are made of. Measured on uniform records
#: of 300-3,000 samples: at ``c R0 = 6 h`` the rate's noise gain is ``1.8 / h`` (a difference quotient's:
#: ``1.41 / h``) and the value's between samples 0.98, and the cardinal weights fall below
#: :data:`REACH_TOL` within 50 samples whatever the rounding; at ``8 h`` that reach already changes with a
#: 1e-12 change of the kernel; at ``12 h`` the gains are ``5-260 / h`` and 6-100, at ``25 h`` (the paper's 1 s
#: kernel on a 25 Hz camera) ``84 / h`` and 230: rates of hundreds of K/s from 0.05 K of pixel noise.
FLAT_KERNEL_SPACINGS = 6.0


def kernel_R0(times, c, R0) -> float:
    """The time normalisation (s) the interpolant uses: ``R0``, or less where ``c R0`` would exceed
    :data:`FLAT_KERNEL_SPACINGS` median spacings of ``times`` (increasing, at least 2)."""
    limit = FLAT_KERNEL_SPACINGS * float(np.median(np.diff(times))) / c
    # at the limit itself (6 Hz and the paper's kernel) R0 stays as given, not its rounding
    return float(limit) if 0 < limit < R0 * (1.0 - 1e-9) else float(R0)


#: Cardinal-weight tail (sum of |weights| of the samples a time window leaves
#: out) below which a window reproduces the whole-series interpolant: with
#: series varying by at most ~10 K about a straight line this bounds the
#: difference by 1e-4 K (see :func:`temporal_reach`).
REACH_TOL = 1e-5

#: Centre spacings a windowed temporal regression reaches beyond the interpolant's reach, on each side
#: (:func:`temporal_window`).
REGRESSION_SPACINGS = 8


class TemporalInterpolant:
    """IMQ interpolation (or regression) in time over sample times, with {1, t}.

    Parameters
    ----------
    times : array_like, shape (M,)
        Frame or stage times in s, strictly increasing (irregular spacing is
        fine); at least 2.
    c : float
        Shape factor (the paper: 1).
    R0 : float
        Time normalisation in s (the paper: 1 s). Interpolation uses at most
        :data:`FLAT_KERNEL_SPACINGS` median sample spacings over ``c``
        (:func:`kernel_R0`; :attr:`R0` holds the value used).
    smoothing : None or float >= 1
        None / 1: interpolation (the paper). ``k > 1``: least squares with
        centres on about every k-th time (first and last always) and a kernel
        six centre spacings wide (``c R0_eff = 6 H``); see :func:`~irdic.numerics.temporal_choice.gcv_temporal`.
    window : None or int >= 1
        None: one operator over all times (the paper). ``n``: the windowed
        operator of a long record: each evaluation time uses only the ``n``
        samples before the sample at or below it and the ``n`` after the
        sample above it (fewer at the series' ends), with the same operator
        (interpolation or regression) on those samples alone. Give the
        :func:`temporal_window` of the whole record.

    Notes
    -----
    Interpolation factorises the (M + 2) saddle-point system once
    (:class:`~irdic.numerics.saddle.SaddleFactor`): fine up to a few thousand
    times. Regression is a QR factorisation of the design matrix. Evaluation
    times outside ``[times[0], times[-1]]`` give NaN weights: the operator is
    not meant to extrapolate; :meth:`in_span` tells which.

    The windowed operator makes a time chunk's result equal the whole
    record's to rounding: an evaluation time's window is fixed by its place
    among the samples, so any subset of the record holding that window (a
    chunk's samples plus ``n + 1`` on each side, :func:`irdic.chunks.window`)
    gives the same weights. Inside the record the windowed interpolant
    equals the global one to the tolerance of :func:`temporal_reach`; within
    ``n`` samples of the first and last sample it is the window's own
    boundary behaviour, which the global one's slowly decaying tail there
    would otherwise tie to the whole record. A windowed regression is a
    local regression (:func:`temporal_window`, Notes).
    It also keeps long records tractable: ``O(M n^2)`` work instead of an
    ``(M + 2)^2`` system.
    """

    def __init__(self, times, *, c=1.0, R0=1.0, smoothing=None, window=None):
        t = increasing_times(times, "times", "n_times")
        if t.size < 2:
            raise DataError(
                f"times: {t.size} time(s); the temporal interpolant with monomials {{1, t}} needs at least 2"
            )
        self.times = t
        self.c = positive(c, "c")
        self.R0 = positive(R0, "R0")
        self.k = smoothing_factor(smoothing, "smoothing", allow_gcv=False)
        if self.k <= 1.0:
            # a flatter kernel's weights are rounding noise (FLAT_KERNEL_SPACINGS); the regression has its own
            self.R0 = kernel_R0(t, self.c, self.R0)
        self._mid = 0.5 * (t[0] + t[-1])
        self.window = None if window is None else as_int(window, "window", 1)
        if self.window is not None:
            self.n_parameters = None
            self._parts = {}
        elif self.k > 1.0:
            self._init_regression()
        else:
            s = (t - self._mid) / self.R0
            A = imq(s[:, None] - s[None, :], self.c)
            self._fac = SaddleFactor(A, np.c_[np.ones(t.size), s])
            self._s = s
            self.n_parameters = t.size

    def _init_regression(self):
        t, M = self.times, self.times.size
        nc = int(math.ceil((M - 1) / self.k)) + 1
        if nc + 2 > M:
            nc = M - 2
        if nc < 2:
            raise DataError(f"smoothing = {self.k:g} leaves fewer than 2 temporal centres for {M} times")
        self.centre_index = np.unique(np.round(np.linspace(0, M - 1, nc)).astype(int))
        H = (t[-1] - t[0]) / (self.centre_index.size - 1)
        self.R0_eff = regression_R0(self.c, H)
        cs = (t[self.centre_index] - self._mid) / self.R0_eff
        s = (t - self._mid) / self.R0_eff
        E = np.c_[imq(s[:, None] - cs[None, :], self.c), np.ones(M), (t - self._mid) / self.R0]
        self._Q, self._R = scipy.linalg.qr(E, mode="economic", check_finite=False)
        dg = np.abs(np.diag(self._R))
        if dg.min() < 1e-12 * dg.max():
            raise GeometryError(f"temporal regression with smoothing {self.k:g} is rank deficient")
        self._cs = cs
        self.n_parameters = E.shape[1]

    @property
    def n_times(self):
        """Number of sample times."""
        return self.times.size

    @property
    def span(self):
        """``(first, last)`` sample time in s."""
        return float(self.times[0]), float(self.times[-1])

    def residual_ss(self, F):
        """The regression's residual sum of squares over the columns of ``F`` (n_times, n); a regression only."""
        return float(np.sum((F - self._Q @ (self._Q.T @ F)) ** 2))

    def in_span(self, t_eval):
        """Boolean array: which evaluation times lie within the span (False for NaN)."""
        te = float_array(t_eval, "t_eval")
        tol = TIME_SNAP * self.R0
        with np.errstate(invalid="ignore"):
            return (te >= self.times[0] - tol) & (te <= self.times[-1] + tol)

    def weights(self, t_eval=None, derivative=0):
        """Weights ``W`` with ``f(t_eval) = W @ f(times)`` (or ``df/dt``).

        Parameters
        ----------
        t_eval : array_like, shape (T,) or scalar, optional
            Evaluation times (s), any order; default the sample times.
        derivative : {0, 1}
            0: value; 1: time derivative (weights in 1/s).

        Returns
        -------
        ndarray, shape (T, M)
            NaN rows for times outside the span (or NaN). Interpolation at a
            sample time gives exactly the identity row.
        """
        if derivative not in (0, 1) or isinstance(derivative, bool):
            raise ConfigError(f"derivative must be 0 or 1, got {derivative!r}")
        te = self.times if t_eval is None else np.atleast_1d(float_array(t_eval, "t_eval"))
        if te.ndim != 1:
            raise ConfigError(f"t_eval must be a scalar or 1-D, got shape {te.shape}")
        ok = self.in_span(te)
        W = np.full((te.size, self.n_times), np.nan)
        if ok.any() and self.window is not None:
            W[ok] = self._windowed(te[ok], derivative)
        elif ok.any():
            tt = te[ok] - self._mid
            W[ok] = self._regression(tt, derivative) if self.k > 1.0 else self._interpolation(te[ok], tt, derivative)
        return W

    def sample_window(self, t_eval):
        """``(first, stop)`` sample indices of the window of each evaluation time (in span), arrays (T,).

        The whole series for the global operator.
        """
        te = np.atleast_1d(float_array(t_eval, "t_eval"))
        if self.window is None:
            return np.zeros(te.size, np.int64), np.full(te.size, self.n_times, np.int64)
        # the bracketing samples: j - 1 <= t < j (a sample time counts as its own bracket)
        j = np.clip(np.searchsorted(self.times, te + TIME_SNAP * self.R0, side="right"), 1, self.n_times - 1)
        return np.maximum(j - 1 - self.window, 0), np.minimum(j + 1 + self.window, self.n_times)

    def _windowed(self, te, derivative):
        """Weight rows of the windowed operator: the global operator of each window's samples."""
        lo, hi = self.sample_window(te)
        W = np.zeros((te.size, self.n_times))
        keys = lo * (self.n_times + 1) + hi
        for key in np.unique(keys):
            rows = np.flatnonzero(keys == key)
            a, b = int(lo[rows[0]]), int(hi[rows[0]])
            part = self._parts.get((a, b))
            if part is None:
                # a short window (a series end) still needs its two monomials' worth of samples
                part = TemporalInterpolant(self.times[a:b], c=self.c, R0=self.R0,
                                           smoothing=self.k if self.k > 1.0 and b - a > 4 else None)
                if len(self._parts) < 4096:
                    self._parts[(a, b)] = part
            W[rows, a:b] = part.weights(te[rows], derivative)
        return W

    def _regression(self, tt, derivative):
        n = tt.size
        d = (tt / self.R0_eff)[:, None] - self._cs[None, :]
        if derivative == 0:
            E = np.c_[imq(d, self.c), np.ones(n), tt / self.R0]
        else:
            E = np.c_[imq_dr(d, self.c) / self.R0_eff, np.zeros(n), np.full(n, 1.0 / self.R0)]
        return scipy.linalg.solve_triangular(self._R, E.T, trans=1, check_finite=False).T @ self._Q.T

    def _interpolation(self, te, tt, derivative):
        n = tt.size
        s = tt / self.R0
        d = s[:, None] - self._s[None, :]
        if derivative == 0:
            B, Q = imq(d, self.c), np.c_[np.ones(n), s]
        else:
            B, Q = imq_dr(d, self.c) / self.R0, np.c_[np.zeros(n), np.full(n, 1.0 / self.R0)]
        W = self._fac.weights(B, Q)
        if derivative == 0:
            # exactly the sample at a sample time (the solve leaves ~1e-13)
            j = np.clip(np.searchsorted(self.times, te), 0, self.n_times - 1)
            for jj in (j, np.clip(j - 1, 0, self.n_times - 1)):
                hit = np.abs(self.times[jj] - te) <= TIME_SNAP * self.R0
                if hit.any():
                    W[hit] = 0.0
                    W[np.flatnonzero(hit), jj[hit]] = 1.0
        return W

    def __call__(self, values, t_eval=None, derivative=0):
        """Interpolate ``values`` (M, ...) at ``t_eval``; returns (T, ...), NaN outside the span."""
        f = float_array(values, "values")
        if f.ndim < 1 or f.shape[0] != self.n_times:
            raise ConfigError(f"values must have n_times = {self.n_times} rows, got shape {f.shape}")
        return np.tensordot(self.weights(t_eval, derivative), f, axes=(1, 0))


def temporal_reach(times, *, c=1.0, R0=1.0, tol=REACH_TOL, model=401):
    """Samples on each side of a time window that make it reproduce the whole-series interpolant.

    Parameters
    ----------
    times : array_like, shape (M,)
        Sample times (s) of the whole series, strictly increasing.
    c, R0 : float
        Kernel of the interpolant (as :class:`TemporalInterpolant`).
    tol : float
        Largest tail of the cardinal weights (dimensionless) allowed.
    model : int
        Samples of the uniform model series the weights are measured on; a
        reach beyond ``model // 2`` counts as the whole series.

    Returns
    -------
    int
        ``n``: a window holding ``n`` samples before and after the evaluation
        times gives the same values and rates as all ``M`` samples. ``M``
        (the whole series) when the kernel reaches farther than the model.

    Notes
    -----
    The interpolant is ``f(t) = sum_j w_j(t) f_j`` with the cardinal weights
    ``w_j`` of the IMQ kernel plus {1, t}. The kernel itself decays only like
    ``1/|t - t_j|``, but the cardinal weights decay much faster: for spacing
    ``h`` with ``c R0 / h`` of order 1-5 exponentially over a few tens of
    samples, then an algebraic tail far below it. A window that drops the
    samples with ``|j - j(t)| > n`` changes ``f(t)`` by about
    ``E(n) = sum_{|j - j(t)| > n} |w_j(t)| max_j |f_j - p(t_j)|`` (``p`` the
    straight line both reproduce exactly), and the window's own cardinal
    weights near ``t`` differ from the whole series' by the same order. ``E``
    is measured on a uniform model series with the record's median spacing,
    for the value at a quarter and half spacing between samples and for the
    rate (weights times ``h``), and ``n`` is the first with ``E(n) < tol``.

    Near the record's ends this does not hold: there the cardinal weights
    keep an algebraic tail over the whole record (h = 0.5 s, c = R0 = 1:
    ~1e-2 of the series' deviation from a straight line for the rate at the
    first sample, 1e-3 for values half a spacing in, still after 160
    samples), so evaluation times within ``n`` samples of the first or last
    one are reproduced only to that level. Neither result is the better
    one there: both are the same interpolant's boundary behaviour.
    ``tol = 1e-5`` holds the difference to 1e-4 K for series within 10 K of
    a straight line (tests compare windowed and whole-series results). The
    kernel is the interpolant's, no flatter than :data:`FLAT_KERNEL_SPACINGS`
    spacings (:func:`kernel_R0`: flatter ones make the saddle system
    ill-conditioned and the weights meaningless); tails that do not fall
    below ``tol`` within the model give the whole series.
    """
    t = increasing_times(times, "times", "n_times")
    if t.size < 8:
        return t.size
    reach = _model_reach(float(np.median(np.diff(t))), float(c), kernel_R0(t, c, R0), float(tol), int(model))
    return t.size if reach is None else min(reach, t.size)


@functools.lru_cache(maxsize=256)
def _model_reach(h, c, R0, tol, model):
    """:func:`temporal_reach` on the uniform model series of spacing ``h`` (``R0`` already narrowed by
    :func:`kernel_R0`); None: the whole series."""
    n = int(model)
    n -= 1 - n % 2  # odd: the evaluation point sits in the middle
    m = n // 2
    tm = (np.arange(n) - m) * h
    # evaluation points (in samples) inside the record: near its ends the weights keep an algebraic
    # tail over the whole record that no bounded window reproduces (Notes)
    pos = np.array([m + 0.25, m + 0.5])
    try:
        ti = TemporalInterpolant(tm, c=c, R0=R0)
        te = tm[0] + pos * h
        W = np.abs(np.r_[ti.weights(te, 0), ti.weights(te, 1) * h])
    except (DataError, GeometryError):
        return None
    if not np.isfinite(W).all() or W.sum(axis=1).max() > 10.0:
        # ill-conditioned model: weights are not trustworthy, use every sample
        return None
    dist = np.abs(np.arange(n)[None, :] - np.r_[pos, pos][:, None])
    for reach in range(1, m):
        if (W * (dist > reach)).sum(axis=1).max() < tol:
            return reach
    return None


def temporal_window(times, *, c=1.0, R0=1.0, smoothing=None, tol=REACH_TOL):
    """The ``window`` of :class:`TemporalInterpolant` for a whole record: None (global) or samples per side.

    Parameters
    ----------
    times : array_like, shape (M,)
        Sample times (s) of the whole record (IR frames or DIC stages), not
        of a time chunk: every chunk and the whole-record run must agree.
    c, R0, tol
        As :func:`temporal_reach`.
    smoothing : None or float >= 1
        The operator's smoothing (:class:`TemporalInterpolant`).

    Returns
    -------
    None or int
        None when the window would cover the record (a short record): the
        paper's one global operator. Else ``n``: the
        record is longer than any evaluation time's window of ``2 n + 2``
        samples, and every time chunk gets the whole-record result.

    Notes
    -----
    Interpolation: ``n`` is the reach (:func:`temporal_reach`), so the
    windowed interpolant equals the global one inside the record to
    ``tol``. Regression (``smoothing = k > 1``): the global regression's
    weights spread over the whole record (its kernel is six centre spacings
    wide with an algebraic tail: 40 % of their mass lies beyond 8 centre
    spacings), so no bounded window reproduces it. The windowed regression
    is a local one instead, over the reach plus :data:`REGRESSION_SPACINGS`
    centre spacings on each side: on a noisy 10 K heating series (0.05 K,
    h = 0.5 s) its rate error against the truth is within 5 % of the
    global regression's for k = 2-4, at the ends too.
    """
    t = increasing_times(times, "times", "n_times")
    k = smoothing_factor(smoothing, "smoothing", allow_gcv=False)
    n = temporal_reach(t, c=c, R0=R0, tol=tol)
    if k > 1.0 and n < t.size:
        n += int(math.ceil(REGRESSION_SPACINGS * k))
    return None if 2 * n + 3 >= t.size else int(n)


def rate_reference_stencil(smoothing):
    """``(samples, degree)`` of the local polynomial that is the reference of a temporal regression's rate bias.

    Parameters
    ----------
    smoothing : float or None
        The rate regression's centre spacing in samples (None: interpolation).

    Returns
    -------
    tuple of int
        :data:`LOCAL_RATE_SAMPLES` and degree 4 (the quartic through 5
        samples) up to :data:`RATE_REFERENCE_MIN_SPACING`; from there the
        least-squares polynomial of degree :data:`RATE_REFERENCE_DEGREE`
        over the ``2 k + 1`` samples nearest each time.

    Notes
    -----
    The reference must be far less biased than the regression, and its noise
    must not drown that bias. A regression with centres every ``k`` samples
    resolves a series on about that scale; a polynomial of degree 6 over
    two of its spacings has three times its parameters per sample. On the
    true series of the demo barrel (31 stages, ``k = 12``) the regression's
    rate bias is 4.9e-4 K/s RMS with a noise gain of 0.15; the quartic
    through 5 samples is off by 1e-6 but has a gain of 1.03 (the bias drowned
    in the noise of the difference: 4.4e-3 K/s against 5e-4), the degree-6
    fit over 25 samples is off by 2.0e-5 with a gain of 0.22. A fast
    transient (the demo tube: 21 stages at 2 Hz, ``k`` 2-3) is only resolved
    by the quartic through 5 samples (bias 0.005 against the regression's
    0.012-0.019; a degree-4 fit over 7 samples: 0.013).
    """
    k = 1.0 if smoothing is None else float(smoothing)
    if k < RATE_REFERENCE_MIN_SPACING:
        return LOCAL_RATE_SAMPLES, LOCAL_RATE_SAMPLES - 1
    return 2 * int(math.floor(k)) + 1, RATE_REFERENCE_DEGREE


def rate_reference_weights(times, t_eval=None, *, smoothing=None):
    """:func:`local_rate_weights` (T, M) with the stencil of :func:`rate_reference_stencil` for a rate regression
    with centre spacing ``smoothing`` (samples; None: interpolation)."""
    samples, degree = rate_reference_stencil(smoothing)
    return local_rate_weights(times, t_eval, samples=samples, degree=degree)


def local_rate_weights(times, t_eval=None, *, samples=LOCAL_RATE_SAMPLES, degree=None):
    """Derivative weights of the polynomial through (or fitted to) the ``samples`` samples nearest each time.

    Parameters
    ----------
    times : array_like, shape (M,)
        Sample times (s), increasing.
    t_eval : array_like, shape (T,), optional
        Evaluation times (s) within the span; default ``times``.
    samples : int
        Stencil size ``n``; fewer when the series is shorter.
    degree : int, optional
        The polynomial's degree, at most (and by default) ``n - 1``: below,
        a least-squares fit over the stencil (:func:`rate_reference_stencil`).

    Returns
    -------
    ndarray, shape (T, M)
        ``W`` with ``df/dt(t_eval) ≈ W @ f(times)`` (1/s).

    Notes
    -----
    The reference of the temporal regression's rate bias
    (:mod:`irdic.uncertainty.model`). The exact IMQ interpolant (``c R0``
    = 1 s) is itself biased where the stages are sparse for the signal: on
    the true series of the demo scenes its rate is off by 3.0 % (barrel,
    1 s stages) and 2.5 % (tube, 0.5 s), as much as the regression it
    should judge; the quartic through 5 samples (``h⁴ f⁽⁵⁾`` error) is
    off by 2e-6 and 0.9 %, with about the interpolant's noise gain. The
    stencil is the ``n`` nearest samples, shifted inwards at the ends; the
    least-squares polynomial of a wider stencil has a smaller noise gain
    (:func:`rate_reference_stencil`).
    """
    t = np.asarray(times, dtype=float)
    te = t if t_eval is None else np.atleast_1d(np.asarray(t_eval, dtype=float))
    n = min(int(samples), t.size)
    p = n - 1 if degree is None else min(int(degree), n - 1)
    W = np.zeros((te.size, t.size))
    for i, ti in enumerate(te):
        lo = int(np.clip(np.searchsorted(t, ti) - n // 2, 0, t.size - n))
        idx = np.arange(lo, lo + n)
        # centred and scaled by the stencil's span: a well-conditioned Vandermonde system
        scale = max(t[idx[-1]] - t[idx[0]], np.finfo(float).tiny)
        V = np.vander((t[idx] - ti) / scale, p + 1, increasing=True)
        # the derivative at ti is the polynomial's linear coefficient: row 1 of the (pseudo-)inverse
        W[i, idx] = (np.linalg.solve(V.T, np.eye(n)[1]) if p + 1 == n else np.linalg.pinv(V)[1]) / scale \
            if n > 1 else 0.0
    return W
