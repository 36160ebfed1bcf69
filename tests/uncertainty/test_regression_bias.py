"""The regressions' bias estimates of the uncertainty (irdic.uncertainty.regression_bias) and the rate's
reference in time (irdic.numerics.temporal.local_rate_weights)."""

import numpy as np

from irdic.numerics.temporal import TemporalInterpolant, local_rate_weights, rate_reference_stencil
from irdic.uncertainty.regression_bias import (BIAS_NEIGHBOURS, BIAS_Z, common_bias, first_mode_bias, half_means,
                                               local_bias, patch_halves, reference_options, reference_spacing,
                                               strain_reference_options)
from irdic.uncertainty.ring import (RING_APART_PX, RING_POINTS, ring_apart, ring_mean, ring_noise_scale, ring_scatter,
                                   value_ring)


def _grid(n=30):
    u, v = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    return np.column_stack([u.ravel(), v.ravel()])


def test_local_bias_on_pure_noise_is_not_a_bias():
    """A difference that is noise alone (variance known from probes) must not come back as a bias: clipped
    at 0 wherever its local average came out positive (the code before), about half of the points got a
    'bias' of ~0.3 noise sd; with the significance test against the probes' own scatter (one standard error)
    about one in eight, with about half the added variance."""
    rng = np.random.default_rng(0)
    psi, T, K = _grid(), 6, 8
    v = np.full((T, psi.shape[0]), 4.0)  # noise sd 2
    d = rng.normal(0.0, 2.0, v.shape)
    null = rng.normal(0.0, 2.0, (K,) + v.shape) ** 2
    b = local_bias(d, v, psi, null=null)
    old = local_bias(d, v, psi)  # without the probes' scatter: the plain clipped average
    assert np.mean(old > 0) > 0.4
    assert np.mean(b > 0) < 0.2 and np.mean(b ** 2) < 0.6 * np.mean(old ** 2), (np.mean(b > 0), np.mean(b ** 2),
                                                                              np.mean(old ** 2))
    assert BIAS_Z >= 1.0


def test_local_bias_resolves_a_bias_above_its_noise():
    """A smooth bias of 1 under noise of sd 2 (96 samples per average): estimated within 20 %."""
    rng = np.random.default_rng(1)
    psi, T, K = _grid(), 6, 8
    v = np.full((T, psi.shape[0]), 4.0)
    d = 1.0 + rng.normal(0.0, 2.0, v.shape)
    null = rng.normal(0.0, 2.0, (K,) + v.shape) ** 2
    b = local_bias(d, v, psi, null=null)
    assert abs(np.sqrt(np.mean(b ** 2)) - 1.0) < 0.2, np.sqrt(np.mean(b ** 2))


def _smooth_noise(rng, T, n, sd):
    """(T, n * n) noise of std ``sd`` correlated over ~3 points (a 3 x 3 box filter of white noise), as a
    regression's noise is."""
    from scipy import ndimage

    w = ndimage.uniform_filter(rng.standard_normal((T, n, n)), size=(1, 3, 3), mode="wrap")
    return sd * (w / w.std()).reshape(T, n * n)


