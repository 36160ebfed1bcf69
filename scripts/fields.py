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
- ``chunk``: (index, count) of a time chunk (rule fields_chunk); with ``chunks`` among
  the inputs (several chunk stores) the chunks are gathered instead.
- ``settings``: the ``fields`` section.
"""

from irdic.stages import fields

if "chunks" in snakemake.input.keys():  # noqa: F821  (gather the time chunks)
    fields.run_gather(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
                      **snakemake.params.settings)  # noqa: F821
else:
    chunk = getattr(snakemake.params, "chunk", None)  # noqa: F821  (rule fields_chunk)
    fields.run(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
              chunk=tuple(chunk) if chunk is not None else None, **snakemake.params.settings)  # noqa: F821
