"""Snakemake script: temperatures at the DIC points of one experiment -> points.zarr."""

from irdic.couple import couple_stores
from irdic.logs import stage_logging

with stage_logging(snakemake.log[0], "couple", threads=snakemake.threads):  # noqa: F821
    i = snakemake.input  # noqa: F821
    couple_stores(i.dic, i.ir, i.calibration, snakemake.output[0], **snakemake.params.settings)  # noqa: F821
