"""Snakemake script: calibrate the IR camera of one setup -> calibration.zarr + figure.

Inputs
------
- the marker export and the target image (or the demo manifest), for
  Snakemake's bookkeeping only; the files read are ``params.markers`` and
  ``params.target``.

Outputs
-------
- ``store``: ``results/setups/<setup>/calibration.zarr``;
- ``figure``: ``results/setups/<setup>/calibration.png`` (detections and residuals).

Params
------
- ``markers``, ``target``: paths of ``setups.<name>.markers`` and ``.target_image``;
- ``target_format``: ``setups.<name>.target_image.format``;
- ``seeds``: ``setups.<name>.seeds``;
- ``settings``: the ``calibration`` section.
"""

from irdic.stages import calibrate

p = snakemake.params  # noqa: F821
calibrate.run({"markers": p.markers, "target": p.target}, snakemake.output, log=snakemake.log[0],  # noqa: F821
              threads=snakemake.threads, target_format=p.target_format, seeds=p.seeds, **p.settings)  # noqa: F821
