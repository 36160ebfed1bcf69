"""Testing machine signals: the machine's own record and the signals at the DIC times.

Two sources carry the load that goes with the temperature field:

- the DIC exports (nodemap ``# SIGNALS:``), stored by :func:`irdic.ingest.dic.ingest_dic`
  in ``dic.zarr`` as ``signal_value(time, signal)``;
- the testing machine's own time series (CSV of time, force, displacement,
  torque, angle at 10-1000 Hz), read by :func:`read_machine` and stored by
  :func:`ingest_machine` in ``machine.zarr`` with the same layout over the
  machine's time axis.

Representation (every store): ``signal_value(time, signal)`` float64,
coordinate ``signal`` (names), ``signal_kind`` (``value_element``,
``analog_input``, ``machine``), ``signal_unit`` ('' when unknown) and
``signal_standard_name`` (force, displacement, torque, angle, cycles, time or
''). A variable cannot share its name with its dimension in xarray, hence
``signal_value`` rather than ``signal``.

Time convention (as for the IR and DIC series, :func:`irdic.ingest.inputs.frame_times`):
``t = t_file - t_file[0] (time_origin "first") + time_offset``; the machine's
default ``time_origin`` is ``"file"`` because its record usually starts
before the cameras, so ``time_offset`` is the DIC time at the machine
clock's zero: a machine clock that reads 12.3 s at the DIC trigger needs
``time_offset: -12.3``.

:func:`signals_at` puts both sources on the DIC times for ``fields.zarr``:
DIC signals at their own stages (NaN where a stage lacks one), machine
signals by linear interpolation (prefixed ``machine_``), NaN with a warning
outside the machine record's span.
"""

from __future__ import annotations

import logging
import os
import re
import warnings
from pathlib import Path
from typing import Mapping

import numpy as np
import xarray as xr

from .errors import ConfigError, DataError, FormatError, IrdicWarning
from .io.signals import signal_coords, standard_name
from .io._tables import data_lines, detect_decimal, find_named_header, match_column, read_lines, read_rows
from .io.units import split_unit, time_scale
from .store import write_dataset

__all__ = ["read_machine", "ingest_machine", "signals_at", "MACHINE_PREFIX"]

log = logging.getLogger(__name__)

#: prefix of machine signals next to the DIC signals in fields.zarr and the exports
MACHINE_PREFIX = "machine_"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _check_columns(columns) -> dict[str, str]:
    if not isinstance(columns, Mapping):
        raise ConfigError(f"machine.columns must map signal names to column names, got {type(columns).__name__}")
    if "time" not in columns:
        raise ConfigError("machine.columns must name the time column (time: 'Zeit [s]' or similar)")
    if len(columns) < 2:
        raise ConfigError("machine.columns names only the time column; add the signals to read, "
                          "e.g. force: 'Kraft [kN]'")
    for k, v in columns.items():
        if not isinstance(k, str) or not _NAME.match(k):
            raise ConfigError(f"machine.columns: signal name {k!r} must be an identifier such as 'force'")
        if not isinstance(v, str) or not v.strip():
            raise ConfigError(f"machine.columns[{k!r}] must be a non-empty column name (str), got {v!r}")
    return {k: v.strip() for k, v in columns.items()}


