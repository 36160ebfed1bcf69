"""Edge tiles: the local saddle-point solves near the mask edge, from factors shared by every tile and time.

A tile is a core of ``tile`` x ``tile`` pixels; its system holds the masked
pixels of its *window*, the pixels within ``halo`` of the core (~840 px for
8 and 12). The window is the same for every tile (the grid is shift
invariant), only which of its pixels are masked (the *pattern*) differs from
tile to tile and, with a moving specimen, from time to time. The system of
a pattern ``S`` is the principal submatrix ``K_SS`` of the kernel matrix
``K`` of the whole window (plus the monomials {1, u, v}), so all of them come
from a few factorisations of ``K`` (see :class:`EdgeWindows`); no
factorisation depends on the mask, and the cost of a tile is the same
whether the outline stands still or moves.
"""

from __future__ import annotations

import math
import threading
from functools import lru_cache

import numpy as np
import scipy.linalg

from ..errors import DataError
from ..numerics.imq import imq_matrix, imq_scaled_inverse
from ..numerics import lapack
from ..numerics.saddle import SaddleFactor
from ..threads import blas_threads

__all__ = ["EDGE_BLOCK", "DIRECTIONS", "EdgeWindows", "edge_windows", "check_unisolvent", "eval_tiles"]

# Points per block in the edge tiles' evaluation (:func:`eval_tiles`): a few window-wide temporaries
# (block x ~840 px x 8 B) stay small
EDGE_BLOCK = 256
#: Pixel orders of the window (directions of the outline's normal, evenly spread; a multiple of 8: the
#: window's symmetries map one octant's orders onto the others, so DIRECTIONS / 8 factorisations serve all)
DIRECTIONS = 128
# Directions tried per pattern, around the one its masked and unmasked pixels point to
_CANDIDATES = 5
# Patterns per block in the choice of the order (memory ~ block x candidates x window x 4 B)
_CHOICE_BLOCK = 512
# Beyond this many pixels past the first gap of the best order a pattern is factorised directly
# (the Schur step costs ~p^2 (n - m) + p^3 / 3 against (m + p)^3 / 3)
_DIRECT_FRACTION = 0.6


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


def _symmetries():
    """The 8 symmetries of the square as 2 x 2 integer matrices acting on (u, v) about the core centre."""
    rot = np.array([[0, -1], [1, 0]])
    flip = np.array([[0, 1], [1, 0]])
    out = []
    for f in (np.eye(2, dtype=int), flip):
        g = f.copy()
        for _ in range(4):
            out.append(g)
            g = rot @ g
    return out


