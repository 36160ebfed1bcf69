"""Tests of irdic.numerics.temporal: the one temporal interpolant and regressor."""

from __future__ import annotations

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError
from irdic.numerics.temporal import TemporalInterpolant

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


