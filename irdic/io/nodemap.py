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
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np
import xarray as xr

from ..errors import FormatError, IrdicWarning
from .signals import parse_signals, stage_signals
from ._common import TextFile
from ._stage import extra_columns, stage_dataset
from ._tables import Header, check_unique, read_body, split_fields
from .units import length_scale, parse_date, parse_duration

__all__ = ["read_nodemap", "RBM_WARNING"]

log = logging.getLogger(__name__)

_REQUIRED = ("ID", "x_undef", "y_undef", "z_undef", "u", "v", "w")
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


def _find_header(lines: Iterable[tuple[int, str]], path: Path) -> tuple[int, Header]:
    for k, ln in lines:
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
    text = TextFile(path)
    p = text.path
    k, header = _find_header(text.lines(), p)
    head = text.head(k)
    flat, sections = _metadata(head)
    rows = read_body(text, k + 1, header, sep=";", decimal=None)
    j_id, *j_xyz = header.require(_REQUIRED, what="a nodemap")

    def coord(j: int) -> np.ndarray:
        return rows.number(j) * length_scale(header.units[j], header.names[j], p, header.line)

    ids = rows.integers(j_id, what="facet ID")
    check_unique(ids, rows.line_nos, p, what="facet ID")
    x_ref = np.column_stack([coord(j) for j in j_xyz[:3]])
    x = x_ref + np.column_stack([coord(j) for j in j_xyz[3:]])
    extras = extra_columns(rows, [j_id, *j_xyz], strict=True)

    attrs = _stage_attrs(flat, p)
    time = _stage_time(flat, p)
    rbm = _rbm_active(flat, sections, p)
    attrs["rbm_compensation"] = rbm
    if rbm:
        warnings.warn(f"{p}: {RBM_WARNING}", IrdicWarning, stacklevel=2)
    ds = stage_dataset(ids, x, x_ref, path=p, fmt="nodemap", time=time, attrs=attrs, extras=extras)
    signals = parse_signals(head, p)
    if signals:
        ds = ds.merge(stage_signals(signals))
    return ds


def _stage_attrs(flat: Mapping[str, tuple[str, int]], p: Path) -> dict[str, Any]:
    """``stage_index``, ``reference_stage_index``, ``stage_name`` and ``stage_date`` (or ``stage_date_text``)."""
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
    return attrs


def _stage_time(flat: Mapping[str, tuple[str, int]], p: Path) -> float | None:
    """Stage time (s) from the first time key present; None (with a warning when unreadable) otherwise."""
    time = None
    for key in _TIME_KEYS:
        if key in flat:
            value, line = flat[key]
            if value.strip().lower() in ("none", "nan", ""):
                break
            try:
                time = parse_duration(value)
            except ValueError as exc:
                # stacklevel 3: the warning names the line that called read_nodemap
                warnings.warn(f"{p}, line {line}: {exc}; the stage has no time", IrdicWarning, stacklevel=3)
            break
    return time
