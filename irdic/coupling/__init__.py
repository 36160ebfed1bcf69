"""Temperatures at the material points: the DIC points projected into every IR frame and interpolated there.

Modules
-------
* :mod:`.compute`: :func:`couple`, the whole computation of ``points.zarr``
  (projection, masks, interpolation of the pixel temperatures, extrapolation
  from the mask edge, status, IR noise), for the record or one time chunk.
* :mod:`.dataset`: the stored variables with their attributes, and the
  record's store gathered from its chunks.

The projection, masks and footprint are :mod:`irdic.footprint`, the pixel
interpolant :mod:`irdic.image_rbf`.
"""

from .compute import couple

__all__ = ["couple"]
