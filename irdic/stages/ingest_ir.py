"""Ingest stage entry, IR: a series of IR exports -> ``ir.zarr``.

The reading, checks and the time axis are :func:`irdic.ingest.ir.ingest_ir`; here
the paths are checked and the stage's logging and threads set.
"""

from __future__ import annotations

import os
from typing import Mapping

from ..ingest.ir import ingest_ir
from .common import paths, stage_context

__all__ = ["run", "ingest_ir"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Stage entry: ``inputs["source"]`` (folder, glob or file of IR exports) -> ``outputs["store"]`` (ir.zarr).

    ``params`` as ``experiments.<name>.ir`` of the configuration without
    ``path`` (see :func:`irdic.ingest.ir.ingest_ir`); ``log`` a log file (Snakemake),
    ``threads`` the CPU threads of the stage (default all cores).
    """
    i = paths(inputs, "ingest_ir", "inputs", ("source",))
    o = paths(outputs, "ingest_ir", "outputs", ("store",), against=i)
    with stage_context("ingest-ir", log, threads):
        ingest_ir(i["source"], o["store"], **params)
