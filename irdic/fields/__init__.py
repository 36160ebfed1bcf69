"""The fields at the DIC points: temperature gradient, rate and strain, from the coupled points and the surface.

Modules
-------
* :mod:`.compute`: :func:`fields`, the whole computation of ``fields.zarr``
  (the surface, the temperature fields, the strain, their uncertainties),
  for the record or one time chunk.
* :mod:`.smoothing`: the smoothing settings checked, "gcv" resolved once
  for the record.
* :mod:`.spatial`: the spatial regression of each time's point temperatures
  and the choice of its centre spacing.
* :mod:`.space_time`: gradient, rate and denoised value by interpolation or
  by the regression in space, then in time.
* :mod:`.dataset`: the stored variables with their attributes.

The surface itself is :mod:`irdic.surface`, the uncertainty model
:mod:`irdic.uncertainty`.
"""

from .compute import fields

__all__ = ["fields"]
