"""Snakemake script: temperatures at the DIC points of one experiment -> points.zarr.

Inputs
------
- ``dic``, ``ir``: ``results/<experiment>/dic.zarr``, ``ir.zarr``;
- ``calibration``: ``results/setups/<setup>/calibration.zarr``.

Outputs
-------
- ``store``: ``results/<experiment>/points.zarr``.

Params
------
- ``settings``: the ``interpolation`` section.
"""

from irdic.stages import couple

couple.run(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
           **snakemake.params.settings)  # noqa: F821