def test_first_mode_bias_is_the_regressions_bias_of_one_heating_history():
    """A patch heated with one history (amplitudes 0-3 K, a quintic step over 10 of 25 stages) under noise of
    0.02 K per value: the rate regression's bias (centres every 4 stages against the local polynomial in time,
    the fields' pair) on the series' first temporal mode is the bias on the noise-free series to 15 % (RMS),
    where each point's own difference is mostly noise; weaker heating is not overestimated by more than a sixth
    of the rate's noise (its noise is subtracted whole: at a tenth of the heating it comes out 0); noise alone
    gives 0; a series with a gap gets 0."""
    from irdic.numerics.series import smooth_series
    from irdic.numerics.temporal import rate_reference_weights

    rng = np.random.default_rng(5)
    t = np.arange(25) * 0.5
    s = np.clip((t - 3.0) / 5.0, 0.0, 1.0)
    phi = s ** 3 * (10 - 15 * s + 6 * s * s)
    amp = rng.uniform(0.0, 3.0, 400)
    difference = smooth_series(np.eye(t.size), t, None, smoothing=4.0).rate - rate_reference_weights(t, smoothing=4.0)

    rms = lambda a: float(np.sqrt(np.mean(a ** 2)))  # noqa: E731
    for scale in (1.0, 0.3, 0.1, 0.03, 0.01, 0.003):
        clean = phi[:, None] * amp[None, :] * scale
        noise = rng.normal(0.0, 0.02, clean.shape)
        truth = np.abs(difference @ clean)
        got = first_mode_bias(clean + 20.0 + noise, difference)
        rate_noise = rms(smooth_series(noise, t, None, smoothing=4.0).rate)
        if scale >= 0.3:
            assert rms(got - truth) < 0.15 * rms(truth), (scale, rms(got - truth), rms(truth))
            assert rms(np.abs(difference @ (clean + noise)) - truth) > 3 * rms(got - truth)
        # weaker: at most the bias (its noise subtracted whole), never noise passed for a bias
        assert rms(np.maximum(got - truth, 0.0)) < rate_noise / 6, (scale, rms(got - truth), rate_noise)
    assert np.all(first_mode_bias(rng.normal(0.0, 0.02, (25, 400)), difference) == 0.0)
    gappy = phi[:, None] * amp[None, :] + rng.normal(0.0, 0.02, (25, 400))
    gappy[3, 7] = np.nan
    out = first_mode_bias(gappy, difference)
    assert np.all(out[:, 7] == 0.0) and np.isfinite(out).all() and out.max() > 0


def test_common_bias_is_the_ripple_the_whole_patch_shares():
    """A ripple of 0.01 changing sign from time to time, shared by every point, under correlated noise of
    0.017 per point (drawn-707's rate: each point's own estimate was 0 there): the RMS of the ripple over
    each time and its neighbours to 10 %; where the points are noise alone, or the bias sits in one half
    of the patch only, it stays below a quarter of the ripple; untrusted points and points without surface
    parameters do not enter; too few points give 0. A bias of one half only (0.02, RMS over the patch 0.014)
    times the other half's noise mean: about the geometric mean of the two, well below the patch's RMS."""
    rng = np.random.default_rng(3)
    n, T = 30, 12
    psi = _grid(n)
    ripple = 0.01 * (-1.0) ** np.arange(T) * (1.0 + 0.3 * np.sin(np.arange(T)))
    expected = np.sqrt(np.convolve(ripple ** 2, np.ones(3), "same") / np.convolve(np.ones(T), np.ones(3), "same"))
    noise = _smooth_noise(rng, T, n, 0.017)
    got = common_bias(ripple[:, None] + noise, psi)
    np.testing.assert_allclose(got, expected, rtol=0.1)
    assert np.all(common_bias(noise, psi) < 0.25 * 0.01), common_bias(noise, psi)
    one_half = np.where(psi[:, 0] < n / 2, 0.02, 0.0)[None, :] * (-1.0) ** np.arange(T)[:, None]
    lopsided = common_bias(one_half + noise, psi)
    assert np.sqrt(np.mean(lopsided ** 2)) < 0.35 * 0.0141 and lopsided.max() < 0.5 * 0.0141, lopsided
    # points outside the trusted set or without parameters carry a wild difference: left out
    tame = ripple[:, None] + noise
    trusted = np.ones(tame.shape, bool)
    trusted[:, ::7] = False
    psi_gaps = psi.copy()
    psi_gaps[5] = np.nan
    wild = tame.copy()
    wild[:, ::7], wild[:, 5] = 1e3, -1e3
    np.testing.assert_array_equal(common_bias(wild, psi_gaps, trusted), common_bias(tame, psi_gaps, trusted))
    np.testing.assert_allclose(common_bias(wild, psi_gaps, trusted), expected, rtol=0.2)
    # with the probes' own products (the same noise drawn again) as the null: on pure noise nothing counts
    # where the plain estimate let some times through, and the ripple is kept whole
    halves = patch_halves(psi)
    null = []
    for _ in range(16):
        m = half_means(_smooth_noise(rng, T, n, 0.017), halves, True)
        null.append(m[:, 0] * m[:, 1])
    assert np.any(common_bias(noise, psi) > 0)
    assert np.mean(common_bias(noise, psi, null=null) > 0) <= 1 / 12, common_bias(noise, psi, null=null)
    np.testing.assert_array_equal(common_bias(ripple[:, None] + noise, psi, null=null), got)
    # a time chunk of one or two times: its own times only
    for n_times in (1, 2):
        short = common_bias(ripple[:n_times, None] + noise[:n_times], psi, null=[x[:n_times] for x in null])
        assert short.shape == (n_times,)  # one product each: its noise not averaged over neighbours
        np.testing.assert_allclose(short, np.sqrt(np.mean(ripple[:n_times] ** 2)), rtol=0.25)
    few = psi[: 2 * BIAS_NEIGHBOURS - 1]
    np.testing.assert_array_equal(common_bias(ripple[:, None] + noise[:, :few.shape[0]], few), 0.0)


