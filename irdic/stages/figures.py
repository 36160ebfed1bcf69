"""Figures stage: ``points.zarr`` (+ ``fields.zarr``) of one experiment -> PNGs for ``snakemake --report``."""

from __future__ import annotations

import os
from typing import Mapping

from ..store import open_store
from ..identity import same_points
from .common import open_optional, optional_path, paths, stage_context, with_heat

__all__ = ["run"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, experiment: str, times, points) -> None:
    """Stage entry: ``inputs`` points (and fields) -> ``outputs`` ``{figure name: PNG path}``.

    Parameters
    ----------
    inputs : mapping
        ``points``: ``points.zarr``; ``fields`` (optional): ``fields.zarr``; ``heat`` (optional,
        with ``fields``): ``heat.zarr``, for the heat figure.
    outputs : mapping
        PNG path of each figure by name (keys of :data:`irdic.plot.FIGURES`, or ``heat``).
    log : path-like, optional
        Log file (Snakemake's ``log:``).
    threads : int, optional
        CPU threads of the stage (default all cores).
    experiment : str
        Name of the experiment (titles, messages).
    times, points : sequence
        ``experiments.<name>.report.times`` (s) and ``.points`` (IDs); empty:
        the defaults of :mod:`irdic.selection`.
    """
    from ..plot import plot_experiment
    from ..selection import select_points, select_times

    i = paths(inputs, "figures", "inputs", ("points",), ("fields", "heat"))
    with stage_context("figures", log, threads):
        pts = open_store(i["points"], "couple")
        fields = open_optional(optional_path(i, "fields"), "fields")
        if fields is not None:
            same_points(pts, i["points"], fields, i["fields"])
        fields = with_heat(fields, open_optional(optional_path(i, "heat"), "heat"))
        key = f"experiments.{experiment}.report"
        t = pts["time"].values
        sel_t = t[select_times(t, list(times) if times else None, name=f"{key}.times")]
        ids = select_points(pts, list(points) if points else None, name=f"{key}.points")
        plot_experiment(pts, {str(k): v for k, v in outputs.items()}, fields=fields, times=sel_t, point_ids=ids,
                        experiment=experiment)
