"""Edge tiles: local saddle-point solves near the mask edge, cached by mask pattern.

A tile is a core of ``tile`` x ``tile`` pixels plus every masked pixel within
``halo`` of the core (~600 px); one factorisation per tile serves every field
and time while the local mask pattern is unchanged. Points are evaluated
directly from the tile's RBF coefficients.

The tile's system depends only on the relative positions of its masked pixels
(the grid is shift invariant), so factorisations are cached by that local
pattern alone and shared by every tile position, mask and time with the same
pattern: a moving straight or gently curved outline repeats a few hundred
patterns along its length and from time to time.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import NamedTuple

import numpy as np

from ..errors import DataError
from ..numerics.imq import imq_matrix
from ..numerics.saddle import SaddleFactor

__all__ = ["EDGE_BLOCK", "Tile", "TileCache", "check_unisolvent", "build_tile", "eval_tile_block"]

# Rows per block in the direct (edge tile) evaluation: keeps the temporaries in
# the CPU cache.
EDGE_BLOCK = 128


def check_unisolvent(u, v, what):
    """Raise DataError unless the pixels ``(u, v)`` admit the monomials {1, u, v}."""
    n = len(u)
    if n >= 3:
        P = np.c_[np.ones(n), u - u.mean(), v - v.mean()]
        sv = np.linalg.svd(P, compute_uv=False)
        if sv[-1] > 1e-8 * sv[0]:
            return
    raise DataError(
        f"{what}: {n} pixel(s){' on one line' if n >= 3 else ''}; the linear "
        "monomials {1, u, v} need at least 3 pixels not on one line"
    )


class Tile(NamedTuple):
    """A factorised edge tile; local coordinates relative to the core centre."""

    pv: np.ndarray  # frame rows of the tile pixels (n_t,)
    pu: np.ndarray  # frame columns
    ov: float  # origin of the local coordinates (core centre), frame px
    ou: float
    cu: np.ndarray  # local coordinates of the centres
    cv: np.ndarray
    fac: SaddleFactor


class TileCache:
    """Factorised edge tiles, keyed by local mask pattern (LRU by bytes).

    Parameters
    ----------
    max_bytes : int
        Bound on the bytes of the cached factorisations; the least recently
        used go beyond it (default 1 GiB, ~2,500 tiles of ~600 px).

    Attributes
    ----------
    built : int
        Factorisations computed (cache misses).
    hits : int
        Tiles served from the cache.
    """

    def __init__(self, max_bytes=1 << 30):
        self.max_bytes = max_bytes
        self._d = OrderedDict()
        self._bytes = 0
        self.built = 0
        self.hits = 0

    @property
    def hit_rate(self):
        """Fraction of tile requests served from the cache (0 before any request)."""
        n = self.built + self.hits
        return self.hits / n if n else 0.0

    def get(self, key):
        """The cached tile of ``key`` or None."""
        tile = self._d.get(key)
        if tile is not None:
            self._d.move_to_end(key)
            self.hits += 1
        return tile

    def put(self, key, tile):
        """Store a tile; the least recently used ones go beyond ``max_bytes``."""
        self._d[key] = tile
        self._bytes += tile.fac.nbytes
        self.built += 1
        while self._bytes > self.max_bytes and len(self._d) > 1:
            _, old = self._d.popitem(last=False)
            self._bytes -= old.fac.nbytes


def build_tile(cache, mask, ty, tx, C, R, ce):
    """The tile of core ``(ty, tx)`` (in units of ``C`` px), from ``cache`` or factorised.

    Parameters
    ----------
    cache : TileCache
    mask : ndarray of bool, shape (H, W)
    ty, tx : int
        Core row and column index.
    C, R : int
        Core size and halo (px).
    ce : float
        ``c * R0`` (px).

    Returns
    -------
    Tile
    """
    H, W = mask.shape
    v0, u0 = ty * C, tx * C
    v1, u1 = v0 + C - 1, u0 + C - 1
    a, b = max(v0 - R, 0), min(v1 + R, H - 1)
    l, r = max(u0 - R, 0), min(u1 + R, W - 1)
    # only the masked pixels within R of the core enter: the key is their
    # pattern, so a change in the corners of the crop does not refactorise
    gv = np.arange(a, b + 1)[:, None]
    gu = np.arange(l, r + 1)[None, :]
    dx = np.maximum(np.maximum(u0 - gu, gu - u1), 0)
    dy = np.maximum(np.maximum(v0 - gv, gv - v1), 0)
    crop = mask[a:b + 1, l:r + 1] & (dx * dx + dy * dy <= R * R)
    # Position-free key: the window relative to the core (it differs only
    # where the frame border clips it) and the pattern in it. The cached tile
    # holds pixel positions relative to the core corner (v0, u0).
    key = (C, R, ce, (a - v0, b - v0, l - u0, r - u0), np.packbits(crop).tobytes())
    tile = cache.get(key)
    if tile is None:
        cv, cu = np.nonzero(crop)
        cv = cv + (a - v0)
        cu = cu + (l - u0)
        ou = ov = 0.5 * (C - 1)
        lu, lv = cu - ou, cv - ov
        check_unisolvent(
            lu, lv, f"mask: the masked pixels within halo = {R} px of pixels u = {u0}..{u1}, v = {v0}..{v1}"
        )
        cen = np.c_[lu, lv]
        fac = SaddleFactor(imq_matrix(cen, cen, ce), np.c_[np.ones(lu.size), lu, lv])
        tile = Tile(cv, cu, ov, ou, lu, lv, fac)
        cache.put(key, tile)
    return tile._replace(pv=tile.pv + v0, pu=tile.pu + u0, ov=tile.ov + v0, ou=tile.ou + u0)


def eval_tile_block(tile, alpha, beta, ce, u, v, sel, gb, g, derivs, out):
    """Evaluate points ``sel`` of one tile from its coefficients, into ``out = (val, du, dv)``.

    Parameters
    ----------
    tile : Tile
    alpha, beta : ndarray, shape (n_fields, n_t), (n_fields, 3)
        RBF and monomial coefficients of every fitted field on the tile.
    ce : float
        ``c * R0`` (px).
    u, v : ndarray
        Point coordinates (px), indexed by ``sel``.
    sel : ndarray of int
        Rows of ``out`` (and of ``u``, ``v``) to evaluate.
    gb : ndarray of int or None
        Group of each point (fields ``gb * g + slot``); None: one group, the
        fields ``0 .. g-1`` for every point.
    g : int
        Fields per group.
    derivs : sequence of bool, length g
        Which slots want ``d/du``, ``d/dv``.
    out : tuple of ndarray, shape (n_points, g)

    Notes
    -----
    ``f(x) = ce sum_j alpha_j s_j + beta . (1, xu, xv)`` with
    ``s_j = 1 / sqrt(ce^2 + |x - c_j|^2)``; ``df/du = -ce sum_j alpha_j s_j^3
    (xu - cu_j) + beta_u``.
    """
    val, du, dv = out
    want = np.array(derivs, bool)
    xu = u[sel] - tile.ou
    xv = v[sel] - tile.ov
    du_ = xu[:, None] - tile.cu[None, :]
    dv_ = xv[:, None] - tile.cv[None, :]
    s = du_ * du_
    s += dv_ * dv_
    s += ce * ce
    np.sqrt(s, out=s)
    np.divide(1.0, s, out=s)
    s3 = None
    if want.any():
        s3 = s * s
        s3 *= s
    if gb is None:
        A = alpha.T  # (n_t, g)
        B = beta  # (g, 3)
        val[sel] = ce * (s @ A) + B[:, 0] + xu[:, None] * B[:, 1] + xv[:, None] * B[:, 2]
        if want.any():
            T = s3 @ A
            Tu = (s3 * tile.cu) @ A
            Tv = (s3 * tile.cv) @ A
            gu = -ce * (xu[:, None] * T - Tu) + B[:, 1]
            gv = -ce * (xv[:, None] * T - Tv) + B[:, 2]
            du[sel[:, None], np.flatnonzero(want)] = gu[:, want]
            dv[sel[:, None], np.flatnonzero(want)] = gv[:, want]
        return
    for f in range(g):
        rows = gb * g + f
        a = alpha[rows]  # (blk, n_t)
        B = beta[rows]  # (blk, 3)
        val[sel, f] = ce * np.einsum("ij,ij->i", s, a) + B[:, 0] + xu * B[:, 1] + xv * B[:, 2]
        if derivs[f]:
            a *= s3
            T = a.sum(axis=1)
            du[sel, f] = -ce * (xu * T - a @ tile.cu) + B[:, 1]
            dv[sel, f] = -ce * (xv * T - a @ tile.cv) + B[:, 2]