def test_pooled_bias_below_the_neighbourhoods_resolution():
    """A bias of 0.8 under noise of sd 2: the neighbourhood's average (96 samples, standard error about 0.6 in
    d²) mostly does not resolve b² = 0.64 at two standard errors, the average over all points (2,700 samples,
    about 0.12) does: ``pooled`` finds it within 20 %, ``share`` takes its part; pure noise stays 0 almost
    everywhere."""
    rng = np.random.default_rng(2)
    psi, T, K = _grid(), 6, 8
    v = np.full((T, psi.shape[0]), 4.0)
    null = rng.normal(0.0, 2.0, (K,) + v.shape) ** 2
    d = 0.8 + rng.normal(0.0, 2.0, v.shape)
    local = local_bias(d, v, psi, null=null, z=2.0)
    assert np.mean(local > 0) < 0.3, np.mean(local > 0)
    b = local_bias(d, v, psi, null=null, z=2.0, pooled=True)
    assert np.mean(b > 0) > 0.95 and abs(np.sqrt(np.mean(b ** 2)) - 0.8) < 0.16, (np.mean(b > 0), np.mean(b ** 2))
    half = local_bias(d, v, psi, null=null, z=2.0, pooled=True, share=0.5)
    np.testing.assert_allclose(half ** 2, 0.5 * b ** 2, rtol=1e-12)
    noise = local_bias(rng.normal(0.0, 2.0, v.shape), v, psi, null=null, z=2.0, pooled=True)
    assert np.mean(noise > 0) < 0.05, np.mean(noise > 0)


