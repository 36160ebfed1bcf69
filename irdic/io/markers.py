"""Marker-centre exports of the DIC software: the calibration target's marker centres as the DIC system measured them.

(Detection of the markers in the IR image is a different matter, in the calibration code.)

Accepted layouts:

- the ``;`` style of the nodemap export (comments start with ``#``; the
  header may itself be a comment)::

      # Calibration target, 84 markers
      #        ID;             x [mm];             y [mm];             z [mm]
               1;          -40.123456;           12.345678;            0.000000

- CSV/TXT with a header naming the ID and x, y, z columns (case ignored,
  units in brackets allowed, other columns ignored); the ID column may be
  called ``id``, ``marker``, ``marker_id``, ``point``, ``point_id``, ``nr`` or
  ``no``;
- four numeric columns ``ID x y z`` without a header.

IDs are integers: they link each marker to its detection in the IR image.
"""

from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

from ..errors import DataError, FormatError, IrdicWarning
from . import COMPONENTS
from ._common import TextFile
from ._tables import Header, check_unique, data_lines, read_body, split_fields
from .units import length_scale

__all__ = ["read_markers"]

log = logging.getLogger(__name__)

_ID_NAMES = ("id", "marker", "marker_id", "markerid", "marker id", "marker no", "point", "point_id",
             "point id", "pointid", "nr", "no", "no.", "number")
_SEPS: tuple[str | None, ...] = (";", "\t", ",", None)


def _header_columns(header: Header) -> list[int] | None:
    """Indices of (ID, x, y, z) in a candidate header, or None."""
    low = [b.lower() for b in header.bare]
    j_id = next((j for j, b in enumerate(low) if b in _ID_NAMES), None)
    if j_id is None:
        return None
    idx = [j_id]
    for c in COMPONENTS:
        hits = [j for j, b in enumerate(low) if b == c]
        if len(hits) != 1:
            return None
        idx.append(hits[0])
    return idx


def _find_header(lines: list[str], path: Path) -> tuple[int, str | None, Header, list[int]] | None:
    for k, ln in enumerate(lines):
        s = ln.strip().lstrip("#").strip()
        if not s:
            continue
        for sep in _SEPS:
            if sep is not None and sep not in s:
                continue
            header = Header.from_fields(split_fields(s, sep), k + 1, path)
            idx = _header_columns(header)
            if idx is not None:
                return k, sep, header, idx
    return None


def _headerless_sep(line: str) -> str | None:
    for sep in (";", "\t"):
        if sep in line:
            return sep
    if line.count(",") == 3:
        return ","
    return None


def read_markers(path: str | os.PathLike) -> xr.Dataset:
    """Read the marker centres of a calibration target (ID, x, y, z in mm).

    Parameters
    ----------
    path : path-like
        See the module docstring for the accepted layouts. Decimal commas are
        detected when the separator is not a comma.

    Returns
    -------
    xarray.Dataset
        ``x(marker, component)`` float64 in mm; coordinate ``marker`` (int64
        IDs, file order), ``component = ["x", "y", "z"]``. attrs: ``format``,
        ``source``, ``n_markers``, ``dropped_markers`` (IDs without
        coordinates).

    Warns
    -----
    IrdicWarning
        Markers with NaN coordinates (not seen by the DIC system) are dropped.

    Raises
    ------
    FormatError
        No usable header and not four columns, non-integer IDs, bad cells
        (named by line and column), rows of the wrong length, no rows.
    DataError
        A marker ID occurs twice, or no marker has coordinates.
    """
    text = TextFile(path)
    p = text.path
    start, sep, header, idx = _layout(text, p)
    rows = read_body(text, start, header, sep=sep, decimal=None)
    j_id, *j_xyz = idx
    _check_integer_ids(rows, j_id, header, p)
    ids = rows.integers(j_id, what="marker ID")
    check_unique(ids, rows.line_nos, p, what="marker ID")
    x = np.column_stack([rows.number(j) * length_scale(header.units[j], header.names[j], p, header.line or None)
                         for j in j_xyz])
    seen = np.isfinite(x).all(axis=1)
    dropped = ids[~seen]
    if dropped.size:
        warnings.warn(
            f"{p}: {dropped.size} marker(s) without coordinates dropped (not seen by the DIC system): "
            f"IDs {', '.join(map(str, dropped.tolist()))}", IrdicWarning, stacklevel=2)
    if not seen.any():
        raise DataError(f"{p}: none of the {ids.size} markers has coordinates (all NaN)")
    ds = xr.Dataset(
        {"x": (("marker", "component"), x[seen], {"units": "mm", "long_name": "marker centre"})},
        coords={"marker": ("marker", ids[seen], {"long_name": "marker ID"}),
                "component": ("component", np.array(COMPONENTS, dtype=object))},
    )
    ds.attrs = {"format": "markers", "source": os.fspath(p), "n_markers": int(seen.sum()),
                "dropped_markers": dropped.tolist()}
    log.info("%s: %d markers read, %d dropped", p, int(seen.sum()), dropped.size)
    return ds


def _layout(text: TextFile, p: Path) -> tuple[int, str | None, Header, list[int]]:
    """First data line (0-based), separator, header and the columns of ID, x, y, z.

    A file without a usable header must have four columns ID x y z.
    """
    found = _find_header(text.head(1000), p)
    if found is not None:
        k, sep, header, idx = found
        start = k + 1
    else:
        start = 0
        first = next(((k, ln) for k, ln in text.lines() if data_lines([ln], 0)[0]), None)
        if first is None:
            raise FormatError("no data rows; expected lines 'ID; x; y; z' (mm)", p)
        sep = _headerless_sep(first[1])
        fields = split_fields(first[1], sep)
        if len(fields) != 4:
            raise FormatError(
                f"found no header naming the columns ID, x, y, z and {len(fields)} fields in the first data row; "
                "expected a header such as '# ID; x [mm]; y [mm]; z [mm]' or four columns ID x y z",
                p, first[0] + 1)
        header = Header.from_fields(["ID", "x", "y", "z"], 0, p)
        idx = [0, 1, 2, 3]
    return start, sep, header, idx


def _check_integer_ids(rows, j_id: int, header: Header, p: Path) -> None:
    """Refuse marker IDs that are not integers (``"P12"``), naming the first one and its line."""
    col = rows.frame.iloc[:, j_id]
    if not rows.is_numeric(j_id):
        # say clearly that names such as "P12" are not accepted, instead of "not a number"
        cells = col.astype(str).str.strip()
        ok = cells.str.fullmatch(r"[+-]?\d+(\.0*)?").to_numpy(dtype=bool) | col.isna().to_numpy()
        bad = np.flatnonzero(~ok)
        if bad.size:
            i = int(bad[0])
            raise FormatError(
                f"marker ID {rows.cell(i, j_id)!r} in column {header.names[j_id]!r} is not an integer; irdic links "
                "markers to their IR detections by integer IDs: number the markers (e.g. 12 instead of 'P12')",
                p, int(rows.line_nos[i]))
