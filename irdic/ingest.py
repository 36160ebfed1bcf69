"""Ingest stage: a folder of raw exports -> ``dic.zarr`` and ``ir.zarr``.

IR frames are streamed into the store one at a time (memory is one frame,
whatever the length of the series). DIC stages are read one file at a time
and gathered as numbers (10,000 points x 1,000 stages x 3 is 240 MB), because
the set of point IDs is only known once every stage has been read.

Times come from the files (IRBIS ``ms``, ``.irb`` time stamps, nodemap
``current_stage_relative_date``) or from a frame rate; ``time_origin="first"``
puts time 0 at the first frame of each series and ``time_offset`` (s) moves a
series onto the clock of the other one. DIC and IR keep their own time axes:
different rates and counts are normal.
"""

from __future__ import annotations

import glob
import logging
import os
import re
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np
import xarray as xr

from . import io as _io
from .errors import DataError, FormatError, IrdicError
from .logs import Progress
from .store import FrameStore, provenance, write_dataset

__all__ = ["list_inputs", "ingest_ir", "ingest_dic", "frame_times"]

log = logging.getLogger(__name__)

_IGNORED_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".pdf", ".yaml", ".yml", ".json", ".md", ".log", ".zarr"}


def _natural_key(p: Path):
    return [int(tok) if tok.isdigit() else tok.lower() for tok in re.split(r"(\d+)", p.name)]


def list_inputs(path: str | os.PathLike, *, what: str = "exports") -> list[Path]:
    """Files of a series: a folder (all regular files in it), a glob or one file.

    Files are returned in natural order (``frame_2`` before ``frame_10``);
    hidden files and pictures/notes next to the exports are skipped.

    Raises
    ------
    DataError
        Nothing matches.
    """
    p = Path(path)
    if p.is_dir():
        files = [f for f in p.iterdir() if f.is_file() and not f.name.startswith(".")
                 and f.suffix.lower() not in _IGNORED_SUFFIXES]
        if not files:
            raise DataError(f"{p}: folder contains no {what}")
    elif any(ch in str(path) for ch in "*?["):
        files = [Path(f) for f in glob.glob(str(path)) if Path(f).is_file()]
        if not files:
            raise DataError(f"{path}: pattern matches no {what}")
    elif p.is_file():
        files = [p]
    else:
        raise DataError(f"{p}: no such file or folder (expected {what})")
    return sorted(files, key=_natural_key)


def frame_times(
    file_times: Sequence[float | None],
    frame_numbers: Sequence[int] | None,
    *,
    time_source: str = "file",
    frame_rate: float | None = None,
    time_origin: str = "first",
    time_offset: float = 0.0,
    labels: Sequence[str] | None = None,
    what: str = "frame",
) -> np.ndarray:
    """Turn per-frame time stamps or frame numbers into the series' time axis (s).

    Parameters
    ----------
    file_times : sequence of float or None
        Time stamp of each frame from its file (s), None where absent.
    frame_numbers : sequence of int, optional
        Frame numbers from the files (gaps = dropped frames), used with
        ``frame_rate``; the position in the series otherwise.
    time_source : {"file", "frame_rate"}
    frame_rate : float, optional
        Hz.
    time_origin : {"first", "file"}
    time_offset : float
        Seconds added at the end.
    labels : sequence of str, optional
        Names of the frames' files, for messages.

    Returns
    -------
    ndarray, shape (n,)
        Strictly increasing times in s.
    """
    n = len(file_times)
    labels = list(labels) if labels is not None else [f"{what} {i}" for i in range(n)]
    if time_source == "file":
        missing = [labels[i] for i, t in enumerate(file_times) if t is None or not np.isfinite(t)]
        if missing:
            if frame_rate is None:
                raise DataError(
                    f"{missing[0]}: no time stamp in the file ({len(missing)} of {n} {what}s lack one); "
                    "set frame_rate (Hz) for this series in the configuration"
                )
            log.warning("%d %ss carry no time stamp; using frame_rate = %g Hz", len(missing), what, frame_rate)
            time_source = "frame_rate"
    if time_source == "frame_rate":
        if frame_rate is None or not frame_rate > 0:
            raise DataError(f"frame_rate must be a positive number of Hz, got {frame_rate!r}")
        numbers = np.arange(n) if frame_numbers is None or any(f is None for f in frame_numbers) \
            else np.asarray(frame_numbers, dtype=float)
        t = numbers / float(frame_rate)
    else:
        t = np.asarray(file_times, dtype=float)
    if time_origin == "first" and n:
        t = t - t[0]
    t = t + float(time_offset)
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"{what} times must increase: {labels[i + 1]} (t = {t[i + 1]:.6g} s) does not come after "
            f"{labels[i]} (t = {t[i]:.6g} s); check the file order or the time stamps"
        )
    return t


# ---------------------------------------------------------------------------- IR

