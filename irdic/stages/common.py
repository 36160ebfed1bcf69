"""What every stage entry does first: name its paths, and run with its log and threads."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterator, Mapping

from ..config import input_folder
from ..errors import ConfigError
from ..logs import stage_logging
from ..threads import stage_threads

__all__ = ["stage_context", "paths", "optional_path", "open_optional", "with_heat", "apart"]


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


def paths(given, stage: str, what: str, required: tuple[str, ...], optional: tuple[str, ...] = (), *,
          against: Mapping | None = None) -> dict:
    """The named paths of a stage's ``inputs`` or ``outputs``.

    ``given`` is a mapping or a Snakemake ``Namedlist`` (``snakemake.input``);
    outputs are checked ``against`` the stage's inputs (:func:`apart`).

    Raises
    ------
    ConfigError
        A required name is missing or an unknown one is given, or an output
        overlaps an input.
    """
    items = dict(given.items()) if hasattr(given, "items") else dict(given)
    missing = [k for k in required if items.get(k) is None]
    unknown = sorted(set(items) - set(required) - set(optional))
    if missing or unknown:
        raise ConfigError(f"stage {stage}: {what} must name {', '.join(required)}"
                          f"{' (optional: ' + ', '.join(optional) + ')' if optional else ''}; "
                          f"missing {missing or 'none'}, unknown {unknown or 'none'}")
    if against is not None:
        apart(against, items, stage)
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


def apart(inputs: Mapping, outputs: Mapping, stage: str) -> None:
    """Refuse outputs that overlap inputs, before the stage reads anything.

    An output inside an input folder would join the series it is made from
    on the next run; an input inside an output would be deleted when the
    output is replaced. Links are followed; a glob counts as its folder.

    Raises
    ------
    ConfigError
        Naming the stage, both paths and their roles.
    """
    for o_name, o_path in outputs.items():
        if not o_path or isinstance(o_path, (list, tuple)):
            continue
        out, _ = input_folder(o_path)
        for i_name, given in inputs.items():
            for one in (given if isinstance(given, (list, tuple)) else [given]):
                if not one:
                    continue
                inp, folder = input_folder(one)
                if inp == out or out in inp.parents or (folder and inp in out.parents):
                    where = "is" if inp == out else "lies inside" if out in inp.parents else "contains"
                    raise ConfigError(f"stage {stage}: input {i_name} {one} {where} output {o_name} {o_path}; "
                                      "inputs and outputs must not overlap (an output replaces what lies in "
                                      "it, and an output in an input folder joins that input)")


def with_heat(fields, heat):
    """``fields`` with the variables of ``heat.zarr`` (heat source, Laplacian, the balance's terms) beside
    its own; ``fields`` alone when there is no heat store."""
    if heat is None or fields is None:
        return fields
    return fields.merge(heat.drop_vars([c for c in heat.coords if c not in ("time", "point")]),
                        join="left", combine_attrs="override")