def test_ring_mean_averages_each_points_finite_nearest_and_keeps_its_gaps():
    """The mean over a point and its nearest (RING_POINTS in all, by surface parameters): the finite values
    only, NaN where the point's own value or its parameters are NaN; a constant stays; white noise keeps
    about 1 / RING_POINTS of its variance; any leading shape."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(5)
    psi = _grid(20) + rng.uniform(-0.2, 0.2, (400, 2))
    psi[7] = np.nan
    ring = ring_mean(psi)
    a = rng.normal(size=(3, 400))
    a[0, [10, 11, 50]] = np.nan
    got = ring(a)
    have = np.flatnonzero(np.isfinite(psi).all(axis=1))
    nb = have[cKDTree(psi[have]).query(psi[have], k=RING_POINTS)[1]]
    want = np.full(a.shape, np.nan)
    want[:, have] = np.nanmean(a[:, nb], axis=2)
    want[~np.isfinite(a)] = np.nan
    np.testing.assert_allclose(got, want, rtol=1e-12, equal_nan=True)
    assert np.isnan(got[:, 7]).all() and np.isnan(got[0, [10, 11, 50]]).all()
    np.testing.assert_allclose(ring(np.full((2, 2, 400), 3.0))[..., have], 3.0, rtol=1e-12)
    white = ring(rng.normal(size=(200, 400)))[:, have]
    assert abs(np.var(white) * RING_POINTS - 1.0) < 0.1, np.var(white) * RING_POINTS


def test_ring_members_apart_and_the_apart_distance_from_the_image_scale():
    """With ``apart`` the ring's members are pairwise at least that far (nearest first, RING_POINTS of them
    inside the cloud): on a unit grid at 1.5, no two members are neighbours on the grid, and a constant is
    still its own mean; the distance is RING_APART_PX over the image's scale (px per mm, its 10th percentile
    over neighbour pairs): 2 / 1.3 mm for an image 1.3 px per mm, whatever the offset and the NaN points."""
    from irdic.uncertainty.ring import _ring_members

    psi = _grid(15)
    rows, cols = _ring_members(psi, RING_POINTS, 1.5)
    inner = np.flatnonzero((np.abs(psi - 7).max(axis=1) <= 3))
    for i in inner:
        m = cols[rows == i]
        assert m.size == RING_POINTS and m[0] == i
        d = np.linalg.norm(psi[m][:, None] - psi[m][None], axis=2)
        assert d[~np.eye(m.size, dtype=bool)].min() >= 1.5
    np.testing.assert_allclose(ring_mean(psi, apart=1.5)(np.full(225, 2.0)), 2.0, rtol=1e-12)
    pixel = np.stack([1.3 * psi + 40.0, 1.3 * psi + 41.0])
    pixel[1, 3] = np.nan
    assert abs(ring_apart(pixel, psi) - RING_APART_PX / 1.3) < 1e-9
    assert ring_apart(np.full((2, 225, 2), np.nan), psi) == 0.0


def test_value_ring_only_where_it_keeps_the_regressions_ripple():
    """The mean of seven points (radius sqrt(2) spacings on a unit grid) for centres 3, 4 or 8 spacings apart,
    none for 2 or 2.5 (radius above half the centre spacing: it would average the bias's ripple away) nor
    without a regression in space."""
    psi = _grid(20)
    assert all(value_ring(psi, k, 0.0) is not None for k in (3.0, 4.0, 8.0))
    assert all(value_ring(psi, k, 0.0) is None for k in (2.0, 2.5, None))
    assert abs(value_ring(psi, 8.0, 0.0).radius - np.sqrt(2.0)) < 1e-12


def test_ring_noise_scale_is_the_noise_ratio_whatever_the_smooth_bias():
    """The data's noise 10 % above the probes' in variance: the scatter within the ring means gives 1.10
    within 2 %, with or without a smooth bias of a third of the noise's sd (which a ratio of the means'
    squares would take in); 1 without a ring or the probes' scatter."""
    rng = np.random.default_rng(3)
    psi, T = _grid(40), 8
    ring = ring_mean(psi)
    probes = rng.normal(0.0, 1.0, (16, T, psi.shape[0]))
    spread = np.mean(ring(probes ** 2) - ring(probes) ** 2, axis=0)
    noise = rng.normal(0.0, np.sqrt(1.1), (T, psi.shape[0]))
    bias = 0.5 * np.sin(psi[:, 0] / 5.0)[None] * np.ones((T, 1))
    for d in (noise, noise + bias):
        k2 = ring_noise_scale(ring_scatter(ring, d)[1], spread, None)
        assert abs(k2 - 1.1) < 0.022, k2
    assert ring_noise_scale(None, spread, None) == 1.0
    assert ring_noise_scale(ring_scatter(ring, noise)[1], 0.0, None) == 1.0


