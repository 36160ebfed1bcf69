"""Snakemake script: the testing machine record of one experiment -> machine.zarr."""

from irdic.logs import stage_logging
from irdic.signals import ingest_machine

with stage_logging(snakemake.log[0], "ingest-machine"):  # noqa: F821
    src = dict(snakemake.params.source)  # noqa: F821
    ingest_machine(src.pop("path"), snakemake.output[0], **src)  # noqa: F821
