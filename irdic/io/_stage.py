"""The stage Dataset in the common layout of all DIC readers (package-private to :mod:`irdic.io`)."""

from __future__ import annotations

import logging
import os
import re
import warnings
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import xarray as xr

from ..errors import IrdicWarning
from . import COMPONENTS
from ._tables import Rows

log = logging.getLogger(__name__)

# Names the stage Dataset uses itself; extra columns with these names are renamed.
RESERVED = frozenset({"x", "x_ref", "point", "component", "time", "marker"})



def extra_name(name: str, taken: set[str], suffix: str = "_col") -> str:
    """A Dataset variable name for an extra column (identifier-safe, not clashing)."""
    base = re.sub(r"\W+", "_", name).strip("_") or "column"
    if base[0].isdigit():
        base = "c_" + base
    out = base
    while out in RESERVED or out in taken:
        out += suffix
    taken.add(out)
    return out


def extra_columns(rows: Rows, skip: Iterable[int], *, strict: bool, rename: Mapping[str, str] | None = None,
                  suffix: str = "_col") -> list[tuple[str, np.ndarray, dict[str, Any]]]:
    """The columns not in ``skip`` as ``(name, values, attrs)`` for :func:`stage_dataset`.

    ``strict`` (numeric export formats): every cell must be a number, else
    FormatError. Otherwise (generic tables) non-numeric columns are left out.
    """
    skip = set(skip)
    taken: set[str] = set()
    out = []
    header = rows.header
    for j, bare in enumerate(header.bare):
        if j in skip:
            continue
        if not strict and not rows.is_numeric(j):
            log.info("%s: column %r is not numeric; left out", rows.path, header.names[j])
            continue
        values = rows.number(j, finite=False)
        name = extra_name((rename or {}).get(bare, bare), taken, suffix)
        attrs: dict[str, Any] = {"long_name": header.names[j]}
        if header.units[j]:
            attrs["units"] = header.units[j]
        out.append((name, values, attrs))
    return out


def stage_dataset(ids: np.ndarray, x: np.ndarray, x_ref: np.ndarray | None = None, *, path: Path, fmt: str,
                  valid: np.ndarray | None = None, time: float | None = None,
                  attrs: Mapping[str, Any] | None = None,
                  extras: Sequence[tuple[str, np.ndarray, dict[str, Any]]] = (),
                  point_id_source: str = "file") -> xr.Dataset:
    """Assemble one DIC stage in the common layout of all readers.

    Parameters
    ----------
    ids : ndarray of int, shape (n,)
        Point IDs in file order.
    x : ndarray, shape (n, 3)
        Current coordinates, mm.
    x_ref : ndarray, shape (n, 3), optional
        Reference (undeformed) coordinates, mm.
    path : Path
    fmt : str
        Format name for ``attrs["format"]``.
    valid : ndarray of bool, shape (n,), optional
        False for points the software marks as failed. Rows with any
        non-finite coordinate are invalid as well; invalid rows are NaN in
        ``x`` and ``x_ref`` (their IDs are kept).
    time : float, optional
        Stage time, s.
    attrs : mapping, optional
        Further Dataset attributes.
    extras : sequence of (name, values (n,), attrs)
        Extra per-point variables.
    point_id_source : {"file", "row"}

    Returns
    -------
    xarray.Dataset
        ``x(point, component)``, optionally ``x_ref(point, component)``, extras.
    """
    x = np.array(x, dtype=np.float64)
    bad = ~np.isfinite(x).all(axis=1)
    if x_ref is not None:
        x_ref = np.array(x_ref, dtype=np.float64)
        bad |= ~np.isfinite(x_ref).all(axis=1)
    if valid is not None:
        bad |= ~np.asarray(valid, dtype=bool)
    x[bad] = np.nan
    data_vars: dict[str, Any] = {
        "x": (("point", "component"), x, {"units": "mm", "long_name": "current coordinates"}),
    }
    if x_ref is not None:
        x_ref[bad] = np.nan
        data_vars["x_ref"] = (("point", "component"), x_ref,
                              {"units": "mm", "long_name": "reference (undeformed) coordinates"})
    for name, values, vattrs in extras:
        data_vars[name] = ("point", np.asarray(values), dict(vattrs))
    coords = {
        "point": ("point", np.asarray(ids, dtype=np.int64), {"long_name": "point ID"}),
        "component": ("component", np.array(COMPONENTS, dtype=object)),
    }
    ds = xr.Dataset(data_vars, coords=coords)
    if time is not None:
        ds = ds.assign_coords(time=((), float(time), {"units": "s", "long_name": "stage time"}))
    n_bad = int(bad.sum())
    ds.attrs = {"format": fmt, "source": os.fspath(path), "point_id_source": point_id_source,
                "n_points": int(x.shape[0]), "n_invalid": n_bad, **dict(attrs or {})}
    if x.shape[0] and n_bad == x.shape[0]:
        warnings.warn(f"{path}: none of the {n_bad} points is valid (all failed or NaN)", IrdicWarning, stacklevel=3)
    log.info("%s: %d points (%d invalid) read as %s", path, x.shape[0], n_bad, fmt)
    return ds