def test_ring_mean_before_the_square_resolves_a_small_bias_under_a_noise_model_misfit():
    """A smooth bias of 0.21 RMS under noise of sd 2 (b² a hundredth of the noise variance, as the family's
    band members' value), with the noise model's variance 7 % low (as the probes' after their scaling on two
    smooth members): squared as it is, the difference reports 0.58 on noise alone and 0.62 with the bias (the
    misfit taken for a bias); averaged over each point's nearest first (the probes' differences alike), 0.25
    and 0.32."""
    rng = np.random.default_rng(0)
    psi, T, K, sd, misfit = _grid(40), 6, 8, 2.0, 0.93
    ring = ring_mean(psi)
    bias = 0.3 * np.sin(psi[:, 0] / 4.0)[None] * np.ones((T, 1))
    noise = rng.normal(0.0, sd, (T, psi.shape[0]))
    probes = rng.normal(0.0, sd, (K,) + noise.shape)
    v_ring = misfit * np.mean(ring(rng.normal(0.0, sd, (64,) + noise.shape)) ** 2, axis=0)
    true = np.sqrt(np.mean(bias ** 2))

    def rms(b):
        return np.sqrt(np.mean(b ** 2))

    plain = [rms(local_bias(d, misfit * sd ** 2, psi, null=misfit * probes ** 2)) for d in (noise, bias + noise)]
    ringed = [rms(local_bias(ring(d), v_ring, psi, null=misfit * ring(probes) ** 2)) for d in (noise, bias + noise)]
    assert plain[0] > 2.5 * true and plain[1] > 2.5 * true, (plain, true)
    assert ringed[0] < 0.5 * plain[0], (ringed, plain)
    assert 0.8 * true < ringed[1] < 1.7 * true, (ringed, true)


def test_strain_reference_options():
    """The strain's reference: half of the difference, pooled, at one standard error, wherever the reference is
    itself a regression; the local estimate where it is the exact interpolation."""
    assert strain_reference_options(None) == strain_reference_options(1.5) == strain_reference_options((1.0, 1.5)) == {}
    assert strain_reference_options((2.5, 5.0)) == strain_reference_options(3.0) == dict(z=BIAS_Z, share=0.5,
                                                                                      pooled=True)


def test_reference_spacing():
    assert reference_options(None) == {} and reference_options(3.0) == {} and reference_options((3.0, 8.0)) == {}
    assert reference_options(4.0) == reference_options((5.0, 12.0)) == dict(z=2.0, share=0.5, pooled=True)
    assert reference_spacing(None) is None and reference_spacing(1.5) is None
    assert reference_spacing(5.0) == 2.5
    assert reference_spacing((2.5, 16.0)) == (1.25, 8.0) and reference_spacing((1.0, 1.5)) is None


def test_local_rate_weights_exact_for_quartics_and_less_biased_than_the_interpolant():
    """The rate bias reference: exact for polynomials of degree 4 (at the ends too); on a fast heating
    sampled at 2 Hz (time constant 1.5 s) its rate error is a fraction of the exact IMQ interpolant's
    (c R0 = 1 s), which was the reference before and is as biased as the regressions it judged."""
    t = np.linspace(0.0, 10.0, 21)
    te = np.array([0.0, 0.3, 5.1, 10.0])
    W = local_rate_weights(t, te)
    f = 1 + 2 * t - t ** 2 + 0.1 * t ** 3 - 0.01 * t ** 4
    df = 2 - 2 * te + 0.3 * te ** 2 - 0.04 * te ** 3
    assert np.allclose(W @ f, df, atol=1e-9)
    heat = 10 * (1 - np.exp(-t / 1.5))
    rate = 10 / 1.5 * np.exp(-t / 1.5)
    inner = slice(2, -2)
    ref = (local_rate_weights(t) @ heat - rate)[inner]
    imq = (TemporalInterpolant(t, c=1.0, R0=1.0).weights(t, 1) @ heat - rate)[inner]
    assert np.sqrt(np.mean(ref ** 2)) < 0.3 * np.sqrt(np.mean(imq ** 2)), (ref, imq)


