"""Ingest stage, testing machine: a machine record (CSV/TXT) -> ``machine.zarr``.

The reader and the store layout are :func:`irdic.signals.ingest_machine`;
this entry names the files and fills ``experiments.<name>.machine`` from the
schema.
"""

from __future__ import annotations

import os
from typing import Mapping

from .common import optional_path, paths, stage_context
from ..parameters import settings

__all__ = ["run"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Stage entry: ``inputs["source"]`` (machine record) -> ``outputs["store"]`` (machine.zarr).

    With ``inputs["ir"]`` (the experiment's ``ir.zarr``) the store also holds
    the signals at the IR frame times (``signal_value_ir``).

    ``params`` as ``experiments.<name>.machine`` of the configuration without
    ``path`` (``columns`` required); ``log`` a log file (Snakemake),
    ``threads`` the CPU threads of the stage (default all cores).
    """
    from ..signals import ingest_machine

    from ..store import open_store

    i = paths(inputs, "ingest_machine", "inputs", ("source",), optional=("ir",))
    o = paths(outputs, "ingest_machine", "outputs", ("store",), against=i)
    with stage_context("ingest-machine", log, threads):
        ir = optional_path(i, "ir")
        ir_times = open_store(ir, "ingest-ir")["time"].values if ir is not None else None
        ingest_machine(i["source"], o["store"], ir_times=ir_times,
                       **settings("machine_source", params, drop=("path",)))
