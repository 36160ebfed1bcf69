"""Snakemake script: the figures of one experiment -> PNGs for ``snakemake --report``.

Inputs
------
- ``points``: ``results/<experiment>/points.zarr``;
- ``fields`` (when the workflow has a fields rule): ``results/<experiment>/fields.zarr``;
- ``heat`` (rule heat_figure): ``results/<experiment>/heat.zarr``.

Outputs
-------
- one PNG per figure, named by figure (``temperature``, ``gradient``, ``rate``,
  ``history``, and ``strain``, ``load`` with fields; ``heat`` with heat.zarr):
  ``results/<experiment>/figures/<name>.png``.

Params
------
- ``experiment``: the experiment's name;
- ``times``, ``points``: ``experiments.<name>.report.times`` and ``.points``.
"""

from irdic.stages import figures

p = snakemake.params  # noqa: F821
figures.run(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
            experiment=p.experiment, times=p.times, points=p.points)
