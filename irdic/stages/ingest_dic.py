"""Ingest stage entry, DIC: a series of DIC exports -> ``dic.zarr``.

The reading, checks and the time axis are :func:`irdic.ingest.dic.ingest_dic`; here
the paths are checked and the stage's logging and threads set.
"""

from __future__ import annotations

import os
from typing import Mapping

from ..ingest.dic import ingest_dic
from .common import paths, stage_context

__all__ = ["run", "ingest_dic"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Stage entry: ``inputs["source"]`` (folder, glob or file of DIC exports) -> ``outputs["store"]`` (dic.zarr).

    ``params`` as ``experiments.<name>.dic`` of the configuration without
    ``path`` (see :func:`irdic.ingest.dic.ingest_dic`); ``log`` a log file (Snakemake),
    ``threads`` the CPU threads of the stage (default all cores).
    """
    i = paths(inputs, "ingest_dic", "inputs", ("source",))
    o = paths(outputs, "ingest_dic", "outputs", ("store",), against=i)
    with stage_context("ingest-dic", log, threads):
        ingest_dic(i["source"], o["store"], **params)
