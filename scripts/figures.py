"""Snakemake script: figures of one experiment (points.zarr, fields.zarr if there) -> PNGs."""

from irdic.logs import stage_logging
from irdic.pipeline import make_figures

with stage_logging(snakemake.log[0], "figures", threads=snakemake.threads):  # noqa: F821
    i, p = snakemake.input, snakemake.params  # noqa: F821
    make_figures(i.points, i.get("fields"), dict(snakemake.output.items()),  # noqa: F821
                 experiment=snakemake.wildcards.experiment, times=p.times, point_ids=p.points)  # noqa: F821
