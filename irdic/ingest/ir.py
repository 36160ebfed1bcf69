"""A series of IR exports -> ``ir.zarr``.

IR frames are streamed into the store one at a time (memory is one frame,
whatever the length of the series). With more than one thread, a pool reads
and parses the next files while the current frame is written (at most two
files per thread ahead, in order): a record of thousands of exports is
bound by the disk and the parser, not by one core. The time axis comes from the files or a
frame rate (:func:`irdic.ingest.inputs.frame_times`).
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import logging
import os
import warnings
from pathlib import Path
from typing import Iterator, Mapping, NamedTuple, Sequence

import numpy as np
import xarray as xr

from .. import io as _io
from ..errors import ConfigError, DataError, IrdicWarning
from ..logs import Progress
from ..store import FrameStore, provenance
from ..vocabulary import series_attrs
from ..threads import thread_budget
from .inputs import as_files, frame_times, log_gaps
from ..parameters import settings

__all__ = ["ingest_ir", "check_nan_fraction", "MAX_NAN_FRACTION", "WARN_NAN_FRACTION"]

log = logging.getLogger(__name__)

#: Above this fraction of NaN pixels in one IR frame, ingest refuses the series
#: (an all-NaN frame, or a mask that hides most of the sensor, is a broken
#: export, not a measurement).
MAX_NAN_FRACTION = 0.5
#: Above this fraction of NaN pixel values over the whole series, ingest warns.
WARN_NAN_FRACTION = 0.01


@contextlib.contextmanager
def _untimed_stacks():
    """Silence the readers' warning that a stack has no time axis, for the whole ingest.

    A stack's missing time axis is no concern here: the stage times every
    frame itself (:func:`~irdic.ingest.inputs.frame_times`, from
    ``frame_rate`` or a clear error), so that warning would only be noise in
    the log. The filter is set once, in the stage's own thread: warning
    filters are process-wide and ``catch_warnings`` is not thread-safe, so
    the reader threads must not set filters of their own.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*frames but no frame_rate given", category=IrdicWarning)
        yield


class _Frame(NamedTuple):
    """One IR frame as the store takes it: what the series checks and writes, without a DataArray.

    A DataArray per frame costs about as much as decoding a frame of a
    binary record, so frames travel as plain arrays from the reader to the
    store.
    """

    label: str
    values: np.ndarray  #: (v, u) °C
    v: np.ndarray  #: full-sensor rows (px)
    u: np.ndarray  #: full-sensor columns (px)
    time: float | None  #: s, None when the file gives none
    frame_index: int | None  #: frame number in the recording
    attrs: Mapping  #: the reader's attributes (those of the first frame describe the series)


