"""Couple stage entry: ``dic.zarr``, ``ir.zarr`` and ``calibration.zarr`` -> ``points.zarr``.

The computation is :func:`irdic.coupling.couple` (projection, masks,
interpolation of the pixel temperatures at the DIC points, status, IR
noise); here the stores are read and the store written, for the whole
record or one time chunk, and the chunks gathered.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

from ..coupling import couple
from ..coupling.dataset import gathered_points
from ..store import open_store, write_dataset
from .common import paths, stage_context

__all__ = ["run", "run_gather", "couple"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, chunk: tuple[int, int] | None = None,
        **params) -> None:
    """Stage entry: ``inputs`` dic, ir, calibration (stores) -> ``outputs["store"]`` (points.zarr).

    ``params``: the ``interpolation`` section of the configuration (see
    :func:`irdic.coupling.couple`); ``log`` a log file (Snakemake), ``threads`` the CPU
    threads of the stage (default all cores); ``chunk`` (index, count):
    write only that time chunk (``results/<experiment>/chunks/points-<i>.zarr``,
    gathered by :func:`run_gather`).
    """
    i = paths(inputs, "couple", "inputs", ("dic", "ir", "calibration"))
    o = paths(outputs, "couple", "outputs", ("store",), against=i)
    with stage_context("couple", log, threads):
        # results/<experiment>/ir.zarr: the experiment's name for messages about its configuration
        ds = couple(open_store(i["dic"], "ingest-dic"), open_store(i["ir"], "ingest-ir"),
                    open_store(i["calibration"], "calibrate"), chunk=chunk,
                    experiment=Path(i["ir"]).parent.name, **params)
        write_dataset(ds, o["store"], stage="couple", params=params,
                      inputs=[os.fspath(i[k]) for k in ("dic", "ir", "calibration")],
                      encoding={"temperature": {"chunks": (1, ds.sizes["point"])}})


def run_gather(inputs: Mapping[str, Sequence[str | os.PathLike]], outputs: Mapping[str, str | os.PathLike], *,
               log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Gather entry: ``inputs["chunks"]`` (chunk stores in time order) -> ``outputs["store"]`` (points.zarr)."""
    o = paths(outputs, "couple", "outputs", ("store",))
    parts = [os.fspath(q) for q in paths(inputs, "couple-gather", "inputs", ("chunks",))["chunks"]]
    with stage_context("couple-gather", log, threads):
        ds, rest = gathered_points([open_store(q, "couple") for q in parts])
        write_dataset(ds, o["store"], stage="couple", params=params, inputs=parts, append=rest,
                      encoding={"temperature": {"chunks": (1, ds.sizes["point"])}})
