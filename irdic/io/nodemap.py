"""ZEISS INSPECT / ARAMIS "nodemap" text exports: one file per stage.

Layout (written by the public ARAMIS data exporter that runs inside the ZEISS
/ GOM software)::

    # Process data:
    # application_name              : ZEISS INSPECT Correlate
    ####################################################################################################
    # stage data:
    # current_stage_index           : 3
    # current_stage_name            : Stage 3
    # current_stage_date            : 2021-04-13T12:38:34.500000
    # current_stage_relative_date   : 1.5
    # reference_stage_index         : 0
    ####################################################################################################
    # rigid body motion compensation:
    # alignment_is_active           : False
    # alignment_rotation_x          : 0.0
    ...
    #        ID;         x_undef [mm];         y_undef [mm]; ...;              w [mm];   epsx [%]; ...
             1;        -12.3456789012;          4.5678901234; ...

Current position = undeformed coordinates + displacement. Failed facets are
``nan``; facets missing in a stage are simply absent. File names end in
``_<reference stage>_<stage>.txt``.
"""

from __future__ import annotations

import logging
import os
import re
import warnings
from datetime import datetime
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import xarray as xr

from ..errors import ConfigError, FormatError, IrdicWarning
from .signals import format_signals, parse_signals, stage_signals
from .table import (Header, check_unique, data_lines, detect_decimal, extra_columns, length_scale,
                    parse_date, parse_duration, read_lines, read_rows, split_fields, stage_dataset)

__all__ = ["read_nodemap", "write_nodemap", "RBM_WARNING"]

log = logging.getLogger(__name__)

_REQUIRED = ("ID", "x_undef", "y_undef", "z_undef", "u", "v", "w")
_STRAIN_UNITS = {"epsx": "%", "epsy": "%", "epsxy": "1", "epseqv": "%"}
_TIME_KEYS = ("current_stage_relative_date", "current_stage_relative_time", "stage_relative_time",
              "relative_time")
_TRUE = {"true", "yes", "1", "on", "active", "activated", "aktiv", "ja", "wahr"}
_FALSE = {"false", "no", "0", "off", "inactive", "deactivated", "inaktiv", "nein", "falsch", "none"}
_STAGE_IN_NAME = re.compile(r"_(\d+)_(\d+)$")

RBM_WARNING = (
    "rigid body motion compensation was active in this export: its coordinates are not in the "
    "sensor's fixed frame in which the calibration markers were measured, so the projection into the "
    "IR image will be wrong; redo the export with rigid body motion compensation deactivated"
)


def _metadata(lines: list[str]) -> tuple[dict[str, tuple[str, int]], dict[str, dict[str, tuple[str, int]]]]:
    """``# key : value`` lines -> (flat {key: (value, line)}, {section: {key: (value, line)}}).

    Keys are lower-case; the first occurrence of a key wins in the flat view.
    A line ``# Title:`` (nothing after the colon) or ``# Title`` starts a section.
    """
    flat: dict[str, tuple[str, int]] = {}
    sections: dict[str, dict[str, tuple[str, int]]] = {}
    section = ""
    for k, ln in enumerate(lines):
        s = ln.strip()
        if not s.startswith("#"):
            continue
        s = s.lstrip("#").strip()
        if not s or set(s) <= set("#-=*_ "):
            continue
        key, colon, value = s.partition(":")
        key, value = key.strip().lower(), value.strip()
        if not colon or not value:
            section = key.rstrip(":").strip()
            sections.setdefault(section, {})
            continue
        if section != "signals":
            # signal names are free text (a signal called "time" is no stage time)
            flat.setdefault(key, (value, k + 1))
        sections.setdefault(section, {}).setdefault(key, (value, k + 1))
    return flat, sections


def _parse_bool(text: str) -> bool | None:
    t = text.strip().lower()
    return True if t in _TRUE else False if t in _FALSE else None


def _rbm_active(flat: Mapping[str, tuple[str, int]], sections: Mapping[str, Mapping[str, tuple[str, int]]],
                path: Path) -> bool:
    """Whether rigid body motion compensation is recorded as active.

    Newer exporters write an explicit flag (``alignment_is_active``); older ones
    always activated the compensation and only wrote its transformation, so a
    non-identity transformation without a flag counts as active.
    """
    rbm = {}
    for title, items in sections.items():
        if "rigid" in title or "rbmc" in title or "motion compensation" in title:
            rbm.update(items)
    for key, item in flat.items():
        if "rigid_body" in key or "rbmc" in key or key.endswith("_is_active") and key.startswith("alignment"):
            rbm.setdefault(key, item)
    if not rbm:
        return False
    for key, (value, _line) in rbm.items():
        if "active" in key or "rigid_body" in key or key in ("rbmc", "status", "state"):
            flag = _parse_bool(value)
            if flag is None:
                log.warning("%s: cannot read %r = %r as true/false; assuming rigid body motion compensation",
                            path, key, value)
                return True
            return flag
    moves = [v for key, (v, _l) in rbm.items() if "rotation" in key or "translation" in key]
    for v in moves:
        try:
            if float(v.replace(",", ".")) != 0.0:
                return True
        except ValueError:
            return True  # unreadable transformation: be safe, assume compensation
    return False


