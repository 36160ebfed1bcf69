"""Tests of irdic.validation: one check per kind, value first, messages naming the argument."""

from __future__ import annotations

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError
from irdic.validation import (
    as_int,
    bool_mask,
    choice,
    float_array,
    increasing_times,
    positive,
    shaped_array,
    smoothing_factor,
)


def test_positive():
    assert positive(2, "c") == 2.0
    assert positive(0, "noise", allow_zero=True) == 0.0
    for bad in (0, -1, np.inf, np.nan, True):
        with pytest.raises(ConfigError, match="`c` must be"):
            positive(bad, "c")
    with pytest.raises(ConfigError, match=r"`noise` must be finite and >= 0; got -1"):
        positive(-1, "noise", allow_zero=True)
    with pytest.raises(ConfigError, match="`c` must be a number; got 'x'"):
        positive("x", "c")


def test_as_int_and_choice():
    assert as_int(np.int64(3), "halo") == 3
    for bad in (0, 2.0, True):
        with pytest.raises(ConfigError, match="`halo` must be an integer >= 1"):
            as_int(bad, "halo")
    assert choice("rbf", "method", ("rbf", "cubic")) == "rbf"
    with pytest.raises(ConfigError, match="`method` must be one of 'rbf', 'cubic'; got 'spline'"):
        choice("spline", "method", ("rbf", "cubic"))


def test_arrays():
    assert float_array([1, 2], "x").dtype == float
    with pytest.raises(ConfigError, match="x must be an array of numbers"):
        float_array(["a"], "x")
    with pytest.raises(ConfigError, match=r"J must have shape \(\.\.\., 2, 3\), got \(2, 2\)"):
        shaped_array(np.zeros((2, 2)), "J", (2, 3))
    assert bool_mask([[0, 1]]).dtype == bool
    with pytest.raises(ConfigError, match="mask must be boolean"):
        bool_mask([[0, 2]])


def test_increasing_times_and_smoothing():
    with pytest.raises(DataError, match=r"t must be strictly increasing: t\[1\] = 1\.0 s is followed by t\[2\] = 1\.0 s"):
        increasing_times([0.0, 1.0, 1.0], "t")
    assert smoothing_factor(None, "s") == 1.0
    assert smoothing_factor("gcv", "s") == "gcv"
    with pytest.raises(ConfigError, match="must be >= 1"):
        smoothing_factor(0.5, "s")
