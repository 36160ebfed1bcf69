"""Export stage: ``points.zarr`` (+ ``fields.zarr``) -> a ParaView time series and a CSV of selected points."""

from __future__ import annotations

import os
from typing import Mapping

from ..store import open_store
from ..identity import same_points
from .common import open_optional, optional_path, paths, stage_context, with_heat
from ..parameters import settings

__all__ = ["run"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, experiment: str, points,
        **params) -> None:
    """Stage entry: ``inputs`` points (and fields) -> ``outputs`` paraview (folder of .pvd + .vtu), csv.

    Parameters
    ----------
    inputs : mapping
        ``points``: ``points.zarr``; ``fields`` (optional): ``fields.zarr``; ``heat``
        (optional, with ``fields``): ``heat.zarr``, whose variables join the fields'.
    outputs : mapping
        ``paraview``: folder of the time series; ``csv``: the table.
    log : path-like, optional
        Log file (Snakemake's ``log:``).
    threads : int, optional
        CPU threads of the stage (default all cores).
    experiment : str
        Name of the experiment (messages).
    points : sequence of int
        ``experiments.<name>.report.points``; empty: the central point.
    **params
        The ``export`` section of the configuration (``csv_points``,
        ``paraview_precision``, ``paraview_every``); absent keys take the
        schema's defaults.
    """
    from ..export import write_csv, write_paraview
    from ..selection import select_points

    i = paths(inputs, "export", "inputs", ("points",), ("fields", "heat"))
    o = paths(outputs, "export", "outputs", ("paraview", "csv"))
    with stage_context("export", log, threads):
        p = settings("export", params)
        pts = open_store(i["points"], "couple")
        fields = open_optional(optional_path(i, "fields"), "fields")
        if fields is not None:
            same_points(pts, i["points"], fields, i["fields"])
        fields = with_heat(fields, open_optional(optional_path(i, "heat"), "heat"))
        ids = "all" if p["csv_points"] == "all" else select_points(
            pts, list(points) if points else None, name=f"experiments.{experiment}.report.points")
        write_paraview(pts, o["paraview"], fields=fields, dtype=p["paraview_precision"], every=p["paraview_every"])
        write_csv(pts, o["csv"], fields=fields, point_ids=ids)