def _stage_int(flat: Mapping[str, tuple[str, int]], key: str, path: Path) -> int | None:
    item = flat.get(key)
    if item is None or item[0].strip().lower() in ("none", "nan", ""):
        return None
    value, line = item
    try:
        f = float(value.replace(",", "."))
        if f != round(f) or abs(f) > 2**31:
            raise ValueError
        return int(f)
    except ValueError:
        raise FormatError(f"{key} must be an integer stage index, found {value!r}", path, line) from None


def _find_header(lines: list[str], path: Path) -> tuple[int, Header]:
    for k, ln in enumerate(lines):
        s = ln.strip()
        if ";" not in s:
            continue
        fields = split_fields(s.lstrip("#"), ";")
        low = {f.lower() for f in fields}
        if "id" in low and any(f.startswith("x_undef") for f in low):
            return k, Header.from_fields(fields, k + 1, path)
    raise FormatError(
        "no column header found; expected a line like "
        "'#  ID; x_undef [mm]; y_undef [mm]; z_undef [mm]; u [mm]; v [mm]; w [mm]' before the data rows",
        path,
    )


def read_nodemap(path: str | os.PathLike) -> xr.Dataset:
    """Read one stage of a ZEISS INSPECT / ARAMIS nodemap text export.

    Parameters
    ----------
    path : path-like
        ``<name>_<reference stage>_<stage>.txt``.

    Returns
    -------
    xarray.Dataset
        ``x(point, component)``: current coordinates (undeformed +
        displacement), mm; ``x_ref``: undeformed coordinates, mm; both NaN
        for failed facets. Coordinate ``point`` = facet IDs. Scalar coordinate
        ``time`` (s) from ``current_stage_relative_date`` when present. Strain
        and other columns as ``(point)`` variables with their units. attrs:
        ``format="nodemap"``, ``source``, ``stage_index``,
        ``reference_stage_index``, ``stage_name``, ``stage_date`` (ISO) when
        present, ``rbm_compensation``. When the header has a ``# SIGNALS:``
        section: ``signal_value(signal)`` values with coordinates ``signal`` (names
        as written), ``signal_kind``, ``signal_unit``,
        ``signal_standard_name`` (see :mod:`irdic.io.signals`).

    Warns
    -----
    IrdicWarning
        Rigid body motion compensation is recorded as active (the coordinates
        are then not in the frame of the camera calibration), or the stage
        time cannot be read.

    Raises
    ------
    FormatError
        No column header, missing columns, bad cells (named by line and
        column), rows of the wrong length, no data rows.
    DataError
        A facet ID occurs twice.
    """
    p, lines = read_lines(path)
    k, header = _find_header(lines, p)
    flat, sections = _metadata(lines[:k])
    body, nos = data_lines(lines, k + 1)
    rows = read_rows(body, nos, header, sep=";", decimal=detect_decimal(body, ";"))
    j_id, *j_xyz = header.require(_REQUIRED, what="a nodemap")

    def coord(j: int) -> np.ndarray:
        return rows.number(j) * length_scale(header.units[j], header.names[j], p, header.line)

    ids = rows.integers(j_id, what="facet ID")
    check_unique(ids, rows.line_nos, p, what="facet ID")
    x_ref = np.column_stack([coord(j) for j in j_xyz[:3]])
    x = x_ref + np.column_stack([coord(j) for j in j_xyz[3:]])
    extras = extra_columns(rows, [j_id, *j_xyz], strict=True)

    attrs: dict[str, Any] = {}
    stage = _stage_int(flat, "current_stage_index", p)
    ref = _stage_int(flat, "reference_stage_index", p)
    m = _STAGE_IN_NAME.search(p.stem)
    if m and (stage is None or ref is None):
        # older exports without a stage block: the file name carries both indices
        ref = int(m.group(1)) if ref is None else ref
        stage = int(m.group(2)) if stage is None else stage
    if stage is not None:
        attrs["stage_index"] = stage
    if ref is not None:
        attrs["reference_stage_index"] = ref
    name = flat.get("current_stage_name")
    if name and name[0].lower() != "none":
        attrs["stage_name"] = name[0]
    for key in ("current_stage_date_ms", "current_stage_date"):
        if key in flat and flat[key][0].lower() not in ("none", "nan"):
            try:
                attrs["stage_date"] = parse_date(flat[key][0])
                break
            except ValueError:
                attrs["stage_date_text"] = flat[key][0]
                log.info("%s, line %d: stage date %r kept as text", p, flat[key][1], flat[key][0])
    time = None
    for key in _TIME_KEYS:
        if key in flat:
            value, line = flat[key]
            if value.strip().lower() in ("none", "nan", ""):
                break
            try:
                time = parse_duration(value)
            except ValueError as exc:
                warnings.warn(f"{p}, line {line}: {exc}; the stage has no time", IrdicWarning, stacklevel=2)
            break
    rbm = _rbm_active(flat, sections, p)
    attrs["rbm_compensation"] = rbm
    if rbm:
        warnings.warn(f"{p}: {RBM_WARNING}", IrdicWarning, stacklevel=2)
    ds = stage_dataset(ids, x, x_ref, path=p, fmt="nodemap", time=time, attrs=attrs, extras=extras)
    signals = parse_signals(lines[:k], p)
    if signals:
        ds = ds.merge(stage_signals(signals))
    return ds


