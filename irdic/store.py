"""Writing and opening irdic zarr stores: atomically, with units and provenance.

Every stage writes one zarr store. A store is first written to a hidden
sibling directory and moved into place only when it is complete; it carries
the attribute ``irdic_complete = True``, written last together with
``irdic_chunks``, the number of chunk files of every array. A job that dies
half-way therefore leaves either nothing or a temporary directory that no
later stage will take for a result, and :func:`open_store` refuses a store
without the completion mark or with fewer chunks than the mark promises.

Replacing a store never exposes a mix (see :mod:`irdic.outputs`, which
also keeps irdic from replacing anything it did not write), and a dataset
still reading the old store lazily gets a :class:`~irdic.errors.DataError`,
never fill values.

Provenance attributes (all stores):

``irdic_stage``        name of the stage that wrote the store
``irdic_version``      version of the irdic package
``irdic_created``      UTC time stamp, ISO 8601
``irdic_parameters``   JSON text of the parameters of the stage
``irdic_inputs``       JSON list of the input files or stores
``irdic_chunks``       JSON: chunk files per array (and each one's size) when the store was finished

A stage opens its inputs with the kind it expects (``open_store(path,
"ingest-ir")``), so a store of another stage is refused by name; a chunk cut
short or damaged in place raises :class:`~irdic.errors.DataError` naming the
store, the variable and the chunk (:mod:`irdic.chunk_errors`).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import itertools
import json
import os
import warnings
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numcodecs
import numpy as np
import xarray as xr
import zarr
from zarr.codecs import BloscCodec

from .chunk_errors import install as _install_chunk_errors
from .errors import DataError, IrdicError
from .outputs import COMPLETE_ATTR, atomic_directory, write_failure, zarr_group_attrs
from .vocabulary import COORD_ATTRS

__all__ = [
    "jsonable",
    "provenance",
    "write_dataset",
    "open_store",
    "STORE_KINDS",
    "FrameStore",
    "COMPLETE_ATTR",
    "CHUNKS_ATTR",
]

#: JSON text written with the completion mark: chunk files of every array (see :func:`open_store`)
CHUNKS_ATTR = "irdic_chunks"

#: Codec of :class:`FrameStore` frames: blosc (a core zarr v3 codec, readable by any zarr) with LZ4 after a
#: bit shuffle. On float32 temperatures it costs ~0.2 ms per 360 x 260 frame against ~1.8 ms for zarr's
#: default zstd, for a store ~1.9x smaller than the float32 values instead of ~3x.
FRAME_BLOSC = {"cname": "lz4", "clevel": 5, "shuffle": "bitshuffle"}
_BLOSC_SHUFFLE = {"noshuffle": 0, "shuffle": 1, "bitshuffle": 2}
# Blosc would start a pool of its own threads when called from the main thread, beyond the threads a stage
# was given; zarr sets the same on import, this keeps it true whatever imports come first.
numcodecs.blosc.use_threads = False
_install_chunk_errors()


def _version() -> str:
    from . import __version__

    return __version__


def jsonable(obj: Any) -> Any:
    """Turn numpy scalars/arrays and paths into plain JSON types."""
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
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
        "irdic_parameters": json.dumps(jsonable(dict(params or {})), sort_keys=True),
        "irdic_inputs": json.dumps(jsonable(list(inputs or []))),
    }


def _chunk_manifest(root: Path) -> dict:
    """``{array path: [chunk files present, chunks in the grid, absent chunk keys, {chunk key: bytes}]}``.

    Chunks equal to the fill value are not written by zarr, so an absent
    chunk is only an error when it was present when the store was finished;
    the few absent ones are listed to tell them apart. The size of each
    chunk file tells a chunk cut short (an interrupted copy) from a whole
    one when it is read.
    """
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        if "zarr.json" not in filenames:
            continue
        try:
            with open(os.path.join(dirpath, "zarr.json"), encoding="utf-8") as fh:
                meta = json.load(fh)
        except (OSError, ValueError):
            continue
        if meta.get("node_type") != "array":
            continue
        dirnames[:] = []
        rel = Path(dirpath).relative_to(root).as_posix()
        enc = meta.get("chunk_key_encoding", {})
        if enc.get("name") != "default" or enc.get("configuration", {}).get("separator", "/") != "/":
            continue  # irdic writes the default encoding only; others are not checked
        sizes = {k: os.path.getsize(os.path.join(dirpath, k)) for k in _chunk_keys(Path(dirpath))}
        present = set(sizes)
        shape = meta["shape"]
        chunks = meta["chunk_grid"]["configuration"]["chunk_shape"]
        grid = [range(-(-s // c)) for s, c in zip(shape, chunks)]
        n_grid = int(np.prod([len(g) for g in grid])) if grid else 1
        absent = []
        if len(present) < n_grid:
            absent = sorted({"/".join(["c", *map(str, idx)]) for idx in itertools.product(*grid)} - present)
        out[rel] = [len(present), n_grid, absent, sizes]
    return out


def _chunk_keys(array_dir: Path) -> Iterator[str]:
    """Chunk keys (``c/0/1``) present under one array's folder."""
    c = array_dir / "c"
    if c.is_file():
        yield "c"
        return
    for dirpath, _, filenames in os.walk(c):
        rel = Path(dirpath).relative_to(array_dir).as_posix()
        for f in filenames:
            yield f"{rel}/{f}"