@functools.lru_cache(maxsize=8)
def _sensor_axes(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """``(v, u)`` full-sensor pixel coordinates of a frame from (0, 0), shared by every frame (read-only)."""
    v, u = np.arange(height, dtype=np.int64), np.arange(width, dtype=np.int64)
    v.flags.writeable = u.flags.writeable = False
    return v, u


def _read_file(f: Path, ffmt: str) -> xr.DataArray:
    """One non-``.irb`` export, read and parsed (its values in memory)."""
    return _io.read_ir(f, format=ffmt).load()


def _frames_of(f: Path, da: xr.DataArray) -> Iterator[_Frame]:
    """The frames of one export read whole (a frame, or a stack along ``time``)."""
    values = da.values
    v, u = da["v"].values, da["u"].values
    fi = da.attrs.get("frame_index")
    fi = None if fi is None else int(fi)
    if "time" not in da.dims:
        t = float(da["time"]) if "time" in da.coords else None
        yield _Frame(f.name, values, v, u, t, fi, da.attrs)
        return
    times = da["time"].values if "time" in da.coords else None
    for i in range(values.shape[0]):
        yield _Frame(f"{f.name}[{i}]", values[i], v, u, None if times is None else float(times[i]), fi, da.attrs)


def _streamed(ffmt: str):
    """``(headers, frames)`` of a format read frame by frame (many frames per file), None for the others.

    ``headers(f, overrides)`` yields ``(time stamp or None, frame number)`` per frame without decoding
    pixels; ``frames(f, overrides)`` yields ``(values, time, attrs)`` per frame, full-sensor pixels from (0, 0).
    """
    if ffmt == "irb":
        from ..io import irb

        return (lambda f, _o: ((irb.unix_time(h), int(h["frame_index"])) for h in irb.iter_irb_headers(f)),
                lambda f, _o: irb.iter_irb_records(f))
    if ffmt == "flir":
        from ..io import flir

        def headers(f, _o):
            heads = list(flir.iter_flir_headers(f))
            flir.check_series(heads, f)
            return ((h["seconds"], h["frame_index"]) for h in heads)

        return headers, flir.iter_flir_records
    return None


def _iter_ir_frames(files: Sequence[Path], formats: Sequence[str], threads: int = 1,
                    overrides: Mapping | None = None) -> Iterator[_Frame]:
    """Yield every frame of the series, in file order.

    ``threads > 1``: up to ``2 threads`` files are read ahead in a thread
    pool (file parsers release the GIL in numpy and I/O). Files of many
    frames each (``.irb``, FLIR) stay streamed frame by frame in this thread.
    """
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    def streamed(f, ffmt):
        for i, (values, t, attrs) in enumerate(_streamed(ffmt)[1](f, overrides)):
            fi = attrs.get("frame_index")
            yield _Frame(f"{f.name}[{i}]", values, *_sensor_axes(*values.shape), t,
                         None if fi is None else int(fi), attrs)

    if threads <= 1:
        for f, ffmt in zip(files, formats):
            yield from streamed(f, ffmt) if _streamed(ffmt) else _frames_of(f, _read_file(f, ffmt))
        return
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="ingest-ir") as pool:
        ahead: deque = deque()
        nxt = 0
        try:
            for f, ffmt in zip(files, formats):
                while nxt < len(files) and len(ahead) < 2 * threads:
                    if not _streamed(formats[nxt]):
                        ahead.append((nxt, pool.submit(_read_file, files[nxt], formats[nxt])))
                    nxt += 1
                if _streamed(ffmt):
                    yield from streamed(f, ffmt)
                    continue
                _, fut = ahead.popleft()  # the pool holds the other files in file order: this is file k
                yield from _frames_of(f, fut.result())
        finally:
            for _, fut in ahead:
                fut.cancel()


def _count_ir_frames(files: Sequence[Path], formats: Sequence[str], overrides: Mapping | None = None
                     ) -> tuple[int, list | None]:
    """Number of frames, and ``(label, time, frame number)`` of each when every file is streamed.

    ``.irb`` and FLIR frames are counted and timed from their headers,
    without decoding pixels.
    """
    n = 0
    stamps: list | None = []
    for f, ffmt in zip(files, formats):
        if _streamed(ffmt):
            for i, (t, number) in enumerate(_streamed(ffmt)[0](f, overrides)):
                if stamps is not None:
                    stamps.append((f"{f.name}[{i}]", t, number))
                n += 1
            continue
        stamps = None
        if ffmt == "irbis":
            n += 1
        else:
            da = _io.read_ir(f, format=ffmt)
            n += da.sizes.get("time", 1)
    return n, stamps


def _overrides(p: dict, files: Sequence[Path], formats: Sequence[str]) -> dict:
    """Pop the FLIR object-parameter overrides from ``p``; ConfigError when set for files of another format."""
    out = {k: p.pop(k) for k in ("emissivity", "reflected_temperature")}
    given = [k for k, v in out.items() if v is not None]
    other = next((f for f, ffmt in zip(files, formats) if ffmt != "flir"), None)
    if given and other is not None:
        raise ConfigError(
            f"ir.{given[0]} applies to FLIR radiometric files only (counts converted by irdic), but {other} is "
            f"{_io.detect_ir_format(other) if other.exists() else 'not FLIR'}: its temperatures were computed by "
            "the camera software; correct the emissivity there and export again, or remove the setting")
    return out


