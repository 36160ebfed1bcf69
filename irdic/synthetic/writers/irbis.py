"""Writer of InfraTec IRBIS 3 text exports (one IR frame per file), read by :func:`irdic.io.irbis.read_irbis`."""

from __future__ import annotations

import datetime as _dt
import math
import os
from pathlib import Path
from typing import Mapping

import numpy as np

from ...errors import ConfigError
from ...io.stack import normalise_unit

__all__ = ["write_irbis"]


def _fmt_number(value: float, decimals: int, mark: str) -> str:
    return f"{value:.{decimals}f}".replace(".", mark)


def write_irbis(
    path: str | os.PathLike,
    temperature,
    *,
    ms: float | None = None,
    frame_index: int | None = None,
    rec_datetime: _dt.datetime | None = None,
    start_pos: tuple[int, int] | None = None,
    sensor_size: tuple[int, int] | None = None,
    sep: str = "\t",
    decimal: str = ".",
    trailing_sep: bool = False,
    decimals: int = 2,
    temp_unit: str = "°C",
    filename: str | None = None,
    parameters: Mapping[str, object] | None = None,
) -> Path:
    """Write one frame as an IRBIS 3 text export (cp1252, CRLF).

    Parameters
    ----------
    path : path-like
        Output file (its folder must exist).
    temperature : array_like, shape (H, W)
        Temperatures in °C, rows = v (top row first). Must be finite.
    ms : float, optional
        Time of the frame in the recording (ms): written as ``ms=``;
        :func:`read_irbis` returns ``time = ms / 1000``.
    frame_index : int, optional
        ``FrameIndex=``.
    rec_datetime : datetime.datetime, optional
        ``RecDate=dd.mm.yyyy`` and ``RecTime=hh:mm:ss`` (seconds truncated;
        sub-second time belongs in ``ms``).
    start_pos : (int, int), optional
        Sensor position (u0, v0) of the top left pixel of a crop export:
        written as ``StartPos=u0;v0`` and ``EndPos=u0+W-1;v0+H-1``.
    sensor_size : (int, int), optional
        Full sensor (width, height) in px; written as irdic's own
        ``SensorWidth``/``SensorHeight`` keys (IRBIS ignores them).
    sep : {"\\t", ";", " ", ","}
        Cell separator.
    decimal : {".", ","}
        Decimal mark (also used in ``ms`` and ``ShotRange``).
    trailing_sep : bool
        End every data row with a separator (as IRBIS does).
    decimals : int
        Digits after the decimal mark (0 to 8); the file holds the values
        rounded to this many decimals.
    temp_unit : {"°C", "K"}
        Unit of the written numbers (``TempUnit=``); °C input is converted.
    filename : str, optional
        ``Filename=`` (name of the recording the frame was exported from).
    parameters : mapping, optional
        More ``key=value`` lines for the ``[Parameter]`` section
        (for example ``{"Distance": 2.0, "EnvTemp": 25.0, "Emissivity": 0.95}``).

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ConfigError
        An argument is invalid (named), or the file cannot be written.
    """
    arr = _checked_frame(temperature)
    unit = _checked_format(sep, decimal, decimals, temp_unit)
    origin, sensor = _checked_placement(start_pos, sensor_size, arr.shape)
    ms = _checked_stamps(ms, frame_index, rec_datetime)
    arr = arr + 273.15 if unit == "K" else arr
    head = _header(arr, unit, origin, sensor, decimal, filename=filename, frame_index=frame_index,
                   rec_datetime=rec_datetime, ms=ms, parameters=parameters)
    p = Path(path)
    try:
        p.write_bytes(head.encode("cp1252") + _body(arr, sep, decimal, decimals, trailing_sep).encode("ascii"))
    except (OSError, UnicodeEncodeError) as exc:
        raise ConfigError(f"cannot write {p}: {exc}") from exc
    return p


