"""Calibration of the IR camera in the DIC frame from one IR image of a 3-D marker target.

- :mod:`~irdic.calibration.image`: one frame as an array, its noise and validity;
- :mod:`~irdic.calibration.detection`: marker detection with sub-pixel centres;
- :mod:`~irdic.calibration.bias`: marker planes and the perspective bias of
  imaged circle centres;
- :mod:`~irdic.calibration.correspondence`: assignment and propagation;
- :mod:`~irdic.calibration.seeds`: the user's seeds, checked against each other and the
  calibrated camera;
- :mod:`~irdic.calibration.lattice`: automatic correspondence for grid targets;
- :mod:`~irdic.calibration.solve`: the calibration itself (a second growth of the
  correspondence from the fitted camera where the first left markers out) and
  the stage entry :func:`calibrate_from_files`;
- :mod:`~irdic.calibration.dataset`: the calibration store's dataset;
- :mod:`~irdic.calibration.summary`: its summary and warnings.
"""

from .bias import perspective_bias
from .correspondence import check_ids
from .detection import detect_markers
from .image import image_array
from .lattice import match_lattice
from .seeds import match_seeds
from .solve import calibrate, calibrate_from_files
from .summary import summarize

__all__ = ["calibrate", "calibrate_from_files", "summarize", "detect_markers", "image_array", "match_seeds",
           "match_lattice", "perspective_bias", "check_ids"]
