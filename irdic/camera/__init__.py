"""The IR camera as a projection of DIC points (mm) into IR pixels.

- :mod:`~irdic.camera.model`: :class:`CameraModel` (projection, Jacobian,
  decomposition, uncertainty, storage) and :func:`load_camera`;
- :mod:`~irdic.camera.dlt`: the normalised direct linear transformation;
- :mod:`~irdic.camera.refine`: Levenberg-Marquardt refinement with radial
  distortion and leave-one-out residuals.

The package knows projections and nothing about images, markers or files.
"""

from .dlt import dlt, fit_dlt, planarity
from .model import CameraGeometry, CameraModel, load_camera
from .refine import leave_one_out, refine

__all__ = ["CameraModel", "CameraGeometry", "load_camera", "dlt", "fit_dlt", "refine", "leave_one_out", "planarity"]