def _checked_frame(temperature) -> np.ndarray:
    """``temperature`` as a finite float64 (H, W) array, or a ConfigError naming the first bad value."""
    arr = np.asarray(temperature)
    if arr.ndim != 2 or 0 in arr.shape:
        raise ConfigError(f"temperature must be a non-empty 2-D array (rows, columns), got shape {arr.shape}")
    if arr.dtype.kind not in "fiu":
        raise ConfigError(f"temperature must hold real numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if not np.isfinite(arr).all():
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ConfigError(f"temperature[{idx[0]}, {idx[1]}] = {arr[idx]}; IRBIS text cannot hold non-finite values")
    return arr


def _checked_format(sep: str, decimal: str, decimals: int, temp_unit: str) -> str:
    """Check the number format; return the unit, ``"degC"`` or ``"K"``."""
    if sep not in ("\t", ";", " ", ","):
        raise ConfigError(f"sep={sep!r}; expected one of '\\t', ';', ' ', ','")
    if decimal not in (".", ","):
        raise ConfigError(f"decimal={decimal!r}; expected '.' or ','")
    if sep == decimal:
        raise ConfigError(f"sep and decimal are both {sep!r}; the numbers could not be told apart")
    if isinstance(decimals, bool) or not isinstance(decimals, (int, np.integer)) or not 0 <= decimals <= 8:
        raise ConfigError(f"decimals={decimals!r}; expected an integer from 0 to 8")
    unit = normalise_unit(temp_unit)
    if unit not in ("degC", "K"):
        raise ConfigError(f"temp_unit={temp_unit!r}; expected '°C' or 'K'")
    return unit


def _checked_placement(start_pos, sensor_size, shape: tuple[int, int]):
    """Check the crop position and sensor size; return ``(u0, v0)`` and ``(width, height)`` (each or None)."""
    h, w = shape
    origin = sensor = None
    if start_pos is not None:
        try:
            u0, v0 = (int(x) for x in start_pos)
        except (TypeError, ValueError):
            raise ConfigError(f"start_pos={start_pos!r}; expected (u0, v0) integers") from None
        if u0 < 0 or v0 < 0:
            raise ConfigError(f"start_pos={start_pos!r}; expected non-negative pixel positions")
        origin = (u0, v0)
    if sensor_size is not None:
        try:
            sw, sh = (int(x) for x in sensor_size)
        except (TypeError, ValueError):
            raise ConfigError(f"sensor_size={sensor_size!r}; expected (width, height) integers") from None
        su, sv = origin if origin is not None else (0, 0)
        if su + w > sw or sv + h > sh:
            raise ConfigError(f"a {w} x {h} frame at start_pos=({su}, {sv}) does not fit on a "
                              f"{sw} x {sh} sensor_size")
        sensor = (sw, sh)
    return origin, sensor


def _checked_stamps(ms, frame_index, rec_datetime) -> float | None:
    """Check the frame's time stamps; return ``ms`` as a float (or None)."""
    if ms is not None:
        ms = float(ms)
        if not math.isfinite(ms):
            raise ConfigError(f"ms={ms}; expected a finite time in ms")
    if frame_index is not None:
        if isinstance(frame_index, bool) or not isinstance(frame_index, (int, np.integer)) or frame_index < 0:
            raise ConfigError(f"frame_index={frame_index!r}; expected a non-negative integer")
    if rec_datetime is not None and not isinstance(rec_datetime, _dt.datetime):
        raise ConfigError(f"rec_datetime must be a datetime.datetime, got {type(rec_datetime).__name__}")
    return ms


def _header(arr: np.ndarray, unit: str, origin, sensor, decimal: str, *, filename, frame_index, rec_datetime,
            ms, parameters) -> str:
    """``[Settings]`` and ``[Parameter]`` sections up to the ``[Data]`` line (CRLF-joined)."""
    h, w = arr.shape
    unit_text = "°C" if unit == "degC" else "K"
    lines = ["[Settings]", "Version=3", f"ImageWidth={w}", f"ImageHeight={h}"]
    if origin is not None:
        u0, v0 = origin
        lines += [f"StartPos={u0};{v0}", f"EndPos={u0 + w - 1};{v0 + h - 1}"]
    if sensor is not None:
        lines += [f"SensorWidth={sensor[0]}", f"SensorHeight={sensor[1]}"]
    lo, hi = float(arr.min()), float(arr.max())
    lines += [f"ShotRange={_fmt_number(lo, 2, decimal)};{_fmt_number(hi, 2, decimal)}",
              f"TempUnit={unit_text}", "", "[Parameter]"]
    if filename is not None:
        lines.append(f"Filename={filename}")
    if frame_index is not None:
        lines.append(f"FrameIndex={int(frame_index)}")
    if rec_datetime is not None:
        lines += [f"RecDate={rec_datetime:%d.%m.%Y}", f"RecTime={rec_datetime:%H:%M:%S}"]
    if ms is not None:
        text = f"{ms:.4f}".rstrip("0")
        lines.append("ms=" + (text + "0" if text.endswith(".") else text).replace(".", decimal))
    for key, value in (parameters or {}).items():
        if isinstance(value, (float, np.floating)):
            value = repr(float(value)).replace(".", decimal)
        lines.append(f"{key}={value}")
    lines += ["", "[Data]", ""]
    return "\r\n".join(lines)


def _body(arr: np.ndarray, sep: str, decimal: str, decimals: int, trailing_sep: bool) -> str:
    """The ``[Data]`` rows, top row first, each ended by CRLF."""
    cell = f"%.{decimals}f"
    row_fmt = sep.join([cell] * arr.shape[1]) + (sep if trailing_sep else "")
    body = "\r\n".join([row_fmt % tuple(row) for row in arr.tolist()]) + "\r\n"
    if decimal == ",":
        body = body.replace(".", ",")
    return body
