"""Argument checks shared by the whole package: one check, one message.

Every check takes the value first and the argument's name second, returns the
value in canonical form (float, int, float64 array) and raises
:class:`~irdic.errors.ConfigError` (a wrong argument) or
:class:`~irdic.errors.DataError` (data that cannot be used) with a message
that names the argument, what was found and what was expected.
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from .errors import ConfigError, DataError

__all__ = [
    "image_array",
    "positive",
    "as_int",
    "choice",
    "float_array",
    "shaped_array",
    "as_points",
    "as_finite",
    "increasing_times",
    "bool_mask",
    "smoothing_factor",
    "psi_array",
]


def positive(value, name: str, *, allow_zero: bool = False) -> float:
    """``value`` as a finite float > 0 (>= 0 with ``allow_zero``)."""
    expected = ">= 0" if allow_zero else "> 0"
    if isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"`{name}` must be a number {expected}; got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`{name}` must be a number; got {value!r}") from exc
    if not math.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        raise ConfigError(f"`{name}` must be finite and {expected}; got {value!r}")
    return x


def as_int(value, name: str, minimum: int = 1) -> int:
    """``value`` as an int >= ``minimum`` (bools and floats are refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"`{name}` must be an integer >= {minimum}; got {value!r}")
    if value < minimum:
        raise ConfigError(f"`{name}` must be an integer >= {minimum}; got {value!r}")
    return int(value)


def choice(value, name: str, options) -> str:
    """``value`` if it is one of ``options``."""
    if not isinstance(value, str) or value not in options:
        raise ConfigError(f"`{name}` must be one of {', '.join(map(repr, options))}; got {value!r}")
    return value


def float_array(value, name: str) -> np.ndarray:
    """``value`` as a float64 array (any shape, NaN allowed)."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name} must be an array of numbers: {exc}") from None


def shaped_array(value, name: str, tail: tuple) -> np.ndarray:
    """``value`` as a float64 array of shape ``(..., *tail)``."""
    a = float_array(value, name)
    if a.ndim < len(tail) or a.shape[a.ndim - len(tail):] != tuple(tail):
        want = "(..., " + ", ".join(map(str, tail)) + ")"
        raise ConfigError(f"{name} must have shape {want}, got {a.shape}")
    return a


def as_points(value, name: str, dim: int = 3) -> np.ndarray:
    """``value`` as a float64 array of shape ``(..., dim)``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`{name}` must be numeric with last axis of length {dim}; got {type(value).__name__}") from exc
    if arr.ndim == 0 or arr.shape[-1] != dim:
        raise ConfigError(f"Expected the last axis of `{name}` to have length {dim}; got shape {arr.shape}.")
    return arr


def as_finite(value, name: str, shape: tuple | None = None) -> np.ndarray:
    """``value`` as a finite float64 array (of ``shape`` when given)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`{name}` must be numeric; got {type(value).__name__}") from exc
    if shape is not None and arr.shape != tuple(shape):
        raise ConfigError(f"Expected `{name}` to have shape {tuple(shape)}; got {arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"`{name}` must be finite; got {arr.ravel()[~np.isfinite(arr.ravel())][:3].tolist()}")
    return arr


def increasing_times(value, name: str, what: str = "times") -> np.ndarray:
    """A 1-D array of finite, strictly increasing times (s); ``what`` names its axis."""
    t = float_array(value, name)
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


def bool_mask(value, name: str = "mask") -> np.ndarray:
    """``value`` as a 2-D boolean array (0/1 numbers are accepted)."""
    try:
        m = np.asarray(value)
    except Exception as exc:  # pragma: no cover - exotic array-likes
        raise ConfigError(f"{name} must be a 2-D boolean array: {exc}") from None
    if m.ndim != 2:
        raise ConfigError(f"{name} must be a 2-D boolean array (rows, columns), got shape {m.shape}")
    if m.dtype != bool:
        if m.dtype.kind not in "biuf" or not np.isin(m, (0, 1)).all():
            raise ConfigError(f"{name} must be boolean (or 0/1), got dtype {m.dtype} with other values")
        m = m.astype(bool)
    return m


def smoothing_factor(value, name: str, allow_gcv: bool = True):
    """A regression's centre spacing factor: None/0/1 -> 1.0 (interpolation), k >= 1, or "gcv"."""
    if value is None:
        return 1.0
    if isinstance(value, str):
        if allow_gcv and value == "gcv":
            return "gcv"
        raise ConfigError(
            f"{name} must be None (interpolation), a centre spacing factor >= 1 or "
            f"{'gcv' if allow_gcv else 'a number'}, got {value!r}"
        )
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be a number >= 1 or 'gcv', got {value!r}")
    try:
        k = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number >= 1 or 'gcv', got {value!r}") from None
    if k == 0:
        return 1.0
    if not (math.isfinite(k) and k >= 1):
        raise ConfigError(
            f"{name} is the centre spacing of the regression in units of the data spacing "
            f"and must be >= 1 (1 = interpolation), got {value!r}"
        )
    return k


def psi_array(value, name: str) -> np.ndarray:
    """Surface parameters: a float64 array of shape (N, 2) (Psi1, Psi2 in mm)."""
    p = float_array(value, name)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ConfigError(f"{name} must have shape (N, 2) (Psi1, Psi2 in mm), got {p.shape}")
    return p


def image_array(image) -> tuple[np.ndarray, int, int]:
    """A single IR frame as a 2-D float64 array plus its sensor offset.

    Parameters
    ----------
    image : xarray.DataArray or array_like
        Dims ``("v", "u")`` (°C) with integer, consecutive full-sensor pixel
        coordinates; a plain 2-D array is taken as a full frame at (0, 0).
        A ``time`` dimension of length 1 is dropped.

    Returns
    -------
    values : ndarray (H, W)
    u0, v0 : int
        Sensor column and row of ``values[0, 0]``.
    """
    if isinstance(image, xr.DataArray):
        da = image
        if "time" in da.dims:
            if da.sizes["time"] != 1:
                raise ConfigError(f"target image has {da.sizes['time']} frames; give one frame (or their mean)")
            da = da.isel(time=0)
        if set(da.dims) != {"u", "v"}:
            raise ConfigError(f"target image must have dims ('v', 'u'), got {da.dims}")
        da = da.transpose("v", "u")
        offs = []
        for d in ("u", "v"):
            c = np.asarray(da[d].values) if d in da.coords else np.arange(da.sizes[d])
            if len(c) > 1 and not np.all(np.diff(c) == 1):
                raise ConfigError(f"target image coordinate {d!r} must be consecutive integer pixels")
            if len(c) and c[0] != np.round(c[0]):
                raise ConfigError(f"target image coordinate {d!r} must be integer (pixel centres), got {c[0]}")
            offs.append(int(c[0]) if len(c) else 0)
        values = np.asarray(da.values, dtype=np.float64)
        return values, offs[0], offs[1]
    values = np.asarray(image, dtype=np.float64)
    if values.ndim != 2:
        raise ConfigError(f"target image must be 2-D (v, u), got shape {values.shape}")
    return values, 0, 0
