"""Temperature stacks stored as plain arrays: multi-page TIFF and ``.npy``.

Some users export their IR sequence from the camera software as a float TIFF
stack or save it from their own scripts as a NumPy array. Both are read here
into the same :class:`xarray.DataArray` layout as the IRBIS and ``.irb``
readers produce, and this module also holds the small helpers that build that
layout (:func:`temperature_dataarray`, :func:`to_celsius`), so that every IR
reader names its dimensions, coordinates and units the same way.

Integer arrays are refused by default: an integer TIFF from an IR camera holds
raw digital levels (counts), not temperatures, and turning counts into
temperatures needs the camera's radiometric calibration, which irdic does not
have. Pass ``allow_integer=True`` when the integers really are temperatures in
``temp_unit`` (for example whole kelvins).
"""

from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path
from typing import Mapping

import numpy as np
import xarray as xr

from ..errors import ConfigError, FormatError, IrdicError, IrdicWarning
from ._common import check_file

__all__ = ["read_tiff", "read_npy", "temperature_dataarray", "to_celsius", "normalise_unit"]

log = logging.getLogger(__name__)

ABSOLUTE_ZERO_C = -273.15

_UNIT_ALIASES = {
    "degc": "degC", "c": "degC", "°c": "degC", "celsius": "degC", "deg_c": "degC", "oc": "degC",
    "k": "K", "kelvin": "K", "°k": "K", "degk": "K",
    "degf": "degF", "f": "degF", "°f": "degF", "fahrenheit": "degF",
}


def normalise_unit(unit: str) -> str | None:
    """Map a temperature unit as written by people and programs to irdic's name.

    Parameters
    ----------
    unit : str
        For example ``"°C"``, ``"degC"``, ``"C"``, ``"K"``, ``"Â°C"`` (a cp1252
        degree sign read as UTF-8), ``"°F"``.

    Returns
    -------
    {"degC", "K", "degF"} or None
        None when the unit is not a temperature unit irdic knows.
    """
    text = str(unit).strip().replace("\u00c2", "").replace("\ufffd", "").replace(" ", "").lower()
    if text in _UNIT_ALIASES:
        return _UNIT_ALIASES[text]
    # a mangled degree sign (any single odd character before the letter)
    if len(text) == 2 and text[1] in "ckf" and not text[0].isalnum():
        return _UNIT_ALIASES[text[1]]
    return None


def to_celsius(values: np.ndarray, unit: str) -> np.ndarray:
    """Convert temperatures to °C as float32.

    Parameters
    ----------
    values : ndarray
        Temperatures in ``unit``, any shape.
    unit : {"degC", "K", "degF"}
        A unit as returned by :func:`normalise_unit`.

    Returns
    -------
    ndarray of float32
        Same shape, °C. The conversion is done in float64 so that a kelvin
        value keeps its last digit.
    """
    # values beyond float32's range become inf here; check_temperatures reports them
    with np.errstate(over="ignore"):
        if unit == "degC":
            return np.asarray(values, dtype=np.float32)
        v = np.asarray(values, dtype=np.float64)
        if unit == "K":
            return (v + ABSOLUTE_ZERO_C).astype(np.float32)
        if unit == "degF":
            return ((v - 32.0) * (5.0 / 9.0)).astype(np.float32)
    raise ConfigError(f"unknown temperature unit {unit!r}; expected one of degC, K, degF")


def check_temperatures(values: np.ndarray, where: str | os.PathLike, *, allow_nan: bool = False) -> None:
    """Raise FormatError if °C values are infinite, NaN (unless allowed) or below absolute zero.

    Parameters
    ----------
    values : ndarray
        Temperatures in °C.
    where : str or path-like
        The file the values came from (for the message).
    allow_nan : bool
        Accept NaN (masked pixels in array stacks).
    """
    finite = np.isfinite(values)
    if finite.all():
        # the usual case: one pass for the minimum (nanmin would copy the frame and scan it for NaN again)
        low = values.min() if values.size else 0.0
    else:
        bad = ~finite if not allow_nan else np.isinf(values)
        if bad.any():
            idx = tuple(int(i) for i in np.argwhere(bad)[0])
            raise FormatError(
                f"non-finite temperature {values[idx]} at index {idx} (dims time, v, u as present; "
                "values beyond ±3.4e38 count as infinite); expected finite numbers",
                where,
            )
        with np.errstate(invalid="ignore"):
            low = np.nanmin(values) if values.size and not np.isnan(values).all() else 0.0
    if low < ABSOLUTE_ZERO_C - 1e-3:
        raise FormatError(
            f"temperature {low:.2f} °C is below absolute zero; the unit is probably wrong "
            "(expected °C after conversion from the file's unit)",
            where,
        )


