"""A series of DIC stage exports -> ``dic.zarr``.

DIC stages are read one file at a time and gathered as numbers (10,000
points x 1,000 stages x 3 is 240 MB), because the set of point IDs is only
known once every stage has been read. The time axis comes from the files or
a frame rate (:func:`irdic.ingest.inputs.frame_times`).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Sequence

import numpy as np
import xarray as xr

from .. import io as _io
from ..errors import DataError
from ..logs import Progress
from ..store import write_dataset
from ..vocabulary import COORD_ATTRS, series_attrs
from .inputs import as_files, frame_times, log_gaps
from ..parameters import settings

__all__ = ["ingest_dic", "check_scale"]

log = logging.getLogger(__name__)

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


def ingest_dic(source: str | os.PathLike | Sequence[str | os.PathLike], out: str | os.PathLike, **params) -> Path:
    """Convert a series of DIC stage exports into ``dic.zarr``.

    Parameters
    ----------
    source : path-like or sequence of path-like
        Folder, glob or file(s), one file per stage.
    out : path-like
        The store to write (replaced atomically).
    **params
        ``format`` (DIC format or ``"auto"``, see :func:`irdic.io.read_dic`),
        ``columns`` (column mapping for ``format="table"``),
        ``time_source``, ``frame_rate`` (Hz), ``time_origin``,
        ``time_offset`` (s) as in ``experiments.<name>.dic`` of the
        configuration (see :func:`irdic.ingest.inputs.frame_times`); absent
        ones take the schema's defaults.

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
    p = settings("dic_source", params, drop=("path",))
    fmt, columns = p.pop("format"), p.pop("columns")
    files = as_files(source, "DIC exports")
    log.info("ingest DIC: %d stages", len(files))
    stages = _read_stages(files, fmt, columns)
    ids = np.unique(np.concatenate([s["point"].values for s in stages]))
    x, x_ref, file_times, stage_numbers = _gather_points(stages, ids)
    t = frame_times(file_times, stage_numbers, labels=[f.name for f in files], what="DIC stage", **p)
    signals = _gather_signals(stages, files)
    missing = np.isnan(x[..., 0])
    never = missing.all(axis=0)
    if never.all():
        raise DataError(f"{files[0].parent}: no valid DIC point in any stage")
    check_scale(x, [f.name for f in files])
    log.info("DIC: %d points, %d stages; %.2f %% of (stage, point) entries missing; %d points never valid",
             ids.size, len(stages), 100 * missing.mean(), int(never.sum()))
    data_vars = {
        "x": (("time", "point", "component"), x,
              {"units": "mm", "long_name": "current coordinates of the material points (DIC frame)"}),
        "stage_file": (("time",), np.array([f.name for f in files], dtype=object), {"long_name": "source file of the stage"}),
    }
    if x_ref is not None:
        data_vars["x_ref"] = (("point", "component"), x_ref,
                              {"units": "mm", "long_name": "reference (undeformed) coordinates from the exports"})
    # stage_index, stage_name, n_invalid, ... of the first file would describe the whole store
    attrs = series_attrs("dic", stages[0].attrs)
    coords_extra = {}
    if signals is not None:
        values, coords_extra = signals
        data_vars["signal_value"] = (("time", "signal"), values,
                               {"long_name": "testing machine signal recorded with the DIC stage (unit of each signal: coordinate signal_unit)"})
    ds = xr.Dataset(
        data_vars,
        coords={"time": ("time", t, {"units": "s", "long_name": "time"}),
                "point": ("point", ids, {"long_name": "point ID of the DIC software"}),
                "component": ("component", np.array(["x", "y", "z"]), COORD_ATTRS["component"]), **coords_extra},
        attrs=attrs,
    )
    write_dataset(ds, out, stage="ingest-dic", params=dict(format=fmt, columns=columns or {}, **p),
                  inputs=[str(f) for f in files[:1000]], encoding={"x": {"chunks": (1, ids.size, 3)}})
    log_gaps("DIC", t, stage_numbers)
    return Path(out)


#: Largest ratio of one stage's point-cloud size to the median stage's: a specimen does not grow or shrink
#: 20-fold between two stages, a stage exported in m among stages in mm (1000x) or in inch (25.4x) does
SCALE_RATIO = 20.0


def check_scale(x: np.ndarray, names: Sequence[str]) -> None:
    """Refuse a stage whose point cloud is far larger or smaller than the others (another length unit).

    Parameters
    ----------
    x : ndarray, shape (n_t, n_p, 3)
        Coordinates of every stage, mm, NaN where missing.
    names : sequence of str
        The stages' file names, for the message.

    Raises
    ------
    DataError
        Naming the stage file and the ratio of its size (median distance of
        its points from their median) to the median stage's.
    """
    size = np.full(x.shape[0], np.nan)
    for i, xi in enumerate(x):
        valid = xi[np.isfinite(xi).all(axis=1)]
        if valid.shape[0] >= 3:
            size[i] = np.median(np.linalg.norm(valid - np.median(valid, axis=0), axis=1))
    ok = np.isfinite(size) & (size > 0)
    if ok.sum() < 2:
        return
    ref = float(np.median(size[ok]))
    ratio = np.where(ok, size / ref, 1.0)
    k = int(np.argmax(np.maximum(ratio, 1 / ratio)))
    if max(ratio[k], 1 / ratio[k]) > SCALE_RATIO:
        raise DataError(f"{names[k]}: its point cloud is {ratio[k]:.4g} times the size of the other stages' "
                        f"(median distance from the centre {size[k]:.4g} mm, median stage {ref:.4g} mm); a stage "
                        "in another length unit (m or inch instead of mm)? Export every stage in one unit")


def _read_stages(files: Sequence[Path], fmt: str, columns: dict | None) -> list[xr.Dataset]:
    """Every stage file read (one format for all), its points given stable IDs."""
    kwargs = {"columns": columns} if (fmt == "table" and columns) else {}
    formats = _dic_formats(files) if fmt == "auto" else [fmt] * len(files)
    stages: list[xr.Dataset] = []
    progress = Progress(len(files), "ingest DIC", unit="stages", logger=log)
    for i, (f, ffmt) in enumerate(zip(files, formats)):
        stages.append(_io.read_dic(f, format=ffmt, **kwargs))
        progress.update(i + 1)
    return _match_row_points(stages, files)


def _gather_points(stages: Sequence[xr.Dataset], ids: np.ndarray):
    """Coordinates of all stages on the union of point IDs.

    Returns ``x`` (n_t, n_p, 3) mm (NaN where a stage lacks the point),
    ``x_ref`` (n_p, 3) mm or None when no export carries reference
    coordinates, the stages' file times (s or None) and stage numbers.
    """
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
    return x, (x_ref if have_ref else None), file_times, stage_numbers


def _gather_signals(stages: Sequence[xr.Dataset], files: Sequence[Path]):
    """Per-stage signals -> (values (n_t, n_s), coordinates), or None when no stage has any.

    Signals are identified by name; a stage without a signal gets NaN there.
    A name whose unit or kind differs between stages is a DataError (the
    values would not be comparable).
    """
    from ..io.signals import signal_coords

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
