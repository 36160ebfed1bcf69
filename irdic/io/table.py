"""Generic delimited tables of DIC points: :func:`read_table`.

Reads any CSV/TXT export whose columns the user names
(``columns={"x": "X [mm]", ...}``), with the shared machinery of
:mod:`irdic.io._tables` (the same structure and messages as the format
readers).
"""

from __future__ import annotations

import csv
import json
import os
from typing import Any, Mapping

import numpy as np
import pandas as pd
import xarray as xr

from ..errors import ConfigError, DataError, FormatError
from ._common import TextFile
from ._stage import extra_columns, stage_dataset
from ._tables import check_unique, find_named_header, match_column, read_body
from .units import length_scale, parse_duration, time_scale

__all__ = ["read_table"]


_ROLES = ("x", "y", "z", "u", "v", "w", "id", "valid", "time")


def _check_columns(columns: Any) -> dict[str, str]:
    if not isinstance(columns, Mapping):
        raise ConfigError(f"columns must be a mapping of roles to column names, got {type(columns).__name__}")
    unknown = [k for k in columns if k not in _ROLES]
    if unknown:
        raise ConfigError(f"columns has unknown role(s) {', '.join(map(repr, unknown))}; "
                          f"expected roles among {', '.join(_ROLES)}")
    missing = [k for k in ("x", "y", "z") if k not in columns]
    if missing:
        raise ConfigError(f"columns must map the roles 'x', 'y', 'z'; missing {', '.join(map(repr, missing))}")
    disp = [k for k in ("u", "v", "w") if k in columns]
    if disp and len(disp) != 3:
        raise ConfigError(f"columns maps {', '.join(map(repr, disp))} but not all of 'u', 'v', 'w'; "
                          "give all three displacement columns or none")
    for k, v in columns.items():
        if not isinstance(v, str) or not v.strip():
            raise ConfigError(f"columns[{k!r}] must be a non-empty column name (str), got {v!r}")
    return {k: v.strip() for k, v in columns.items()}


def read_table(path: str | os.PathLike, *, columns: Mapping[str, str], sep: str | None = None,
               decimal: str | None = ".", header_line: int | None = None, time: float | str | None = None,
               invalid_value: float = -1.0) -> xr.Dataset:
    """Read one DIC stage from a generic CSV/TXT table.

    Parameters
    ----------
    path : path-like
        The table: one header row (preamble lines before it are skipped),
        then one row per point.
    columns : mapping
        Roles to column names as written in the header (the unit in brackets
        may be left out, case is ignored when unambiguous). Required ``"x"``,
        ``"y"``, ``"z"``: the current coordinates; or, together with ``"u"``,
        ``"v"``, ``"w"``, the reference coordinates and the displacement
        (current = reference + displacement). Optional ``"id"`` (integer point
        IDs; else the row index is used), ``"valid"`` (a column whose value
        ``invalid_value`` or NaN marks a failed point, or a boolean column) and
        ``"time"`` (stage time, constant within the file).
        Coordinates with a length unit in brackets (``[m]``) are converted to mm.
    sep : str, optional
        Field separator; sniffed among tab, ``;``, ``,`` and whitespace when None.
    decimal : {".", ",", None}
        Decimal mark; None detects it (only when the separator is not a comma).
    header_line : int, optional
        1-based line number of the header row; found automatically when None
        (the first line containing all mapped names).
    time : float or str, optional
        Stage time (s, or text like ``"1.5 s"``, ``"0:00:01.5"``) when the file
        has no time column.
    invalid_value : float
        Value of the ``"valid"`` column that marks a failed point (VIC and
        DICe: -1; MatchID: 0).

    Returns
    -------
    xarray.Dataset
        ``x(point, component)`` in mm (NaN rows for invalid points),
        ``x_ref`` when displacements are given, unmapped numeric columns as
        ``(point)`` variables, scalar coordinate ``time`` when known.

    Raises
    ------
    ConfigError
        Bad ``columns``/``sep``/``decimal``/``header_line``/``time``, or a
        mapped column that the file does not have.
    FormatError, DataError
        Problems in the file (named by line and column).
    """
    cols = _check_columns(columns)
    sep, t_param = _check_options(cols, sep, decimal, time, invalid_value)
    text = TextFile(path)
    p = text.path
    k, sep_found, header = find_named_header(_head(text, header_line), list(cols.values()), sep, header_line, p)
    if decimal == "," and sep_found == ",":
        raise ConfigError(f"{p} is comma-separated, so decimal ',' is impossible; use decimal='.'")
    rows = read_body(text, k + 1, header, sep=sep_found, decimal=decimal, quoting=csv.QUOTE_MINIMAL)
    idx = {role: match_column(header, name) for role, name in cols.items()}
    x, x_ref = _positions(rows, header, idx, p)
    if "id" in cols:
        ids = rows.integers(idx["id"])
        check_unique(ids, rows.line_nos, p)
    else:
        ids = np.arange(len(rows), dtype=np.int64)
    valid = _valid(rows, idx["valid"], invalid_value) if "valid" in cols else None
    t = _stage_time(rows, header, idx["time"], p) if "time" in cols else t_param
    extras = extra_columns(rows, {j for j in idx.values() if j is not None}, strict=False)
    attrs = {"columns": json.dumps(cols), "separator": "whitespace" if sep_found is None else sep_found,
             "decimal": rows.decimal, "header_line": header.line}
    return stage_dataset(ids, x, x_ref, path=p, fmt="table", valid=valid, time=t, attrs=attrs,
                         extras=extras, point_id_source="file" if "id" in cols else "row")


