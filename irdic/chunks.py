"""Time chunks of the couple and fields stages: plan, windows with overlap, gather.

A long record is split into ``n`` chunks of consecutive DIC times
(``execution.chunk_frames`` per chunk); each chunk is a separate job (a
Snakemake rule instance, a SLURM job) that reads only the IR frames or DIC
stages its temporal interpolant needs: its own times plus the reach of the
temporal operators on each side (:func:`irdic.numerics.temporal.temporal_window`).
The gather step appends the chunk stores along time, one at a time, to the usual
``points.zarr`` / ``fields.zarr``: the store contract does not change.

The split is by position (:func:`numpy.array_split` of the DIC times into
``n`` parts), so a chunk count fixed when the workflow is planned (from the
number of DIC export files) stays valid whatever the ingested record holds.
"""

from __future__ import annotations

import math
import os
from typing import Iterator, Sequence

import numpy as np
import xarray as xr

from .errors import ConfigError, DataError

__all__ = ["n_chunks", "chunk_slice", "window", "chunk_path", "gathered"]


def n_chunks(n_times: int, chunk_frames: int) -> int:
    """Number of chunks for ``n_times`` DIC times at ``chunk_frames`` per chunk (0: one chunk)."""
    if isinstance(chunk_frames, bool) or not isinstance(chunk_frames, (int, np.integer)) or chunk_frames < 0:
        raise ConfigError(f"execution.chunk_frames must be an integer >= 0 (0: no chunking), got {chunk_frames!r}")
    if chunk_frames == 0 or n_times <= chunk_frames:
        return 1
    return int(math.ceil(n_times / chunk_frames))


def chunk_slice(n_times: int, index: int, count: int) -> slice:
    """DIC times of chunk ``index`` of ``count`` (consecutive, sizes differing by at most one).

    Raises
    ------
    DataError
        The record has fewer DIC times than chunks, or ``index`` is not one of them.
    """
    if not 0 <= index < count:
        raise ConfigError(f"chunk {index} does not exist: the record is split into {count} chunk(s)")
    if n_times < count:
        raise DataError(
            f"the record has {n_times} DIC time(s) but the workflow planned {count} chunks: raise "
            f"execution.chunk_frames (or set it to 0) so that every chunk gets at least one DIC time"
        )
    bounds = np.r_[0, np.cumsum([len(a) for a in np.array_split(np.arange(n_times), count)])]
    return slice(int(bounds[index]), int(bounds[index + 1]))


def window(samples: np.ndarray, t_first: float, t_last: float, reach: int | None) -> slice:
    """Samples a chunk's temporal interpolant needs: those in ``[t_first, t_last]`` plus ``reach`` on each side.

    One more sample on each side than ``reach`` covers evaluation times
    between two samples (the reach counts from the nearest sample).
    ``reach`` None (the global operator, :func:`~irdic.numerics.temporal.temporal_window`):
    every sample.
    """
    if reach is None:
        return slice(0, samples.size)
    lo = int(np.searchsorted(samples, t_first, side="right")) - 1 - reach - 1
    hi = int(np.searchsorted(samples, t_last, side="left")) + 1 + reach + 1
    return slice(max(lo, 0), min(hi, samples.size))


def chunk_path(folder: str | os.PathLike, kind: str, index: int) -> str:
    """``<folder>/chunks/<kind>-<index>.zarr``: where chunk ``index`` of ``points``/``fields`` is written."""
    return os.path.join(os.fspath(folder), "chunks", f"{kind}-{index}.zarr")


def gathered(parts: Sequence[xr.Dataset]) -> tuple[xr.Dataset, Iterator[xr.Dataset]]:
    """The first chunk (loaded) and the others one by one (loaded as they come), for
    :func:`irdic.store.write_dataset`'s ``append``: a gather that holds one chunk in memory at a time.

    Raises
    ------
    DataError
        The chunks overlap or are out of order in time (a chunk store from
        an older run with another chunk count, for instance), checked
        before anything is loaded.
    """
    _check_order(parts)
    # compute(), not load(): a loaded copy that is freed once written, while the caller's lazy stores stay lazy
    return parts[0].compute(), (p.compute() for p in parts[1:])


def _check_order(parts: Sequence[xr.Dataset]) -> None:
    if not parts:
        raise DataError("no chunk stores to gather")
    ends = [(float(p["time"][0]), float(p["time"][-1])) for p in parts]
    for (a0, a1), (b0, _) in zip(ends, ends[1:]):
        if not b0 > a1:
            raise DataError(
                f"chunk stores overlap or are out of order in time ({a0:g}..{a1:g} s, then from {b0:g} s): "
                f"delete the results' chunks folder and run the workflow again"
            )
