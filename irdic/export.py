"""Export of the point results: ParaView time series and CSV tables.

* :func:`write_paraview` writes one VTK unstructured grid (``.vtu``) per DIC
  time with one vertex cell per point and every per-point variable of
  ``points.zarr`` (and ``fields.zarr``) as point data, plus a ParaView data
  collection (``.pvd``) that lists the files with their times. Open the
  ``.pvd`` in ParaView and the time slider steps through the DIC stages.
* :func:`write_csv` writes selected points over time in long format, one
  row per (time, point), a header with units.
* which times and points are written: :mod:`irdic.selection`.

Variable names are those of the stores. In the ``.vtu`` files vectors keep
their components (``x``, ``temperature_gradient``: 3; ``pixel``: 2), a
2 x 2 tensor is flattened row by row to 4 components (``strain``: E11, E12,
E21, E22), booleans become 0/1 (uint8), and a variable with a ``principal``
dimension is split into ``<name>_max`` and ``<name>_min``.
"""

from __future__ import annotations

import logging
import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Sequence

import numpy as np
import xarray as xr

from .errors import ConfigError
from .selection import aligned_fields, require_variables, select_points, select_times
from .outputs import atomic_directory

__all__ = [
    "point_variables",
    "write_paraview",
    "write_pvd",
    "write_csv",
]

log = logging.getLogger(__name__)

#: copies of points.zarr variables in fields.zarr: taken from points.zarr
_COPIED = ("x", "temperature")


def point_variables(points: xr.Dataset, fields: xr.Dataset | None = None) -> dict[str, xr.DataArray]:
    """Every per-point variable of the stores, by export name.

    Variables whose dimensions start with ``("time", "point")`` or are
    ``("point", ...)`` are taken; ``fields.zarr``'s copies of ``x`` and
    ``temperature`` are left out, other name clashes get the prefix
    ``fields_``.

    Returns
    -------
    dict of str to xarray.DataArray
        In store order, points first.
    """
    out: dict[str, xr.DataArray] = {}
    fields = aligned_fields(points, fields)
    for source, ds in (("points", points), ("fields", fields)):
        if ds is None:
            continue
        for name, da in ds.data_vars.items():
            dims = da.dims
            if not (dims[:2] == ("time", "point") or dims[:1] == ("point",)):
                continue
            if da.dtype.kind not in "biuf":
                log.info("export: %s.%s (dtype %s) left out: not numeric", source, name, da.dtype)
                continue
            key = str(name)
            if source == "fields" and key in out:
                if key in _COPIED:
                    continue
                key = f"fields_{key}"
            out[key] = da
    return out


def signal_columns(fields: xr.Dataset | None, taken=()) -> dict[str, np.ndarray]:
    """The testing machine signals of ``fields.zarr`` as ``{"name [unit]": values (time,)}``.

    Names as in the ``signal`` coordinate (machine signals already carry
    ``machine_``); a name that clashes with one of ``taken`` (other columns,
    ``time``) gets the prefix ``signal_``. Empty without signals.
    """
    if fields is None or "signal_value" not in fields:
        return {}
    v = np.asarray(fields["signal_value"].transpose("time", "signal").values, dtype=float)
    units = ([str(u) for u in fields["signal_unit"].values] if "signal_unit" in fields.coords
             else [""] * v.shape[1])
    taken = {str(t).lower() for t in taken} | {"time", "point", "point_id", "x", "y", "z"}
    out = {}
    for j, name in enumerate(str(n) for n in fields["signal"].values):
        if name.lower() in taken:
            name = f"signal_{name}"
        out[f"{name} [{units[j]}]" if units[j] else name] = v[:, j]
    return out


def _vtk_arrays(name: str, a: np.ndarray, dims: tuple, labels: dict, dtype) -> dict[str, np.ndarray]:
    """VTK point-data arrays ((N,) or (N, k)) of one time slice ``a`` with dimensions ``("point", ...)``."""
    if a.dtype == bool:
        a = a.astype(np.uint8)
    elif a.dtype.kind == "f" and a.dtype.itemsize > np.dtype(dtype).itemsize:
        a = a.astype(dtype)  # only down: float32 data stay float32 with dtype="float64"
    extra = dims[1:]
    if "principal" in extra:
        ax = extra.index("principal") + 1
        names = labels.get("principal") or [str(k) for k in range(a.shape[ax])]
        res = {}
        for j, lab in enumerate(names):
            res.update(_vtk_arrays(f"{name}_{lab}", np.take(a, j, axis=ax), dims[:ax] + dims[ax + 1:], labels, dtype))
        return res
    if a.ndim > 2:
        a = a.reshape(a.shape[0], -1)
    return {name: np.ascontiguousarray(a)}