def _check_options(cols: dict[str, str], sep, decimal, time, invalid_value) -> tuple[str | None, float | None]:
    """Check the reading options; return the separator (None: sniff or any whitespace) and the stage time (s)."""
    if sep is not None and (not isinstance(sep, str) or len(sep) != 1 or sep in "\r\n\"'#"):
        raise ConfigError(f"sep must be one character such as ',', ';' or '\\t' (or None to sniff), got {sep!r}")
    if sep is not None and not sep.strip():
        sep = None  # any run of whitespace
    if decimal not in (".", ",", None):
        raise ConfigError(f"decimal must be '.', ',' or None (detect), got {decimal!r}")
    if decimal == "," and sep == ",":
        raise ConfigError("decimal ',' needs a separator other than ','")
    t_param = None
    if time is not None:
        if "time" in cols:
            raise ConfigError("give the stage time either as time= or as columns['time'], not both")
        try:
            t_param = float(time) if isinstance(time, (int, float, np.number)) and not isinstance(time, bool) \
                else parse_duration(str(time))
        except ValueError as exc:
            raise ConfigError(f"time: {exc}") from None
        if not np.isfinite(t_param):
            raise ConfigError(f"time must be finite, got {time!r}")
    if not np.isfinite(invalid_value):
        raise ConfigError(f"invalid_value must be a finite number, got {invalid_value!r}")
    return sep, t_param


def _head(text: TextFile, header_line) -> list[str]:
    """The lines searched for the header: the first 1000, or up to ``header_line``."""
    # an invalid header_line is reported with the file's line count, so then all lines are read
    # (an error path only)
    limit: int | None = 1000
    if header_line is not None:
        valid_line = isinstance(header_line, (int, np.integer)) and not isinstance(header_line, bool) \
            and header_line >= 1
        limit = max(1000, int(header_line)) if valid_line else None
    return text.head(limit) if limit is not None else [ln for _k, ln in text.lines()]


def _positions(rows, header, idx: dict, p) -> tuple[np.ndarray, np.ndarray | None]:
    """Current positions ``x`` and, with displacement columns, reference positions ``x_ref`` (mm, (N, 3))."""

    def coord(role: str) -> np.ndarray:
        j = idx[role]
        return rows.number(j) * length_scale(header.units[j], header.names[j], p, header.line)

    first = np.column_stack([coord(r) for r in ("x", "y", "z")])
    if "u" not in idx:
        return first, None
    return first + np.column_stack([coord(r) for r in ("u", "v", "w")]), first


def _valid(rows, j: int, invalid_value: float) -> np.ndarray:
    """Validity of each point from column ``j``: a boolean column, or not NaN and not ``invalid_value``."""
    col = rows.frame.iloc[:, j]
    if pd.api.types.is_bool_dtype(col.dtype):
        return col.to_numpy(dtype=bool)
    v = rows.number(j, finite=False)
    return np.isfinite(v) & (v != invalid_value)


def _stage_time(rows, header, j: int, p) -> float | None:
    """The stage time (s) from time column ``j``, which must be constant; None when it is all empty."""
    tv = rows.number(j) * time_scale(header.units[j], header.names[j], p, header.line)
    tv = tv[np.isfinite(tv)]
    if not tv.size:
        return None
    if np.ptp(tv) > 1e-9 * max(1.0, float(np.abs(tv).max())):
        raise DataError(f"{p}: time column {header.names[j]!r} varies within the file "
                        f"({tv.min():g} to {tv.max():g} s); expected one stage per file")
    return float(tv[0])