def _mark_complete(path: Path) -> None:
    """Write the completion mark, with the chunk manifest that proves the data is there."""
    manifest = json.dumps(_chunk_manifest(path), separators=(",", ":"))
    group = zarr.open_group(str(path), mode="r+")
    # one metadata write: a store never carries the mark without the manifest
    group.attrs.update({CHUNKS_ATTR: manifest, COMPLETE_ATTR: True})
    # Consolidated metadata lets plain ``xr.open_zarr`` open the store without
    # listing its folder (no warning about it missing, none about the
    # ``.snakemake_timestamp`` file Snakemake puts into directory outputs).
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"Consolidated metadata is currently not part")
        zarr.consolidate_metadata(str(path))


def write_dataset(
    ds: xr.Dataset,
    path: str | os.PathLike,
    *,
    stage: str,
    params: Mapping | None = None,
    inputs: Sequence | None = None,
    encoding: Mapping | None = None,
    append: Iterable[xr.Dataset] = (),
) -> Path:
    """Write ``ds`` to the zarr store ``path`` atomically, with provenance.

    Parameters
    ----------
    ds : xarray.Dataset
        The data; variables should carry ``units`` and ``long_name`` attributes.
    path : path-like
        Destination store (a directory; replaced if it is an irdic store,
        refused if it is anything else, see :func:`atomic_directory`).
    stage, params, inputs
        See :func:`provenance`.
    encoding : mapping, optional
        Per-variable zarr encoding (chunks, ...), passed to ``to_zarr``.
    append : iterable of xarray.Dataset, optional
        Further parts along ``time``, each appended after ``ds`` (their
        variables with a time dimension): a store gathered from time chunks
        holds one part in memory at a time. The store is complete, and
        opens, only once every part is in.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    ds = _prepared(ds)
    ds.attrs.update(provenance(stage, params, inputs))
    ds.attrs.pop(COMPLETE_ATTR, None)
    ds.attrs.pop(CHUNKS_ATTR, None)
    with atomic_directory(path) as tmp:
        ds.to_zarr(str(tmp), mode="w", encoding=dict(encoding or {}), consolidated=False, zarr_format=3)
        for part in append:
            part = _prepared(part)
            timed = [n for n, v in part.data_vars.items() if "time" in v.dims]
            part = part[timed]
            part = part.drop_vars([c for c in part.coords if "time" not in part[c].dims])
            part.attrs = dict(ds.attrs)  # an append rewrites the store's attributes with the part's
            part.to_zarr(str(tmp), append_dim="time", consolidated=False, zarr_format=3)
            del part
        _mark_complete(tmp)
    return Path(path)


def _prepared(ds: xr.Dataset) -> xr.Dataset:
    """A copy of ``ds`` as stores hold it: variable-length strings, shared coordinate attributes."""
    ds = ds.copy()
    # fixed-width unicode arrays are not yet stable in the zarr v3 spec; variable-length strings are
    for name in list(ds.variables):
        if ds[name].dtype.kind == "U":
            ds[name] = ds[name].astype(object)
    for name, c in ds.coords.items():
        # a coordinate without a long_name gets the shared one, so every store describes its indices alike
        if "long_name" not in c.attrs and name in COORD_ATTRS:
            ds.variables[name].attrs.update({**COORD_ATTRS[name], **c.attrs})
    return ds


def _identity(path: Path) -> tuple | None:
    """What tells one write of a store from the next: its metadata file's inode and change time."""
    try:
        st = os.stat(path / "zarr.json")
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_ctime_ns)