def read_machine(path: str | os.PathLike, *, columns: Mapping[str, str], format: str = "csv",
                 sep: str | None = None, decimal: str | None = None, time_origin: str = "file",
                 time_offset: float = 0.0) -> xr.Dataset:
    """Read a testing machine's time series (CSV/TXT with a header row).

    Parameters
    ----------
    path : path-like
        The record: preamble lines, one header row, one row per sample.
    columns : mapping of str to str
        ``{"time": "Zeit [s]", "force": "Kraft [kN]", ...}``: signal names
        (identifiers, they become the ``signal`` coordinate) to column names
        as in the header (unit in brackets optional; case ignored when
        unambiguous). ``time`` is required; its unit (s, ms, min, h) is
        converted to s; other units are recorded as ``signal_unit``.
    format : {"csv"}
    sep : str, optional
        Field separator; sniffed among tab, ``;``, ``,`` and whitespace.
    decimal : {".", ",", None}
        Decimal mark; None detects it (not with a comma separator).
    time_origin : {"file", "first"}
        ``first`` puts time 0 at the first sample.
    time_offset : float
        Seconds added to every time (after ``time_origin``) to put the record
        on the DIC clock.

    Returns
    -------
    xarray.Dataset
        ``signal_value(time, signal)`` float64 (NaN for empty cells), ``time``
        (s, DIC clock), signal coordinates (kind ``"machine"``).

    Raises
    ------
    ConfigError
        Bad ``columns``/``sep``/``decimal``, or a named column missing from
        the file (the message lists the header's columns).
    FormatError
        A cell is not a number, a time is missing, times do not increase
        (file, line and column named), rows of the wrong length.
    DataError
        Fewer than two samples.
    """
    cols = _check_options(format, columns, sep, decimal, time_origin, time_offset)
    p, lines = read_lines(path)
    k, sep_found, header = find_named_header(lines, list(cols.values()), sep, None, p)
    body, nos = data_lines(lines, k + 1)
    dec = decimal if decimal is not None else detect_decimal(body, sep_found)
    if dec == "," and sep_found == ",":
        raise ConfigError(f"{p} is comma-separated, so machine.decimal ',' is impossible; use '.'")
    rows = read_rows(body, nos, header, sep=sep_found, decimal=dec)
    idx = {role: match_column(header, name) for role, name in cols.items()}
    jt = idx["time"]
    t = _machine_times(rows, header, jt, p)
    if time_origin == "first":
        t = t - t[0]
    t = t + float(time_offset)
    names = [r for r in cols if r != "time"]
    values = np.column_stack([rows.number(idx[r]) for r in names])
    units = [header.units[idx[r]] or "" for r in names]
    # the column's own name knows the quantity when the user's key does not (kraft: 'Kraft [kN]')
    std = [standard_name(r) or standard_name(split_unit(header.names[idx[r]])[0]) for r in names]
    log.info("machine record %s: %d samples, %.6g..%.6g s (DIC clock), %s", p, t.size, t[0], t[-1], ", ".join(names))
    return xr.Dataset(
        {"signal_value": (("time", "signal"), values, {"long_name": "testing machine signal (unit of each signal: coordinate signal_unit)"})},
        coords={"time": ("time", t, {"units": "s", "long_name": "time on the DIC clock"}),
                **signal_coords(names, ["machine"] * len(names), units, std)},
        attrs={"source_columns": ", ".join(header.names[idx[r]] for r in names)},
    )


def _check_options(format, columns, sep, decimal, time_origin, time_offset) -> dict[str, str]:
    """Check the ``machine`` options; return the checked ``columns``."""
    if format != "csv":
        raise ConfigError(f"machine.format must be 'csv', got {format!r}")
    cols = _check_columns(columns)
    if sep is not None and (not isinstance(sep, str) or len(sep) != 1 or sep in "\r\n\"'#"):
        raise ConfigError(f"machine.sep must be one character such as ',', ';' or '\\t', got {sep!r}")
    if decimal not in (".", ",", None):
        raise ConfigError(f"machine.decimal must be '.', ',' or null (detect), got {decimal!r}")
    if time_origin not in ("file", "first"):
        raise ConfigError(f"machine.time_origin must be 'file' or 'first', got {time_origin!r}")
    if not np.isfinite(time_offset):
        raise ConfigError(f"machine.time_offset must be a finite number of seconds, got {time_offset!r}")
    return cols


def _machine_times(rows, header, jt: int, p: Path) -> np.ndarray:
    """Sample times (s, file clock) from column ``jt``: at least two, none missing, strictly increasing."""
    t = rows.number(jt) * time_scale(header.units[jt], header.names[jt], p, header.line)
    if len(t) < 2:
        raise DataError(f"{p}: the machine record has {len(t)} sample; expected a time series of at least two")
    gap = np.flatnonzero(~np.isfinite(t))
    if gap.size:
        raise FormatError(f"column {header.names[jt]!r}: missing time; every sample needs a time",
                          p, int(rows.line_nos[gap[0]]))
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0])
        raise FormatError(f"column {header.names[jt]!r}: time {rows.cell(i + 1, jt)!r} does not come after "
                          f"{rows.cell(i, jt)!r} (line {int(rows.line_nos[i])}); machine times must increase",
                          p, int(rows.line_nos[i + 1]))
    return t


def ingest_machine(path: str | os.PathLike, out: str | os.PathLike, *, columns: Mapping[str, str],
                   format: str = "csv", sep: str | None = None, decimal: str | None = None,
                   time_origin: str = "file", time_offset: float = 0.0, ir_times=None) -> Path:
    """Read a testing machine record (:func:`read_machine`) and write ``machine.zarr``.

    Parameters
    ----------
    ir_times : array_like, shape (F,), optional
        The IR frame times (s, ``ir.zarr`` ``time``): the store then also
        holds the signals interpolated onto them, ``signal_value_ir(ir_time,
        signal)``, so that every IR frame has its load. (The signals at the
        DIC times are in ``fields.zarr``, :func:`signals_at`.)

    Returns
    -------
    pathlib.Path
        ``out``.
    """
    params = dict(format=format, columns=dict(columns), sep=sep, decimal=decimal, time_origin=time_origin,
                  time_offset=time_offset)
    ds = read_machine(path, **params)
    if ir_times is not None:
        t = np.asarray(ir_times, dtype=float)
        v = ds["signal_value"].transpose("time", "signal").values.astype(float)
        ds["signal_value_ir"] = (("ir_time", "signal"), _interpolate(ds["time"].values.astype(float), v, t,
                                                                     "IR frame times"),
                                 {"long_name": "machine signal at the IR frame time (linear interpolation; unit of each signal: "
                                  "coordinate signal_unit)"})
        ds = ds.assign_coords(ir_time=("ir_time", t, {"units": "s", "long_name": "IR frame time"}))
    write_dataset(ds, out, stage="ingest-machine", params=params, inputs=[os.fspath(path)])
    return Path(out)


