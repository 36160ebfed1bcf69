"""Overlapping local tiles of the surface interpolant: their points, factorisations and weights.

A tile is a square core of points plus every point within ``halo`` of it;
one Cholesky factorisation per tile gives the weights of linear functionals
(value, ``d/dPsi^alpha``) at its core points and its core points' rows of the
data-to-coefficient map ``G``. :class:`~irdic.surface.SpatialInterpolant`
chooses the tiles and runs them on a thread pool; see :mod:`irdic.surface`
(Notes) for their accuracy.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ..numerics.imq import imq_matrix, imq_planar
from ..numerics.saddle import SaddleFactor
from ..numerics.threads import blas_threads, parallel_map
from .parametrisation import MIN_POINTS
from .regression import monomials

__all__ = ["LocalOperator", "Tiles", "coefficient_matrix", "tile_weights"]


class Tiles:
    """Overlapping tiles: a square core of side ``core`` plus every point within ``halo``."""

    def __init__(self, psi, c, R0, halo, core):
        self.psi = psi
        self.c, self.R0, self.halo, self.core = c, R0, halo, core
        self.tree = cKDTree(psi)
        self.lo = psi.min(axis=0)

    def cells(self, pts):
        return np.floor((pts - self.lo) / self.core).astype(np.int64)

    def tile_nodes(self, cell):
        lo = self.lo + cell * self.core
        hi = lo + self.core
        ctr = 0.5 * (lo + hi)
        cand = np.asarray(self.tree.query_ball_point(ctr, self.core / math.sqrt(2) + self.halo), dtype=np.int64)
        p = self.psi[cand]
        d = np.hypot(np.maximum(0, np.maximum(lo[0] - p[:, 0], p[:, 0] - hi[0])),
                     np.maximum(0, np.maximum(lo[1] - p[:, 1], p[:, 1] - hi[1])))
        return np.sort(cand[d <= self.halo]), ctr

    def factor(self, nodes, ctr):
        p = self.psi[nodes]
        P = monomials(p, ctr, self.R0, 0)
        # factorised in place (no copy of a matrix of thousands of points); rebuilt for the LU fallback
        return SaddleFactor(imq_matrix(p, p, self.c * self.R0), P, rebuild=lambda: imq_matrix(p, p, self.c * self.R0))

    def functionals(self, nodes, ctr, pts, kinds):
        """Kernel/monomial rows of the functionals ``kinds`` (0 value, 1 d/dPsi1, 2 d/dPsi2) at ``pts``."""
        p = self.psi[nodes]
        dx = pts[:, None, 0] - p[None, :, 0]
        dy = pts[:, None, 1] - p[None, :, 1]
        m, m1, m2 = imq_planar(dx, dy, self.c, self.R0, any(k > 0 for k in kinds))
        rows = {0: m, 1: m1, 2: m2}
        return [(rows[k], monomials(pts, ctr, self.R0, k)) for k in kinds]

    def count(self, pts):
        """Tile sizes for the cells of ``pts``: list of (n_points_in_cell, K)."""
        cells, inv = np.unique(self.cells(pts), axis=0, return_inverse=True)
        per = np.bincount(inv.ravel(), minlength=len(cells))
        return per, np.maximum(self.sizes(cells), per)

    def sizes(self, cells):
        """Estimated number of points of the tiles of ``cells`` (k, 2): (k,)."""
        ctr = self.lo + (cells + 0.5) * self.core
        r = self.core / math.sqrt(2) + self.halo
        K = self.tree.query_ball_point(ctr, r, return_length=True)
        # the ball circumscribes the rounded box: correct by the area ratio
        ratio = (self.core**2 + 4 * self.core * self.halo + math.pi * self.halo**2) / (math.pi * r * r)
        return np.asarray(K) * ratio


class LocalOperator:
    """Per-tile weights of a set of functionals, and rows of ``G``."""

    def __init__(self, n_eval, kinds, tiles, g_rows, G, at_nodes):
        self.n_eval, self.kinds, self.tiles = n_eval, tuple(kinds), tiles
        self.g_rows, self.G, self.at_nodes = g_rows, G, at_nodes

    def apply(self, F, kinds):
        """Functionals ``kinds`` (a subset of the built ones) of the interpolant of ``F`` (N, ncols)."""
        pos = [self.kinds.index(k) for k in kinds]
        out = [np.empty((self.n_eval, F.shape[1])) for _ in kinds]

        def work(tile):
            idx, nodes, Wk = tile
            Fl = F[nodes]
            for o, j in zip(out, pos):
                o[idx] = Wk[j] @ Fl

        with blas_threads(1):
            parallel_map(work, self.tiles)
        return out


def tile_weights(tiles, cell, pts, kinds, grow, n):
    """Nodes of the tile of ``cell``, weights of the functionals ``kinds`` at ``pts`` and rows ``grow`` of G."""
    nodes, ctr = tiles.tile_nodes(cell)
    if nodes.size < MIN_POINTS:
        # a cell far from every point (evaluation outside the cloud)
        nodes = np.sort(tiles.tree.query(ctr, k=min(n, 4 * MIN_POINTS))[1])
    fac = tiles.factor(nodes, ctr)
    Bs, Qs = [], []
    for B, Q in tiles.functionals(nodes, ctr, pts, kinds) if pts.shape[0] else []:
        Bs.append(B)
        Qs.append(Q)
    if grow.size:
        B = np.zeros((grow.size, nodes.size))
        B[np.arange(grow.size), np.searchsorted(nodes, grow)] = 1.0
        Bs.append(B)
        Qs.append(np.zeros((grow.size, 3)))
    W = fac.weights(np.concatenate(Bs), np.concatenate(Qs))
    ne = pts.shape[0]
    Wk = [W[i * ne:(i + 1) * ne] for i in range(len(kinds))] if ne else []
    return nodes, Wk, W[len(kinds) * ne:]


def coefficient_matrix(results, rows, n):
    """Sparse rows ``rows`` of the data-to-coefficient map G from the tiles' results.

    A row's entries are the weights of its tile's (sorted) nodes, and each row
    comes from one tile, so the CSR arrays are written directly: a COO triplet
    of the ~N K entries and its conversion took three times the memory.
    """
    length = np.zeros(rows.size, np.int64)
    for _, nodes, _, _, grow in results:
        length[np.searchsorted(rows, grow)] = nodes.size
    indptr = np.concatenate([[0], np.cumsum(length)])
    index = np.int32 if indptr[-1] < 2**31 and n < 2**31 else np.int64
    data = np.empty(indptr[-1])
    indices = np.empty(indptr[-1], index)
    for _, nodes, _, Wg, grow in results:
        if grow.size:
            at = indptr[np.searchsorted(rows, grow)][:, None] + np.arange(nodes.size)
            data[at] = Wg
            indices[at] = nodes
    G = sparse.csr_matrix((data, indices, indptr.astype(index)), shape=(rows.size, n))
    G.has_sorted_indices = True
    return G
