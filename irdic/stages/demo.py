"""Demo stage entry: no inputs -> the demo folder and its ``manifest.yaml``.

The folder is written by :func:`irdic.synthetic.demo_folder.make_demo`
(what an earlier demo wrote is replaced file by file from the record it
kept; a folder holding anything else is refused before anything is
touched).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

from ..synthetic.demo_folder import make_demo
from .common import paths, stage_context

__all__ = ["run", "make_demo"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Stage entry: no inputs -> ``outputs["manifest"]`` (the demo is written into its folder).

    ``params``: the ``demo`` section of the configuration without ``enabled``
    and ``outdir`` (see :func:`irdic.synthetic.demo_folder.make_demo`); ``log`` a log file (Snakemake),
    ``threads`` the CPU threads of the stage (default all cores).
    """
    paths(inputs, "demo", "inputs", ())
    o = paths(outputs, "demo", "outputs", ("manifest",))
    with stage_context("demo", log, threads):
        make_demo(Path(o["manifest"]).parent, manifest=o["manifest"], **params)
