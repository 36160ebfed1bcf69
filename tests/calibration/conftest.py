"""The lab open-book target and its detections, rendered once per test session."""

import pytest

from irdic.calibration import detect_markers
from irdic.synthetic.camera import lab_camera
from irdic.synthetic.target import open_book_target


@pytest.fixture(scope="session")
def target():
    return open_book_target(lab_camera())


@pytest.fixture(scope="session")
def detections(target):
    return detect_markers(target.image)


