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
    neighbourhood's covariance ``sum_j (x_j - xbar)(x_j - xbar)^T``
    (:func:`_smallest_eigenvector`).
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
    return _smallest_eigenvector(cov)


def _smallest_eigenvector(cov: np.ndarray) -> np.ndarray:
    """Unit eigenvectors (n, 3) of the smallest eigenvalue of symmetric 3 x 3 matrices ``cov`` (n, 3, 3).

    Notes
    -----
    The eigenvalue in closed form (the trigonometric solution of the
    characteristic cubic): with ``q = tr A / 3``, ``B = A - q I``,
    ``p = sqrt(tr B² / 6)`` and ``r = det B / (2 p³)``,
    ``λ_min = q + 2 p cos(arccos(r) / 3 + 2π / 3)``; the eigenvector is the
    largest cross product of two rows of ``A - λ_min I`` (they span the plane
    orthogonal to it). A surface's two larger eigenvalues are often nearly
    equal (``r`` near -1), where ``arccos`` loses digits but the cosine is
    flat in them: the normals equal LAPACK's (``numpy.linalg.eigh``, 4-5 x
    slower on many small matrices) to 1e-14 rad. Where the two smaller
    eigenvalues coincide (collinear points: no plane) the normal is
    arbitrary, and ``eigh``'s is returned.
    """
    a, b, c = cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2]
    d, e, f = cov[:, 0, 1], cov[:, 1, 2], cov[:, 0, 2]
    q = (a + b + c) / 3.0
    a0, b0, c0 = a - q, b - q, c - q
    p2 = (a0 * a0 + b0 * b0 + c0 * c0 + 2.0 * (d * d + e * e + f * f)) / 6.0
    p = np.sqrt(p2)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.clip((a0 * (b0 * c0 - e * e) - d * (d * c0 - e * f) + f * (d * e - b0 * f)) / (2.0 * p2 * p), -1.0, 1.0)
    lam = q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)
    rows = cov.copy()  # A - λ_min I
    rows[:, [0, 1, 2], [0, 1, 2]] -= lam[:, None]
    cands = np.stack([np.cross(rows[:, 0], rows[:, 1]), np.cross(rows[:, 0], rows[:, 2]),
                      np.cross(rows[:, 1], rows[:, 2])], axis=1)
    size = np.einsum("nki,nki->nk", cands, cands)
    best = size.argmax(axis=1)
    n = np.arange(cov.shape[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        out = cands[n, best] / np.sqrt(size[n, best])[:, None]
    # no plane: the cross products vanish next to the matrix's scale (p² squared: they are products of two rows)
    bad = ~(size[n, best] > (1e-10 * p2) ** 2) | ~np.isfinite(out).all(axis=1)
    if bad.any():
        out[bad] = np.linalg.eigh(cov[bad])[1][:, :, 0]
    return out


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