def test_rate_reference_of_a_slow_regression_is_a_least_squares_polynomial():
    """A regression with centres 12 stages apart (the demo barrel's) is judged against a degree-6 fit over 25
    stages: exact for sextics, at the ends too; on a slow heating its rate error is a thousandth of the
    regression's, and its noise gain a fifth of the quartic through 5 stages' (which drowned the regression's
    ripple in noise), 1.5 x the regression's own."""
    assert rate_reference_stencil(None) == rate_reference_stencil(3.0) == (5, 4)
    assert rate_reference_stencil(12.0) == (25, 6) and rate_reference_stencil(6.5) == (13, 6)
    t = np.arange(31.0)
    te = np.array([0.0, 0.4, 15.2, 30.0])
    W = local_rate_weights(t, te, samples=25, degree=6)
    c = np.array([1.0, 0.3, -0.02, 1e-3, -2e-5, 3e-7, -1e-9])
    assert np.allclose(W @ np.polyval(c[::-1], t), np.polyval(np.polyder(c[::-1]), te), atol=1e-9)
    heat = 20 + 15 * (1 - np.exp(-t / 25))
    rate = 15 / 25 * np.exp(-t / 25)
    inner = slice(1, -1)
    rms = lambda a: np.sqrt(np.mean(np.square(a[inner])))  # noqa: E731
    gain = lambda W: rms(np.sqrt(np.sum(W ** 2, axis=1)))  # noqa: E731
    ref = local_rate_weights(t, samples=25, degree=6)
    reg = TemporalInterpolant(t, smoothing=12.0).weights(t, 1)
    assert rms(ref @ heat - rate) < 1e-3 * rms(reg @ heat - rate)
    assert gain(ref) < 0.25 * gain(local_rate_weights(t)) and gain(ref) < 1.6 * gain(reg)


def test_local_bias_reads_a_noise_variance_held_at_the_probed_times(monkeypatch):
    """The probes' noise variance, held at the probed times (a SpreadStack of one) and spread a block of times
    at a time, gives exactly the estimate of its spread array; with blocks of a few times, so that the block
    edges (each block reads its neighbouring times) are crossed. A point hidden at its nearest probed time
    takes its median over the probed times, as spread() gives it."""
    from irdic.uncertainty import regression_bias
    from irdic.uncertainty.probes import SpreadStack, probe_times, spread

    rng = np.random.default_rng(3)
    psi, T = _grid(), 40
    sub, near = probe_times(T)
    assert sub.size < T  # the variance is spread, not every time probed
    v_sub = rng.uniform(2.0, 6.0, (sub.size, psi.shape[0], 3))
    v_sub[3, 7] = np.nan
    d = 1.0 + rng.normal(0.0, 2.0, (T, psi.shape[0], 3))
    null = SpreadStack(rng.normal(0.0, 2.0, (4, sub.size, psi.shape[0], 3)) ** 2, near)
    monkeypatch.setattr(regression_bias, "_BIAS_BLOCK", 7 * psi.shape[0] * 3)
    want = local_bias(d, spread(v_sub, near), psi, null=null)
    got = local_bias(d, SpreadStack(v_sub[None], near), psi, null=null)
    assert (want > 0).mean() > 0.5
    np.testing.assert_array_equal(got, want)


