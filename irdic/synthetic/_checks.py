"""Argument checks shared by the synthetic-experiment modules.

Messages name the parameter, what was found and what was expected, in the
manner of scipy's ``RBFInterpolator``; every failure is a
:class:`~irdic.errors.ConfigError`.
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError

__all__ = ["as_points", "as_finite", "positive", "choice", "as_int"]


def as_points(value, name: str, dim: int = 3) -> np.ndarray:
    """Return ``value`` as a float64 array of shape ``(..., dim)``, finite."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`{name}` must be numeric with last axis of length {dim}; got {type(value).__name__}") from exc
    if arr.ndim == 0 or arr.shape[-1] != dim:
        raise ConfigError(f"Expected the last axis of `{name}` to have length {dim}; got shape {arr.shape}.")
    return arr


def as_finite(value, name: str, shape: tuple | None = None) -> np.ndarray:
    """Return ``value`` as a finite float64 array (of ``shape`` when given)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`{name}` must be numeric; got {type(value).__name__}") from exc
    if shape is not None and arr.shape != tuple(shape):
        raise ConfigError(f"Expected `{name}` to have shape {tuple(shape)}; got {arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"`{name}` must be finite; got {arr.ravel()[~np.isfinite(arr.ravel())][:3].tolist()}")
    return arr


def positive(value, name: str, *, allow_zero: bool = False) -> float:
    """Return ``value`` as a float that is > 0 (or >= 0 with ``allow_zero``)."""
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`{name}` must be a number; got {value!r}") from exc
    if not np.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        expected = ">= 0" if allow_zero else "> 0"
        raise ConfigError(f"`{name}` must be finite and {expected}; got {value!r}")
    return x


def as_int(value, name: str, minimum: int = 1) -> int:
    """Return ``value`` as an int >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"`{name}` must be an integer >= {minimum}; got {value!r}")
    if value < minimum:
        raise ConfigError(f"`{name}` must be an integer >= {minimum}; got {value!r}")
    return int(value)


def choice(value, name: str, options) -> str:
    """Return ``value`` if it is one of ``options``."""
    if value not in options:
        raise ConfigError(f"`{name}` must be one of {', '.join(map(repr, options))}; got {value!r}")
    return value