def temperature_dataarray(
    values: np.ndarray,
    *,
    u0: int = 0,
    v0: int = 0,
    time: float | np.ndarray | None = None,
    extra_coords: Mapping[str, np.ndarray] | None = None,
    attrs: Mapping | None = None,
) -> xr.DataArray:
    """Wrap °C temperatures in irdic's IR DataArray layout.

    Parameters
    ----------
    values : ndarray, shape (V, U) or (T, V, U)
        Temperatures in °C (converted to float32).
    u0, v0 : int
        Sensor column/row of ``values[..., 0, 0]`` (non-zero for crop exports).
    time : float or ndarray of shape (T,), optional
        Frame time(s) in s: a scalar coordinate for one frame, the ``time``
        coordinate for a stack. None leaves it out.
    extra_coords : mapping, optional
        More coordinates along ``time`` (``frame_index``, ...).
    attrs : mapping, optional
        Source metadata; ``units`` and ``long_name`` are set here.

    Returns
    -------
    xarray.DataArray
        float32, dims ``("v", "u")`` or ``("time", "v", "u")``, integer
        coordinates ``u``/``v`` in full-sensor pixels.
    """
    data = np.asarray(values, dtype=np.float32)
    if data.ndim not in (2, 3):
        raise ConfigError(f"expected a 2-D frame or a 3-D stack of temperatures, got {data.ndim}-D")
    nv, nu = data.shape[-2:]
    coords: dict = {
        "v": ("v", np.arange(v0, v0 + nv, dtype=np.int64), {"long_name": "sensor row", "units": "px"}),
        "u": ("u", np.arange(u0, u0 + nu, dtype=np.int64), {"long_name": "sensor column", "units": "px"}),
    }
    if data.ndim == 2:
        dims: tuple = ("v", "u")
        if time is not None:
            coords["time"] = ((), float(time), {"units": "s"})
    else:
        dims = ("time", "v", "u")
        if time is not None:
            t = np.asarray(time, dtype=np.float64)
            if t.shape != (data.shape[0],):
                raise ConfigError(f"expected {data.shape[0]} frame times, got shape {t.shape}")
            coords["time"] = ("time", t, {"units": "s"})
    for name, val in (extra_coords or {}).items():
        coords[name] = ("time", np.asarray(val)) if data.ndim == 3 else ((), np.asarray(val)[()])
    out_attrs = {"units": "degC", "long_name": "temperature"}
    out_attrs.update(attrs or {})
    return xr.DataArray(data, dims=dims, coords=coords, attrs=out_attrs)


