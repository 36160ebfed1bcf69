"""Snakemake script: every figure of the results folder -> results/report.html.

Inputs
------
- ``figures``: the PNGs (Snakemake's bookkeeping; the page collects them from ``params.results``).

Outputs
-------
- ``html``: ``results/report.html``.

Params
------
- ``results``: the results folder.
"""

from irdic.stages import report

report.run({"results": snakemake.params.results}, snakemake.output, log=snakemake.log[0],  # noqa: F821
           threads=snakemake.threads)  # noqa: F821
