"""Snakemake script: the testing machine record of one experiment -> machine.zarr.

Inputs
------
- ``raw``: the machine record (or the demo manifest), for Snakemake's
  bookkeeping only; the file read is ``params.path``;
- ``ir``: the experiment's ``ir.zarr`` (its frame times: the store also holds
  the signals at every IR frame).

Outputs
-------
- ``store``: ``results/<experiment>/machine.zarr``.

Params
------
- ``path``: the record (``experiments.<name>.machine.path``);
- ``settings``: the rest of ``experiments.<name>.machine`` (``columns``, ...).
"""

from irdic.stages import ingest_machine

ingest_machine.run({"source": snakemake.params.path, "ir": snakemake.input.ir},  # noqa: F821
                   snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
                   **snakemake.params.settings)  # noqa: F821
