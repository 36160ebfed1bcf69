"""Writer of ZEISS INSPECT / ARAMIS nodemap text exports (one stage per file), read by :mod:`irdic.io.nodemap`."""

from __future__ import annotations

import os
import re
from datetime import datetime
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ...errors import ConfigError
from ...io.signals import format_signals
from ...io.units import parse_date

__all__ = ["write_nodemap"]

_STRAIN_UNITS = {"epsx": "%", "epsy": "%", "epsxy": "1", "epseqv": "%"}


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
    ids_arr = _checked_ids(ids)
    n = ids_arr.size
    xu = _as_points(x_undef, "x_undef", n)
    d = _as_points(displacement, "displacement", n)
    stage_date = _checked_stage(stage_index, reference_stage_index, decimals, relative_time, stage_name,
                                stage_date)
    strain_cols = _strain_table(strains, n)
    signal_items = _checked_signals(signals)
    head = _header(stage_index, reference_stage_index, stage_name, stage_date, relative_time, rbm_compensation,
                   signal_items)
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


def _checked_ids(ids: Any) -> np.ndarray:
    """Facet IDs as unique int64, shape (n,)."""
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
    return ids_arr


def _checked_stage(stage_index, reference_stage_index, decimals, relative_time, stage_name,
                   stage_date) -> str | None:
    """Check the stage's indices, decimals, time and texts; return ``stage_date`` as ISO 8601 text (or None)."""
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
    return stage_date


def _checked_signals(signals: Any) -> list[tuple[str, str, float]]:
    """``(name, kind, value)`` triples of the ``# SIGNALS:`` section."""
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
    return signal_items


def _block(title: str, items: list[tuple[str, Any]]) -> list[str]:
    return [f"# {title}:"] + [f"# {k.ljust(30)}: {v}" for k, v in items] + ["#" * 100]


def _header(stage_index, reference_stage_index, stage_name, stage_date, relative_time, rbm_compensation,
            signal_items) -> list[str]:
    """Comment blocks above the column names: process, stage, rigid body motion and signals."""
    head: list[str] = []
    head += _block("Process data", [("application_name", "irdic nodemap writer"),
                                    ("export_format", "ARAMIS data exporter text layout")])
    head += _block("stage data", [
        ("current_stage_index", int(stage_index)),
        ("current_stage_name", stage_name if stage_name is not None else f"Stage {int(stage_index)}"),
        ("current_stage_date", stage_date if stage_date is not None else "None"),
        ("current_stage_relative_date", repr(float(relative_time)) if relative_time is not None else "None"),
        ("reference_stage_index", int(reference_stage_index)),
    ])
    head += _block("rigid body motion compensation", [("alignment_is_active", bool(rbm_compensation))]
                   + [(f"alignment_{kind}_{c}", 0.0) for kind in ("rotation", "translation") for c in "xyz"])
    if signal_items:
        head += format_signals(signal_items) + ["#" * 100]
    return head
