"""Shared test points, poses and models for the irdic.camera tests."""

import numpy as np

from irdic.camera import CameraModel
from irdic.synthetic.camera import TrueCamera

POSES = [
    dict(distance=450.0, azimuth_deg=17.5, elevation_deg=10.0, roll_deg=1.0),
    dict(distance=380.0, azimuth_deg=-25.0, elevation_deg=-8.0, roll_deg=-3.0),
    dict(distance=600.0, azimuth_deg=5.0, elevation_deg=20.0, roll_deg=90.0),
]


def cloud(n=60, seed=0):
    """Random 3-D points in a 80 x 60 x 40 mm box around the lab target point."""
    rng = np.random.default_rng(seed)
    return rng.uniform([-40, -30, -25], [40, 30, 15], (n, 3))


def model_of(cam: TrueCamera) -> CameraModel:
    return CameraModel(K=cam.K, R=cam.R, C=cam.C, k1=cam.k1, k2=cam.k2)


def fd_jacobian(model, x, h=1e-4):
    cols = [(model.project(x + h * e) - model.project(x - h * e)) / (2 * h) for e in np.eye(3)]
    return np.stack(cols, axis=-1)