def ingest_ir(source: str | os.PathLike | Sequence[str | os.PathLike], out: str | os.PathLike, **params) -> Path:
    """Convert a series of IR exports into ``ir.zarr``.

    Parameters
    ----------
    source : path-like or sequence of path-like
        Folder, glob or file(s) of IR exports.
    out : path-like
        The store to write (replaced atomically).
    **params
        ``format`` (IR format or ``"auto"``, see :func:`irdic.io.read_ir`),
        ``emissivity``/``reflected_temperature`` (°C) replacing a FLIR
        file's object parameters (None keeps them), ``time_source``, ``frame_rate`` (Hz), ``time_origin``,
        ``time_offset`` (s, or ``"auto"``: the times are kept on the IR
        clock and the couple stage estimates the offset from the data) as in
        ``experiments.<name>.ir`` of the configuration (see
        :func:`irdic.ingest.inputs.frame_times`); absent ones take the
        schema's defaults. The store's attribute ``time_offset`` says which.

    Returns
    -------
    pathlib.Path
        ``out``; the store holds ``temperature(time, v, u)`` float32 °C chunked
        by frame, ``time`` (s), full-sensor ``u``/``v`` (px), ``frame_index``
        and ``source_file`` per frame.

    Raises
    ------
    DataError
        Frames of different sizes or crop windows; times that do not
        increase (for ``.irb`` series found from the image headers, before
        any frame is decoded); a frame with more than
        :data:`MAX_NAN_FRACTION` (50 %) NaN pixels.
    FormatError
        An unreadable file (named).
    ConfigError
        An unknown parameter.

    Notes
    -----
    NaN pixels (masked pixels of TIFF/``.npy`` stacks) are kept; more than
    :data:`WARN_NAN_FRACTION` (1 %) NaN values over the series are logged
    as a warning with the fraction, since the coupling needs finite values
    at every pixel under the specimen.
    """
    p = settings("ir_source", params, drop=("path",))
    fmt = p.pop("format")
    offset = p["time_offset"]
    # auto: the IR clock is kept as the files give it; the couple stage estimates the offset from the data
    p["time_offset"] = 0.0 if offset == "auto" else _offset(offset)
    files = as_files(source, "IR exports")
    formats = [_io.detect_ir_format(f) if fmt == "auto" else fmt for f in files]
    overrides = _overrides(p, files, formats)
    with _untimed_stacks():
        n, stamps = _count_ir_frames(files, formats, overrides)
        log.info("ingest IR: %d frames from %d files", n, len(files))
        if stamps:
            # the time axis from the headers: duplicate or decreasing time stamps
            # are refused before hours of frames are decoded and written
            labels0, times0, numbers0 = zip(*stamps)
            frame_times(times0, numbers0, labels=labels0, what="IR frame", **p)
        it = _iter_ir_frames(files, formats, thread_budget(), overrides)
        first = next(it)
        # the first frame's own values (frame_index, units of the DataArray, ...) would describe the whole store
        attrs = series_attrs("ir", first.attrs)
        attrs.update(provenance("ingest-ir", dict(format=fmt, **overrides, **dict(p, time_offset=offset)),
                                [str(f) for f in files[:1000]]))
        attrs["n_source_files"] = len(files)
        attrs["time_offset"] = offset if offset == "auto" else float(offset)  # the couple stage reads it
        with FrameStore(
            out, "temperature", n, ("v", "u"), {"v": first.v, "u": first.u},
            dtype=np.float32,
            var_attrs={"units": "degC", "long_name": "temperature"},
            attrs=attrs,
            extra_time_vars={"frame_index": ("int64",
                                             {"long_name": "frame number in the recording (-1: unknown)"})},
        ) as fs:
            t, numbers = _write_frames(fs, itertools.chain([first], it), n, files, p)
    log_gaps("IR", t, numbers)
    return Path(out)