class _CheckedStore(zarr.storage.LocalStore):
    """A local store that raises :class:`DataError` instead of reading fill values.

    zarr reads a missing chunk as the fill value (NaN): a store replaced or
    deleted while a lazy dataset still reads it would yield silently wrong
    numbers. Every read therefore checks that the store is still the one
    opened, and that a missing chunk was absent when the store was finished.
    """

    def __init__(self, root, *, read_only: bool = True, identity=None, absent=None, arrays=None, sizes=None):
        super().__init__(root, read_only=read_only)
        self._identity = identity
        self._absent = absent or {}
        self._arrays = arrays or set()
        self._sizes = sizes or {}
        self.irdic_checked = True  # a chunk that fails to decode is named (irdic.chunk_errors)

    def with_read_only(self, read_only: bool = False):
        return type(self)(self.root, read_only=read_only, identity=self._identity, absent=self._absent,
                          arrays=self._arrays, sizes=self._sizes)

    def _array_of(self, key: str) -> str | None:
        # chunk keys are "<array>/c/<i>/<j>..." (or "<array>/c" for a 0-d array); indices are numbers
        head = key[:-2] if key.endswith("/c") else key.rpartition("/c/")[0]
        return head if head in self._arrays else None

    async def get(self, key, prototype=None, byte_range=None):
        value = await super().get(key, prototype, byte_range)
        if self._identity is not None and _identity(self.root) != self._identity:
            raise DataError(
                f"{self.root}: store was replaced or removed while it was being read "
                "(another job rewrote it); open it again"
            )
        arr = self._array_of(key)
        if arr is None:
            return value
        if value is None:
            if key[len(arr) + 1:] not in self._absent.get(arr, ()):
                raise DataError(f"{self.root}: variable {arr!r}: chunk {key} is missing; the store is damaged, "
                                "run the stage that writes it again")
        elif byte_range is None:
            expected = self._sizes.get(arr, {}).get(key[len(arr) + 1:])
            if expected is not None and len(value) != expected:
                raise DataError(f"{self.root}: variable {arr!r}: chunk {key} holds {len(value)} bytes, {expected} "
                                "when the store was finished (cut short by an interrupted copy?); the store is "
                                "damaged, copy it again or run the stage that writes it again")
        return value


#: What each stage's store holds, for messages when a store of another kind is handed to a stage
STORE_KINDS = {"ingest-ir": "IR frames (ir.zarr)", "ingest-dic": "DIC points (dic.zarr)",
               "ingest-machine": "a testing machine record (machine.zarr)", "calibrate": "a calibration "
               "(calibration.zarr)", "couple": "point temperatures (points.zarr)", "fields": "fields (fields.zarr)",
               "heat": "heat sources (heat.zarr)"}


def _check_kind(p: Path, attrs: Mapping, kind: str | None) -> None:
    """Refuse a store that another stage than ``kind`` wrote (``--dic ir.zarr``)."""
    found = attrs.get("irdic_stage")
    if kind is None or found is None or found == kind:
        return
    raise DataError(f"{p}: holds {STORE_KINDS.get(found, found)}, written by stage {found}; expected "
                    f"{STORE_KINDS.get(kind, kind)}, written by stage {kind} (are two paths swapped?)")


