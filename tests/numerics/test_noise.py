"""Noise levels estimated from the data (irdic.noise) against the noise that was added."""

from __future__ import annotations

import numpy as np
import pytest

from irdic.noise import choose_smoothing, dic_noise, ir_noise, quantisation_step


def _frames(sigma, decimals=None, seed=1):
    """A smooth, heating field on an elliptic specimen plus white noise sigma (K)."""
    rng = np.random.default_rng(seed)
    t = np.arange(40) * 0.04
    v, u = np.mgrid[0:60, 0:80]
    f = 25 + 0.05 * u + 0.002 * (v - 30) ** 2 + 3 * np.sin(t)[:, None, None] * np.exp(-((u - 40) ** 2 + (v - 30) ** 2) / 800)
    f = f + rng.normal(0, sigma, f.shape)
    if decimals is not None:
        f = np.round(f, decimals)
    mask = (u - 40) ** 2 / 35 ** 2 + (v - 30) ** 2 / 25 ** 2 < 1
    # the background is 5 K colder: pixels outside the mask must not count
    f = np.where(mask, f, 20.0)
    return f.astype(np.float32), t, mask


@pytest.mark.parametrize("sigma", [0.02, 0.05, 0.1])
@pytest.mark.parametrize("decimals", [None, 2])
def test_ir_noise_recovered(sigma, decimals):
    f, t, mask = _frames(sigma, decimals)
    n = ir_noise(f, t, mask)
    # rounding to q adds q^2/12 to the variance: that is the noise the data carry
    true = np.hypot(sigma, 0.01 / np.sqrt(12)) if decimals == 2 else sigma
    assert n.temporal == pytest.approx(true, rel=0.15)
    assert n.spatial == pytest.approx(true, rel=0.15)
    assert n.quantisation == (0.01 if decimals == 2 else 0.0)


def test_ir_noise_unequal_frame_spacing():
    f, t, mask = _frames(0.05)
    t = t + 0.01 * np.sin(np.arange(t.size))  # jittered frame times
    assert ir_noise(f, t, mask).temporal == pytest.approx(0.05, rel=0.15)


def test_quantisation_step():
    rng = np.random.default_rng(0)
    x = 20 + 5 * rng.random(5000)
    assert quantisation_step(np.round(x, 2).astype(np.float32)) == 0.01
    assert quantisation_step(np.round(x, 3).astype(np.float32)) == 0.001
    assert quantisation_step(np.round(x / 0.05) * 0.05) == pytest.approx(0.05)
    assert quantisation_step(x.astype(np.float32)) == 0.0
    assert quantisation_step(x) == 0.0


@pytest.mark.parametrize("name", ["tube", "halfshell"])
def test_dic_noise_recovered(name):
    from irdic.synthetic.experiments import experiment

    ex = experiment(name, "demo", ir_noise=0.0, dic_noise=0.003, seed=3)
    assert dic_noise(ex.x_dic) == pytest.approx(0.003, rel=0.2)
    clean = experiment(name, "demo", ir_noise=0.0, dic_noise=0.0, seed=3)
    # curvature beyond the local quadric leaves well under a tenth of that
    assert dic_noise(clean.x_dic) < 3e-4


def test_choose_smoothing_rule():
    assert choose_smoothing(None, noise=1.0, gain=1.0, signal=1.0, what="x") == (None, "set in the configuration")
    c, why = choose_smoothing("auto", noise=0.05, gain=np.sqrt(2), signal=0.5, what="gradient")
    assert c == "gcv" and "regression" in why
    c, why = choose_smoothing("auto", noise=0.001 / np.sqrt(12), gain=np.sqrt(2), signal=0.5, what="gradient")
    assert c is None and "interpolation" in why
    assert choose_smoothing("auto", noise=0.003, gain=np.sqrt(2), signal=None, what="strain")[0] == "gcv"
    assert choose_smoothing("auto", noise=np.nan, gain=1.0, signal=1.0, what="x")[0] is None


@pytest.mark.parametrize("sigma", [0.02, 0.05, 0.1])
def test_ir_noise_of_an_export_rounded_to_two_decimals(sigma):
    """White noise exported with 2 decimals (0.01 K steps): the temporal and spatial estimates are within 1.5 %
    of ``sqrt(σ² + q²/12)``; the MAD of the same residuals, quantised by the rounding, is 10 % low at 0.02 K."""
    from irdic.noise import ir_noise, mad_std

    rng = np.random.default_rng(7)
    frames = np.round(25.0 + rng.normal(0.0, sigma, (30, 60, 80)), 2)
    est = ir_noise(frames, np.arange(30) * 0.1, np.ones((60, 80), bool))
    want = np.hypot(sigma, 0.01 / np.sqrt(12))
    assert abs(est.temporal / want - 1) < 0.015 and abs(est.spatial / want - 1) < 0.015, (est, want)
    if sigma == 0.02:
        r = (frames[:-2] - 2 * frames[1:-1] + frames[2:]) / np.sqrt(6)
        assert mad_std(r) / want < 0.93


