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


def test_smallest_eigenvector_equals_lapack_on_thin_and_isotropic_neighbourhoods():
    """The closed form against numpy.linalg.eigh: nearly equal larger eigenvalues (a regular grid's in-plane
    covariance, where arccos loses digits), thicknesses from 1e-3 to 1e-9 of the extent, far from the origin."""
    from irdic.pointcloud import _smallest_eigenvector

    rng = np.random.default_rng(3)
    for thickness in (1e-3, 1e-6, 1e-9):
        pts = np.concatenate([rng.standard_normal((2000, 12, 2)), thickness * rng.standard_normal((2000, 12, 1))],
                             axis=2)
        pts = pts @ np.linalg.qr(rng.standard_normal((3, 3)))[0].T + 100.0
        nb = pts - pts.mean(axis=1, keepdims=True)
        cov = np.einsum("nki,nkj->nij", nb, nb)
        got, ref = _smallest_eigenvector(cov), np.linalg.eigh(cov)[1][:, :, 0]
        np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-14)
        assert np.linalg.norm(np.cross(got, ref), axis=1).max() < 1e-12
    # an exactly isotropic plane, a line (no plane: LAPACK's answer) and a point (all zero)
    cov = np.stack([np.diag([2.0, 2.0, 0.0]), np.diag([0.0, 3.0, 0.0]), np.zeros((3, 3))])
    got = _smallest_eigenvector(cov)
    assert abs(abs(got[0, 2]) - 1.0) < 1e-14
    np.testing.assert_allclose(got[1:], np.linalg.eigh(cov[1:])[1][:, :, 0])