def _iter_ir_frames(files: Sequence[Path], fmt: str) -> Iterator[tuple[str, xr.DataArray]]:
    """Yield (label, frame DataArray with dims (v, u)) for every frame of the series."""
    for f in files:
        ffmt = _io.detect_ir_format(f) if fmt == "auto" else fmt
        if ffmt == "irb":
            from .io import irb

            for i, frame in enumerate(irb.iter_irb_dataarrays(f)):
                yield f"{f.name}[{i}]", frame
            continue
        da = _io.read_ir(f, format=ffmt)
        if "time" in da.dims:
            for i in range(da.sizes["time"]):
                yield f"{f.name}[{i}]", da.isel(time=i)
        else:
            yield f.name, da


def _count_ir_frames(files: Sequence[Path], fmt: str) -> int:
    n = 0
    for f in files:
        ffmt = _io.detect_ir_format(f) if fmt == "auto" else fmt
        if ffmt == "irbis":
            n += 1
        elif ffmt == "irb":
            from .io import irb

            n += irb.count_irb_frames(f)
        else:
            da = _io.read_ir(f, format=ffmt)
            n += da.sizes.get("time", 1)
    return n


def ingest_ir(
    source: str | os.PathLike | Sequence[str | os.PathLike],
    out: str | os.PathLike,
    *,
    format: str = "auto",
    time_source: str = "file",
    frame_rate: float | None = None,
    time_origin: str = "first",
    time_offset: float = 0.0,
) -> Path:
    """Convert a series of IR exports into ``ir.zarr``.

    Parameters
    ----------
    source : path-like or sequence of path-like
        Folder, glob or file(s) of IR exports.
    out : path-like
        The store to write (replaced atomically).
    format : str
        IR format or ``"auto"`` (see :func:`irdic.io.read_ir`).
    time_source, frame_rate, time_origin, time_offset
        See :func:`frame_times`.

    Returns
    -------
    pathlib.Path
        ``out``; the store holds ``temperature(time, v, u)`` float32 °C chunked
        by frame, ``time`` (s), full-sensor ``u``/``v`` (px), ``frame_index``
        and ``source_file`` per frame.
    """
    files = _as_files(source, "IR exports")
    n = _count_ir_frames(files, format)
    log.info("ingest IR: %d frames from %d files", n, len(files))
    progress = Progress(n, "ingest IR", unit="frames", logger=log)
    it = _iter_ir_frames(files, format)
    label0, first = next(it)
    frame_coords = {"v": first["v"].values, "u": first["u"].values}
    attrs = {k: v for k, v in first.attrs.items() if isinstance(v, (str, int, float, bool))}
    attrs.pop("source", None)
    attrs.update(provenance("ingest-ir", dict(format=format, time_source=time_source, frame_rate=frame_rate,
                                              time_origin=time_origin, time_offset=time_offset),
                            [str(f) for f in files[:1000]]))
    attrs["n_source_files"] = len(files)
    file_times: list[float | None] = []
    numbers: list[int | None] = []
    labels: list[str] = []
    with FrameStore(
        out, "temperature", n, ("v", "u"), frame_coords, dtype=np.float32,
        var_attrs={"units": "degC", "long_name": "temperature"},
        attrs=attrs,
        extra_time_vars={"frame_index": ("int64", {"long_name": "frame number in the recording (-1: unknown)"})},
    ) as fs:
        for i, (label, frame) in enumerate(_chain(first, label0, it)):
            if i >= n:
                raise DataError(f"{label}: more frames than counted ({n}); is a file changing while being read?")
            if frame.shape != first.shape or not (
                np.array_equal(frame["u"].values, frame_coords["u"]) and np.array_equal(frame["v"].values, frame_coords["v"])
            ):
                raise DataError(
                    f"{label}: frame covers u {_span(frame['u'])}, v {_span(frame['v'])} (shape {frame.shape}), "
                    f"but the first frame ({label0}) covers u {_span(first['u'])}, v {_span(first['v'])} "
                    f"(shape {first.shape}); all frames of a series must have the same size and crop window"
                )
            t = float(frame["time"]) if "time" in frame.coords else None
            file_times.append(t)
            fi = frame.attrs.get("frame_index")
            numbers.append(int(fi) if fi is not None else None)
            labels.append(label)
            fs.write(i, 0.0, frame.values.astype(np.float32, copy=False), frame_index=-1 if fi is None else int(fi))
            progress.update(i + 1)
        if len(labels) != n:
            raise DataError(f"{files[0].parent}: counted {n} frames but read {len(labels)}")
        t = frame_times(file_times, numbers, time_source=time_source, frame_rate=frame_rate,
                        time_origin=time_origin, time_offset=time_offset, labels=labels, what="IR frame")
        fs.set_times(t)
    _log_gaps("IR", t, numbers)
    return Path(out)


def _chain(first, label0, it):
    yield label0, first
    yield from it


def _span(c) -> str:
    v = np.asarray(c)
    return f"{v[0]}..{v[-1]}" if v.size else "(empty)"


