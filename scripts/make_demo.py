"""Snakemake script: generate the synthetic demo experiment (raw exports + truth)."""

from irdic.logs import stage_logging
from irdic.pipeline import make_demo

with stage_logging(snakemake.log[0], "demo", threads=snakemake.threads):  # noqa: F821
    p = snakemake.params  # noqa: F821
    make_demo(p.outdir, scale=p.scale, ir_noise=p.ir_noise, dic_noise=p.dic_noise, seed=p.seed,
              manifest=snakemake.output.manifest)  # noqa: F821
