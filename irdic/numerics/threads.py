"""Thread pools of a stage: its parallel parts share the stage's thread budget.

The stage's thread budget (:func:`irdic.threads.thread_budget`) caps the
workers; while a pool runs, each worker runs single-threaded BLAS (LAPACK and
BLAS release the GIL, so the workers' factorisations run at once). A pool started inside a pool's worker runs
inline (:func:`workers` is 1 there): the stage's threads are taken, and a
nested pool would run more threads than the stage was given.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

from ..threads import blas_threads, thread_budget

__all__ = ["workers", "parallel_map", "map_beside", "both", "worker_slices", "blas_threads"]

#: set in the threads of a pool of this module
_pool = threading.local()


def workers():
    """Workers of :func:`parallel_map`: the stage's thread budget, at most 8; 1 inside a pool's worker.

    Beyond 8 the tiles are too few to share.
    """
    if getattr(_pool, "inside", False):
        return 1
    return max(1, min(thread_budget(), 8))


def _marked():
    _pool.inside = True


def parallel_map(fn, items):
    """``list(map(fn, items))`` on a thread pool of :func:`workers` threads.

    While the pool runs, BLAS runs on one thread per worker
    (:func:`blas_threads`): threaded BLAS beside the other workers would run
    more threads than the stage was given, and only contend. Run in the
    calling thread (one worker or one item), BLAS keeps the stage's threads.
    """
    items = list(items)
    n = workers()
    if n == 1 or len(items) < 2:
        return [fn(i) for i in items]
    with blas_threads(1), ThreadPoolExecutor(max_workers=n, initializer=_marked) as ex:
        return list(ex.map(fn, items))


def worker_slices(n):
    """Consecutive slices of ``range(n)``, one per worker of :func:`parallel_map` at most (``ceil(n / workers)``
    items each)."""
    step = max(1, -(-n // workers()))
    return [slice(i, i + step) for i in range(0, n, step)]


def map_beside(task, fn, items):
    """``(task(), list(map(fn, items)))`` on one pool of :func:`workers` threads: ``task`` starts first on one
    worker, the items share the others and take that one too once ``task`` is done.

    For an independent job of one thread (the couple stage's IR clock) beside many small ones (its masks):
    the stage's threads stay busy to the end and the job costs no thread beyond the budget. With one worker,
    ``task`` runs first, then the items.
    """
    items = list(items)
    n = workers()
    if n == 1:
        return task(), [fn(i) for i in items]

    queued = threading.Event()

    def beside():  # the task may hand work to a worker the items leave free (:func:`both`)
        # once the items are queued: what the task hands on is queued behind them, not taken before them
        queued.wait()
        _pool.spare = ex
        try:
            return task()
        finally:
            _pool.spare = None

    with blas_threads(1), ThreadPoolExecutor(max_workers=n, initializer=_marked) as ex:
        first = ex.submit(beside)  # the pool's queue is first in, first out
        try:
            results = ex.map(fn, items)  # every item submitted here
        finally:
            queued.set()
        rest = list(results)
        return first.result(), rest


def both(first, second):
    """``(first(), second())``, the two at once where a thread of the stage is free for ``second``.

    Outside a pool with two workers or more, on a pool of two. In the job
    run beside a pool's items (:func:`map_beside`), ``second`` is queued on
    that pool behind the items and taken by the first worker they leave
    free; if none has taken it when ``first`` is done, it runs here. Inside
    any other pool's worker, one after the other. Never more threads than
    the stage was given.
    """
    spare = getattr(_pool, "spare", None)
    if spare is not None:
        later = spare.submit(second)
        try:
            a = first()
        except BaseException:
            later.cancel()
            raise
        return a, (second() if later.cancel() else later.result())
    if workers() > 1:
        return tuple(parallel_map(lambda f: f(), [first, second]))
    return first(), second()