def _stack_from_array(
    arr: np.ndarray,
    path: Path,
    *,
    fmt: str,
    frame_rate: float | None,
    time_offset: float,
    temp_unit: str,
    allow_integer: bool,
    extra_attrs: Mapping | None = None,
) -> xr.DataArray:
    """Common checks and conversion for TIFF and .npy stacks."""
    unit = normalise_unit(temp_unit)
    if unit is None:
        raise ConfigError(f"temp_unit={temp_unit!r} is not a temperature unit; expected degC, K or degF")
    if frame_rate is not None:
        try:
            frame_rate = float(frame_rate)
        except (TypeError, ValueError):
            raise ConfigError(f"frame_rate must be a number in Hz, got {frame_rate!r}") from None
        if not np.isfinite(frame_rate) or frame_rate <= 0:
            raise ConfigError(f"frame_rate must be positive and finite (Hz), got {frame_rate}")
    try:
        time_offset = float(time_offset)
    except (TypeError, ValueError):
        raise ConfigError(f"time_offset must be a number in s, got {time_offset!r}") from None
    if not np.isfinite(time_offset):
        raise ConfigError(f"time_offset must be finite, got {time_offset}")

    kind = arr.dtype.kind
    if kind in "iu":
        if not allow_integer:
            raise FormatError(
                f"holds integers ({arr.dtype}); these are usually raw detector counts, not temperatures. "
                "Convert them with the camera's calibration and save floats in °C or K, or pass "
                "allow_integer=True if the integers are temperatures in temp_unit",
                path,
            )
    elif kind != "f":
        raise FormatError(f"holds {arr.dtype} values; expected floating-point temperatures", path)
    if arr.ndim not in (2, 3):
        raise FormatError(
            f"holds a {arr.ndim}-D array of shape {arr.shape}; expected one frame (rows, columns) "
            "or a stack (frames, rows, columns)",
            path,
        )
    if 0 in arr.shape:
        raise FormatError(f"holds an empty array of shape {arr.shape}", path)
    temps = to_celsius(arr, unit)
    check_temperatures(temps, path, allow_nan=True)
    n_nan = int(np.isnan(temps).sum())
    if n_nan:
        log.info("%s: %d NaN pixels (kept as NaN)", path, n_nan)

    attrs = {"format": fmt, "source": str(path), "source_unit": unit}
    attrs.update(extra_attrs or {})
    if temps.ndim == 2:
        time = time_offset if frame_rate is not None or time_offset != 0.0 else None
        return temperature_dataarray(temps, time=time, attrs=attrs)
    if frame_rate is None:
        warnings.warn(
            f"{path}: {temps.shape[0]} frames but no frame_rate given; the time coordinate is left out",
            IrdicWarning,
            stacklevel=3,
        )
        time = None
    else:
        attrs["frame_rate"] = frame_rate
        time = time_offset + np.arange(temps.shape[0]) / frame_rate
    return temperature_dataarray(temps, time=time, attrs=attrs)


#: A TIFF may decode to at most this many times its file size (compressed
#: temperatures shrink by a factor of 2 to 4; a crafted file by a thousand) ...
MAX_DECODE_RATIO = 32
#: ... or to this many bytes, whichever is larger (small files of smooth test data)
MAX_DECODE_FLOOR = 256 * 2**20


def _check_decoded_size(shape, dtype, file_size: int, path: Path) -> None:
    """Refuse a TIFF whose pixels would decode to far more memory than its size suggests.

    Notes
    -----
    The decoded stack is counted at ``max(itemsize, 4)`` bytes per value (it
    is converted to float32) and allowed up to
    ``max(MAX_DECODE_RATIO * file_size, MAX_DECODE_FLOOR)`` bytes.
    """
    values = int(np.prod(shape, dtype=object))
    need = values * max(np.dtype(dtype).itemsize, 4)
    limit = max(MAX_DECODE_RATIO * file_size, MAX_DECODE_FLOOR)
    if need > limit:
        raise FormatError(
            f"its pages (shape {tuple(int(n) for n in shape)}, {np.dtype(dtype)}) would decode to "
            f"{need / 2**20:.0f} MiB from a {file_size / 1024:.0f} kB file; irdic reads TIFFs that decode to at "
            f"most {MAX_DECODE_RATIO} times their size or {MAX_DECODE_FLOOR // 2**20} MiB (damaged or crafted "
            "compression?). Save large stacks uncompressed or as .npy",
            path,
        )


def _all_series(series, file_size: int, p: Path) -> np.ndarray:
    """The frames of every image series of a TIFF, in file order (pages written one by one are a series each).

    Raises
    ------
    FormatError
        The series differ in frame size or type: reading the first alone would drop the others silently.
    """
    shapes = {(tuple(int(n) for n in s.shape[-2:]), np.dtype(s.dtype), s.axes[-2:]) for s in series}
    if len(shapes) > 1 or any(s.ndim not in (2, 3) for s in series):
        listed = ", ".join(f"{tuple(int(n) for n in s.shape)} {np.dtype(s.dtype)}" for s in series[:4])
        raise FormatError(f"holds {len(series)} image series of different shapes or types ({listed}"
                          f"{', ...' if len(series) > 4 else ''}); expected frames of one size and type: save "
                          "each series to a file of its own", p)
    frames = sum(int(np.prod(s.shape[:-2])) for s in series)
    (size, dtype, _), = shapes
    _check_decoded_size((frames, *size), dtype, file_size, p)
    return np.concatenate([s.asarray().reshape(-1, *size) for s in series])


