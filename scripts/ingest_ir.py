"""Snakemake script: IR exports of one experiment -> ir.zarr."""

from irdic.ingest import ingest_ir
from irdic.logs import stage_logging

with stage_logging(snakemake.log[0], "ingest-ir", threads=snakemake.threads):  # noqa: F821
    src = dict(snakemake.params.source)  # noqa: F821
    ingest_ir(src.pop("path"), snakemake.output[0], **src)  # noqa: F821
