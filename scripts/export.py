"""Snakemake script: ParaView time series and CSV of selected points of one experiment.

Inputs
------
- ``points``: ``results/<experiment>/points.zarr``;
- ``fields`` (when the workflow has a fields rule): ``results/<experiment>/fields.zarr``;
- ``heat`` (experiments with a material block): ``results/<experiment>/heat.zarr`` (the heat source).

Outputs
-------
- ``paraview``: ``results/<experiment>/paraview/`` (``.pvd`` + one ``.vtu`` per DIC time);
- ``csv``: ``results/<experiment>/points.csv``.

Params
------
- ``experiment``: the experiment's name;
- ``points``: ``experiments.<name>.report.points``;
- ``settings``: the ``export`` section.
"""

from irdic.stages import export

p = snakemake.params  # noqa: F821
export.run(snakemake.input, snakemake.output, log=snakemake.log[0], threads=snakemake.threads,  # noqa: F821
           experiment=p.experiment, points=p.points, **p.settings)
