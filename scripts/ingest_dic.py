"""Snakemake script: DIC stage exports of one experiment -> dic.zarr."""

from irdic.ingest import ingest_dic
from irdic.logs import stage_logging

with stage_logging(snakemake.log[0], "ingest-dic", threads=snakemake.threads):  # noqa: F821
    src = dict(snakemake.params.source)  # noqa: F821
    ingest_dic(src.pop("path"), snakemake.output[0], **src)  # noqa: F821
