"""Calibrate stage: one IR image of the reference object + the DIC marker export -> ``calibration.zarr``.

The algorithm is :func:`irdic.calibration.calibrate_from_files`; this entry
names the files and fills the ``calibration`` settings from the schema.
"""

from __future__ import annotations

import os
from typing import Mapping

from .common import optional_path, paths, stage_context
from ..parameters import settings

__all__ = ["run"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Stage entry: ``inputs`` markers (centres, mm), target (IR image) -> ``outputs`` store (+ figure PNG).

    Parameters
    ----------
    inputs : mapping
        ``markers``: marker centres export (ID, x, y, z in mm); ``target``:
        IR image of the reference object.
    outputs : mapping
        ``store``: ``calibration.zarr``; ``figure`` (optional): PNG of the
        detections and residuals.
    log : path-like, optional
        Log file (Snakemake's ``log:``).
    threads : int, optional
        CPU threads of the stage (default all cores).
    **params
        ``target_format`` and ``seeds`` (``{marker_id: [u, v]}``) of the
        setup, and the ``calibration`` section of the configuration.
    """
    from ..calibration import calibrate_from_files

    i = paths(inputs, "calibrate", "inputs", ("markers", "target"))
    o = paths(outputs, "calibrate", "outputs", ("store",), ("figure",), against=i)
    rest = dict(params)
    setup = {k: rest.pop(k) for k in ("target_format", "seeds") if k in rest}
    with stage_context("calibrate", log, threads):
        calibrate_from_files(i["markers"], i["target"], o["store"], optional_path(o, "figure"), **setup,
                             **settings("calibration", rest))