def _log_gaps(what: str, t: np.ndarray, numbers: Sequence[int | None]) -> None:
    if len(t) > 2:
        dt = np.diff(t)
        med = np.median(dt)
        gaps = np.flatnonzero(dt > 1.5 * med)
        if gaps.size:
            log.warning("%s: %d gap(s) in the time axis (dropped frames?), first after t = %.4g s (%.4g s instead of %.4g s)",
                        what, gaps.size, t[gaps[0]], dt[gaps[0]], med)


def _as_files(source, what: str) -> list[Path]:
    if isinstance(source, (str, os.PathLike)):
        return list_inputs(source, what=what)
    files: list[Path] = []
    for s in source:
        files.extend(list_inputs(s, what=what))
    if not files:
        raise DataError(f"no {what} given")
    return files


# ---------------------------------------------------------------------------- DIC

def ingest_dic(
    source: str | os.PathLike | Sequence[str | os.PathLike],
    out: str | os.PathLike,
    *,
    format: str = "auto",
    columns: dict | None = None,
    time_source: str = "file",
    frame_rate: float | None = None,
    time_origin: str = "first",
    time_offset: float = 0.0,
) -> Path:
    """Convert a series of DIC stage exports into ``dic.zarr``.

    Parameters
    ----------
    source : path-like or sequence of path-like
        Folder, glob or file(s), one file per stage.
    out : path-like
        The store to write (replaced atomically).
    format : str
        DIC format or ``"auto"`` (see :func:`irdic.io.read_dic`).
    columns : dict, optional
        Column mapping for ``format="table"``.
    time_source, frame_rate, time_origin, time_offset
        See :func:`frame_times`.

    Returns
    -------
    pathlib.Path
        ``out``; the store holds ``x(time, point, component)`` (mm, NaN where a
        point is missing in a stage), ``x_ref(point, component)`` when the
        exports carry reference coordinates, ``time`` (s), ``stage_file``.
    """
    files = _as_files(source, "DIC exports")
    log.info("ingest DIC: %d stages", len(files))
    kwargs = {"columns": columns} if (format == "table" and columns) else {}
    stages: list[xr.Dataset] = []
    progress = Progress(len(files), "ingest DIC", unit="stages", logger=log)
    for i, f in enumerate(files):
        ds = _io.read_dic(f, format=format, **kwargs)
        stages.append(ds)
        progress.update(i + 1)
    ids = np.unique(np.concatenate([s["point"].values for s in stages]))
    n_t, n_p = len(stages), ids.size
    x = np.full((n_t, n_p, 3), np.nan)
    x_ref = np.full((n_p, 3), np.nan)
    have_ref = False
    file_times: list[float | None] = []
    stage_numbers: list[int | None] = []
    for i, s in enumerate(stages):
        pos = np.searchsorted(ids, s["point"].values)
        x[i, pos] = s["x"].transpose("point", "component").values
        if "x_ref" in s:
            have_ref = True
            r = s["x_ref"].transpose("point", "component").values
            fill = np.isnan(x_ref[pos, 0]) & np.isfinite(r[:, 0])
            x_ref[pos[fill]] = r[fill]
        file_times.append(float(s["time"]) if "time" in s.coords else None)
        si = s.attrs.get("stage_index")
        stage_numbers.append(int(si) if si is not None else None)
    t = frame_times(file_times, stage_numbers, time_source=time_source, frame_rate=frame_rate,
                    time_origin=time_origin, time_offset=time_offset, labels=[f.name for f in files],
                    what="DIC stage")
    missing = np.isnan(x[..., 0])
    never = missing.all(axis=0)
    if never.all():
        raise DataError(f"{files[0].parent}: no valid DIC point in any stage")
    log.info("DIC: %d points, %d stages; %.2f %% of (stage, point) entries missing; %d points never valid",
             n_p, n_t, 100 * missing.mean(), int(never.sum()))
    data_vars = {
        "x": (("time", "point", "component"), x,
              {"units": "mm", "long_name": "current coordinates of the material points (DIC frame)"}),
        "stage_file": (("time",), np.array([f.name for f in files], dtype=object), {"long_name": "source file of the stage"}),
    }
    if have_ref:
        data_vars["x_ref"] = (("point", "component"), x_ref,
                              {"units": "mm", "long_name": "reference (undeformed) coordinates from the exports"})
    attrs = {k: v for k, v in stages[0].attrs.items() if isinstance(v, (str, int, float, bool)) and k != "source"}
    ds = xr.Dataset(
        data_vars,
        coords={"time": ("time", t, {"units": "s", "long_name": "time"}),
                "point": ("point", ids, {"long_name": "point ID of the DIC software"}),
                "component": ("component", np.array(["x", "y", "z"]))},
        attrs=attrs,
    )
    params = dict(format=format, columns=columns or {}, time_source=time_source, frame_rate=frame_rate,
                  time_origin=time_origin, time_offset=time_offset)
    write_dataset(ds, out, stage="ingest-dic", params=params, inputs=[str(f) for f in files[:1000]],
                  encoding={"x": {"chunks": (1, n_p, 3)}})
    _log_gaps("DIC", t, stage_numbers)
    return Path(out)
