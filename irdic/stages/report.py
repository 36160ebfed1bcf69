"""Report stage: the figures of one run -> one HTML page with the figures' own captions and a header."""

from __future__ import annotations

import os
from typing import Mapping

from .common import paths, stage_context

__all__ = ["run"]


def run(inputs: Mapping, outputs: Mapping[str, str | os.PathLike], *, title: str | None = None,
        settings: Mapping | None = None, log: str | os.PathLike | None = None, threads: int | None = None) -> None:
    """Stage entry: figures (and stores) of one run -> ``outputs["html"]`` (see :mod:`irdic.report`).

    Parameters
    ----------
    inputs : mapping
        ``figures``: the PNGs of the run (each setup's ``calibration.png``,
        each experiment's ``figures/*.png``): the page shows exactly these,
        in pipeline order; ``stores`` (optional): the calibration and fields
        stores, whose ``auto`` choices the header lists. Without ``figures``,
        ``results``: every figure under that folder (``irdic report``).
    outputs : mapping
        ``html``: the page to write.
    title : str, optional
        What the page is of: the configuration file (default: the results folder).
    settings : mapping, optional
        The configuration's non-default parameters (:func:`irdic.config.non_defaults`).
    log, threads
        As every stage.
    """
    from ..report import collect_figures, order_figures, write_report

    items = dict(inputs.items()) if hasattr(inputs, "items") else dict(inputs)
    i = paths(items, "report", "inputs", (), ("figures", "stores", "results"))
    o = paths(outputs, "report", "outputs", ("html",))
    with stage_context("report", log, threads):
        if i.get("figures"):
            figures = order_figures(i["figures"])
        else:
            paths({"results": i.get("results")}, "report", "inputs", ("results",))
            figures = collect_figures(i["results"])
        write_report(figures, o["html"], title=str(title or i.get("results") or o["html"]), settings=settings,
                     stores=list(i.get("stores") or []))
