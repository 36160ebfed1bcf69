"""CPU threads of a stage: BLAS and OpenMP pools limited once at stage entry.

Every stage (Snakemake script, CLI command, :func:`irdic.pipeline.run`)
runs inside :func:`stage_threads` with the threads it was given. Without a
limit every process starts one BLAS thread per core; several jobs on one
machine then fight over the cores, and the many small factorisations of the
couple stage become up to 30 x slower (two couple runs at once on 2 cores:
8.7 x their time alone). Code that runs its own thread pool inside a stage
(:mod:`irdic.surface`) asks :func:`thread_budget` how many workers it may use
and limits BLAS to one thread per worker with :func:`blas_threads`.
"""

from __future__ import annotations

import contextlib
import numbers
import os
import threading
from typing import Iterator

from threadpoolctl import threadpool_limits

from .errors import ConfigError

__all__ = ["stage_threads", "thread_budget", "blas_threads", "default_threads"]

#: threads of the stage being run (None outside a stage: all cores)
_budget: int | None = None


def default_threads() -> int:
    """The cores this process may run on (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _check(threads, name="threads") -> int:
    if isinstance(threads, bool) or not isinstance(threads, numbers.Integral):
        raise ConfigError(f"{name} must be a whole number of CPU threads >= 1, got {threads!r}")
    n = int(threads)
    if n < 1:
        raise ConfigError(f"{name} must be a whole number of CPU threads >= 1, got {n}")
    return n


def thread_budget() -> int:
    """Threads the running stage was given (all cores outside a stage)."""
    return _budget if _budget is not None else default_threads()


@contextlib.contextmanager
def stage_threads(threads: int | None = None) -> Iterator[int]:
    """Run a stage with ``threads`` CPU threads for BLAS and OpenMP.

    Parameters
    ----------
    threads : int, optional
        Threads the stage was given (Snakemake's ``threads`` of the rule,
        ``--threads`` on the command line); None: every core this process may
        run on.

    Yields
    ------
    int
        The number of threads in force.

    Raises
    ------
    ConfigError
        ``threads`` is not a whole number >= 1.
    """
    global _budget
    n = default_threads() if threads is None else _check(threads)
    old = _budget
    _budget = n
    try:
        with threadpool_limits(limits=n):
            yield n
    finally:
        _budget = old


@contextlib.contextmanager
def blas_threads(n: int) -> Iterator[None]:
    """Limit BLAS to ``min(n, thread_budget())`` threads inside the block.

    For code that runs many small factorisations or products on its own
    thread pool: threaded BLAS spends more time synchronising than computing
    on them (measured 3 GF/s against 30 GF/s single-threaded for n = 1000 on a
    loaded 2-core VM).

    Notes
    -----
    BLAS has one limit for the process, so the blocks of all threads share
    it: the first to enter sets it, a later one may only lower it, and the
    last to leave restores the stage's. That is the block of a pool's caller
    (:func:`irdic.numerics.threads.parallel_map`), whose workers, and their own
    blocks, end before it; OpenBLAS 0.3.30 applies a limit set from a worker
    thread to that thread only, so a worker restoring the limit it found would
    not restore the process's.
    """
    limit = max(1, min(int(n), thread_budget()))
    with _BLAS_LOCK:
        if _blas["depth"] == 0:
            _blas["limits"], _blas["limit"] = threadpool_limits(limits=limit, user_api="blas"), limit
        elif limit < _blas["limit"]:
            threadpool_limits(limits=limit, user_api="blas")
            _blas["limit"] = limit
        _blas["depth"] += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _blas["depth"] -= 1
            if _blas["depth"] == 0:
                _blas.pop("limits").restore_original_limits()


#: the BLAS limit of :func:`blas_threads` in force: blocks inside it (all threads), the limit, its restorer
_blas: dict = {"depth": 0}
_BLAS_LOCK = threading.Lock()
