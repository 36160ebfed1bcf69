"""Argument checks shared by the numerical modules (messages name the argument)."""

from __future__ import annotations

import math

import numpy as np

from .errors import ConfigError, DataError

__all__ = ["positive", "float_array", "increasing_times"]


def positive(name: str, value) -> float:
    """``value`` as a positive finite float, else ConfigError naming ``name``."""
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be a positive number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a positive number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ConfigError(f"{name} must be a positive finite number, got {value!r}")
    return v


def float_array(name: str, value) -> np.ndarray:
    """``value`` as a float array, else ConfigError naming ``name``."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name} must be an array of numbers: {exc}") from None


def increasing_times(name: str, times, what: str = "times") -> np.ndarray:
    """A 1-D array of finite, strictly increasing times (s), else a precise error."""
    t = float_array(name, times)
    if t.ndim != 1:
        raise ConfigError(f"{name} must be 1-D ({what},), got shape {t.shape}")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise DataError(f"{name}: non-finite time at index {bad[0]} ({float(t[bad[0]])})")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = bad[0]
        raise DataError(
            f"{name} must be strictly increasing: {name}[{i}] = {float(t[i])!r} s is followed by "
            f"{name}[{i + 1}] = {float(t[i + 1])!r} s ({bad.size} such step(s))"
        )
    return t
