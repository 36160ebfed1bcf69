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

A moving outline still makes most tiles new. Given a *stable* mask (pixels
masked in every mask of a run of neighbouring times), a tile orders its stable
pixels first: the Cholesky factor of their block is computed once per stable
pattern and shared, and a new pattern costs only the extension by the few
pixels near the moving outline (see :func:`build_tile`).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import NamedTuple

import numpy as np
from scipy.spatial.distance import cdist

import scipy.linalg

from ..errors import DataError
from ..numerics.imq import imq_matrix, imq_scaled_inverse
from ..numerics.saddle import SaddleFactor

__all__ = ["EDGE_BLOCK", "Tile", "TileCache", "check_unisolvent", "build_tile", "eval_tile_block"]

# Rows per block in the direct (edge tile) evaluation: keeps the temporaries in
# the CPU cache.
EDGE_BLOCK = 128


def check_unisolvent(u, v, what):
    """Raise DataError unless the pixels ``(u, v)`` admit the monomials {1, u, v}."""
    n = len(u)
    if n >= 3:
        P = np.column_stack([np.ones(n), u - u.mean(), v - v.mean()])
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
        used go beyond it (default 512 MiB: ~1,200 tiles of ~600 px factorised
        whole, several times more extending a stable factor).
    stable_bytes : int
        Bound on the bytes of the stable factors (see :func:`build_tile`);
        a stable factor that goes takes the tiles extending it along, so
        that the two bounds hold for the memory actually held.

    Attributes
    ----------
    built : int
        Factorisations computed (cache misses).
    hits : int
        Tiles served from the cache.
    """

    def __init__(self, max_bytes=1 << 29, stable_bytes=1 << 29):
        self.max_bytes = max_bytes
        self.stable_bytes = stable_bytes
        self._d = OrderedDict()
        self._bytes = 0
        self._s = OrderedDict()
        self._s_bytes = 0
        self.built = 0
        self.hits = 0
        self.extended = 0
        # held by whoever looks up or builds a tile (the stable factors grow in place)
        self.lock = threading.RLock()

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

    def put(self, key, tile, stable=None):
        """Store a tile (extending the :class:`_Stable` ``stable``); the least recently used go beyond ``max_bytes``."""
        self._d[key] = tile
        if stable is not None:
            stable.tiles.append(key)
        self._bytes += tile.fac.nbytes
        self.built += 1
        while self._bytes > self.max_bytes and len(self._d) > 1:
            _, old = self._d.popitem(last=False)
            self._bytes -= old.fac.nbytes

    def stable_factor(self, key, make):
        """The :class:`_Stable` factor of a stable pattern: cached, or ``make()`` (None: not definite)."""
        st = self._s.get(key, False)
        if st is not False:
            self._s.move_to_end(key)
            return st
        st = make()
        self._s[key] = st
        self.grew(0 if st is None else st.nbytes)
        return st

    def grew(self, nbytes):
        """Account ``nbytes`` more of stable factors; the least recently used go beyond ``stable_bytes``."""
        self._s_bytes += nbytes
        while self._s_bytes > self.stable_bytes and len(self._s) > 1:
            _, old = self._s.popitem(last=False)
            if old is None:
                continue
            self._s_bytes -= old.nbytes
            # the tiles extending it hold its factor: dropped with it, or the
            # factor would stay in memory uncounted
            for k in old.tiles:
                tile = self._d.pop(k, None)
                if tile is not None:
                    self._bytes -= tile.fac.nbytes


class _Stable:
    """Cholesky factor ``L`` of a stable pattern's kernel block and the columns ``L^-1 A_sp`` of extra pixels.

    A run of masks adds and removes the same few pixels near the outline
    again and again, so the triangular solve of each extra pixel (``s^2``
    flops, the bulk of an extension) is done once per stable pattern.
    """

    def __init__(self, L, cen, shape):
        self.L = L
        self.cen = cen
        self.col = np.full(shape, -1, np.int64)  # column of each window pixel in X, -1: not yet solved
        self.X = np.empty((L.shape[0], 0), order="F")
        self.n = 0
        self.tiles = []  # keys of the cached tiles extending this factor

    @property
    def nbytes(self):
        return self.L.nbytes + self.X.nbytes

    def columns(self, iv, iu, cr, ce):
        """``L^-1 A_sr`` (s, r) for the extra pixels at window rows/columns ``iv``, ``iu`` (local coordinates ``cr``), and the bytes added."""
        c = self.col[iv, iu]
        new = np.flatnonzero(c < 0)
        added = 0
        if new.size:
            Xn = scipy.linalg.solve_triangular(self.L, imq_matrix(self.cen, cr[new], ce), lower=True,
                                               check_finite=False)
            if self.n + new.size > self.X.shape[1]:
                grown = np.empty((self.L.shape[0], max(2 * self.X.shape[1], self.n + new.size)), order="F")
                grown[:, :self.n] = self.X[:, :self.n]
                added = grown.nbytes - self.X.nbytes
                self.X = grown
            self.X[:, self.n:self.n + new.size] = Xn
            self.col[iv[new], iu[new]] = np.arange(self.n, self.n + new.size)
            self.n += new.size
            c = self.col[iv, iu]
        return self.X[:, c], added


def _cholesky(A):
    """Lower Cholesky factor of ``A`` (Fortran order), or None when round-off makes it indefinite."""
    try:
        return np.asfortranarray(scipy.linalg.cholesky(A, lower=True, overwrite_a=True, check_finite=False))
    except np.linalg.LinAlgError:
        return None


def _extended_factor(cache, key, cen, s, ce, P, rest):
    """Saddle factor of the centres ``cen`` whose first ``s`` form the stable pattern ``key``, and that :class:`_Stable` (None, None on failure).

    ``rest`` (window-shaped bool) marks the other pixels, in the order of ``cen[s:]``.

    Notes
    -----
    With ``A = [[A_ss, A_sr], [A_rs, A_rr]]`` and ``A_ss = L_ss L_ss^T``
    (cached): ``L_rs = A_rs L_ss^-T`` and ``L_rr L_rr^T = A_rr - L_rs L_rs^T``,
    ``s^2 r + r^3 / 3`` flops instead of ``(s + r)^3 / 3`` for ``r`` pixels
    beyond the stable ones. The factor is that of the same matrix (in this
    pixel order), so results agree with a direct factorisation to round-off.
    """
    def make():
        L = _cholesky(imq_matrix(cen[:s], cen[:s], ce))
        return None if L is None else _Stable(L, cen[:s].copy(), rest.shape)

    st = cache.stable_factor(key, make)
    if st is None:
        return None, None
    L_ss = st.L
    cr = cen[s:]
    # L_rs^T = L_ss^-1 A_sr, (s, r)
    X, added = st.columns(*np.nonzero(rest), cr, ce)
    cache.grew(added)
    # A_rr - X^T X, lower triangle only (syrk: half the flops of a product)
    schur = scipy.linalg.blas.dsyrk(-1.0, X, beta=1.0, c=np.asfortranarray(imq_matrix(cr, cr, ce)), trans=1,
                                    lower=1, overwrite_c=1)
    L_rr = _cholesky(schur)
    if L_rr is None:
        return None, None
    cache.extended += 1
    # L = [[L_ss, 0], [X^T, L_rr]] in blocks: L_ss stays shared, not copied
    return SaddleFactor.from_blocks(L_ss, X, L_rr, P), st


def build_tile(cache, mask, ty, tx, C, R, ce, stable=None):
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
    stable : ndarray of bool, shape (H, W), optional
        Pixels of ``mask`` shared with neighbouring masks: the tile's pixels
        among them come first and their factor is shared through ``cache``.

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
        keep = crop if stable is None else crop & stable[a:b + 1, l:r + 1]
        rest = crop & ~keep
        # stable pixels first, then the ones near the moving outline; with
        # either part empty this is the plain np.nonzero order of the pattern
        cv, cu = (np.concatenate(x) for x in zip(np.nonzero(keep), np.nonzero(rest)))
        s = int(keep.sum())
        cv = cv + (a - v0)
        cu = cu + (l - u0)
        ou = ov = 0.5 * (C - 1)
        lu, lv = cu - ou, cv - ov
        check_unisolvent(
            lu, lv, f"mask: the masked pixels within halo = {R} px of pixels u = {u0}..{u1}, v = {v0}..{v1}"
        )
        cen = np.column_stack([lu, lv])
        P = np.column_stack([np.ones(lu.size), lu, lv])
        fac = st = None
        if 0 < s < lu.size:
            fac, st = _extended_factor(cache, key[:4] + (np.packbits(keep).tobytes(),), cen, s, ce, P, rest)
        if fac is None:
            fac = SaddleFactor(imq_matrix(cen, cen, ce), P)
        tile = Tile(cv, cu, ov, ou, lu, lv, fac)
        cache.put(key, tile, st)
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
    want = np.flatnonzero(np.array(derivs, bool))
    xu = u[sel] - tile.ou
    xv = v[sel] - tile.ov
    # np.column_stack, not np.c_: this runs ~10^4 times per evaluation pass
    s = cdist(np.column_stack([xu, xv]), np.column_stack([tile.cu, tile.cv]), "sqeuclidean")
    imq_scaled_inverse(s, ce, out=s)
    s3 = None
    if want.size:
        s3 = s * s
        s3 *= s
    # Points come sorted by group (time) within a tile: one matrix product per
    # run of a group instead of a gather of coefficient rows per point.
    if gb is None:
        runs = [(0, sel.size, 0)]
    else:
        cut = np.flatnonzero(np.concatenate([[True], gb[1:] != gb[:-1], [True]]))
        runs = [(a, b, int(gb[a])) for a, b in zip(cut[:-1], cut[1:])]
    for r0, r1, q in runs:
        A = alpha[q * g:(q + 1) * g].T  # (n_t, g)
        B = beta[q * g:(q + 1) * g]  # (g, 3)
        rows = sel[r0:r1]
        x1, x2 = xu[r0:r1, None], xv[r0:r1, None]
        val[rows] = ce * (s[r0:r1] @ A) + B[:, 0] + x1 * B[:, 1] + x2 * B[:, 2]
        if want.size:
            Aw = A[:, want]
            # sum_j alpha_j s_j^3 (1, cu_j, cv_j) for the wanted slots at once
            T = s3[r0:r1] @ np.concatenate([Aw, tile.cu[:, None] * Aw, tile.cv[:, None] * Aw], axis=1)
            k = want.size
            du[rows[:, None], want] = -ce * (x1 * T[:, :k] - T[:, k:2 * k]) + B[want, 1]
            dv[rows[:, None], want] = -ce * (x2 * T[:, :k] - T[:, 2 * k:]) + B[want, 2]