# --------------------------------------------------------------------------- writer


def _as_points(a: Any, name: str, n: int | None) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3 or (n is not None and arr.shape[0] != n):
        want = f"({n}, 3)" if n is not None else "(n, 3)"
        raise ConfigError(f"{name} must have shape {want}, got {arr.shape}")
    if np.isinf(arr).any():
        raise ConfigError(f"{name} holds infinite values; use NaN for failed points")
    return arr


def _strain_table(strains: Any, n: int) -> list[tuple[str, str, np.ndarray]]:
    if strains is None:
        return []
    if isinstance(strains, Mapping):
        items = list(strains.items())
    else:
        arr = np.asarray(strains, dtype=np.float64)
        if arr.ndim != 2 or arr.shape != (n, 4):
            raise ConfigError(f"strains must be a mapping of column name to ({n},) array or an array of shape "
                              f"({n}, 4) (epsx, epsy, epsxy, epseqv), got shape {arr.shape}")
        items = list(zip(_STRAIN_UNITS, arr.T))
    out = []
    for key, values in items:
        if not isinstance(key, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", key):
            raise ConfigError(f"strains: column name {key!r} must be an identifier such as 'epsx'")
        v = np.asarray(values, dtype=np.float64)
        if v.shape != (n,):
            raise ConfigError(f"strains[{key!r}] must have shape ({n},), got {v.shape}")
        out.append((key, _STRAIN_UNITS.get(key, "1"), v))
    return out


def write_nodemap(path: str | os.PathLike, ids: Any, x_undef: Any, displacement: Any, *, stage_index: int,
                  relative_time: float | None = None, reference_stage_index: int = 0,
                  stage_name: str | None = None, stage_date: datetime | str | None = None,
                  rbm_compensation: bool = False, strains: Any = None, decimals: int = 4,
                  signals: Any = None) -> Path:
    """Write one stage in the ZEISS INSPECT / ARAMIS nodemap text layout.

    Parameters
    ----------
    path : path-like
        Output file; the ``<name>_<ref>_<stage>.txt`` naming is the caller's.
    ids : array_like of int, shape (n,)
        Facet IDs, unique. Facets absent from this stage are simply not passed.
    x_undef : array_like, shape (n, 3)
        Undeformed coordinates, mm.
    displacement : array_like, shape (n, 3)
        Displacement, mm; NaN rows are failed facets (written as ``nan``).
    stage_index, reference_stage_index : int
        0-based stage indices (``current_stage_index``, ``reference_stage_index``).
    relative_time : float, optional
        Time since the first stage, s (``current_stage_relative_date``).
    stage_name : str, optional
    stage_date : datetime or str, optional
        Absolute time stamp (written ISO 8601).
    rbm_compensation : bool
        Recorded as ``alignment_is_active`` in the rigid body motion block.
    strains : mapping or array_like, optional
        ``{"epsx": (n,), ...}`` (units: % for epsx, epsy, epseqv; 1 otherwise)
        or an ``(n, 4)`` array of epsx, epsy, epsxy, epseqv.
    decimals : int
        Decimals of coordinates and displacements (mm); the round trip
        through :func:`read_nodemap` is exact to ``0.5 * 10**-decimals``.
    signals : sequence of (name, kind, value), optional
        The ``# SIGNALS:`` section, e.g. ``("force [N]", "value_element",
        1500.0)``; values are written with ``repr`` (exact round trip).

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ConfigError
        An argument has the wrong shape, type or value.
    """
    ids_arr = np.asarray(ids)
    if ids_arr.ndim != 1 or ids_arr.size == 0:
        raise ConfigError(f"ids must be a non-empty 1-D array of integers, got shape {ids_arr.shape}")
    if not np.issubdtype(ids_arr.dtype, np.integer):
        f = np.asarray(ids_arr, dtype=np.float64)
        if not np.all(np.isfinite(f) & (f == np.round(f))):
            raise ConfigError("ids must be integers")
        ids_arr = f.astype(np.int64)
    ids_arr = ids_arr.astype(np.int64)
    if np.unique(ids_arr).size != ids_arr.size:
        raise ConfigError("ids must be unique")
    n = ids_arr.size
    xu = _as_points(x_undef, "x_undef", n)
    d = _as_points(displacement, "displacement", n)
    for name, value in (("stage_index", stage_index), ("reference_stage_index", reference_stage_index)):
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 0:
            raise ConfigError(f"{name} must be a non-negative integer, got {value!r}")
    if not isinstance(decimals, (int, np.integer)) or isinstance(decimals, bool) or not 0 <= decimals <= 15:
        raise ConfigError(f"decimals must be an integer from 0 to 15, got {decimals!r}")
    if relative_time is not None and not np.isfinite(relative_time):
        raise ConfigError(f"relative_time must be finite seconds or None, got {relative_time!r}")
    if isinstance(stage_date, datetime):
        stage_date = stage_date.isoformat()
    elif stage_date is not None:
        try:
            stage_date = parse_date(str(stage_date))
        except ValueError as exc:
            raise ConfigError(f"stage_date: {exc}") from None
    for name, text in (("stage_name", stage_name), ("stage_date", stage_date)):
        if text is not None and ("\n" in str(text) or "\r" in str(text)):
            raise ConfigError(f"{name} must be one line of text")
    strain_cols = _strain_table(strains, n)
    signal_items = []
    for item in signals or ():
        try:
            name, kind, value = item
            value = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"signals must be (name, kind, value) triples with a numeric value, got {item!r}") from None
        if not str(name).strip() or any(c in f"{name}{kind}" for c in ":\n\r"):
            raise ConfigError(f"signal name and kind must be one line of text without ':', got {name!r}, {kind!r}")
        signal_items.append((str(name), str(kind), value))

    def block(title: str, items: list[tuple[str, Any]]) -> list[str]:
        return [f"# {title}:"] + [f"# {k.ljust(30)}: {v}" for k, v in items] + ["#" * 100]

    head: list[str] = []
    head += block("Process data", [("application_name", "irdic nodemap writer"),
                                   ("export_format", "ARAMIS data exporter text layout")])
    head += block("stage data", [
        ("current_stage_index", int(stage_index)),
        ("current_stage_name", stage_name if stage_name is not None else f"Stage {int(stage_index)}"),
        ("current_stage_date", stage_date if stage_date is not None else "None"),
        ("current_stage_relative_date", repr(float(relative_time)) if relative_time is not None else "None"),
        ("reference_stage_index", int(reference_stage_index)),
    ])
    head += block("rigid body motion compensation", [("alignment_is_active", bool(rbm_compensation))]
                  + [(f"alignment_{kind}_{c}", 0.0) for kind in ("rotation", "translation") for c in "xyz"])
    if signal_items:
        head += format_signals(signal_items) + ["#" * 100]
    names = ["ID", "x_undef [mm]", "y_undef [mm]", "z_undef [mm]", "u [mm]", "v [mm]", "w [mm]"]
    names += [f"{key} [{unit}]" for key, unit, _ in strain_cols]
    head.append("#" + "; ".join([f"{names[0]:>10}"] + [f"{c:>20}" for c in names[1:]]))
    fmt = "%10d; " + "; ".join([f"%20.{decimals}f"] * 6 + ["%20.10f"] * len(strain_cols))
    cols = [xu, d] + [v[:, None] for _, _, v in strain_cols]
    values = np.column_stack(cols).tolist()
    body = [fmt % (i, *row) for i, row in zip(ids_arr.tolist(), values)]
    out = Path(path)
    out.write_text("\n".join(head + body) + "\n", encoding="utf-8", newline="\n")
    return out
