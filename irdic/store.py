"""Writing and opening irdic zarr stores: atomically, with units and provenance.

Every stage writes one zarr store. A store is first written to a hidden
sibling directory and renamed into place only when it is complete, and it
carries the attribute ``irdic_complete = True`` written last. A job that dies
half-way therefore leaves either nothing or a temporary directory that no
later stage will take for a result, and :func:`open_store` refuses a store
without the completion mark.

Provenance attributes (all stores):

``irdic_stage``        name of the stage that wrote the store
``irdic_version``      version of the irdic package
``irdic_created``      UTC time stamp, ISO 8601
``irdic_parameters``   JSON text of the parameters of the stage
``irdic_inputs``       JSON list of the input files or stores
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
import shutil
import uuid
import warnings
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np
import xarray as xr
import zarr

from .errors import DataError, IrdicError

__all__ = [
    "provenance",
    "write_dataset",
    "open_store",
    "atomic_directory",
    "FrameStore",
    "COMPLETE_ATTR",
]

COMPLETE_ATTR = "irdic_complete"


def _version() -> str:
    from . import __version__

    return __version__


def _jsonable(obj: Any) -> Any:
    """Turn numpy scalars/arrays and paths into plain JSON types."""
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def provenance(stage: str, params: Mapping | None = None, inputs: Sequence | None = None) -> dict:
    """Attributes that say who wrote a store, when, from what and how.

    Parameters
    ----------
    stage : str
        Stage name (``"ingest-ir"``, ``"calibrate"``, ...).
    params : mapping, optional
        Parameters of the stage; stored as JSON text.
    inputs : sequence of path-like, optional
        Input files or stores.

    Returns
    -------
    dict
        Attributes to merge into the dataset's ``attrs``.
    """
    return {
        "irdic_stage": stage,
        "irdic_version": _version(),
        "irdic_created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "irdic_parameters": json.dumps(_jsonable(dict(params or {})), sort_keys=True),
        "irdic_inputs": json.dumps(_jsonable(list(inputs or []))),
    }


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale_siblings(final: Path) -> None:
    """Remove temporaries of ``final`` left by killed jobs (their process is gone)."""
    for tmp in final.parent.glob(f".{final.name}.tmp-*"):
        try:
            pid = int(tmp.name.rsplit(".tmp-", 1)[1].split("-")[0])
        except (IndexError, ValueError):
            continue
        if not _pid_alive(pid):
            shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary sibling of ``path``; move it to ``path`` on success.

    On any exception the temporary directory is removed and ``path`` is left
    as it was before (an older complete result stays; nothing half-written
    appears).

    Parameters
    ----------
    path : path-like
        Final location of the directory (for example ``results/x/ir.zarr``).
    """
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_siblings(final)
    tmp = final.with_name(f".{final.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if final.exists():
        if final.is_dir() and not final.is_symlink():
            shutil.rmtree(final)
        else:
            final.unlink()
    os.replace(tmp, final)


def _mark_complete(path: Path) -> None:
    group = zarr.open_group(str(path), mode="r+")
    group.attrs[COMPLETE_ATTR] = True
    pass  # zarr v3 has no consolidated metadata in the spec; the mark is enough


def write_dataset(
    ds: xr.Dataset,
    path: str | os.PathLike,
    *,
    stage: str,
    params: Mapping | None = None,
    inputs: Sequence | None = None,
    encoding: Mapping | None = None,
) -> Path:
    """Write ``ds`` to the zarr store ``path`` atomically, with provenance.

    Parameters
    ----------
    ds : xarray.Dataset
        The data; variables should carry ``units`` and ``long_name`` attributes.
    path : path-like
        Destination store (a directory, replaced if it exists).
    stage, params, inputs
        See :func:`provenance`.
    encoding : mapping, optional
        Per-variable zarr encoding (chunks, ...), passed to ``to_zarr``.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    ds = ds.copy()
    # fixed-width unicode arrays are not yet stable in the zarr v3 spec; variable-length strings are
    for name in list(ds.variables):
        if ds[name].dtype.kind == "U":
            ds[name] = ds[name].astype(object)
    ds.attrs.update(provenance(stage, params, inputs))
    ds.attrs.pop(COMPLETE_ATTR, None)
    with atomic_directory(path) as tmp:
        ds.to_zarr(str(tmp), mode="w", encoding=dict(encoding or {}), consolidated=False, zarr_format=3)
        _mark_complete(tmp)
    return Path(path)


def open_store(path: str | os.PathLike) -> xr.Dataset:
    """Open a store written by irdic, refusing incomplete or foreign ones.

    Parameters
    ----------
    path : path-like
        A zarr store written by :func:`write_dataset` or :class:`FrameStore`.

    Returns
    -------
    xarray.Dataset
        Lazily loaded dataset.

    Raises
    ------
    DataError
        The store does not exist, is not a zarr store or is incomplete.
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: store not found (run the stage that produces it first)")
    try:
        with warnings.catch_warnings():
            # Snakemake drops a .snakemake_timestamp file into directory outputs
            warnings.filterwarnings("ignore", message=r".*\.snakemake_timestamp.*")
            ds = xr.open_zarr(str(p), consolidated=False)
    except Exception as exc:  # zarr raises several unrelated types here
        raise DataError(f"{p}: not a readable zarr store ({type(exc).__name__}: {exc})") from exc
    if not ds.attrs.get(COMPLETE_ATTR, False):
        raise DataError(
            f"{p}: store is incomplete (written by an interrupted job?); delete it and run the stage again"
        )
    return ds


class FrameStore:
    """Stream a stack of frames into a zarr store, one frame at a time.

    Memory use is one frame, whatever the number of frames. The store is
    written to a temporary sibling and moved into place by :meth:`close`
    (or on leaving a ``with`` block without an exception).

    Parameters
    ----------
    path : path-like
        Final store location.
    name : str
        Variable name of the stack (``"temperature"``).
    n_frames : int
        Number of frames (first dimension, ``time``).
    frame_dims : tuple of str
        Names of the frame dimensions (``("v", "u")``).
    frame_coords : mapping of str to 1-D array
        Coordinate values of each frame dimension.
    dtype : numpy dtype
        Stored dtype (``float32`` for temperatures).
    var_attrs : mapping
        Attributes of the variable (``units``, ``long_name``).
    time_attrs : mapping
        Attributes of the ``time`` coordinate.
    attrs : mapping
        Dataset attributes (merged with provenance).

    Examples
    --------
    >>> with FrameStore(p, "temperature", 3, ("v", "u"), {"v": v, "u": u}) as fs:  # doctest: +SKIP
    ...     for i, (t, frame) in enumerate(frames):
    ...         fs.write(i, t, frame)
    """

    def __init__(
        self,
        path: str | os.PathLike,
        name: str,
        n_frames: int,
        frame_dims: tuple[str, ...],
        frame_coords: Mapping[str, np.ndarray],
        *,
        dtype=np.float32,
        var_attrs: Mapping | None = None,
        time_attrs: Mapping | None = None,
        attrs: Mapping | None = None,
        extra_time_vars: Mapping[str, tuple[np.dtype, Mapping]] | None = None,
    ):
        if n_frames < 1:
            raise DataError(f"{path}: no frames to write")
        self.path = Path(path)
        self._ctx = atomic_directory(self.path)
        self._tmp = self._ctx.__enter__()
        self._closed = False
        self.n_frames = n_frames
        self.frame_shape = tuple(len(frame_coords[d]) for d in frame_dims)
        root = zarr.open_group(str(self._tmp), mode="w", zarr_format=3)
        self._root = root
        self._data = root.create_array(
            name,
            shape=(n_frames, *self.frame_shape),
            chunks=(1, *self.frame_shape),
            dtype=dtype,
            fill_value=np.nan if np.dtype(dtype).kind == "f" else 0,
            dimension_names=("time", *frame_dims),
        )
        self._data.attrs.update(dict(var_attrs or {}))
        self._time = root.create_array(
            "time", shape=(n_frames,), chunks=(n_frames,), dtype="float64", fill_value=np.nan,
            dimension_names=("time",),
        )
        self._time.attrs.update({"units": "s", "long_name": "time", **dict(time_attrs or {})})
        self._time_buf = np.full(n_frames, np.nan)
        self._extra = {}
        self._extra_buf = {}
        for vname, (vdtype, vattrs) in (extra_time_vars or {}).items():
            arr = root.create_array(
                vname, shape=(n_frames,), chunks=(n_frames,), dtype=vdtype,
                fill_value=np.nan if np.dtype(vdtype).kind == "f" else 0, dimension_names=("time",),
            )
            arr.attrs.update(dict(vattrs))
            self._extra[vname] = arr
            self._extra_buf[vname] = np.zeros(n_frames, dtype=vdtype)
        for d in frame_dims:
            c = np.asarray(frame_coords[d])
            arr = root.create_array(d, shape=c.shape, chunks=c.shape, dtype=c.dtype, dimension_names=(d,))
            arr[:] = c
            arr.attrs.update({"units": "px", "long_name": f"pixel {d} (full-sensor, 0-based)"})
        self._attrs = dict(attrs or {})
        self._written = np.zeros(n_frames, dtype=bool)

    def write(self, index: int, time: float, frame: np.ndarray, **extra) -> None:
        """Store ``frame`` at position ``index`` with frame time ``time`` (s).

        ``extra`` gives the values of the ``extra_time_vars`` for this frame.
        """
        frame = np.asarray(frame)
        if frame.shape != self.frame_shape:
            raise DataError(
                f"frame {index} has shape {frame.shape}, expected {self.frame_shape} like the first frame"
            )
        self._data[index] = frame
        self._time_buf[index] = time
        for k, v in extra.items():
            self._extra_buf[k][index] = v
        self._written[index] = True

    def set_times(self, times: np.ndarray) -> None:
        """Set all frame times at once (s), e.g. when they are known only at the end."""
        times = np.asarray(times, dtype=float)
        if times.shape != (self.n_frames,):
            raise DataError(f"{self.path}: got {times.shape[0]} frame times for {self.n_frames} frames")
        self._time_buf[:] = times

    def close(self) -> Path:
        """Finish the store and move it into place."""
        if self._closed:
            return self.path
        missing = np.flatnonzero(~self._written)
        if missing.size:
            raise DataError(f"{self.path}: frames {missing[:10].tolist()} were never written")
        self._time[:] = self._time_buf
        for k, arr in self._extra.items():
            arr[:] = self._extra_buf[k]
        self._root.attrs.update(self._attrs)
        self._closed = True
        _mark_complete(self._tmp)
        self._ctx.__exit__(None, None, None)
        return self.path

    def abort(self) -> None:
        """Discard everything written so far."""
        if not self._closed:
            self._closed = True
            with contextlib.suppress(BaseException):
                self._ctx.__exit__(IrdicError, IrdicError("aborted"), None)

    def __enter__(self) -> "FrameStore":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