def test_clipped_std_is_robust_and_handles_noise_below_the_rounding():
    """Outliers (1 % dead pixels at 50 σ) leave :func:`clipped_std` within 1 % of σ; residuals mostly 0 (noise
    below the export's step) give the plain standard deviation, not 0."""
    from irdic.noise import clipped_std

    rng = np.random.default_rng(2)
    r = rng.normal(0.0, 0.05, 100_000)
    r[:1000] = 2.5
    assert abs(clipped_std(r) / 0.05 - 1) < 0.01
    q = np.round(rng.normal(0.0, 0.002, 10_000), 2)
    assert clipped_std(q) == pytest.approx(np.std(q)) and clipped_std(q) > 0
    assert np.isnan(clipped_std([np.nan]))


@pytest.mark.parametrize("sigma", [0.02, 0.05, 0.1])
def test_spatial_noise_of_whole_frames(sigma):
    """The IR clock's pixel noise: whole frames (specimen, a 5 K colder background, its edge, a dead column),
    2-decimal exports: within 3 % of ``sqrt(σ² + q²/12)``; with the specimen's mask it is ir_noise's spatial
    estimate, to the last bit."""
    from irdic.noise import spatial_noise

    f, t, mask = _frames(sigma, decimals=2, seed=4)
    rng = np.random.default_rng(5)
    # the camera's noise is on the background too
    f = np.where(mask, f, np.round(20.0 + rng.normal(0.0, sigma, f.shape), 2)).astype(np.float64)
    f[:, :, 20] = 80.0  # a dead column on the specimen
    want = np.hypot(sigma, 0.01 / np.sqrt(12))
    got = spatial_noise(f)
    assert abs(got / want - 1) < 0.03, (got, want)
    # ir_noise reads three frames of three
    assert spatial_noise(f[:3], mask) == ir_noise(f[:3], t[:3], mask).spatial
    assert np.isnan(spatial_noise(f, np.zeros_like(mask))) and np.isnan(spatial_noise(f[:, :2]))


def _moving_stripes(sigma, seed=3):
    """Hot and cold stripes 12 px apart (2.5 K amplitude) travelling 0.5 px per frame across a 60 x 80 px
    specimen, white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(60) * 0.1
    v, u = np.mgrid[0:60, 0:80]
    f = 25.0 + 2.5 * np.sin(2 * np.pi * (u - 5.0 * t[:, None, None]) / 12.0) + rng.normal(0.0, sigma, (t.size, 60, 80))
    return f, t, np.ones((60, 80), bool)


@pytest.mark.parametrize("sigma", [0.02, 0.05])
def test_ir_noise_temporal_under_a_moving_pattern(sigma):
    """A pattern moving across the pixels is no noise: the fourth divided difference reads the noise within 3 %
    where the second (the estimate before) read 1.4-2.7 x it; on unequal frame spacings as well."""
    from irdic.noise import temporal_residual

    f, t, mask = _moving_stripes(sigma)
    assert ir_noise(f, t, mask).temporal == pytest.approx(sigma, rel=0.03)
    second = np.concatenate([temporal_residual(f[s:s + 3][:, mask], t[s:s + 3]) for s in range(0, 57, 3)])
    assert np.std(second) > 1.3 * sigma
    jittered = t + 0.02 * np.sin(np.arange(t.size))
    # a cubic in time leaves nothing; the weights have unit norm
    cubic = 1.0 + jittered[:5] ** 3
    assert abs(temporal_residual(cubic, jittered[:5])) < 1e-9
    assert temporal_residual(np.eye(5), jittered[:5]) @ temporal_residual(np.eye(5), jittered[:5]) == pytest.approx(1.0)


@pytest.mark.parametrize("sigma", [0.0, 0.02, 0.05])
def test_noise_levels_count_the_rounding_once(sigma):
    """The frame-to-frame estimate of a 2-decimal export holds the rounding (``sqrt(σ² + q²/12)``, as the data
    do): :func:`noise_levels` gives it as the noise the data carry and the pixels' own noise without it; on a
    noise-free export the pixels' own noise is below the rounding's (the uncertainty's bias flag: the export step
    exceeds the noise)."""
    from irdic.noise import noise_levels

    f, t, mask = _frames(sigma, decimals=2, seed=6)
    est = ir_noise(f, t, mask)
    own, q, carried = noise_levels({"ir_noise_temporal_k": est.temporal, "ir_quantisation_k": est.quantisation})
    assert q == 0.01 and carried == est.temporal
    if sigma:
        assert carried == pytest.approx(np.hypot(sigma, q / np.sqrt(12)), rel=0.03)
        assert own == pytest.approx(sigma, rel=0.03)
    else:
        assert own < q / np.sqrt(12)
    assert np.isnan(noise_levels({})[0])