#: bytes of variables loaded at once while writing the time series
_BLOCK_BYTES = 256 * 2**20


# --------------------------------------------------------------------------- ParaView


def _add_field_data(path: Path, values: dict[str, float], compression: str | None) -> None:
    """Insert one-value VTK field data arrays (the signals of the time step) into a .vtu meshio wrote.

    meshio's .vtu writer leaves field data out. The arrays are encoded as
    meshio encodes its own (binary, the file's compressor, UInt32 block
    header), since ParaView's ASCII parser does not read ``nan``.
    """
    import base64
    import lzma
    import zlib
    from xml.sax.saxutils import quoteattr

    def encode(a: np.ndarray) -> str:
        raw = a.astype("<f8").tobytes()
        if compression is None:
            return base64.b64encode(np.array([len(raw)], "<u4").tobytes() + raw).decode()
        packed = (zlib.compress(raw) if compression == "zlib" else lzma.compress(raw))
        head = np.array([1, max(len(raw), 1), len(raw), len(packed)], "<u4").tobytes()
        return base64.b64encode(head).decode() + base64.b64encode(packed).decode()

    block = "<FieldData>\n" + "".join(
        f'<DataArray type="Float64" Name={quoteattr(k)} NumberOfTuples="1" format="binary">\n'
        f"{encode(np.array([v]))}\n</DataArray>\n" for k, v in values.items()) + "</FieldData>\n"
    text = path.read_text(encoding="utf-8")
    at = text.index("<UnstructuredGrid>") + len("<UnstructuredGrid>\n")
    path.write_text(text[:at] + block + text[at:], encoding="utf-8")


def write_pvd(path, files: Sequence[str], times: Sequence[float]) -> Path:
    """A ParaView data collection listing ``files`` (relative to ``path``) at ``times`` (s).

    Parameters
    ----------
    path : path-like
        The ``.pvd`` to write.
    files : sequence of str
        Data files, relative to the folder of ``path``.
    times : sequence of float
        Time of each file, s.

    Returns
    -------
    pathlib.Path
    """
    if len(files) != len(times):
        raise ConfigError(f"write_pvd: {len(files)} files but {len(times)} times")
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    coll = ET.SubElement(root, "Collection")
    for f, t in zip(files, times):
        # repr: the shortest text that reads back as the same float
        ET.SubElement(coll, "DataSet", timestep=repr(float(t)), group="", part="0", file=str(f))
    ET.indent(root)
    p = Path(path)
    ET.ElementTree(root).write(p, encoding="utf-8", xml_declaration=True)
    return p


def _check_paraview_args(points, name, compression, dtype, every) -> None:
    """ConfigError/DataError for arguments of :func:`write_paraview` it cannot write."""
    require_variables(points, ("x",), "the points store")
    if not isinstance(name, str) or not name or any(c in name for c in '/\\:*?"<>|'):
        raise ConfigError(f"name must be a plain file name stem, got {name!r}")
    if compression not in ("zlib", "lzma", None):
        raise ConfigError(f"compression must be 'zlib', 'lzma' or None, got {compression!r}")
    if dtype not in ("float32", "float64"):
        raise ConfigError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise ConfigError(f"every must be an integer >= 1, got {every!r}")


def _write_vtu(path: Path, varying: dict, static: dict, ids, labels, dtype, compression) -> None:
    """One time step: a vertex per point with coordinates (``varying["x"]``), leaving out points without them.

    ``varying`` and ``static`` map names to (values with the point axis
    first, the dimensions after ``point``); static arrays hold every point.
    """
    import meshio

    x = varying["x"][0].astype(float)
    keep = np.isfinite(x).all(axis=1)
    data = {"point_id": ids[keep]}
    for vname, (a, dims) in varying.items():
        if vname != "x":
            data.update(_vtk_arrays(vname, a[keep], dims, labels, dtype))
    for vname, (a, dims) in static.items():
        data.update(_vtk_arrays(vname, a[keep], dims, labels, dtype))
    mesh = meshio.Mesh(points=x[keep], cells=[("vertex", np.arange(int(keep.sum()))[:, None])], point_data=data)
    meshio.vtu.write(os.fspath(path), mesh, binary=True, compression=compression)


