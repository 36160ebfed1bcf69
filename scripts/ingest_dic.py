"""Snakemake script: the DIC stage exports of one experiment -> dic.zarr.

Inputs
------
- the raw DIC files (or the demo manifest), for Snakemake's bookkeeping only;
  the series read is ``params.path``.

Outputs
-------
- ``store``: ``results/<experiment>/dic.zarr``.

Params
------
- ``path``: folder, glob or file of the DIC exports (``experiments.<name>.dic.path``);
- ``settings``: the rest of ``experiments.<name>.dic``.
"""

from irdic.stages import ingest_dic

ingest_dic.run({"source": snakemake.params.path}, snakemake.output, log=snakemake.log[0],  # noqa: F821
               threads=snakemake.threads, **snakemake.params.settings)  # noqa: F821