class EdgeWindows:
    """The factorised kernel matrices of a tile's window, and the solves of any pattern of it.

    Parameters
    ----------
    ce : float
        ``c * R0`` (px).
    tile, halo : int
        Core size and halo (px).

    Attributes
    ----------
    n : int
        Pixels of the window.
    dv, du : ndarray of int, shape (n,)
        Window pixels relative to the core's first pixel (row-major order: the *natural* order).
    lu, lv : ndarray, shape (n,)
        Their local coordinates, relative to the core centre.

    Notes
    -----
    For a pixel order ``pi`` of the window let ``K = L L^T`` (Cholesky). A
    pattern ``S`` whose first ``m`` pixels in that order are the first ``m``
    of the window (the *prefix*), followed by ``p`` more pixels ``Q`` (past
    the first unmasked one), has ``K_SS = L_S L_S^T`` with ``L_S`` the rows of
    ``L`` of its pixels, so its factor is ``[[L_mm, 0], [L_Qm, M]]`` with
    ``M M^T = L_Q,m: L_Q,m:^T``, the Gram matrix of the rows of ``Q`` past
    column ``m``: ``p^2 (n - m)`` flops instead of ``(m + p)^3 / 3``. The
    substitutions with ``L_mm`` are those with ``L`` itself (forward: the
    first ``m`` rows; backward: with zeros below row ``m``), so the patterns
    of many tiles and times run through one triangular solve per order.

    The orders sort the window by the projection on one of
    :data:`DIRECTIONS` directions (deepest first, for the outline's outward
    normal): a straight outline with that normal makes the pattern a prefix
    (``p = 0``), a curved one or a tilted one a prefix and a few pixels
    (median 4 on a moving tube, 99 % below 230 at the patch corners). Each
    pattern takes the order, among the few around its own normal, with the
    fewest. The symmetries of the square window map orders into each other
    with the same kernel matrix, so ``DIRECTIONS / 8`` factorisations serve
    all (8 x n^2 x 8 B: 45 MB for the default window); the monomials of an
    order are those of its octant's transformed linearly.

    Every pattern's system is the same as a direct factorisation of its own
    pixels would give (same matrix; the order changes round-off only). When
    round-off makes a kernel matrix numerically indefinite (very flat
    kernels) the pattern is solved by :class:`~irdic.numerics.saddle.SaddleFactor`
    directly.
    """

    def __init__(self, ce, tile, halo):
        self.ce, self.tile, self.halo = float(ce), int(tile), int(halo)
        C, R = self.tile, self.halo
        g = np.arange(-R, C + R)
        GV, GU = np.meshgrid(g, g, indexing="ij")
        dx = np.maximum(np.maximum(-GU, GU - (C - 1)), 0)
        dy = np.maximum(np.maximum(-GV, GV - (C - 1)), 0)
        keep = dx * dx + dy * dy <= R * R
        self.dv, self.du = GV[keep], GU[keep]
        self.n = n = self.dv.size
        c0 = 0.5 * (C - 1)
        self.lu, self.lv = self.du - c0, self.dv - c0
        self.P = np.column_stack([np.ones(n), self.lu, self.lv])
        # natural index of each window pixel, to map transformed pixels back
        index = {(int(a), int(b)): i for i, (a, b) in enumerate(zip(2 * self.du - (C - 1), 2 * self.dv - (C - 1)))}
        twice = np.column_stack([2 * self.du - (C - 1), 2 * self.dv - (C - 1)])  # 2 (u, v) about the centre: integers
        base = DIRECTIONS // 8
        step = 2 * math.pi / DIRECTIONS
        orders, angles, mons, of = [], [], [], []
        base_orders = []
        for j in range(base):
            th = (j + 0.5) * step  # inside the first octant, never on an axis or a diagonal
            key = math.cos(th) * self.lu + math.sin(th) * self.lv
            base_orders.append(np.lexsort((self.dv, self.du, key)))
        for G in _symmetries():
            moved = twice @ G.T
            perm = np.array([index[(int(a), int(b))] for a, b in moved])  # natural index of g(pixel i)
            Mg = np.eye(3)
            Mg[1:, 1:] = G.T  # (1, u, v) of g(x) = (1, u, v) of x @ Mg
            for j in range(base):
                th = (j + 0.5) * step
                d = G @ np.array([math.cos(th), math.sin(th)])
                orders.append(perm[base_orders[j]])
                angles.append(math.atan2(d[1], d[0]) % (2 * math.pi))
                mons.append(Mg)
                of.append(j)
        self.order = np.array(orders, dtype=np.int64)  # (D, n) natural index at each position
        self.rank = np.empty_like(self.order, dtype=np.int32)  # (D, n) position of each natural index
        for d in range(DIRECTIONS):
            self.rank[d, self.order[d]] = np.arange(n)
        self.base_of = np.array(of)
        self._mono = np.array(mons)
        angles = np.array(angles)
        # directions sorted by angle: the candidates of a pattern are neighbours in this ring
        self._ring = np.argsort(angles)
        self._ring_angle = angles[self._ring]
        self._base_orders = base_orders
        self._factor(base_orders)

    def _factor(self, base_orders):
        """The factors of the octant's orders, and per order the monomials' forward solves and their Gram sums."""
        cen = np.column_stack([self.lu, self.lv])
        self.L = []
        with blas_threads(1):  # cached for the process: the same numbers whichever stage built them
            for order in base_orders:
                try:
                    L = scipy.linalg.cholesky(imq_matrix(cen[order], cen[order], self.ce), lower=True,
                                              overwrite_a=True, check_finite=False)
                except np.linalg.LinAlgError:
                    self.L = None
                    return
                self.L.append(L)
            # the explicit inverses: the substitutions of many columns become matrix products
            self.Linv = [np.asfortranarray(scipy.linalg.lapack.dtrtri(L, lower=1)[0]) for L in self.L]
            Yb = [scipy.linalg.solve_triangular(L, self.P[o], lower=True, check_finite=False)
                  for L, o in zip(self.L, base_orders)]
        self.Yb = Yb
        # row-major: the pixels past a prefix read rows of L
        self.L = [np.ascontiguousarray(L) for L in self.L]
        n = self.n
        self.Y = np.empty((DIRECTIONS, n, 3))  # L^-1 P in each order
        self.Gram = np.zeros((DIRECTIONS, n + 1, 3, 3))  # Gram[d, m] = Y[d, :m]^T Y[d, :m]
        self.Pord = np.empty((DIRECTIONS, n, 3))  # monomials in each order
        for d in range(DIRECTIONS):
            Y = Yb[self.base_of[d]] @ self._mono[d]
            self.Y[d] = Y
            np.cumsum(Y[:, :, None] * Y[:, None, :], axis=0, out=self.Gram[d, 1:])
            self.Pord[d] = self.P[self.order[d]]

    @property
    def nbytes(self):
        return 0 if self.L is None else 2 * sum(L.nbytes for L in self.L) + self.Y.nbytes + self.Gram.nbytes

    # -- orders -------------------------------------------------------------

    def unisolvent(self, patterns):
        """Which patterns (k, n) admit the monomials {1, u, v} (3 or more pixels not on one line), (k,) bool."""
        u = 2 * self.du - (self.tile - 1)
        v = 2 * self.dv - (self.tile - 1)
        X = np.column_stack([np.ones(self.n), u, v, u * u, v * v, u * v]).astype(np.int64)
        s = patterns.astype(np.int64) @ X  # exact integer moments
        n, su, sv, suu, svv, suv = s.T
        a, b, c = n * suu - su * su, n * svv - sv * sv, n * suv - su * sv
        return (n >= 3) & (a * b - c * c > 0)

    def choose(self, patterns):
        """Order (direction index), prefix length ``m`` and pixels past it ``p`` of each pattern (k, n)."""
        k = patterns.shape[0]
        d_out = np.zeros(k, np.int64)
        m_out = np.full(k, self.n, np.int64)
        holes = ~patterns
        nh = holes.sum(axis=1)
        ns = self.n - nh
        some = np.flatnonzero(nh > 0)
        if some.size:
            H = holes[some].astype(float)
            S = 1.0 - H
            # the outward normal: from the masked pixels' centroid to the unmasked ones'
            du = H @ self.lu / nh[some] - S @ self.lu / np.maximum(ns[some], 1)
            dv = H @ self.lv / nh[some] - S @ self.lv / np.maximum(ns[some], 1)
            ang = np.arctan2(dv, du) % (2 * math.pi)
            pos = np.searchsorted(self._ring_angle, ang)
            half = _CANDIDATES // 2
            cand = self._ring[(pos[:, None] + np.arange(-half, _CANDIDATES - half)) % DIRECTIONS]  # (k', c)
            for b0 in range(0, some.size, _CHOICE_BLOCK):
                b1 = min(b0 + _CHOICE_BLOCK, some.size)
                rk = self.rank[cand[b0:b1]]  # (b, c, n)
                first = np.where(holes[some[b0:b1], None, :], rk, self.n).min(axis=2)  # prefix length per candidate
                best = np.argmax(first, axis=1)  # the longest prefix: the fewest pixels past it
                d_out[some[b0:b1]] = cand[b0:b1][np.arange(b1 - b0), best]
                m_out[some[b0:b1]] = first[np.arange(b1 - b0), best]
        return d_out, m_out, ns - m_out

    # -- solves -------------------------------------------------------------

    def solve(self, patterns, values):
        """Kernel and monomial coefficients of the interpolants of ``values`` on each pattern.

        Parameters
        ----------
        patterns : ndarray of bool, shape (k, n)
            Masked window pixels of each of ``k`` tiles (natural order); each
            unisolvent (:meth:`unisolvent`).
        values : ndarray, shape (k, n, nf)
            Field values at the window pixels (those outside the pattern are ignored).

        Returns
        -------
        alpha : ndarray, shape (k, n, nf)
            Kernel coefficients at the window pixels, zero outside the pattern.
        beta : ndarray, shape (k, 3, nf)
            Coefficients of {1, u, v} (local coordinates).
        """
        k, n, nf = values.shape
        alpha = np.zeros((k, n, nf))
        beta = np.zeros((k, 3, nf))
        if k == 0:
            return alpha, beta
        d, m, p = self.choose(patterns)
        direct = np.zeros(k, bool) if self.L is not None else np.ones(k, bool)
        direct |= p > _DIRECT_FRACTION * (m + p)
        for j in range(DIRECTIONS // 8):
            sel = np.flatnonzero((self.base_of[d] == j) & ~direct)
            if sel.size:
                fail = self._solve_order(j, sel, d[sel], m[sel], patterns, values, alpha, beta)
                direct[sel[fail]] = True
        for i in np.flatnonzero(direct):
            self._solve_direct(patterns[i], values[i], alpha[i], beta[i])
        return alpha, beta

    def _solve_direct(self, pattern, vals, alpha, beta):
        """One pattern by its own factorisation (:class:`SaddleFactor`)."""
        s = np.flatnonzero(pattern)
        cen = np.column_stack([self.lu[s], self.lv[s]])
        fac = SaddleFactor(imq_matrix(cen, cen, self.ce), self.P[s])
        a, b = fac.solve(vals[s])
        alpha[s] = a
        beta[:] = b

    def _solve_order(self, j, sel, d, m, patterns, values, alpha, beta):
        """Patterns ``sel`` in orders ``d`` of octant order ``j`` (prefix lengths ``m``); True where one failed.

        Right-hand sides are columns ``i * nf + f`` (pattern ``i``, field ``f``),
        patterns sorted by decreasing ``m``: the substitutions run on blocks of
        columns with similar ``m``, each on the leading rows it needs.
        """
        L, Li, Yj = self.L[j], self.Linv[j], self.Yb[j]
        n = self.n
        nf = values.shape[2]
        srt = np.argsort(-m, kind="stable")
        sel, d, m = sel[srt], d[srt], m[srt]
        k = sel.size
        K = k * nf
        idx = self.order[d]  # (k, n) natural index at each position
        F = values[sel[:, None], idx]  # (k, n, nf) in each pattern's order
        rhs = np.ascontiguousarray(F.transpose(0, 2, 1)).reshape(K, n).T  # (n, K), F-contiguous
        mc = np.repeat(m, nf)  # prefix length of each column
        y = np.zeros((n, K), order="F")
        blocks = _blocks(mc)
        trmm = lapack.trmm  # GIL-free: the stage's threads solve their edge tiles at once
        # forward: the first m rows of L^-1 f are those of L_mm^-1 f_m (L^-1 lower triangular)
        for c0, c1 in blocks:
            mb = int(mc[c0])
            y[:mb, c0:c1] = trmm(1.0, Li[:mb, :mb], rhs[:mb, c0:c1], lower=True)
        y *= np.arange(n)[:, None] < mc[None, :]
        # Y_d = Y_j M_d: the monomials' part through the octant's Y_j and each order's 3 x 3 map
        Md = self._mono[d]  # (k, 3, 3)
        rb = np.einsum("kba,kbf->kaf", Md, (Yj.T @ y).reshape(3, k, nf).transpose(1, 0, 2))  # Y_d,m^T y_m
        C = self.Gram[d, m]  # (k, 3, 3)
        on = patterns[sel[:, None], idx]  # (k, n) pattern in each order
        fail = np.zeros(k, bool)
        # the pixels past the prefix (see the class Notes), pattern by pattern: with Q their rows of L, B the
        # columns before m and T from m on, the Schur complement is G = T T^T, and G^-1 r of the fields'
        # r = f_Q - B y_m and the monomials' P_Q - B Y_m give their shares of C and rb, and x_Q once beta is known
        extra = []
        potrf, potrs = lapack.potrf, lapack.potrs
        for i in np.flatnonzero(m < on.sum(axis=1)):
            mi = int(m[i])
            q = mi + np.flatnonzero(on[i, mi:])
            Lq = L[q]
            B = Lq[:, :mi]
            T = Lq[:, mi:]
            Mq, info = potrf(T @ T.T, lower=True)
            if info:
                fail[i] = True
                continue
            cols = slice(i * nf, (i + 1) * nf)
            r = np.concatenate([F[i, q] - B @ y[:mi, cols], self.Pord[d[i], q] - (B @ Yj[:mi]) @ Md[i]], axis=1)
            w = potrs(Mq, r, lower=True)[0]
            rP = r[:, nf:]
            C[i] += rP.T @ w[:, nf:]
            rb[i] += rP.T @ w[:, :nf]
            extra.append((i, q, B, w))
        ok = ~fail
        b = np.zeros((k, 3, nf))
        b[ok] = np.linalg.solve(C[ok], rb[ok])
        z = y - Yj @ np.einsum("kab,kbf->akf", Md, b).reshape(3, K)
        z *= np.arange(n)[:, None] < mc[None, :]
        z[:, np.repeat(fail, nf)] = 0.0
        xq = []
        for i, q, B, w in extra:
            xp = w[:, :nf] - w[:, nf:] @ b[i]  # x_Q = G^-1 (r_f - r_P beta)
            z[:B.shape[1], i * nf:(i + 1) * nf] -= B.T @ xp
            xq.append((i, q, xp))
        # backward: with zeros below row m, L^-T gives L_mm^-T on the first m rows and zeros below
        x = np.zeros((n, K), order="F")
        for c0, c1 in blocks:
            mb = int(mc[c0])
            x[:mb, c0:c1] = trmm(1.0, Li[:mb, :mb], z[:mb, c0:c1], lower=True, trans_a=True)
        x = x.T.reshape(k, nf, n).transpose(0, 2, 1)  # (k, n, nf) in each order
        for i, q, xp in xq:
            x[i, q] = xp
        good = np.flatnonzero(ok)
        alpha[sel[good, None], idx[good]] = x[good]
        beta[sel[good]] = b[good]
        out = np.zeros(k, bool)
        out[srt] = fail
        return out


def _blocks(mc, ratio=0.85, least=32):
    """Column ranges of ``mc`` (decreasing) whose values lie within ``ratio`` of the range's first (at least
    ``least`` columns each, the rest of the columns once fewer remain)."""
    out = []
    c0, K = 0, mc.size
    while c0 < K:
        c1 = max(c0 + least, int(np.searchsorted(-mc, -ratio * mc[c0], side="right")))
        c1 = K if K - c1 < least else min(c1, K)
        out.append((c0, c1))
        c0 = c1
    return out


_BUILD = threading.Lock()


def edge_windows(ce, tile, halo):
    """The :class:`EdgeWindows` of ``c * R0 = ce`` px, core ``tile`` px and ``halo`` px (cached).

    Built once per process, by one thread: the worker threads of a stage that
    ask for it together wait for that one (two builds at once would also
    change each other's BLAS thread limits, and with them the rounding).
    """
    with _BUILD:
        return _edge_windows(float(ce), int(tile), int(halo))


@lru_cache(maxsize=4)
def _edge_windows(ce, tile, halo):
    return EdgeWindows(ce, tile, halo)


def eval_tiles(P, alpha, beta, ce, ou, ov, tile_of, u, v, sel, gb, g, derivs, out, need=None):
    """Evaluate the points of many tiles of one window from their coefficients, into ``out = (val, du, dv)``.

    Parameters
    ----------
    P : ndarray, shape (n, 3)
        The monomials {1, u, v} at the window's pixels, relative to its core
        centre (px): :attr:`EdgeWindows.P`.
    alpha, beta : ndarray, shape (k, n, n_fields), (k, 3, n_fields)
        RBF coefficients (zero outside each tile's pattern) and monomial
        coefficients of every fitted field on each of ``k`` tiles.
    ce : float
        ``c * R0`` (px).
    ou, ov : ndarray, shape (k,)
        The tiles' core centres (px, the frame coordinates of ``u``, ``v``).
    tile_of : ndarray of int, shape (P,)
        The tile of each point.
    u, v : ndarray
        Point coordinates (px), indexed by ``sel``.
    sel : ndarray of int, shape (P,)
        Rows of ``out`` (and of ``u``, ``v``) to evaluate.
    gb : ndarray of int, shape (P,), or None
        Group of each point (fields ``gb * g + slot``); None: one group, the
        fields ``0 .. g-1`` for every point.
    g : int
        Fields per group.
    derivs : sequence of bool, length g
        Which slots want ``d/du``, ``d/dv``.
    out : tuple of ndarray, shape (n_points, g)
    need : ndarray of bool, shape (P,), optional
        Which points want the derivatives (default all); the others' stay as they are.

    Notes
    -----
    ``f(x) = ce sum_j alpha_j s_j + beta . (1, xu, xv)`` with
    ``s_j = 1 / sqrt(ce^2 + |x - c_j|^2)``; ``df/du = -ce sum_j alpha_j s_j^3
    (xu - cu_j) + beta_u``. The sums run over the whole window (the
    coefficients off a tile's pattern are zero), point by point in blocks of
    :data:`EDGE_BLOCK` points of any tiles: a few vectorised passes instead
    of a matrix product per tile and group (the points of a tile at one
    time are a handful, and the products' call overhead dominated).
    """
    val, du, dv = out
    lu, lv = P[:, 1], P[:, 2]
    for b0 in range(0, sel.size, EDGE_BLOCK):
        b1 = min(b0 + EDGE_BLOCK, sel.size)
        j, rows = tile_of[b0:b1], sel[b0:b1]
        xu = u[rows] - ou[j]
        xv = v[rows] - ov[j]
        s = np.subtract.outer(xu, lu)
        s *= s
        dd = np.subtract.outer(xv, lv)
        s += dd * dd
        imq_scaled_inverse(s, ce, out=s)
        d = slice(None) if need is None else np.flatnonzero(need[b0:b1])
        s3 = None
        for f in range(g):
            fld = np.full(b1 - b0, f) if gb is None else gb[b0:b1] * g + f
            A = alpha[j, :, fld]  # (b, n): each point's tile and field
            B = beta[j, :, fld]  # (b, 3)
            val[rows, f] = ce * np.einsum("pn,pn->p", s, A) + B[:, 0] + xu * B[:, 1] + xv * B[:, 2]
            if derivs[f] and (need is None or d.size):
                if s3 is None:
                    s3 = s[d]
                    s3 = s3 * s3 * s3
                As = s3 * A[d]
                T = As @ P  # sum_j alpha_j s_j^3 (1, cu_j, cv_j)
                r = rows[d]
                du[r, f] = -ce * (xu[d] * T[:, 0] - T[:, 1]) + B[d, 1]
                dv[r, f] = -ce * (xv[d] * T[:, 0] - T[:, 2]) + B[d, 2]
