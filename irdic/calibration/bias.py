"""Perspective bias of imaged circle centres, and the planes of a marker layout.

The centre of an imaged circle is not the image of its centre:
:func:`perspective_bias` gives the difference once the camera is known, with
the marker planes from :func:`plane_normals`; :func:`projected_ellipses`
predicts where and how each marker is imaged.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..camera import CameraModel
from ..pointcloud import plane_normal

__all__ = ["plane_normals", "find_planes", "perspective_bias", "projected_ellipses"]



def plane_normals(x, *, k: int = 6) -> np.ndarray:
    """Unit normal of the target surface at each marker, from the marker layout.

    Markers on a plane with at least 6 members (the wings of an open book,
    found by RANSAC) get that plane's normal; the others the normal of a
    plane fitted to their ``k`` nearest neighbours.

    Parameters
    ----------
    x : array_like, shape (N, 3)
        Marker centres, mm.

    Returns
    -------
    ndarray, shape (N, 3)
        Unit normals (sign arbitrary).
    """
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    normals = np.full((n, 3), np.nan)
    for members in find_planes(x):
        normals[members] = plane_normal(x[members])
    rest = np.flatnonzero(np.isnan(normals[:, 0]))
    if len(rest):
        tree = cKDTree(x)
        _, idx = tree.query(x[rest], k=min(k + 1, n))
        for i, nb in zip(rest, idx):
            normals[i] = plane_normal(x[nb])
    return normals


def find_planes(x: np.ndarray, min_size: int = 6, tol: float | None = None, seed: int = 0) -> list[np.ndarray]:
    """Index sets of the planes (>= min_size points) in a point cloud, largest first (RANSAC).

    Parameters
    ----------
    x : ndarray, shape (N, 3)
        Points, mm.
    min_size : int
        Fewest points of a plane.
    tol : float, optional
        Largest distance from a plane of its members, mm; default a tenth of
        the median nearest-neighbour distance.
    seed : int
        Seed of the random 3-point samples (the result is deterministic).

    Returns
    -------
    list of ndarray of int
        Indices into ``x`` of each plane's members.
    """
    n = len(x)
    if n < min_size:
        return []
    if tol is None:
        d, _ = cKDTree(x).query(x, k=2)
        tol = 0.1 * float(np.median(d[:, 1]))
    rng = np.random.default_rng(seed)
    remaining = np.arange(n)
    planes = []
    while len(remaining) >= min_size:
        pts = x[remaining]
        best = None
        for _ in range(300):
            i, j, k = rng.choice(len(pts), 3, replace=False)
            nrm = np.cross(pts[j] - pts[i], pts[k] - pts[i])
            ln = np.linalg.norm(nrm)
            if ln < 1e-12:
                continue
            inl = np.abs((pts - pts[i]) @ (nrm / ln)) < tol
            if best is None or inl.sum() > best.sum():
                best = inl
        if best is None or best.sum() < min_size:
            break
        # refit on the inliers, then take the points near the refined plane
        c = pts[best].mean(axis=0)
        nrm = plane_normal(pts[best])
        best = np.abs((pts - c) @ nrm) < tol
        if best.sum() < min_size:
            break
        planes.append(remaining[best])
        remaining = remaining[~best]
    return planes


def perspective_bias(camera: CameraModel, x, normals, radius_mm) -> np.ndarray:
    """Image position of the centre of each imaged circle minus the image of its centre.

    A circle of radius ``radius_mm`` around ``x`` in the plane normal to
    ``normals`` is imaged (pinhole part) as a conic; the centroid of that
    ellipse, which is what a centroid detector measures, is the conic
    centre. Distortion, when present, is applied to both points.

    Parameters
    ----------
    camera : CameraModel
    x : array_like, shape (N, 3)
        Marker centres, mm.
    normals : array_like, shape (N, 3)
        Normals of the marker planes (any length and sign).
    radius_mm : float or array_like (N,)
        Marker radius, mm.

    Returns
    -------
    ndarray, shape (N, 2)
        Bias in px: subtract it from the detected centres.
    """
    x = np.asarray(x, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    rho = np.broadcast_to(np.asarray(radius_mm, dtype=np.float64), (len(x),))
    e1, e2 = _plane_axes(nrm)
    R, C = camera.R, camera.C
    P = np.hstack([R, -(R @ C)[:, None]])  # normalised camera: (x_n, y_n, 1)
    B = np.zeros((len(x), 4, 3))
    B[:, :3, 0], B[:, :3, 1], B[:, :3, 2], B[:, 3, 2] = e1, e2, x, 1.0
    H = np.einsum("ij,njk->nik", P, B)
    Hi = np.linalg.inv(H)
    Cp = np.zeros((len(x), 3, 3))
    Cp[:, 0, 0] = Cp[:, 1, 1] = 1.0
    Cp[:, 2, 2] = -rho**2
    Q = np.einsum("nji,njk,nkl->nil", Hi, Cp, Hi)
    centre = -np.linalg.solve(Q[:, :2, :2], Q[:, :2, 2][..., None])[..., 0]
    h0 = (x - C) @ R.T
    proj = h0[:, :2] / h0[:, 2:3]

    if not camera.has_distortion:
        K = camera.K
        return (centre - proj) @ K[:2, :2].T
    # with distortion the imaged marker is no longer a conic: area centroid of
    # its boundary polygon (256 vertices: error ~1e-5 px at these sizes)
    ang = 2 * np.pi * np.arange(256) / 256
    ring = x[:, None, :] + rho[:, None, None] * (np.cos(ang)[None, :, None] * e1[:, None, :]
                                                 + np.sin(ang)[None, :, None] * e2[:, None, :])
    uv = camera.project(ring.reshape(-1, 3)).reshape(len(x), -1, 2)
    a, b = uv[..., 0], uv[..., 1]
    a1, b1 = np.roll(a, -1, axis=1), np.roll(b, -1, axis=1)
    cross = a * b1 - a1 * b
    area = 0.5 * cross.sum(axis=1)
    cu = ((a + a1) * cross).sum(axis=1) / (6 * area)
    cv = ((b + b1) * cross).sum(axis=1) / (6 * area)
    return np.column_stack([cu, cv]) - camera.project(x)



def _plane_axes(nrm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two orthonormal in-plane axes (each (N, 3)) of the planes with unit normals ``nrm`` (N, 3)."""
    helper = np.where(np.abs(nrm[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(nrm, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(nrm, e1)


def projected_ellipses(camera: CameraModel, x, normals, radius_mm) -> tuple[np.ndarray, np.ndarray]:
    """Image position and elliptical shape of each imaged marker circle.

    Parameters
    ----------
    camera : CameraModel
    x : array_like, shape (N, 3)
        Marker centres, mm.
    normals : array_like, shape (N, 3)
        Normals of the marker planes (any length and sign).
    radius_mm : float or array_like (N,)
        Marker radius, mm.

    Returns
    -------
    centre : ndarray, shape (N, 2)
        Centre of the imaged circle (projection of ``x`` plus its
        :func:`perspective_bias`), px; NaN where ``x`` is not in front of
        the camera.
    shape : ndarray, shape (N, 2, 2)
        Shape matrix ``S`` of the imaged circle, px^2: its boundary is
        ``{c + d : d^T S^-1 d = 1}``, so the square roots of the eigenvalues
        of ``S`` are the semi-axes and its eigenvectors their directions.

    Notes
    -----
    The projection is linearised on the marker plane: with in-plane unit
    axes ``e1, e2`` and radius ``rho``, the columns of ``J = [j1, j2]``,
    ``j_k = (P(x + rho e_k) - P(x - rho e_k)) / 2``, map the unit circle onto
    the imaged ellipse, ``S = J J^T``. The neglected curvature of the
    projection across one marker changes the semi-axes by a fraction of the
    order of (marker radius / depth)^2.
    """
    x = np.asarray(x, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    rho = np.broadcast_to(np.asarray(radius_mm, dtype=np.float64), (len(x),))[:, None]
    e1, e2 = _plane_axes(nrm)
    j1 = 0.5 * (camera.project(x + rho * e1) - camera.project(x - rho * e1))
    j2 = 0.5 * (camera.project(x + rho * e2) - camera.project(x - rho * e2))
    J = np.stack([j1, j2], axis=-1)
    shape = np.einsum("nik,njk->nij", J, J)
    centre = camera.project(x) + perspective_bias(camera, x, nrm, rho[:, 0])
    return centre, shape
