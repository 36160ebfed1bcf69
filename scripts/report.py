"""Snakemake script: the figures of this configuration's setups and experiments -> results/report.html.

Inputs
------
- ``figures``: the PNGs the page shows, in pipeline order (calibrations, then each experiment's figures);
- ``stores``: the calibration and fields stores (the ``auto`` choices in the page's header).

Outputs
-------
- ``html``: ``results/report.html``.

Params
------
- ``title``: the configuration file(s);
- ``settings``: the configuration's non-default parameters.
"""

from irdic.stages import report

report.run(snakemake.input, snakemake.output, title=snakemake.params.title,  # noqa: F821
           settings=snakemake.params.settings, log=snakemake.log[0], threads=snakemake.threads)  # noqa: F821
