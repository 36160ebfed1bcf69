"""Snakemake script: calibrate the IR camera of one setup -> calibration.zarr + figure."""

from irdic.logs import stage_logging
from irdic.pipeline import calibrate_setup

with stage_logging(snakemake.log[0], "calibrate", threads=snakemake.threads):  # noqa: F821
    p = snakemake.params  # noqa: F821
    calibrate_setup(p.markers, p.target, snakemake.output.store, snakemake.output.figure,  # noqa: F821
                    seeds=p.seeds, **p.settings)
