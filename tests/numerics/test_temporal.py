"""Tests of irdic.numerics.temporal: the one temporal interpolant and regressor."""

from __future__ import annotations

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError
from irdic.chunks import window as chunk_window
from irdic.numerics.series import smooth_series
from irdic.numerics.temporal import FLAT_KERNEL_SPACINGS, TemporalInterpolant, kernel_R0, temporal_window

# --------------------------------------------------------------------------
# time
# --------------------------------------------------------------------------


def irregular_times():
    t = np.arange(40) * 0.5
    return np.delete(t, [7, 8, 20])  # dropped frames


def test_temporal_identity_at_frame_times():
    t = irregular_times()
    ti = TemporalInterpolant(t)
    W0 = ti.weights(t)
    assert np.array_equal(W0, np.eye(t.size))


def test_temporal_reproduces_linear_functions_exactly():
    t = irregular_times()
    ti = TemporalInterpolant(t, c=1.0, R0=1.0)
    te = np.linspace(t[0], t[-1], 97)
    f = 3.0 - 0.7 * t
    np.testing.assert_allclose(ti.weights(te) @ f, 3.0 - 0.7 * te, atol=1e-10)
    np.testing.assert_allclose(ti.weights(te, 1) @ f, -0.7, atol=1e-9)
    np.testing.assert_allclose(ti.weights(te).sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(ti.weights(te, 1).sum(axis=1), 0.0, atol=1e-10)


def test_temporal_derivative_weights_match_finite_differences():
    t = irregular_times()
    ti = TemporalInterpolant(t, c=1.0, R0=2.0)
    te = np.array([0.3, 3.71, 9.9, 17.25])
    h = 1e-5
    fd = (ti.weights(te + h) - ti.weights(te - h)) / (2 * h)
    np.testing.assert_allclose(ti.weights(te, 1), fd, atol=1e-6)


def test_temporal_accuracy_on_smooth_function():
    t = np.arange(60) * 0.5
    ti = TemporalInterpolant(t)
    te = np.linspace(0.1, 29.4, 301)
    f = np.sin(t / 3.0)
    err = np.abs(ti(f, te) - np.sin(te / 3.0))
    derr = np.abs(ti(f, te, 1) - np.cos(te / 3.0) / 3.0)
    inner = (te > 6) & (te < 23.5)
    # period 38 frames: ~5e-6 (rate 3e-5) from 12 frames off the ends of the
    # span on, 1e-2 within the first and last 2 frames (RBF boundary error)
    assert err[inner].max() < 1e-5
    assert derr[inner].max() < 1e-4
    assert err.max() < 2e-2


def test_temporal_outside_span_is_nan():
    ti = TemporalInterpolant([0.0, 1.0, 2.5])
    W = ti.weights([-0.1, 0.0, 2.5, 2.6, np.nan])
    assert np.isnan(W[[0, 3, 4]]).all()
    assert np.isfinite(W[[1, 2]]).all()
    assert ti.in_span([-0.1, 0.0, 2.5, 2.6, np.nan]).tolist() == [False, True, True, False, False]


def test_temporal_bad_arguments():
    with pytest.raises(DataError, match=r"strictly increasing: times\[2\] = 1\.0 s is followed by times\[3\] = 1\.0 s"):
        TemporalInterpolant([0.0, 0.5, 1.0, 1.0, 2.0])
    with pytest.raises(DataError, match=r"times: 1 time\(s\); .* needs at least 2"):
        TemporalInterpolant([1.0])
    with pytest.raises(DataError, match=r"times: non-finite time at index 1"):
        TemporalInterpolant([0.0, np.nan, 1.0])
    with pytest.raises(ConfigError, match="times must be 1-D"):
        TemporalInterpolant(np.zeros((2, 2)))
    with pytest.raises(ConfigError, match="`c` must be finite and > 0"):
        TemporalInterpolant([0.0, 1.0], c=0)
    with pytest.raises(ConfigError, match="derivative must be 0 or 1"):
        TemporalInterpolant([0.0, 1.0]).weights([0.5], derivative=2)
    with pytest.raises(ConfigError, match="values must have n_times = 2 rows"):
        TemporalInterpolant([0.0, 1.0])(np.zeros(3), [0.5])




# --- the windowed operator of long records ---------------------------------------------------------------------


def _series(t):
    return 20 + 10 * np.tanh((t - t.mean()) / 20) + 0.5 * np.sin(2.3 * t)


def _series_rate(t):
    return 0.5 / np.cosh((t - t.mean()) / 20) ** 2 + 1.15 * np.cos(2.3 * t)


@pytest.mark.parametrize("k", [None, 2.0, 4.0])
def test_a_chunk_of_the_windowed_operator_equals_the_whole_record_everywhere(k):
    """Chunks, the record's first and last samples included, give the whole-record values and rates to rounding."""
    t = np.arange(900) * 0.5
    f = _series(t)
    n = temporal_window(t, smoothing=k)
    assert n is not None and 2 * n + 3 < t.size
    whole = TemporalInterpolant(t, smoothing=k, window=n)
    for a, b in ((0, 100), (400, 500), (800, 900)):
        w = chunk_window(t, t[a], t[b - 1], n)
        assert w.stop - w.start < t.size  # a chunk reads a bounded window
        part = TemporalInterpolant(t[w], smoothing=k, window=n)
        te = np.r_[t[a:b], np.linspace(t[a], t[b - 1], 61)]
        for d in (0, 1):
            np.testing.assert_allclose(part(f[w], te, d), whole(f, te, d), rtol=0, atol=1e-10)


def test_windowed_operator_matches_the_global_one_inside_and_the_truth_at_the_ends():
    t = np.arange(600) * 0.5
    f = _series(t)
    n = temporal_window(t)
    g, w = TemporalInterpolant(t), TemporalInterpolant(t, window=n)
    inner = np.linspace(t[100], t[500], 333)
    for d in (0, 1):  # REACH_TOL: 1e-4 of a series within 10 K of a straight line
        np.testing.assert_allclose(w(f, inner, d), g(f, inner, d), rtol=0, atol=1e-4)
    # at the ends both are the interpolant's boundary behaviour: the windowed rate is as close to the truth
    ends = np.r_[t[:3], t[-3:]]
    err_w = np.abs(w(f, ends, 1) - _series_rate(ends)).max()
    err_g = np.abs(g(f, ends, 1) - _series_rate(ends)).max()
    assert err_w < 0.3 and err_w < 1.5 * err_g, (err_w, err_g)
    # each row touches only its window
    W = w.weights(inner, 1)
    lo, hi = w.sample_window(inner)
    cols = np.arange(t.size)
    assert not np.any(W[(cols[None, :] < lo[:, None]) | (cols[None, :] >= hi[:, None])])


def test_short_records_keep_the_global_operator_and_fast_records_get_a_window():
    assert temporal_window(np.arange(30) * 0.5) is None  # shorter than two reaches: the paper's operator
    # 50 Hz with c R0 = 1 s: the kernel narrowed to FLAT_KERNEL_SPACINGS frames, whose weights decay in a window
    assert temporal_window(np.arange(3000) * 0.02) == temporal_window(np.arange(3000) * 0.02, R0=0.12)
    assert temporal_window(np.arange(3000) * 0.02, R0=0.05) is not None  # R0 scaled to the frame rate


def test_the_kernel_is_narrowed_only_where_it_is_flatter_than_the_limit():
    assert kernel_R0(np.arange(40) * 0.5, 1.0, 1.0) == 1.0  # the paper's kernel at 2 Hz
    assert kernel_R0(np.arange(40) / 6.0, 1.0, 1.0) == 1.0  # at the limit itself: as given, not its rounding
    assert kernel_R0(np.arange(40) * 0.04, 1.0, 1.0) == pytest.approx(FLAT_KERNEL_SPACINGS * 0.04)
    assert kernel_R0(np.arange(40) * 0.04, 2.0, 1.0) == pytest.approx(FLAT_KERNEL_SPACINGS * 0.04 / 2.0)
    assert TemporalInterpolant(np.arange(40) * 0.04).R0 == pytest.approx(FLAT_KERNEL_SPACINGS * 0.04)
    assert TemporalInterpolant(np.arange(40) * 0.04, smoothing=3.0).R0 == 1.0  # the regression has its own kernel


@pytest.mark.parametrize("rate_hz, n", [(25.0, 500), (50.0, 1500), (12.5, 300), (2.0, 60)])
def test_a_fast_camera_with_the_papers_kernel_gives_rates_at_the_noise_of_a_difference_quotient(rate_hz, n):
    """The paper's kernel (c R0 = 1 s) on 12.5-50 Hz records spanned 12-50 frame spacings: its weights were
    rounding noise and 0.05 K of pixel noise gave rates of hundreds of K/s. Narrowed, the rate's noise is that
    of a difference quotient (``sqrt(2) sigma / h``) within 40 %, and a smooth signal's rate stays exact."""
    h = 1.0 / rate_hz
    t = np.arange(n) * h
    rng = np.random.default_rng(5)
    truth = 22.0 + 2.0 * np.sin(0.7 * t) + 0.3 * t
    noisy = truth[:, None] + 0.05 * rng.standard_normal((n, 400))
    ti = TemporalInterpolant(t, window=temporal_window(t))
    te = t[n // 4: 3 * n // 4: 7] + 0.37 * h  # between frames, inside the record
    rate = 1.4 * np.cos(0.7 * te) + 0.3
    np.testing.assert_allclose(ti(truth, te, 1), rate, atol=1e-3)  # of 1.7 K/s
    np.testing.assert_allclose(ti(truth, te, 0), 22.0 + 2.0 * np.sin(0.7 * te) + 0.3 * te, atol=1e-4)
    err = ti(noisy, te, 1) - rate[:, None]
    assert np.sqrt(np.mean(err ** 2)) <= 1.4 * np.sqrt(2.0) * 0.05 / h
    err0 = ti(noisy, te, 0) - (22.0 + 2.0 * np.sin(0.7 * te) + 0.3 * te)[:, None]
    assert np.sqrt(np.mean(err0 ** 2)) <= 1.4 * 0.05


def test_smooth_series_of_a_chunk_uses_the_record_window():
    t = np.arange(700) * 0.5
    rng = np.random.default_rng(3)
    F = _series(t)[:, None] + 0.05 * rng.standard_normal((t.size, 4))
    whole = smooth_series(F, t, smoothing=2.0)
    n = temporal_window(t, smoothing=2.0)
    w = chunk_window(t, t[600], t[699], n)
    part = smooth_series(F[w], t[w], t[600:], smoothing=2.0, record_times=t)
    np.testing.assert_allclose(part.rate, whole.rate[600:], rtol=0, atol=1e-10)
    np.testing.assert_allclose(part.value, whole.value[600:], rtol=0, atol=1e-10)


@pytest.mark.parametrize("n_t, R0, threads", [(200, 0.3, 1), (90, 1.0, 1), (90, 1.0, 3)])
def test_gap_fill_equals_each_series_own_interpolant(n_t, R0, threads):
    """Series with scattered gaps (failed DIC points), shared gap patterns, series ends and all-but-one gaps:
    the grouped and the windowed fills give what each column's own (windowed) interpolant gives, also with
    the patterns on worker threads."""
    from irdic.numerics.series import fill_gaps
    from irdic.threads import stage_threads

    rng = np.random.default_rng(0)
    t = np.arange(n_t) * 0.1
    F = np.sin(t)[:, None] + 0.01 * rng.normal(size=(n_t, 300))
    bad = rng.random(F.shape) < 0.02
    bad[:, 100:150] = bad[:, [100]]  # one pattern shared by 50 series
    bad[:3, 5], bad[-2:, 6], bad[1:, 8] = True, True, True
    F[bad] = np.nan
    n = temporal_window(t, c=1.0, R0=R0)
    assert (n is None) == (n_t < 100)  # both operators are exercised (the window of 2 x 50 + 2 covers 90 times)
    got = F.copy()
    with stage_threads(threads):
        dead = fill_gaps(got, t, 1.0, R0, n)
    assert np.flatnonzero(dead).tolist() == [8]
    for j in range(F.shape[1]):
        ok = np.isfinite(F[:, j])
        if ok.all() or j == 8:
            continue
        want = TemporalInterpolant(t[ok], c=1.0, R0=R0, window=n).weights(t[~ok]) @ F[ok, j]
        out = ~np.isfinite(want)  # outside the valid span: the nearest valid value
        want[out] = np.interp(t[~ok][out], t[ok], F[ok, j])
        np.testing.assert_allclose(got[~ok, j], want, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(got[ok, j], F[ok, j])


def test_same_patterns_groups_identical_rows():
    from irdic.numerics.patterns import same_patterns

    m = np.array([[1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 0, 0], [0, 1, 0], [1, 0, 0]], bool)
    groups = sorted(g.tolist() for g in same_patterns(m))
    assert groups == [[0, 2, 5], [1, 4], [3]]
    assert same_patterns(np.zeros((0, 3), bool)) == []
    wide = np.zeros((2, 20), bool)
    wide[1, 17] = True  # beyond the first packed byte
    assert sorted(g.tolist() for g in same_patterns(wide)) == [[0], [1]]


def test_fill_series_of_several_arrays_is_each_filled_alone():
    """Arrays filled together (one interpolant per pattern of missing times) are what smooth_series fills
    in each alone; a series with fewer than two valid times stays NaN."""
    from irdic.numerics.series import fill_series

    rng = np.random.default_rng(1)
    t = np.arange(60) * 0.25
    A = np.cos(t)[:, None] + 0.01 * rng.normal(size=(60, 40))
    A[rng.random(A.shape) < 0.05] = np.nan
    A[1:, 3] = np.nan  # one valid time: dead
    B = (2 * A + 1).reshape(60, 20, 2)  # the same gaps, another shape
    fa, fb = fill_series([A, B], t, c=1.0, R0=1.0)
    assert fa.shape == A.shape and fb.shape == B.shape
    assert np.isnan(fa[:, 3]).all() and np.isfinite(np.delete(fa, 3, axis=1)).all()
    ok = np.isfinite(A).sum(axis=0) >= 2
    for arr, filled in ((A, fa), (B.reshape(60, 40), fb.reshape(60, 40))):
        interp = smooth_series(arr[:, ok], t, smoothing=None, c=1.0, R0=1.0).value  # fills, then interpolates
        np.testing.assert_allclose(filled[:, ok], interp, rtol=0, atol=1e-9)


def test_gcv_max_fraction_admits_the_rates_lighter_regression():
    """GCV used to leave out every candidate with more than M/2 parameters, so on 21 stages of a fast
    transient it could not reach centres every 2 stages (13 parameters), where its own curve has its minimum;
    the rate's regression admits up to RATE_MAX_FRACTION."""
    from irdic.numerics.temporal_choice import RATE_MAX_FRACTION, gcv_temporal

    t = np.arange(21) * 0.5
    rng = np.random.default_rng(0)
    truth = np.sin(2 * np.pi * t / 4.0)  # a period of 8 stages
    F = truth[:, None] + rng.normal(0.0, 0.005, (21, 200))
    k_value, table = gcv_temporal(t, F)
    assert all(p <= 10 for _, p, _ in table)
    k_rate, table = gcv_temporal(t, F, max_fraction=RATE_MAX_FRACTION)
    assert max(p for _, p, _ in table) == 13 and k_rate < k_value, (k_value, k_rate, table)
    fit_v = smooth_series(F, t, smoothing="gcv")
    fit_r = smooth_series(F, t, smoothing="gcv", gcv_max_fraction=RATE_MAX_FRACTION)
    rate = (np.pi / 2.0 * np.cos(2 * np.pi * t / 4.0))[1:-1, None]
    err = lambda fit: np.sqrt(np.mean((fit.rate[1:-1] - rate) ** 2))  # noqa: E731
    assert err(fit_r) < 0.5 * err(fit_v), (err(fit_r), err(fit_v))


@pytest.mark.parametrize("n_series", [300, 5000])
def test_gcv_on_the_judged_columns_is_the_choice_of_smooth_series(n_series):
    """gcv_columns fills only the series GCV pools (at most GCV_MAX_SERIES of those with two valid times, evenly
    spaced): GCV on them chooses as smooth_series does after filling every series, with the same table, for
    the value's and the rate's limit, with gaps inside and at the ends and dead series among the others."""
    from irdic.numerics.series import gcv_columns
    from irdic.numerics.temporal_choice import GCV_MAX_SERIES, RATE_MAX_FRACTION, gcv_temporal

    rng = np.random.default_rng(4)
    t = np.arange(48) * 0.25
    F = np.sin(t / 2.0)[:, None] * rng.uniform(0.5, 2.0, n_series) + rng.normal(0.0, 0.02, (48, n_series))
    F[rng.random(F.shape) < 0.03] = np.nan
    F[:5, ::7] = np.nan  # lost at the start
    F[-3:, ::11] = np.nan  # and at the end
    F[1:, ::13] = np.nan  # one valid time: not judged
    judged = gcv_columns(F, t, c=1.0, R0=1.0)
    assert judged.shape == (48, min(GCV_MAX_SERIES, int((np.isfinite(F).sum(axis=0) >= 2).sum())))
    assert np.isfinite(judged).all()
    for limit in ({}, {"max_fraction": RATE_MAX_FRACTION}):
        k, table = gcv_temporal(t, judged, **limit)
        fit = smooth_series(F, t, smoothing="gcv",
                            **({"gcv_max_fraction": limit["max_fraction"]} if limit else {}))
        assert fit.smoothing == k and len(fit.gcv) == len(table) > 1
        np.testing.assert_allclose([g for *_, g in table], [g for *_, g in fit.gcv], rtol=1e-12, atol=0)
    dead = np.full((48, 3), np.nan)
    dead[0] = 1.0
    with pytest.raises(DataError, match="NaN"):
        gcv_temporal(t, gcv_columns(dead, t))


def test_bias_ratio_is_one_on_noise_and_large_where_the_regression_cannot_follow():
    from irdic.numerics.temporal_risk import CP_LIMIT, bias_ratio

    rng = np.random.default_rng(0)
    t = np.arange(21) * 0.5
    sigma = 0.05
    # a smooth heating with white noise: the residual is the noise's (M - p) sigma² per series
    smooth = 20.0 + 0.03 * t[:, None] ** 2 + rng.normal(0.0, sigma, (21, 400))
    assert 0.9 < bias_ratio(t, smooth, 3.0, sigma**2) < 1.1
    # a 1.4 mm band passing the points at 1.9 mm/s, sampled at 2 Hz: no regression with centres every 3 times
    # follows it; its residual is bias, many times the noise's
    x = np.linspace(0.0, 18.0, 400)
    band = 20.0 + 2.0 * np.exp(-0.5 * ((1.9 * t[:, None] - x[None, :]) / 0.6) ** 2) + rng.normal(0.0, sigma, (21, 400))
    assert bias_ratio(t, band, 3.0, sigma**2) > 5 * CP_LIMIT
    assert np.isnan(bias_ratio(t, band, 3.0, 0.0))


@pytest.mark.parametrize("period, M, sigma", [(4.0, 21, 0.05), (8.0, 21, 0.05), (3.0, 31, 0.02), (6.0, 41, 0.1)])
def test_rate_risk_temporal_tracks_the_true_risk(period, M, sigma):
    """2,000 sinusoids of one period (random amplitude and phase) at 2 Hz with white noise: the estimated risk of
    every candidate's rate is within 20 % of its true mean squared error (interior samples) and the spacing
    chosen is the truly best one; GCV (judging the values) takes 3 stages on the 3-s period, whose rate errs
    hundreds of times more than at 2."""
    from irdic.numerics.temporal_choice import gcv_temporal, rate_risk_temporal

    rng = np.random.default_rng(0)
    t = np.arange(M) * 0.5
    phase, amp, w = rng.uniform(0, 2 * np.pi, 2000), rng.uniform(0.5, 1.5, 2000), 2 * np.pi / period
    rate = amp * w * np.cos(w * t[:, None] + phase)
    F = amp * np.sin(w * t[:, None] + phase) + rng.normal(0.0, sigma, (M, 2000))
    k, table = rate_risk_temporal(t, F)
    true = {}
    for kk, _, risk in table:
        D = TemporalInterpolant(t, smoothing=kk).weights(t, 1)
        true[kk] = float(np.mean((D @ F - rate)[1:-1] ** 2))
        assert risk == pytest.approx(true[kk], rel=0.2), (kk, risk, true[kk])
    assert k == min(true, key=true.get) and len(table) >= 5
    if period == 3.0:
        g = gcv_temporal(t, F)[0]
        assert g == 3.0 and true[g] > 100 * true[k]


def test_rate_risk_temporal_needs_two_candidates():
    from irdic.numerics.temporal_choice import rate_risk_temporal

    t = np.arange(5) * 0.5
    assert rate_risk_temporal(t, np.ones((5, 3))) == (1.0, [])
    with pytest.raises(DataError, match="NaN"):
        rate_risk_temporal(np.arange(21.0), np.full((21, 2), np.nan))


def test_rate_smoothing_is_bounded_by_the_values_gcv_spacing_only_where_gcv_chose_one():
    """Nine stages: GCV has no candidate for the value (1/2 parameters per stage) and the rate's risk takes its own
    regression (4 stages, as GCV's choice for the rate did); on more stages the value's spacing bounds it."""
    from irdic.fields.smoothing import rate_smoothing
    from irdic.numerics.temporal_choice import gcv_temporal, rate_risk_temporal

    p = {"c_time": 1.0, "R0_time": 1.0}
    rng = np.random.default_rng(0)
    t = np.arange(9) * 0.5
    F = np.sin(0.4 * t[:, None] + rng.uniform(0, 2 * np.pi, 2000)) + rng.normal(0.0, 0.05, (9, 2000))
    assert gcv_temporal(t, F)[0] == 1.0
    assert rate_smoothing(t, F, 1.0, p) == rate_smoothing(t, F, None, p) == rate_risk_temporal(t, F)[0] == 4.0
    assert rate_smoothing(t, F, 3.0, p) == 3.0
