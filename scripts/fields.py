"""Snakemake script: gradient, rate and strain fields of one experiment -> fields.zarr.

Inputs
------
- ``points``: ``results/<experiment>/points.zarr``;
- ``calibration``: ``results/setups/<setup>/calibration.zarr``;
- ``dic``: ``results/<experiment>/dic.zarr`` (its testing machine signals);
- ``machine`` (when configured): ``results/<experiment>/machine.zarr``.

Outputs
-------
- ``store``: ``results/<experiment>/fields.zarr``.

Params
------
- ``settings``: the ``fields`` section.
"""

from irdic.stages import fields

fields.run(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
           **snakemake.params.settings)  # noqa: F821
