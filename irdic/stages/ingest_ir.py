"""Ingest stage, IR: a series of IR exports -> ``ir.zarr``.

IR frames are streamed into the store one at a time (memory is one frame,
whatever the length of the series). With more than one thread, a pool reads
and parses the next files while the current frame is written (at most two
files per thread ahead, in order): a record of thousands of exports is
bound by the disk and the parser, not by one core. The time axis comes from the files or a
frame rate (:func:`irdic.stages.inputs.frame_times`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import warnings
from pathlib import Path
from typing import Iterator, Mapping, Sequence

import numpy as np
import xarray as xr

from .. import io as _io
from ..errors import DataError, IrdicWarning
from ..logs import Progress
from ..store import FrameStore, provenance
from ..vocabulary import series_attrs
from ..threads import thread_budget
from .common import paths, stage_context
from .inputs import as_files, frame_times, log_gaps
from .parameters import settings

__all__ = ["run", "ingest_ir", "check_nan_fraction", "MAX_NAN_FRACTION", "WARN_NAN_FRACTION"]

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
    frame itself (:func:`~irdic.stages.inputs.frame_times`, from
    ``frame_rate`` or a clear error), so that warning would only be noise in
    the log. The filter is set once, in the stage's own thread: warning
    filters are process-wide and ``catch_warnings`` is not thread-safe, so
    the reader threads must not set filters of their own.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*frames but no frame_rate given", category=IrdicWarning)
        yield


def _read_file(f: Path, ffmt: str) -> xr.DataArray:
    """One non-``.irb`` export, read and parsed (its values in memory)."""
    return _io.read_ir(f, format=ffmt).load()


def _frames_of(f: Path, da: xr.DataArray) -> Iterator[tuple[str, xr.DataArray]]:
    if "time" in da.dims:
        for i in range(da.sizes["time"]):
            yield f"{f.name}[{i}]", da.isel(time=i)
    else:
        yield f.name, da


def _iter_ir_frames(files: Sequence[Path], fmt: str, threads: int = 1) -> Iterator[tuple[str, xr.DataArray]]:
    """Yield (label, frame DataArray with dims (v, u)) for every frame of the series, in file order.

    ``threads > 1``: up to ``2 threads`` files are read ahead in a thread
    pool (file parsers release the GIL in numpy and I/O). ``.irb`` files
    (many frames each) stay streamed frame by frame in this thread.
    """
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    formats = [_io.detect_ir_format(f) if fmt == "auto" else fmt for f in files]
    if threads <= 1:
        for f, ffmt in zip(files, formats):
            if ffmt == "irb":
                from ..io import irb

                for i, frame in enumerate(irb.iter_irb_dataarrays(f)):
                    yield f"{f.name}[{i}]", frame
                continue
            yield from _frames_of(f, _read_file(f, ffmt))
        return
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="ingest-ir") as pool:
        ahead: deque = deque()
        nxt = 0
        try:
            for f, ffmt in zip(files, formats):
                while nxt < len(files) and len(ahead) < 2 * threads:
                    if formats[nxt] != "irb":
                        ahead.append((nxt, pool.submit(_read_file, files[nxt], formats[nxt])))
                    nxt += 1
                if ffmt == "irb":
                    from ..io import irb

                    for i, frame in enumerate(irb.iter_irb_dataarrays(f)):
                        yield f"{f.name}[{i}]", frame
                    continue
                _, fut = ahead.popleft()  # the pool holds the non-.irb files in file order: this is file k
                yield from _frames_of(f, fut.result())
        finally:
            for _, fut in ahead:
                fut.cancel()


def _count_ir_frames(files: Sequence[Path], fmt: str) -> tuple[int, list | None]:
    """Number of frames, and ``(label, time, frame number)`` of each when every file is ``.irb``.

    ``.irb`` frames are counted and timed from their image headers, without
    decoding pixels.
    """
    n = 0
    stamps: list | None = []
    for f in files:
        ffmt = _io.detect_ir_format(f) if fmt == "auto" else fmt
        if ffmt == "irb":
            from ..io import irb

            for i, info in enumerate(irb.iter_irb_headers(f)):
                if stamps is not None:
                    stamps.append((f"{f.name}[{i}]", irb.unix_time(info), int(info["frame_index"])))
                n += 1
            continue
        stamps = None
        if ffmt == "irbis":
            n += 1
        else:
            da = _io.read_ir(f, format=ffmt)
            n += da.sizes.get("time", 1)
    return n, stamps


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
        ``time_source``, ``frame_rate`` (Hz), ``time_origin``,
        ``time_offset`` (s) as in ``experiments.<name>.ir`` of the
        configuration (see :func:`irdic.stages.inputs.frame_times`); absent
        ones take the schema's defaults.

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
    files = as_files(source, "IR exports")
    with _untimed_stacks():
        n, stamps = _count_ir_frames(files, fmt)
        log.info("ingest IR: %d frames from %d files", n, len(files))
        if stamps:
            # the time axis from the headers: duplicate or decreasing time stamps
            # are refused before hours of frames are decoded and written
            labels0, times0, numbers0 = zip(*stamps)
            frame_times(times0, numbers0, labels=labels0, what="IR frame", **p)
        it = _iter_ir_frames(files, fmt, thread_budget())
        label0, first = next(it)
        # the first frame's own values (frame_index, units of the DataArray, ...) would describe the whole store
        attrs = series_attrs("ir", first.attrs)
        attrs.update(provenance("ingest-ir", dict(format=fmt, **p), [str(f) for f in files[:1000]]))
        attrs["n_source_files"] = len(files)
        with FrameStore(
            out, "temperature", n, ("v", "u"), {"v": first["v"].values, "u": first["u"].values},
            dtype=np.float32,
            var_attrs={"units": "degC", "long_name": "temperature"},
            attrs=attrs,
            extra_time_vars={"frame_index": ("int64",
                                             {"long_name": "frame number in the recording (-1: unknown)"})},
        ) as fs:
            t, numbers = _write_frames(fs, _chain(first, label0, it), n, files, p)
    log_gaps("IR", t, numbers)
    return Path(out)


def _write_frames(fs: FrameStore, frames, n: int, files: Sequence[Path], time_params: dict):
    """Write every frame into ``fs`` and set the time axis; returns (times in s, frame numbers)."""
    file_times: list[float | None] = []
    numbers: list[int | None] = []
    labels: list[str] = []
    nan_total, first_nan = 0, None
    progress = Progress(n, "ingest IR", unit="frames", logger=log)
    label0 = first = None
    for i, (label, frame) in enumerate(frames):
        if i >= n:
            raise DataError(f"{label}: more frames than counted ({n}); is a file changing while being read?")
        if first is None:
            label0, first = label, frame
        _check_window(label, frame, label0, first)
        values = frame.values.astype(np.float32, copy=False)
        n_nan = check_nan_fraction(label, frame, values)
        nan_total += n_nan
        if n_nan and first_nan is None:
            first_nan = (label, n_nan / values.size)
        file_times.append(float(frame["time"]) if "time" in frame.coords else None)
        fi = frame.attrs.get("frame_index")
        numbers.append(int(fi) if fi is not None else None)
        labels.append(label)
        fs.write(i, 0.0, values, frame_index=-1 if fi is None else int(fi))
        progress.update(i + 1)
    if len(labels) != n:
        raise DataError(f"{files[0].parent}: counted {n} frames but read {len(labels)}")
    t = frame_times(file_times, numbers, labels=labels, what="IR frame", **time_params)
    fs.set_times(t)
    frac = nan_total / (n * first.size)
    if frac > WARN_NAN_FRACTION:
        log.warning("IR: %.2f %% of all pixel values are NaN (no temperature), first in %s (%.2f %% of "
                    "that frame); the coupling cannot use NaN pixels inside the specimen's footprint",
                    100 * frac, first_nan[0], 100 * first_nan[1])
    elif nan_total:
        log.info("IR: %d NaN pixel values (%.3f %%), kept as NaN", nan_total, 100 * frac)
    return t, numbers


def check_nan_fraction(label: str, frame: xr.DataArray, values: np.ndarray) -> int:
    """Number of NaN pixels of one frame; DataError when more than MAX_NAN_FRACTION of it is NaN."""
    nan = np.isnan(values)
    n_nan = int(nan.sum())
    if n_nan > MAX_NAN_FRACTION * values.size:
        rows, cols = np.nonzero(~nan)
        if rows.size == 0:
            what = "every pixel is NaN (no temperature at all)"
        else:
            u, v = frame["u"].values, frame["v"].values
            what = (f"{100 * n_nan / values.size:.1f} % of the pixels are NaN; the valid ones lie in "
                    f"u {u[cols.min()]}..{u[cols.max()]}, v {v[rows.min()]}..{v[rows.max()]} (full-sensor px)")
        raise DataError(
            f"{label}: {what}; irdic accepts at most {100 * MAX_NAN_FRACTION:.0f} % NaN per frame. Check the "
            "export (wrong unit or range, a mask that covers the specimen), or leave such frames out of the series")
    return n_nan


def _check_window(label: str, frame: xr.DataArray, label0: str, first: xr.DataArray) -> None:
    """DataError when ``frame`` differs in size or crop window from the series' first frame."""
    if frame.shape != first.shape or not (
        np.array_equal(frame["u"].values, first["u"].values) and np.array_equal(frame["v"].values, first["v"].values)
    ):
        raise DataError(
            f"{label}: frame covers u {_span(frame['u'])}, v {_span(frame['v'])} (shape {frame.shape}), "
            f"but the first frame ({label0}) covers u {_span(first['u'])}, v {_span(first['v'])} "
            f"(shape {first.shape}); all frames of a series must have the same size and crop window"
        )


def _chain(first, label0, it):
    yield label0, first
    yield from it


def _span(c) -> str:
    v = np.asarray(c)
    return f"{v[0]}..{v[-1]}" if v.size else "(empty)"


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Stage entry: ``inputs["source"]`` (folder, glob or file of IR exports) -> ``outputs["store"]`` (ir.zarr).

    ``params`` as ``experiments.<name>.ir`` of the configuration without
    ``path`` (see :func:`ingest_ir`); ``log`` a log file (Snakemake),
    ``threads`` the CPU threads of the stage (default all cores).
    """
    i = paths(inputs, "ingest_ir", "inputs", ("source",))
    o = paths(outputs, "ingest_ir", "outputs", ("store",), against=i)
    with stage_context("ingest-ir", log, threads):
        ingest_ir(i["source"], o["store"], **params)