def open_store(path: str | os.PathLike, kind: str | None = None) -> xr.Dataset:
    """Open a store written by irdic, refusing incomplete, damaged, foreign or mistaken ones.

    A store that opens is complete: the completion mark lists how many chunk
    files each array had when the store was finished, and they are counted
    here; a chunk that disappears later (the store is rewritten by another
    job while this dataset is read lazily) raises :class:`DataError` when it
    is read, instead of reading as NaN.

    Parameters
    ----------
    path : path-like
        A zarr store written by :func:`write_dataset` or :class:`FrameStore`.
    kind : str, optional
        The stage whose store is expected (a key of :data:`STORE_KINDS`,
        ``"ingest-ir"``); its ``irdic_stage`` attribute must say so.

    Returns
    -------
    xarray.Dataset
        Lazily loaded dataset.

    Raises
    ------
    DataError
        The store does not exist, is not a zarr store, is incomplete, misses
        chunks, is replaced while it is read, or another stage than ``kind``
        wrote it.
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: store not found (run the stage that produces it first)")
    identity = _identity(p)
    attrs = zarr_group_attrs(p)
    if identity is None or attrs is None:
        raise DataError(f"{p}: not a readable zarr store (no group metadata zarr.json)")
    if not attrs.get(COMPLETE_ATTR, False):
        raise DataError(
            f"{p}: store is incomplete (written by an interrupted job?); delete it and run the stage again"
        )
    _check_kind(p, attrs, kind)
    absent, arrays, sizes = {}, set(), {}
    if CHUNKS_ATTR in attrs:  # stores of irdic versions before the manifest are trusted as they are
        try:
            manifest = json.loads(attrs[CHUNKS_ATTR])
        except (TypeError, ValueError):
            raise DataError(f"{p}: chunk manifest {CHUNKS_ATTR} is unreadable; run the stage again") from None
        for arr, (n_present, _, missing, *chunk_sizes) in manifest.items():
            found = sum(1 for _ in _chunk_keys(p / arr))
            if found < n_present:
                raise DataError(
                    f"{p}: variable {arr!r} has {found} of its {n_present} chunks (the store is damaged, or being "
                    "replaced by another job); run the stage that writes it again"
                )
            absent[arr] = set(missing)
            arrays.add(arr)
            if chunk_sizes:  # stores of irdic versions before the chunk sizes are trusted as they are
                sizes[arr] = chunk_sizes[0]
    store = _CheckedStore(p, identity=identity, absent=absent, arrays=arrays, sizes=sizes)
    try:
        with warnings.catch_warnings():
            # Snakemake drops a .snakemake_timestamp file into directory outputs
            warnings.filterwarnings("ignore", message=r".*\.snakemake_timestamp.*")
            ds = xr.open_zarr(store, consolidated=False)
    except IrdicError:
        raise
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
        try:
            self._create(name, n_frames, frame_dims, frame_coords, dtype, var_attrs, time_attrs, attrs,
                         extra_time_vars)
        except BaseException:
            self.abort()  # releases the lock and removes the temporary
            raise

    def _create(self, name, n_frames, frame_dims, frame_coords, dtype, var_attrs, time_attrs, attrs,
                extra_time_vars) -> None:
        self.n_frames = n_frames
        self.frame_shape = tuple(len(frame_coords[d]) for d in frame_dims)
        root = zarr.open_group(str(self._tmp), mode="w", zarr_format=3)
        self._root = root
        dtype = np.dtype(dtype)
        self._data = root.create_array(
            name,
            shape=(n_frames, *self.frame_shape),
            chunks=(1, *self.frame_shape),
            dtype=dtype,
            fill_value=np.nan if dtype.kind == "f" else 0,
            dimension_names=("time", *frame_dims),
            serializer={"name": "bytes", "configuration": {"endian": "little"}},
            compressors=BloscCodec(typesize=dtype.itemsize, **FRAME_BLOSC),
        )
        self._data.attrs.update(dict(var_attrs or {}))
        # Frames are encoded here and written as chunk files at the keys zarr gives them: zarr's own write
        # path (an event loop in another thread, buffer copies) costs ~1 ms of CPU per frame on top of the
        # encoding, as much as parsing the frame. The bytes are those of the array's codecs
        # (little-endian values, then blosc), so zarr and xarray read the store as usual.
        self._dtype = dtype.newbyteorder("<")
        self._blosc = numcodecs.Blosc(cname=FRAME_BLOSC["cname"], clevel=FRAME_BLOSC["clevel"],
                                      shuffle=_BLOSC_SHUFFLE[FRAME_BLOSC["shuffle"]], blocksize=0,
                                      typesize=dtype.itemsize)
        self._data_dir = self._tmp / name
        self._folders: set[str] = set()
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
        self._attrs = {k: v for k, v in dict(attrs or {}).items() if k not in (COMPLETE_ATTR, CHUNKS_ATTR)}
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
        if not 0 <= index < self.n_frames:
            raise DataError(f"{self.path}: frame index {index} outside 0..{self.n_frames - 1}")
        key = self._data.metadata.encode_chunk_key((index,) + (0,) * len(self.frame_shape))
        self._make_folders(key.rpartition("/")[0])
        (self._data_dir / key).write_bytes(self._blosc.encode(np.ascontiguousarray(frame, dtype=self._dtype)))
        self._time_buf[index] = time
        for k, v in extra.items():
            self._extra_buf[k][index] = v
        self._written[index] = True

    def _make_folders(self, folder: str) -> None:
        """Create the chunk folder ``folder`` (``c/7/0``) and those above it, each once (no failed mkdir calls)."""
        if folder in self._folders:
            return
        head = folder.rpartition("/")[0]
        if head:
            self._make_folders(head)
        with contextlib.suppress(FileExistsError):
            os.mkdir(os.path.join(self._data_dir, folder))
        self._folders.add(folder)

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
        try:
            self._time[:] = self._time_buf
            for k, arr in self._extra.items():
                arr[:] = self._extra_buf[k]
            self._root.attrs.update(self._attrs)
            _mark_complete(self._tmp)
        except OSError as exc:
            self._fail(exc)
        self._closed = True
        self._ctx.__exit__(None, None, None)
        return self.path

    def _fail(self, exc: OSError):
        """Discard the store and raise the error naming it (disk full while writing), or ``exc`` as it is."""
        self.abort()
        failure = write_failure(exc, self._tmp, self.path)
        if failure is None:
            raise exc
        raise failure from exc

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
        elif isinstance(exc, OSError):
            self._fail(exc)
        else:
            self.abort()
