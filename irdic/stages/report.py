"""Report stage: every figure under a results folder -> one HTML page with the figures' own captions."""

from __future__ import annotations

import os
from typing import Mapping

from .common import paths, stage_context

__all__ = ["run"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None) -> None:
    """Stage entry: ``inputs["results"]`` (the results folder) -> ``outputs["html"]`` (see :mod:`irdic.report`).

    Parameters
    ----------
    inputs : mapping
        ``results``: the results folder; other entries (the figures, for
        Snakemake's bookkeeping) are ignored.
    outputs : mapping
        ``html``: the page to write.
    log, threads
        As every stage.
    """
    from ..report import write_report

    items = dict(inputs.items()) if hasattr(inputs, "items") else dict(inputs)
    i = paths({"results": items.get("results")}, "report", "inputs", ("results",))
    o = paths(outputs, "report", "outputs", ("html",))
    with stage_context("report", log, threads):
        write_report(i["results"], o["html"])
