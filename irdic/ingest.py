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
from .io._common import non_regular_kind as _non_regular_kind
from .logs import Progress
from .store import FrameStore, provenance, write_dataset

__all__ = ["list_inputs", "ingest_ir", "ingest_dic", "frame_times"]

log = logging.getLogger(__name__)

#: Above this fraction of NaN pixels in one IR frame, ingest refuses the series
#: (an all-NaN frame, or a mask that hides most of the sensor, is a broken
#: export, not a measurement).
MAX_NAN_FRACTION = 0.5
#: Above this fraction of NaN pixel values over the whole series, ingest warns.
WARN_NAN_FRACTION = 0.01

_IGNORED_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".pdf", ".yaml", ".yml", ".json", ".md", ".log", ".zarr"}


def _natural_key(p: Path):
    return [int(tok) if tok.isdigit() else tok.lower() for tok in re.split(r"(\d+)", p.name)]


def _special_file(f: Path) -> str | None:
    """What ``f`` is when it exists but is neither a regular file nor a folder, else None."""
    try:
        kind = _non_regular_kind(f.stat().st_mode)
    except OSError:  # vanished or a broken link: the reader says so when it opens it
        return None
    return None if kind == "a folder" else kind


def list_inputs(path: str | os.PathLike, *, what: str = "exports") -> list[Path]:
    """Files of a series: a folder (all regular files in it), a glob or one file.

    Files are returned in natural order (``frame_2`` before ``frame_10``);
    hidden files, sub-folders and pictures/notes next to the exports are
    skipped.

    Raises
    ------
    DataError
        Nothing matches, or a named pipe, device or socket is among the
        inputs (reading one would block or never end; skipping it could
        silently drop frames).
    """
    p = Path(path)
    if p.is_dir():
        candidates = [f for f in p.iterdir() if not f.name.startswith(".")
                      and f.suffix.lower() not in _IGNORED_SUFFIXES]
    elif any(ch in str(path) for ch in "*?["):
        candidates = [Path(f) for f in glob.glob(str(path))]
    else:
        candidates = [p]
    for f in candidates:
        kind = _special_file(f)
        if kind is not None:
            raise DataError(f"{f}: is {kind}, not a regular file; expected {what} stored as files "
                            "(remove it from the input or copy the data into a file)")
    files = [f for f in candidates if f.is_file()]
    if not files:
        if p.is_dir():
            raise DataError(f"{p}: folder contains no {what}")
        if candidates != [p]:
            raise DataError(f"{path}: pattern matches no {what}")
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
        has = [t is not None and np.isfinite(t) for t in file_times]
        missing = [labels[i] for i in range(n) if not has[i]]
        if missing and len(missing) < n:
            # Some files carry a stamp and some do not: the usual cause is a file
            # from another export in the folder. Numbering the stages by a frame
            # rate would then shift every time silently, so do not offer that.
            dated = labels[has.index(True)]
            raise DataError(
                f"{missing[0]}: no time stamp in the file, but {dated} has one ({len(missing)} of {n} {what}s "
                "lack one); check that every file belongs to this series (same software, same export) and "
                "remove the ones that do not"
            )
        if missing:
            if frame_rate is None:
                raise DataError(
                    f"{missing[0]}: no time stamp in the file (none of the {n} {what}s has one); "
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
            from .io import irb

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

    Raises
    ------
    DataError
        Frames of different sizes or crop windows; times that do not
        increase (for ``.irb`` series found from the image headers, before
        any frame is decoded); a frame with more than
        :data:`MAX_NAN_FRACTION` (50 %) NaN pixels.
    FormatError
        An unreadable file (named).

    Notes
    -----
    NaN pixels (masked pixels of TIFF/``.npy`` stacks) are kept; more than
    :data:`WARN_NAN_FRACTION` (1 %) NaN values over the series are logged
    as a warning with the fraction, since the coupling needs finite values
    at every pixel under the specimen.
    """
    files = _as_files(source, "IR exports")
    n, stamps = _count_ir_frames(files, format)
    log.info("ingest IR: %d frames from %d files", n, len(files))
    if stamps:
        # the time axis from the headers: duplicate or decreasing time stamps
        # are refused before hours of frames are decoded and written
        labels0, times0, numbers0 = zip(*stamps)
        frame_times(times0, numbers0, time_source=time_source, frame_rate=frame_rate,
                    time_origin=time_origin, time_offset=time_offset, labels=labels0, what="IR frame")
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
    nan_total, first_nan = 0, None
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
            values = frame.values.astype(np.float32, copy=False)
            n_nan = _check_nan(label, frame, values)
            nan_total += n_nan
            if n_nan and first_nan is None:
                first_nan = (label, n_nan / values.size)
            t = float(frame["time"]) if "time" in frame.coords else None
            file_times.append(t)
            fi = frame.attrs.get("frame_index")
            numbers.append(int(fi) if fi is not None else None)
            labels.append(label)
            fs.write(i, 0.0, values, frame_index=-1 if fi is None else int(fi))
            progress.update(i + 1)
        if len(labels) != n:
            raise DataError(f"{files[0].parent}: counted {n} frames but read {len(labels)}")
        t = frame_times(file_times, numbers, time_source=time_source, frame_rate=frame_rate,
                        time_origin=time_origin, time_offset=time_offset, labels=labels, what="IR frame")
        fs.set_times(t)
        frac = nan_total / (n * first.size)
        if frac > WARN_NAN_FRACTION:
            log.warning("IR: %.2f %% of all pixel values are NaN (no temperature), first in %s (%.2f %% of "
                        "that frame); the coupling cannot use NaN pixels inside the specimen's footprint",
                        100 * frac, first_nan[0], 100 * first_nan[1])
        elif nan_total:
            log.info("IR: %d NaN pixel values (%.3f %%), kept as NaN", nan_total, 100 * frac)
    _log_gaps("IR", t, numbers)
    return Path(out)


def _check_nan(label: str, frame: xr.DataArray, values: np.ndarray) -> int:
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

def _dic_formats(files: Sequence[Path]) -> list[str]:
    """The detected format of every file; all must be the same.

    Raises
    ------
    DataError
        The files are of two or more formats (named, with an example file each).
    """
    formats = [_io.detect_dic_format(f) for f in files]
    # the most common format first: it is most likely the series the user meant
    kinds = sorted(set(formats), key=lambda k: (-formats.count(k), formats.index(k)))
    if len(kinds) > 1:
        parts = []
        for k in kinds:
            mine = [f.name for f, fk in zip(files, formats) if fk == k]
            parts.append(f"{len(mine)} {k} file{'s' if len(mine) > 1 else ''} (e.g. {mine[0]})")
        raise DataError(
            f"{files[0].parent}: the DIC series mixes export formats: {' and '.join(parts)}; one series must "
            "come from one export of one DIC software; move the files that do not belong out of the folder"
        )
    return formats


def _match_row_points(stages: list[xr.Dataset], files: Sequence[Path]) -> list[xr.Dataset]:
    """Give points of exports without an ID column (VIC-3D, DICe without SUBSET_ID) stable IDs.

    Such readers number points by row. Rows only identify points if every
    stage lists the same points in the same order, which a stage with a row
    more or less breaks (every later point would take its neighbour's place).
    Points are therefore matched by what the software writes for them in
    every stage: the reference-image subset centre (``attrs["point_key"]``,
    e.g. VIC's ``x, y`` or DICe's ``COORDINATE_X/Y``). A point keeps its row
    number in the first stage; points absent from it are numbered after.

    Raises
    ------
    DataError
        A stage has no such key columns and a different number of rows than
        the first stage, or a key occurs twice in one stage.
    """
    rows = [i for i, s in enumerate(stages) if s.attrs.get("point_id_source") == "row"]
    if not rows:
        return stages
    keyed = [i for i in rows if _point_key(stages[i])]
    if len(keyed) == len(rows):
        table: dict[tuple, int] = {}
        out = list(stages)
        for i in rows:
            s = stages[i]
            names = _point_key(s)
            pairs = list(zip(*(s[n].values.tolist() for n in names)))
            ids = np.empty(len(pairs), dtype=np.int64)
            seen: set[tuple] = set()
            for r, key in enumerate(pairs):
                if key in seen:
                    raise DataError(
                        f"{files[i].name}: two rows have the same reference image position "
                        f"({', '.join(names)} = {', '.join(f'{v:g}' for v in key)}); cannot tell the points apart"
                    )
                seen.add(key)
                if key not in table:
                    table[key] = len(table)
                ids[r] = table[key]
            out[i] = s.assign_coords(point=("point", ids, s["point"].attrs))
        return out
    n0 = stages[rows[0]].sizes["point"]
    for i in rows:
        n = stages[i].sizes["point"]
        if n != n0:
            raise DataError(
                f"{files[i].name}: {n} rows, but {files[rows[0]].name} has {n0}; this export has no point IDs "
                "nor reference image coordinates, so points are identified by their row and every stage must "
                "list the same points in the same order; export the image coordinates (VIC-3D: x, y; "
                "DICe: COORDINATE_X/Y or SUBSET_ID) so that points can be matched"
            )
    return stages


def _point_key(ds: xr.Dataset) -> tuple[str, ...]:
    """Names of the variables that identify a point of ``ds`` without an ID column (may be empty)."""
    names = tuple(n for n in str(ds.attrs.get("point_key", "")).split(",") if n)
    return names if names and all(n in ds for n in names) else ()


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
        exports carry reference coordinates, ``time`` (s), ``stage_file``;
        when the exports carry testing machine signals (nodemap ``# SIGNALS:``)
        also ``signal_value(time, signal)`` (float64, NaN in stages without that
        signal) with coordinates ``signal`` (names as written),
        ``signal_kind``, ``signal_unit``, ``signal_standard_name``.
    """
    files = _as_files(source, "DIC exports")
    log.info("ingest DIC: %d stages", len(files))
    kwargs = {"columns": columns} if (format == "table" and columns) else {}
    formats = _dic_formats(files) if format == "auto" else [format] * len(files)
    stages: list[xr.Dataset] = []
    progress = Progress(len(files), "ingest DIC", unit="stages", logger=log)
    for i, (f, fmt) in enumerate(zip(files, formats)):
        ds = _io.read_dic(f, format=fmt, **kwargs)
        stages.append(ds)
        progress.update(i + 1)
    stages = _match_row_points(stages, files)
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
    signals = _gather_signals(stages, files)
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
    coords_extra = {}
    if signals is not None:
        values, coords_extra = signals
        data_vars["signal_value"] = (("time", "signal"), values,
                               {"long_name": "testing machine signal recorded with the DIC stage"})
    ds = xr.Dataset(
        data_vars,
        coords={"time": ("time", t, {"units": "s", "long_name": "time"}),
                "point": ("point", ids, {"long_name": "point ID of the DIC software"}),
                "component": ("component", np.array(["x", "y", "z"])), **coords_extra},
        attrs=attrs,
    )
    params = dict(format=format, columns=columns or {}, time_source=time_source, frame_rate=frame_rate,
                  time_origin=time_origin, time_offset=time_offset)
    write_dataset(ds, out, stage="ingest-dic", params=params, inputs=[str(f) for f in files[:1000]],
                  encoding={"x": {"chunks": (1, n_p, 3)}})
    _log_gaps("DIC", t, stage_numbers)
    return Path(out)


def _gather_signals(stages: Sequence[xr.Dataset], files: Sequence[Path]):
    """Per-stage signals -> (values (n_t, n_s), coordinates), or None when no stage has any.

    Signals are identified by name; a stage without a signal gets NaN there.
    A name whose unit or kind differs between stages is a DataError (the
    values would not be comparable).
    """
    from .io.signals import signal_coords

    order: dict[str, tuple[str, str, str, str]] = {}  # name -> (kind, unit, standard name, first file)
    for s, f in zip(stages, files):
        if "signal" not in s.coords:
            continue
        for name, kind, unit, std in zip(*(s[c].values for c in ("signal", "signal_kind", "signal_unit",
                                                                  "signal_standard_name"))):
            name, kind, unit = str(name), str(kind), str(unit)
            if name not in order:
                order[name] = (kind, unit, str(std), f.name)
                continue
            k0, u0, _, f0 = order[name]
            if (kind, unit) != (k0, u0):
                raise DataError(
                    f"{f}: signal {name!r} is a {kind or 'signal'} in {unit or 'no unit'}, but in {f0} a "
                    f"{k0 or 'signal'} in {u0 or 'no unit'}; a signal must keep its kind and unit in every stage"
                )
    if not order:
        return None
    names = list(order)
    col = {n: j for j, n in enumerate(names)}
    values = np.full((len(stages), len(names)), np.nan)
    for i, s in enumerate(stages):
        if "signal" in s.coords:
            values[i, [col[str(n)] for n in s["signal"].values]] = s["signal_value"].values
    missing = np.isnan(values).sum(axis=0)
    for n, m in zip(names, missing):
        if m:
            log.info("DIC signal %r: missing (NaN) in %d of %d stages", n, int(m), len(stages))
    log.info("DIC: %d signals (%s)", len(names), ", ".join(names))
    return values, signal_coords(names, [order[n][0] for n in names], [order[n][1] for n in names],
                                 [order[n][2] for n in names])