def _offset(value) -> float:
    """A configured ``time_offset`` as a finite number of seconds (ConfigError otherwise)."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = np.nan
    if isinstance(value, bool) or not np.isfinite(out):
        raise ConfigError(f"ir.time_offset must be a finite number of seconds or 'auto', got {value!r}")
    return out


def _write_frames(fs: FrameStore, frames: Iterator[_Frame], n: int, files: Sequence[Path], time_params: dict):
    """Write every frame into ``fs`` and set the time axis; returns (times in s, frame numbers)."""
    file_times: list[float | None] = []
    numbers: list[int | None] = []
    labels: list[str] = []
    nan_total, first_nan = 0, None
    progress = Progress(n, "ingest IR", unit="frames", logger=log)
    first = None
    for i, frame in enumerate(frames):
        label = frame.label
        if i >= n:
            raise DataError(f"{label}: more frames than counted ({n}); is a file changing while being read?")
        if first is None:
            first = frame
        _check_window(frame, first)
        values = frame.values.astype(np.float32, copy=False)
        n_nan = check_nan_fraction(label, values, frame.u, frame.v)
        nan_total += n_nan
        if n_nan and first_nan is None:
            first_nan = (label, n_nan / values.size)
        file_times.append(frame.time)
        numbers.append(frame.frame_index)
        labels.append(label)
        fs.write(i, 0.0, values, frame_index=-1 if frame.frame_index is None else frame.frame_index)
        progress.update(i + 1)
    if len(labels) != n:
        raise DataError(f"{files[0].parent}: counted {n} frames but read {len(labels)}")
    t = frame_times(file_times, numbers, labels=labels, what="IR frame", **time_params)
    fs.set_times(t)
    frac = nan_total / (n * first.values.size)
    if frac > WARN_NAN_FRACTION:
        log.warning("IR: %.2f %% of all pixel values are NaN (no temperature), first in %s (%.2f %% of "
                    "that frame); the coupling cannot use NaN pixels inside the specimen's footprint",
                    100 * frac, first_nan[0], 100 * first_nan[1])
    elif nan_total:
        log.info("IR: %d NaN pixel values (%.3f %%), kept as NaN", nan_total, 100 * frac)
    return t, numbers


def check_nan_fraction(label: str, values: np.ndarray, u: np.ndarray, v: np.ndarray) -> int:
    """Number of NaN pixels of one frame; DataError when more than MAX_NAN_FRACTION of it is NaN.

    Parameters
    ----------
    label : str
        The frame, for the message (``file[k]``).
    values : ndarray, shape (V, U)
        °C.
    u, v : ndarray of int, shapes (U,) and (V,)
        Full-sensor column and row of each pixel (px), named in the message.
    """
    nan = np.isnan(values)
    n_nan = int(np.count_nonzero(nan))
    if n_nan > MAX_NAN_FRACTION * values.size:
        rows, cols = np.nonzero(~nan)
        if rows.size == 0:
            what = "every pixel is NaN (no temperature at all)"
        else:
            u, v = np.asarray(u), np.asarray(v)
            what = (f"{100 * n_nan / values.size:.1f} % of the pixels are NaN; the valid ones lie in "
                    f"u {u[cols.min()]}..{u[cols.max()]}, v {v[rows.min()]}..{v[rows.max()]} (full-sensor px)")
        raise DataError(
            f"{label}: {what}; irdic accepts at most {100 * MAX_NAN_FRACTION:.0f} % NaN per frame. Check the "
            "export (wrong unit or range, a mask that covers the specimen), or leave such frames out of the series")
    return n_nan


def _check_window(frame: _Frame, first: _Frame) -> None:
    """DataError when ``frame`` differs in size or crop window from the series' first frame."""
    if frame.values.shape != first.values.shape or not (
        (frame.u is first.u or np.array_equal(frame.u, first.u))
        and (frame.v is first.v or np.array_equal(frame.v, first.v))
    ):
        raise DataError(
            f"{frame.label}: frame covers u {_span(frame.u)}, v {_span(frame.v)} (shape {frame.values.shape}), "
            f"but the first frame ({first.label}) covers u {_span(first.u)}, v {_span(first.v)} "
            f"(shape {first.values.shape}); all frames of a series must have the same size and crop window"
        )


def _span(c) -> str:
    v = np.asarray(c)
    return f"{v[0]}..{v[-1]}" if v.size else "(empty)"
