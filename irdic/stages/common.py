"""What every stage entry does first: name its paths, and run with its log and threads."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterator, Mapping

from ..errors import ConfigError
from ..logs import stage_logging
from ..threads import stage_threads

__all__ = ["stage_context", "paths", "optional_path", "open_optional"]


@contextlib.contextmanager
def stage_context(stage: str, log: str | os.PathLike | None, threads: int | None) -> Iterator[None]:
    """Run a stage with ``threads`` CPU threads (once, here), logging to ``log`` when given.

    With a log file (the Snakemake ``log:`` of the rule) an
    :class:`~irdic.errors.IrdicError` becomes one line in the log and a
    non-zero exit (:func:`irdic.logs.stage_logging`); without one (the CLI,
    :func:`irdic.pipeline.run`, tests) it propagates to the caller.
    """
    if log is not None:
        with stage_logging(log, stage, threads=threads):
            yield
    else:
        with stage_threads(threads):
            yield


def paths(given, stage: str, what: str, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict:
    """The named paths of a stage's ``inputs`` or ``outputs``.

    ``given`` is a mapping or a Snakemake ``Namedlist`` (``snakemake.input``).

    Raises
    ------
    ConfigError
        A required name is missing or an unknown one is given.
    """
    items = dict(given.items()) if hasattr(given, "items") else dict(given)
    missing = [k for k in required if items.get(k) is None]
    unknown = sorted(set(items) - set(required) - set(optional))
    if missing or unknown:
        raise ConfigError(f"stage {stage}: {what} must name {', '.join(required)}"
                          f"{' (optional: ' + ', '.join(optional) + ')' if optional else ''}; "
                          f"missing {missing or 'none'}, unknown {unknown or 'none'}")
    return items


def optional_path(items: Mapping, name: str):
    """``items[name]``, or None when it is absent or empty (an optional store not configured)."""
    v = items.get(name)
    return v if v else None


def open_optional(path, kind: str | None = None):
    """The store at ``path`` (of ``kind``, see :func:`irdic.store.open_store`), or None when no path is given or
    nothing is there (fields.zarr is optional)."""
    from ..store import open_store

    return open_store(path, kind) if path is not None and Path(path).exists() else None
