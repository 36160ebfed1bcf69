"""Heat stage: ``fields.zarr`` + ``points.zarr`` of one experiment -> ``heat.zarr`` (the local heat balance)."""

from __future__ import annotations

import os
from typing import Mapping

from ..store import open_store, write_dataset
from .common import paths, stage_context
from ..parameters import settings

__all__ = ["run"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, fields_settings: Mapping | None = None,
        **material) -> None:
    """Stage entry: ``inputs`` fields, points -> ``outputs["store"]`` (heat.zarr).

    Parameters
    ----------
    inputs : mapping
        ``fields``: ``fields.zarr``; ``points``: ``points.zarr`` of the same experiment.
    outputs : mapping
        ``store``: ``heat.zarr``.
    log : path-like, optional
        Log file (Snakemake's ``log:``).
    threads : int, optional
        CPU threads of the stage (default all cores).
    fields_settings : mapping, optional
        The ``fields`` section (its ``c_space``, ``R0_space``: the kernel of the regressions in Ψ).
    **material
        ``experiments.<name>.material`` (see :func:`irdic.heat.dataset.heat_dataset`); absent keys
        take the schema's defaults.
    """
    from ..heat.dataset import heat_dataset
    from ..footprint.fields import pixel_pitch

    i = paths(inputs, "heat", "inputs", ("fields", "points"))
    o = paths(outputs, "heat", "outputs", ("store",))
    with stage_context("heat", log, threads):
        m = settings("material", material)
        f = settings("fields", dict(fields_settings or {}))
        flds, pts = open_store(i["fields"]), open_store(i["points"])
        psi = flds["surface_parameter"].values if "surface_parameter" in flds else None
        sep = pixel_pitch(pts.sel(point=flds["point"].values), psi) if psi is not None else None
        kernel = {k: f[k] for k in ("c_space", "R0_space", "c_time", "R0_time")}
        ds = heat_dataset(flds, pts, m, c=f["c_space"], R0=f["R0_space"], c_t=f["c_time"], R0_t=f["R0_time"],
                          separation=sep)
        write_dataset(ds, o["store"], stage="heat", params={"material": m, **kernel},
                      inputs=[os.fspath(i["fields"]), os.fspath(i["points"])])
