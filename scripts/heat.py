"""Snakemake script: the heat source and the terms of the local heat balance of one experiment -> heat.zarr.

Inputs
------
- ``fields``: ``results/<experiment>/fields.zarr``;
- ``points``: ``results/<experiment>/points.zarr``.

Outputs
-------
- ``store``: ``results/<experiment>/heat.zarr``.

Params
------
- ``material``: ``experiments.<name>.material``;
- ``fields``: the ``fields`` section (the kernel of the regressions in the surface parameters).
"""

from irdic.stages import heat

heat.run(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
         fields_settings=snakemake.params.fields, **snakemake.params.material)  # noqa: F821
