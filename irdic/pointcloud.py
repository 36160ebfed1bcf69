"""Normals of point clouds by principal component analysis (PCA).

The one PCA-normal implementation: the surface parametrisation
(:mod:`irdic.surface`), the visibility test of the IR footprint
(:mod:`irdic.footprint.mask`) and the calibration markers use it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["local_normals", "nearest_neighbours", "plane_normal"]


def local_normals(x, k=12, neighbours=None):
    """Unit normals by PCA of each point's ``k`` nearest neighbours.

    Parameters
    ----------
    x : ndarray, shape (n, 3)
        Finite point coordinates (mm).
    k : int
        Neighbours per local plane fit, including the point itself (capped at n).
    neighbours : ndarray of int, shape (n, k'), optional
        Each point's neighbours (rows of ``x``), where they are known (e.g.
        :func:`nearest_neighbours` of the same material points in another
        configuration); ``k`` is then ignored.

    Returns
    -------
    ndarray, shape (n, 3)
        Unit normals, orientation arbitrary.

    Notes
    -----
    The normal is the eigenvector of the smallest eigenvalue of the
    neighbourhood's covariance ``sum_j (x_j - xbar)(x_j - xbar)^T``.
    """
    idx = nearest_neighbours(x, k) if neighbours is None else np.asarray(neighbours)
    nb = x[idx]
    nb -= nb.mean(axis=1, keepdims=True)
    # the 6 distinct entries, summed over the neighbours in order (the same numbers as
    # einsum("nki,nkj->nij"), at half its time on (n, 12, 3) arrays)
    cov = np.empty((x.shape[0], 3, 3))
    for i in range(3):
        for j in range(i, 3):
            acc = nb[:, 0, i] * nb[:, 0, j]
            for m in range(1, nb.shape[1]):
                acc += nb[:, m, i] * nb[:, m, j]
            cov[:, i, j] = acc
            cov[:, j, i] = acc
    return np.linalg.eigh(cov)[1][:, :, 0]


def nearest_neighbours(x, k=12):
    """Indices (n, min(k, n)) of each of the points ``x`` (n, 3)'s ``k`` nearest (itself included)."""
    k = min(k, x.shape[0])
    return cKDTree(x).query(x, k=k)[1].reshape(x.shape[0], k)


def plane_normal(points):
    """Unit normal of the least-squares plane through ``points``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Finite coordinates, n >= 3.

    Returns
    -------
    ndarray, shape (3,)
        The last right singular vector of the centred points; orientation
        arbitrary.
    """
    p = np.asarray(points, dtype=float)
    _, _, vt = np.linalg.svd(p - p.mean(axis=0), full_matrices=False)
    return vt[-1]
