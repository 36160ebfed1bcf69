"""Automatic correspondence for grid targets (irdic.calibration.lattice)."""

import numpy as np
import pytest

from irdic.calibration import detect_markers, match_lattice
from irdic.calibration.correspondence import assign
from irdic.errors import CalibrationError

from ._targets import erase, uv_of


def test_match_lattice_refuses_a_symmetric_target(target, detections):
    # the synthetic open book is symmetric under a half turn about its bisector:
    # an upside-down camera on the other side explains the image equally well
    with pytest.raises(CalibrationError, match=r"(?s)ambiguous.*seeds: \{<marker id>: \[u, v\]"):
        match_lattice(uv_of(detections), target.markers.x.values)


def test_match_lattice_on_an_asymmetric_target(target):
    book = target.book
    gone = book.ids[(book.marker_wing == 0) & (book.marker_col == 6)]  # one wing has a column less
    keep = ~np.isin(target.markers.marker.values, gone)
    image = erase(target, keep)
    det = detect_markers(image)
    assert det.sizes["detection"] == 78
    x = target.markers.x.values[keep]
    mi, di, model = match_lattice(uv_of(det), x)
    true_mi, true_di = assign(target.truth.marker_pixel.values[keep], uv_of(det), 1.0)
    assert len(mi) == 78
    assert mi.tolist() == true_mi.tolist() and di.tolist() == true_di.tolist()