def _interpolate(src_t: np.ndarray, v: np.ndarray, t: np.ndarray, what: str) -> np.ndarray:
    """Machine samples ``v`` (S, n) at times ``src_t`` linearly at ``t``; NaN and a warning outside the record."""
    out = np.full((t.size, v.shape[1]), np.nan)
    for j in range(v.shape[1]):
        ok = np.isfinite(v[:, j])
        if ok.sum() >= 2:
            out[:, j] = np.interp(t, src_t[ok], v[ok, j], left=np.nan, right=np.nan)
    outside = (t < src_t[0]) | (t > src_t[-1])
    if outside.any():
        msg = (f"{int(outside.sum())} of {t.size} {what} ({t[outside][0]:.6g} s first) lie outside the "
               f"machine record's span {src_t[0]:.6g}..{src_t[-1]:.6g} s (DIC clock, after time_offset); "
               "their machine signals are NaN. If the record covers the test, check machine.time_offset "
               "(seconds added to the machine times)")
        log.warning(msg)
        warnings.warn(msg, IrdicWarning, stacklevel=3)
    return out


def _coords_of(ds: xr.Dataset, prefix: str = "") -> tuple[list, list, list, list]:
    def col(name, default=""):
        return [str(v) for v in ds[name].values] if name in ds.coords else [default] * ds.sizes["signal"]

    return ([prefix + n for n in col("signal")], col("signal_kind"), col("signal_unit"), col("signal_standard_name"))


def signals_at(times, *, dic: xr.Dataset | None = None, machine: xr.Dataset | None = None,
               atol: float = 1e-6) -> xr.Dataset | None:
    """DIC and machine signals at ``times`` (s), as one ``signal_value(time, signal)``.

    Parameters
    ----------
    times : array_like, shape (T,)
        The DIC times of the result (``points.zarr``/``fields.zarr``), s.
    dic : xarray.Dataset, optional
        ``dic.zarr``; its signals are taken at the stage whose time matches
        within ``atol`` (NaN where none does, or where the stage lacks the
        signal: DIC signals are never interpolated between stages).
    machine : xarray.Dataset, optional
        ``machine.zarr``; linear interpolation between the finite samples of
        each signal; NaN (and an IrdicWarning) outside the record's span.
        Names get the prefix ``machine_``.
    atol : float
        Tolerance of the time match, s.

    Returns
    -------
    xarray.Dataset or None
        None when neither source has a signal.
    """
    t = np.asarray(times, dtype=float)
    blocks: list[np.ndarray] = []
    meta = ([], [], [], [])
    if dic is not None and "signal_value" in dic:
        src_t = dic["time"].values.astype(float)
        v = dic["signal_value"].transpose("time", "signal").values.astype(float)
        out = np.full((t.size, v.shape[1]), np.nan)
        j = np.clip(np.searchsorted(src_t, t), 0, src_t.size - 1)
        for cand in (j, np.clip(j - 1, 0, src_t.size - 1)):
            hit = np.abs(src_t[cand] - t) <= atol
            out[hit] = v[cand[hit]]
        blocks.append(out)
        for m, c in zip(meta, _coords_of(dic)):
            m.extend(c)
    if machine is not None and "signal_value" in machine:
        v = machine["signal_value"].transpose("time", "signal").values.astype(float)
        blocks.append(_interpolate(machine["time"].values.astype(float), v, t, "DIC times"))
        for m, c in zip(meta, _coords_of(machine, MACHINE_PREFIX)):
            m.extend(c)
    if not blocks:
        return None
    names = meta[0]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise DataError(f"signal name(s) {', '.join(map(repr, dup))} occur in both the DIC exports and the machine "
                        "record after prefixing; rename the machine.columns keys")
    return xr.Dataset(
        {"signal_value": (("time", "signal"), np.concatenate(blocks, axis=1),
                          {"long_name": "testing machine signal at the DIC time (DIC export or machine record; unit of each signal: coordinate signal_unit)"})},
        coords={"time": ("time", t, {"units": "s"}), **signal_coords(*meta)},
    )
