"""Snakemake script: ParaView time series (.pvd + .vtu) and CSV of selected points of one experiment."""

from irdic.logs import stage_logging
from irdic.pipeline import export_experiment

with stage_logging(snakemake.log[0], "export", threads=snakemake.threads):  # noqa: F821
    i, o, p = snakemake.input, snakemake.output, snakemake.params  # noqa: F821
    export_experiment(i.points, i.get("fields"), o.paraview, o.csv, experiment=snakemake.wildcards.experiment,  # noqa: F821
                      point_ids=p.points, csv_points=p.csv_points, precision=p.precision, every=p.every)