def test_the_interpolations_derivative_weights_go_only_where_nothing_interpolates():
    """The uncertainty frees the exact interpolation's derivative weights only where every operator it evaluates
    derivatives with is a regression: the surface's (shape, motion) and their halves, the temperature's and its
    half; an interpolated surface, or a spacing whose half is the interpolation (2 and below), keeps them."""
    from types import SimpleNamespace

    from irdic.uncertainty.model import _regressions_only

    def sf(shape, motion):
        return SimpleNamespace(info={"smoothing_shape": shape, "smoothing": motion})

    assert _regressions_only(sf(8.0, 16.0), 33.0)
    assert _regressions_only(sf(None, 8.0), None)
    assert _regressions_only(sf(8.0, 16.0), 3.0)  # its half, 1.5, is a regression
    assert not _regressions_only(sf(8.0, 16.0), 2.0)  # its half is the interpolation
    assert not _regressions_only(sf(None, None), 33.0)
    assert not _regressions_only(sf(2.0, 16.0), 33.0)
    assert not _regressions_only(sf(None, 1.0), 33.0)


def test_spread_stack_rows_are_the_spread_arrays_rows_before_and_after_scaling():
    """SpreadStack.rows gives the rows of spread() of each array (a hidden point: its median over the probed
    times), with its medians kept between calls, and after an in-place scaling those of the scaled arrays."""
    from irdic.uncertainty.probes import SpreadStack, probe_times, spread

    rng = np.random.default_rng(4)
    sub, near = probe_times(50)
    a = rng.uniform(1.0, 2.0, (3, sub.size, 20))
    a[1, 4, 5] = np.nan
    st = SpreadStack(a.copy(), near)
    times = np.array([0, 7, 13, 49])
    for _ in range(2):
        np.testing.assert_array_equal(st.rows(times), np.array([spread(x, near)[times] for x in a]))
    st *= 3.0
    np.testing.assert_array_equal(st.rows(times), np.array([spread(x * 3.0, near)[times] for x in a]))
    every = SpreadStack(a[:, :3], np.arange(3))
    np.testing.assert_array_equal(every.rows(np.array([2, 0])), a[:, [2, 0]])


def test_window_sums_on_threads_and_the_mask_counted_once_equal_one_thread():
    from irdic.threads import stage_threads
    from irdic.uncertainty.regression_bias import local_bias

    rng = np.random.default_rng(5)
    T, N = 9, 400
    psi = rng.uniform(size=(N, 2))
    d = rng.normal(size=(T, N, 3))
    d[2, 7] = np.nan
    var = np.abs(rng.normal(size=(T, N, 3)))
    null = np.abs(rng.normal(size=(4, T, N, 3)))
    with stage_threads(1):
        one = [local_bias(d, var, psi, None, null, 6.0, {}, **kw) for kw in ({}, dict(z=2.0, share=0.5, pooled=True))]
    with stage_threads(2):
        two = [local_bias(d, var, psi, None, null, 6.0, {}, **kw) for kw in ({}, dict(z=2.0, share=0.5, pooled=True))]
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a, b)


def test_wide_window_sums_along_the_path_equal_the_direct_sums():
    from irdic.uncertainty.regression_bias import _neighbours, _window_sum

    rng = np.random.default_rng(6)
    # a scattered strip with a hole and points without parameters
    psi = rng.uniform(size=(3000, 2)) * [4.0, 1.0]
    psi[np.hypot(psi[:, 0] - 2.0, psi[:, 1] - 0.5) < 0.3] = np.nan
    psi[::41] = np.nan
    nb = _neighbours(psi, 256)
    assert nb[2] is not None and nb[2][1].nnz < 0.3 * nb[1].nnz  # the path's differences are the cheaper sums
    direct = nb[:2] + (None,)
    v = rng.normal(size=(4, psi.shape[0], 3)) + 5.0
    got, want = _window_sum(v, nb), _window_sum(v, direct)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    assert not got[:, ::41].any()  # no parameters: no neighbourhood
    # a value that is not finite spoils its neighbours' sums only, as the direct sums do
    v[1, 5, 0] = np.nan
    got, want = _window_sum(v, nb), _window_sum(v, direct)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    assert 0 < np.isnan(got[..., 0]).mean() < 0.3
    # a small neighbourhood keeps the direct sums
    assert _neighbours(psi, 32)[2] is None
