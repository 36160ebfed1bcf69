"""Raw series on disk: which files, and the time axis they give.

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
from typing import Sequence

import numpy as np

from ..errors import DataError, IrdicError
from ..io._common import non_regular_kind as _non_regular_kind

__all__ = ["list_inputs", "frame_times", "as_files", "log_gaps"]

log = logging.getLogger(__name__)

_IGNORED_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".pdf", ".yaml", ".yml", ".json", ".md", ".log", ".zarr"}


def _radiometric_jpeg(f: Path) -> bool:
    """A FLIR radiometric JPEG among the pictures of a folder: an IR frame, not a picture to skip."""
    if f.suffix.lower() not in (".jpg", ".jpeg") or not f.is_file():
        return False
    from ..io.flir import is_radiometric_jpeg

    try:
        return is_radiometric_jpeg(f)
    except (OSError, IrdicError):
        return False


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
    skipped (JPEGs that hold FLIR radiometric data are IR frames and kept).

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
                      and (f.suffix.lower() not in _IGNORED_SUFFIXES or _radiometric_jpeg(f))]
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
        if frame_numbers is None or any(f is None for f in frame_numbers):
            numbers = _numbers_in_names(labels, what)
        else:
            numbers = np.asarray(frame_numbers, dtype=float)
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


def _numbers_in_names(labels: Sequence[str], what: str) -> np.ndarray:
    """Frame positions from the numbers that end the file names (``stage_0012.csv``), first at 0.

    A numbered series with a member missing (``stage_3`` deleted) keeps the
    times of the others: the numbers, not the positions, count the frames.
    Names without a number each, numbers that do not increase, or numbers
    of which fewer than half step by one (not a count of frames) give the
    positions ``0 .. n-1``, as before.
    """
    # "stack.npy[3]": frame 3 of a file; one-frame files ("frame_7.npy[0]") are numbered by their names
    names = [name[:-3] if name.endswith("[0]") else name for name in labels]
    found = [re.search(r"(\d+)\D*$", Path(name).stem) if "[" not in name else None for name in names]
    positions = np.arange(len(labels), dtype=float)
    if not found or any(m is None for m in found):
        return positions
    numbers = np.array([int(m.group(1)) for m in found], dtype=float)
    steps = np.diff(numbers)
    if (steps <= 0).any() or 2 * (steps == 1).sum() < steps.size:
        return positions  # not a count of frames (a time stamp in ms, a date): the positions, as before
    if (steps > 1).any():
        k = int(np.flatnonzero(steps > 1)[0])
        log.warning("%ss: %d numbers missing in the file names (first after %s); the frame rate counts the "
                    "numbers, so the missing ones leave gaps in the time axis", what,
                    int((steps - 1).sum()), labels[k])
    return numbers - numbers[0]


def log_gaps(what: str, t: np.ndarray, numbers: Sequence[int | None]) -> None:
    """Warn about steps longer than 1.5 median steps in the time axis ``t`` (s) of a series (dropped frames)."""
    if len(t) > 2:
        dt = np.diff(t)
        med = np.median(dt)
        gaps = np.flatnonzero(dt > 1.5 * med)
        if gaps.size:
            log.warning("%s: %d gap(s) in the time axis (dropped frames?), first after t = %.4g s (%.4g s instead of %.4g s)",
                        what, gaps.size, t[gaps[0]], dt[gaps[0]], med)


def as_files(source, what: str) -> list[Path]:
    """The files of one source or of several (see :func:`list_inputs`); DataError when there are none."""
    if isinstance(source, (str, os.PathLike)):
        return list_inputs(source, what=what)
    files: list[Path] = []
    for s in source:
        files.extend(list_inputs(s, what=what))
    if not files:
        raise DataError(f"no {what} given")
    return files
