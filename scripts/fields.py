"""Snakemake script: gradient, rate and strain fields of one experiment -> fields.zarr."""

from irdic.fields import fields_stores
from irdic.logs import stage_logging

with stage_logging(snakemake.log[0], "fields", threads=snakemake.threads):  # noqa: F821
    i = snakemake.input  # noqa: F821
    fields_stores(i.points, i.calibration, snakemake.output[0], dic=i.dic, machine=i.get("machine"),  # noqa: F821
                  **snakemake.params.settings)  # noqa: F821
