"""Tests of irdic.pointcloud: PCA normals against analytic surfaces."""

from __future__ import annotations

import numpy as np

from irdic.pointcloud import local_normals, plane_normal


def test_plane_normal_of_a_tilted_plane():
    rng = np.random.default_rng(0)
    n = np.array([1.0, -2.0, 2.0]) / 3.0
    e1 = np.cross(n, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    p = rng.uniform(-5, 5, (50, 1)) * e1 + rng.uniform(-5, 5, (50, 1)) * e2 + np.array([3.0, 1.0, -2.0])
    got = plane_normal(p)
    assert abs(np.linalg.norm(got) - 1.0) < 1e-12
    assert abs(abs(got @ n) - 1.0) < 1e-12


def test_local_normals_of_a_cylinder_are_radial():
    R = 15.0
    th, z = np.meshgrid(np.linspace(0, np.pi, 40), np.linspace(0, 20, 30))
    x = np.c_[R * np.cos(th.ravel()), z.ravel(), R * np.sin(th.ravel())]
    nrm = local_normals(x, k=12)
    radial = np.c_[np.cos(th.ravel()), np.zeros(th.size), np.sin(th.ravel())]
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-12)
    ang = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ni,ni->n", nrm, radial)), 0, 1)))
    # a symmetric neighbourhood tilts only to second order; a one-sided one at
    # the patch edge by ~2 h / R (h = 1.2 mm arc spacing: 4.6 deg)
    inner = (th.ravel() > 0.2) & (th.ravel() < np.pi - 0.2)
    assert ang[inner].max() < 0.5
    assert ang.max() < 6.0