def write_paraview(points: xr.Dataset, directory, *, fields: xr.Dataset | None = None, times=None,
                   every: int = 1, name: str = "points", compression: str | None = "zlib", dtype: str = "float32") -> Path:
    """One ``.vtu`` per time with every point variable, and a ``.pvd`` collection.

    The testing machine signals of ``fields.zarr`` (if any) are written as
    field data of each time step (one value each, named as the CSV columns,
    see :func:`signal_columns`).

    Points whose coordinates are missing at a time (DIC correlation failed
    there) are left out of that time's file; the ``point_id`` array keeps the
    DIC point IDs, so ParaView selections by ID work across times.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr`` (``x(time, point, component)`` mm and the per-point
        variables).
    directory : path-like
        Output folder, replaced as a whole (written to a temporary sibling
        first): ``<name>.pvd`` and ``<name>_<index>.vtu``.
    fields : xarray.Dataset, optional
        ``fields.zarr`` of the same experiment.
    times : sequence of float, optional
        Times to write, s (nearest stored); None: every stored time.
    every : int
        Write every ``every``-th of those times (the first always): long
        series at full resolution make large folders (about 0.25 kB per
        point and time with every variable of both stores, float32).
    name : str
        File name stem.
    compression : {"zlib", "lzma", None}
        Compression of the binary arrays in the ``.vtu`` files.
    dtype : {"float32", "float64"}
        Type of the floating-point point data (coordinates stay float64):
        float32 halves the files and keeps 7 significant digits, plenty for
        viewing; float64 keeps the stored values exactly (float32 variables
        are never widened).

    Returns
    -------
    pathlib.Path
        The ``.pvd`` file.
    """
    _check_paraview_args(points, name, compression, dtype, every)
    t_all = points["time"].values.astype(float)
    idx = np.arange(t_all.size) if times is None else select_times(t_all, times, name="times")
    idx = idx[::every]
    variables = point_variables(points, fields)
    signals = signal_columns(aligned_fields(points, fields), taken=variables)
    ids = points["point"].values.astype(np.int64)
    width = max(4, len(str(t_all.size - 1)))
    labels = {d: [str(v) for v in ds[d].values] for ds in (points, fields) if ds is not None
              for d in ds.dims if d in ds.coords}
    static = {k: (np.asarray(da.transpose("point", ...).values), da.transpose("point", ...).dims)
              for k, da in variables.items() if "time" not in da.dims}
    varying = {k: da.transpose("time", "point", ...) for k, da in variables.items() if "time" in da.dims}
    per_time = sum(da.dtype.itemsize * da.size // max(da.sizes["time"], 1) for da in varying.values())
    block = max(1, int(_BLOCK_BYTES // max(per_time, 1)))
    directory = Path(directory)
    files = []
    with atomic_directory(directory) as tmp:
        tmp.mkdir(parents=True)
        # a block of times at a time: zarr chunks span many times, reading them once per time would be quadratic
        for start in range(0, idx.size, block):
            chunk = idx[start:start + block]
            loaded = {k: np.asarray(da.isel(time=chunk).values) for k, da in varying.items()}
            for j, i in enumerate(chunk):
                fname = f"{name}_{int(i):0{width}d}.vtu"
                point_data = {k: (loaded[k][j], da.dims[1:]) for k, da in varying.items()}
                _write_vtu(tmp / fname, point_data, static, ids, labels, dtype, compression)
                if signals:
                    # one value per time step: VTK field data, shown by ParaView's spreadsheet and plot-over-time
                    _add_field_data(tmp / fname, {k: float(v[i]) for k, v in signals.items()}, compression)
                files.append(fname)
        write_pvd(tmp / f"{name}.pvd", files, t_all[idx])
    log.info("paraview: %d times x %d point variables -> %s", len(files), len(variables), directory / f"{name}.pvd")
    return directory / f"{name}.pvd"


# --------------------------------------------------------------------------- CSV


def _units(da: xr.DataArray) -> str:
    return str(da.attrs.get("units", "")).strip()


def write_csv(points: xr.Dataset, path, *, fields: xr.Dataset | None = None, point_ids=None,
              times=None, variables: Sequence[str] | None = None) -> Path:
    """Selected points over time, long format: one row per (time, point).

    Columns: ``time [s]``, ``point``, ``x [mm]``, ``y [mm]``, ``z [mm]``,
    then every per-point variable (or ``variables``) with its unit in
    brackets, then the testing machine signals of ``fields.zarr`` at each
    time (:func:`signal_columns`: ``force [N]``, ``machine_force [kN]``); vector and tensor components get the component label
    (``temperature_gradient_x [K/mm]``, ``strain_12 [1]``,
    ``principal_direction_max_x [1]``). Decimal point, comma separator, UTF-8,
    missing values empty.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    path : path-like
        CSV file to write.
    fields : xarray.Dataset, optional
        ``fields.zarr`` of the same experiment.
    point_ids : sequence of int, "all" or None
        Points to write; None: :func:`central_point`.
    times : sequence of float or None
        Times (s, nearest stored); None: every stored time.
    variables : sequence of str, optional
        Export names (see :func:`point_variables`) to include; default all.

    Returns
    -------
    pathlib.Path
    """
    import pandas as pd

    require_variables(points, ("x",), "the points store")
    ids = select_points(points, point_ids, name="point_ids")
    t_all = points["time"].values.astype(float)
    idx = np.arange(t_all.size) if times is None else select_times(t_all, times, name="times")
    avail = point_variables(points, fields)
    chosen = _chosen_variables(avail, variables)
    pos = {int(p): k for k, p in enumerate(points["point"].values)}
    sel = np.array([pos[int(p)] for p in ids])
    n_t, n_p = idx.size, sel.size
    cols: dict[str, np.ndarray] = {
        "time [s]": np.repeat(t_all[idx], n_p),
        "point": np.tile(ids, n_t),
    }

    def take(da):
        if "time" in da.dims:
            da = da.isel(time=xr.DataArray(idx, dims="time_sel"), point=xr.DataArray(sel, dims="point_sel"))
            da = da.transpose("time_sel", "point_sel", ...)
        else:
            da = da.isel(point=xr.DataArray(sel, dims="point_sel"))
            da = da.expand_dims(time_sel=n_t).transpose("time_sel", "point_sel", ...)
        return da

    x = take(avail["x"]).values
    for k, c in enumerate("xyz"):
        cols[f"{c} [{_units(avail['x']) or 'mm'}]"] = x[..., k].ravel()
    for v in chosen:
        cols.update(_csv_columns(v, take(avail[v]), _units(avail[v])))
    for name, v in signal_columns(aligned_fields(points, fields), taken=[c.split(" [")[0] for c in cols]).items():
        cols[name] = np.repeat(v[idx], n_p)
    frame = pd.DataFrame(cols)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.name}.tmp-{os.getpid()}")
    try:  # written beside and renamed: a reader never sees half a table
        frame.to_csv(tmp, index=False, encoding="utf-8", lineterminator="\n")
        os.replace(tmp, p)
    finally:
        if tmp.exists():
            tmp.unlink()
    log.info("csv: %d points x %d times, %d columns -> %s", n_p, n_t, frame.shape[1], p)
    return p


def _chosen_variables(avail: dict, variables) -> list[str]:
    """Export names of the CSV's variable columns (``x`` has its own columns); ConfigError for unknown ones."""
    if variables is None:
        return [v for v in avail if v != "x"]
    if isinstance(variables, str):
        raise ConfigError(f"variables must be a list of names, got {variables!r}")
    unknown = [v for v in variables if v not in avail]
    if unknown:
        raise ConfigError(f"variables: {', '.join(map(repr, unknown))} not in the stores; "
                          f"available: {', '.join(avail)}")
    return [v for v in variables if v != "x"]


def _csv_columns(v: str, da: xr.DataArray, unit: str) -> dict[str, np.ndarray]:
    """Columns of one variable ``da`` (time_sel, point_sel, ...): one per component, labelled, with the unit."""
    a = da.values
    extra = da.dims[2:]
    suffix = f" [{unit}]" if unit else ""
    if not extra:
        return {v + suffix: a.ravel()}
    labels = [[str(s) for s in (da[d].values if d in da.coords else range(1, da.sizes[d] + 1))] for d in extra]
    flat = a.reshape(a.shape[0] * a.shape[1], -1)
    combos = np.array(np.meshgrid(*[np.arange(len(lb)) for lb in labels], indexing="ij")).reshape(len(extra), -1).T
    # tensor components: index labels joined without separator (strain_12)
    joiner = "" if all(len(s) == 1 and s.isdigit() for lb in labels for s in lb) else "_"
    return {f"{v}_{joiner.join(labels[d][c] for d, c in enumerate(combo))}{suffix}": flat[:, j]
            for j, combo in enumerate(combos)}

