"""Snakemake script: the testing machine record of one experiment -> machine.zarr.

Inputs
------
- the machine record (or the demo manifest), for Snakemake's bookkeeping only;
  the file read is ``params.path``.

Outputs
-------
- ``store``: ``results/<experiment>/machine.zarr``.

Params
------
- ``path``: the record (``experiments.<name>.machine.path``);
- ``settings``: the rest of ``experiments.<name>.machine`` (``columns``, ...).
"""

from irdic.stages import ingest_machine

ingest_machine.run({"source": snakemake.params.path}, snakemake.output, log=snakemake.log[0],  # noqa: F821
                   threads=snakemake.threads, **snakemake.params.settings)  # noqa: F821