def read_tiff(
    path: str | os.PathLike,
    *,
    frame_rate: float | None = None,
    time_offset: float = 0.0,
    temp_unit: str = "degC",
    allow_integer: bool = False,
) -> xr.DataArray:
    """Read a (multi-page) TIFF of temperatures.

    Parameters
    ----------
    path : path-like
        TIFF file; one page is one frame (rows = v, top row first).
    frame_rate : float, optional
        Frames per second (Hz). Gives the ``time`` coordinate of a stack:
        ``time_offset + n / frame_rate``. Without it a stack has no time
        coordinate (an :class:`~irdic.errors.IrdicWarning` says so).
    time_offset : float
        Time of the first frame (s).
    temp_unit : {"degC", "K", "degF"}
        Unit of the stored values.
    allow_integer : bool
        Accept integer pixels as temperatures in ``temp_unit``; by default
        integer data are refused as raw detector counts.

    Returns
    -------
    xarray.DataArray
        float32 °C, dims ``("v", "u")`` for one page, ``("time", "v", "u")``
        for several.

    Raises
    ------
    FormatError
        Not a readable TIFF, colour (RGB) pages, more than three dimensions,
        integer or non-float samples, infinite values or values below
        absolute zero; pages that would decode to more than
        :data:`MAX_DECODE_RATIO` times the file size (and more than
        :data:`MAX_DECODE_FLOOR` bytes).

    Notes
    -----
    Only the pages stored in ``path`` are read: references to other files in
    OME-XML (or Micro-Manager/NDTiff metadata) are ignored, so a TIFF cannot
    make irdic read another file.
    """
    import tifffile

    p = check_file(path)
    file_size = p.stat().st_size
    try:
        # OME, Micro-Manager and NDTiff metadata can name other files (any
        # path) whose pages tifffile would splice into the series: only the
        # pages of this file are read
        with tifffile.TiffFile(p, _multifile=False, is_ome=False, is_mmstack=False, is_ndtiff=False) as tif:
            series = tif.series[0]
            axes = series.axes
            _check_decoded_size(series.shape, series.dtype, file_size, p)
            arr = series.asarray() if len(tif.series) == 1 else _all_series(tif.series, file_size, p)
    except IrdicError:
        raise
    except Exception as exc:  # tifffile raises many types for damaged files
        raise FormatError(f"cannot read as TIFF ({type(exc).__name__}: {exc})", p) from exc
    if "S" in axes:
        raise FormatError(
            f"holds colour/multi-sample pages (axes {axes!r}, shape {arr.shape}); expected one "
            "temperature value per pixel (a screenshot or false-colour image is not a temperature field; "
            "3 or 4 frames saved as colour planes must be rewritten with photometric='minisblack')",
            p,
        )
    return _stack_from_array(
        arr, p, fmt="tiff", frame_rate=frame_rate, time_offset=time_offset,
        temp_unit=temp_unit, allow_integer=allow_integer, extra_attrs={"tiff_axes": axes},
    )


def read_npy(
    path: str | os.PathLike,
    *,
    frame_rate: float | None = None,
    time_offset: float = 0.0,
    temp_unit: str = "degC",
    allow_integer: bool = False,
) -> xr.DataArray:
    """Read a ``.npy`` array of temperatures (2-D frame or 3-D stack).

    Parameters
    ----------
    path : path-like
        ``.npy`` file written by :func:`numpy.save`; shape (rows, columns) or
        (frames, rows, columns). Object arrays (pickles) are refused.
    frame_rate, time_offset, temp_unit, allow_integer
        As in :func:`read_tiff`.

    Returns
    -------
    xarray.DataArray
        float32 °C, dims ``("v", "u")`` or ``("time", "v", "u")``.

    Raises
    ------
    FormatError
        Not a ``.npy`` file, object/complex/bool/integer dtype, wrong
        number of dimensions, infinite values or values below absolute zero.
    """
    p = check_file(path)
    try:
        # memory map: a long stack is converted frame block by frame block
        # by numpy itself instead of being read twice
        arr = np.load(p, mmap_mode="r", allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise FormatError(f"cannot read as a .npy array ({exc})", p) from exc
    if not isinstance(arr, np.ndarray):
        arr.close()
        raise FormatError("is a .npz archive; expected a single .npy array", p)
    return _stack_from_array(
        arr, p, fmt="npy", frame_rate=frame_rate, time_offset=time_offset,
        temp_unit=temp_unit, allow_integer=allow_integer,
    )
