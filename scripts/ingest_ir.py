"""Snakemake script: the IR exports of one experiment -> ir.zarr.

Inputs
------
- the raw IR files (or the demo manifest), for Snakemake's bookkeeping only;
  the series read is ``params.path``.

Outputs
-------
- ``store``: ``results/<experiment>/ir.zarr``.

Params
------
- ``path``: folder, glob or file of the IR exports (``experiments.<name>.ir.path``);
- ``settings``: the rest of ``experiments.<name>.ir``.
"""

from irdic.stages import ingest_ir

ingest_ir.run({"source": snakemake.params.path}, snakemake.output, log=snakemake.log[0],  # noqa: F821
              threads=snakemake.threads, **snakemake.params.settings)  # noqa: F821
