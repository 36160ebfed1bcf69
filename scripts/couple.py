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
- ``chunk``: (index, count) of a time chunk (rule couple_chunk); with ``chunks`` among
  the inputs (several chunk stores) the chunks are gathered instead.
- ``settings``: the ``interpolation`` section.
"""

from irdic.stages import couple

if "chunks" in snakemake.input.keys():  # noqa: F821  (gather the time chunks)
    couple.run_gather(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
                      **snakemake.params.settings)  # noqa: F821
else:
    chunk = getattr(snakemake.params, "chunk", None)  # noqa: F821  (rule couple_chunk)
    couple.run(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
              chunk=tuple(chunk) if chunk is not None else None, **snakemake.params.settings)  # noqa: F821
