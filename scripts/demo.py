"""Snakemake script: generate the synthetic demo (raw exports in real formats + analytic truth).

Inputs
------
- none.

Outputs
-------
- ``manifest``: ``<demo.outdir>/manifest.yaml``, written last; the demo is
  written into its folder.

Params
------
- ``settings``: the ``demo`` section without ``enabled`` and ``outdir``
  (``scale``, ``ir_noise``, ``dic_noise``, ``seed``).
"""

from irdic.stages import demo

demo.run({}, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
         **snakemake.params.settings)  # noqa: F821
