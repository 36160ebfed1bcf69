"""Fields stage entry: ``points.zarr`` and ``calibration.zarr`` -> ``fields.zarr``.

The computation is :func:`irdic.fields.fields` (the surface, the
temperature gradient and rate, the strain and their uncertainties); here the
stores are read, the testing machine's signals added at the DIC times, and
the store written, for the whole record or one time chunk.
"""

from __future__ import annotations

import os
from typing import Mapping, Sequence

from ..chunks import gathered
from ..fields import fields
from ..store import open_store, write_dataset
from ..identity import fields_inputs
from .common import optional_path, paths, stage_context

__all__ = ["run", "run_gather", "fields"]


def run(inputs: Mapping[str, str | os.PathLike], outputs: Mapping[str, str | os.PathLike], *,
        log: str | os.PathLike | None = None, threads: int | None = None, chunk: tuple[int, int] | None = None,
        **params) -> None:
    """Stage entry: ``inputs`` points, calibration (and dic, machine) -> ``outputs["store"]`` (fields.zarr).

    ``dic`` (``dic.zarr``) and ``machine`` (``machine.zarr``), when given,
    add the testing machine signals at the DIC times:
    ``signal_value(time, signal)`` with the signal coordinates (see
    :func:`irdic.signals.signals_at`; machine signals prefixed ``machine_``).
    ``params``: the ``fields`` section of the configuration (see
    :func:`fields`); ``log`` a log file (Snakemake), ``threads`` the CPU
    threads of the stage (default all cores); ``chunk`` (index, count):
    write only that time chunk (``results/<experiment>/chunks/fields-<i>.zarr``,
    gathered by :func:`run_gather`).
    """
    from ..signals import signals_at

    i = paths(inputs, "fields", "inputs", ("points", "calibration"), ("dic", "machine"))
    o = paths(outputs, "fields", "outputs", ("store",), against=i)
    dic, machine = optional_path(i, "dic"), optional_path(i, "machine")
    with stage_context("fields", log, threads):
        points, calibration, dic_ds, machine_ds = fields_inputs(i["points"], i["calibration"], dic, machine)
        ds = fields(points, calibration, chunk=chunk, **params)
        sig = signals_at(ds["time"].values, dic=dic_ds, machine=machine_ds)
        if sig is not None:
            ds = ds.merge(sig.drop_vars("time"))
        inputs_used = [os.fspath(i["points"]), os.fspath(i["calibration"])]
        inputs_used += [os.fspath(q) for q in (dic, machine) if q is not None]
        write_dataset(ds, o["store"], stage="fields", params=params, inputs=inputs_used)


def run_gather(inputs: Mapping[str, Sequence[str | os.PathLike]], outputs: Mapping[str, str | os.PathLike], *,
               log: str | os.PathLike | None = None, threads: int | None = None, **params) -> None:
    """Gather entry: ``inputs["chunks"]`` (chunk stores in time order) -> ``outputs["store"]`` (fields.zarr)."""
    o = paths(outputs, "fields", "outputs", ("store",))
    parts = [os.fspath(q) for q in paths(inputs, "fields-gather", "inputs", ("chunks",))["chunks"]]
    with stage_context("fields-gather", log, threads):
        first, rest = gathered([open_store(q, "fields") for q in parts])
        write_dataset(first, o["store"], stage="fields", params=params, append=rest,
                      inputs=parts)
