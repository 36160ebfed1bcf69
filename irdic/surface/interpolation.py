"""The spatial operator over fixed surface parameters: global, local tiles or regression.

See :mod:`irdic.surface` (Notes) for the solvers, their accuracy and the
fill of missing points.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import warnings
import time as _time

import numpy as np
import scipy.linalg
from scipy.spatial import cKDTree

from ..errors import ConfigError, DataError, GeometryError
from ..logs import report
from ..numerics.patterns import same_patterns
from ..numerics.imq import imq_matrix, imq_planar
from ..numerics.lapack import lu_solve
from ..numerics.saddle import SaddleFactor
from ..numerics.threads import blas_threads, parallel_map
from ..threads import thread_budget
from ..validation import choice, float_array, positive, psi_array, smoothing_factor
from .parametrisation import MIN_POINTS
from .regression import ls_design, monomials
from .tiles import LocalOperator, Tiles, coefficient_matrix, tile_weights

__all__ = ["SOLVERS", "SpatialInterpolant", "LocalOperator", "shared_interpolant", "drop_derivative_weights"]

log = logging.getLogger(__name__)

SOLVERS = ("auto", "global", "local")
# Cost of a flop in a matrix product relative to one in a factorisation or a
# triangular solve (GEMM sustains about twice the rate): only the ratio
# enters the choice between the two spatial solvers.
_GEMM_COST = 0.48
# Kernel rows built per block in the global evaluation (rows x N x 8 B ~ 64 MB).
_BLOCK_BYTES = 64 * 2**20
# LU factorisations of the fill's missing patterns kept per interpolant.
_FILL_LU_BYTES = 256 * 2**20


def default_halo(cR0, h):
    """Default halo of the local tiles (mm) for the kernel width ``c R0`` and the point spacing ``h`` (mm).

    Nine kernel widths, but at most 20 point spacings: a tile then holds a
    bounded number of points however dense the grid, so the local pass costs
    time linear in the points (:mod:`irdic.surface`, Notes); never fewer than
    6 spacings.
    """
    return max(min(9.0 * cR0, 20.0 * h), 6.0 * h)


class SpatialInterpolant:
    """IMQ interpolant (or regression) over fixed surface parameters, for many fields.

    Parameters
    ----------
    psi : array_like, shape (N, 2)
        Surface parameters of the points (mm), all finite and distinct.
    c : float
        Shape factor of the IMQ (the paper: 0.969 half-shell, 0.9328 tube).
    R0 : float
        Distance normalisation (mm); the paper: 1 mm.
    smoothing : None, float >= 1
        None or 1: interpolation (the paper). ``k > 1``: least-squares
        regression with centres spaced ``k`` times the median point spacing
        (see the module Notes); use :func:`gcv_spatial` to choose ``k``.
    solver : {"auto", "global", "local"}
        Interpolation solver (module Notes); regression is always global.
    halo : float, optional
        Halo of the local tiles (mm); default ``max(min(9 c R0, 20 h), 6 h)``
        (h: median point spacing; see :mod:`irdic.surface`, Notes).
    core : float, optional
        Core side of the local tiles (mm); default: chosen by a cost model.

    Raises
    ------
    DataError
        Fewer than 6 points, or all on a line.
    GeometryError
        Two points with the same ``Psi`` (duplicates: the interpolation is singular).
    """

    def __init__(self, psi, *, c=0.95, R0=1.0, smoothing=None, solver="auto", halo=None, core=None):
        p = psi_array(psi, "psi")
        if not np.isfinite(p).all():
            i = int(np.flatnonzero(~np.isfinite(p).all(axis=1))[0])
            raise ConfigError(f"psi must be finite (drop missing points first); row {i} is {p[i]}")
        self.c = positive(c, "c")
        self.R0 = positive(R0, "R0")
        k = smoothing_factor(smoothing, "smoothing", allow_gcv=False)
        self.k = k
        self.solver = choice(solver, "solver", SOLVERS)
        n = p.shape[0]
        if n < MIN_POINTS:
            raise DataError(f"psi: {n} point(s); the surface interpolant needs at least {MIN_POINTS}")
        q = p - p.mean(axis=0)
        sv = np.linalg.svd(q, compute_uv=False)
        if not sv[1] > 1e-8 * max(sv[0], 1e-300):
            raise DataError(
                f"psi: the {n} points lie on one line; the monomials {{1, Psi1, Psi2}} need points off a line"
            )
        self.psi = p
        self.n = n
        d, j = cKDTree(p).query(p, k=2)
        self.h = float(np.median(d[:, 1]))
        dup = np.flatnonzero(d[:, 1] <= 1e-9 * max(self.h, 1e-300) + 1e-12)
        if dup.size:
            i = int(dup[0])
            other = int(j[i, 1] if j[i, 1] != i else j[i, 0])
            i, other = min(i, other), max(i, other)
            raise GeometryError(
                f"psi: points {i} and {other} have the same surface parameters "
                f"({p[i, 0]:.6g}, {p[i, 1]:.6g}) mm ({max(dup.size // 2, 1)} such pair(s)); duplicate DIC "
                "points make the interpolation singular: remove them"
            )
        ratio = self.c * self.R0 / self.h
        if ratio > 6:
            log.warning(
                "c R0 = %.3g mm is %.1f times the point spacing %.3g mm: the kernel matrix is very "
                "ill-conditioned (derivatives lose digits); consider a smaller R0",
                self.c * self.R0, ratio, self.h,
            )
        self.halo = positive(halo, "halo") if halo is not None else default_halo(self.c * self.R0, self.h)
        self.core = positive(core, "core") if core is not None else None
        self._global = None
        self._ls = None
        self._ls_at = None
        # the regression's factor and rows are built on first use, maybe by two of a pool's workers at once
        self._ls_lock = threading.RLock()
        self._local = None
        self._local_tiles = None
        self._g = None
        self._fill_lu = [None, {}, 0]  # (the G they factorise, {missing points: LU}, bytes)
        self._chosen = None
        self.info = {"spacing": self.h, "halo": self.halo, "smoothing": self.k}

    # ---- cost model -------------------------------------------------------

    def _tiles(self, core):
        return Tiles(self.psi, self.c, self.R0, self.halo, core)

    def _choose_core(self, pts, n_func, ncols):
        if self.core is not None:
            t = self._tiles(self.core)
            return t, self._tile_cost(t, pts, n_func, ncols)
        best = None
        for f in (0.25, 0.4, 0.6, 0.9, 1.3):
            core = max(f * self.halo, 2 * self.h)
            t = self._tiles(core)
            cost = self._tile_cost(t, pts, n_func, ncols)
            if best is None or cost < best[1]:
                best = (t, cost)
        return best

    @staticmethod
    def _tile_cost(tiles, pts, n_func, ncols):
        per, K = tiles.count(pts)
        return float(np.sum(K**3 / 3 + 2 * K * K * n_func * per) + np.sum(2 * per * K * ncols * n_func) * _GEMM_COST)

    def _global_cost(self, n_eval, ncols, n_func):
        N = self.n
        return N**3 / 3 + (2 * N * N * ncols + 2 * n_eval * N * ncols * n_func) * _GEMM_COST

    def resolve(self, n_eval, ncols, n_func, pts):
        """The interpolation solver for this job (``"global"`` or ``"local"``) and, when just chosen, its tiles.

        ``"auto"`` compares the estimated costs (module Notes of :mod:`irdic.surface`)
        once and keeps the choice.
        """
        if self.solver != "auto":
            return self.solver, None
        if self._chosen is not None:
            return self._chosen, None
        tiles, t_cost = self._choose_core(pts, n_func, ncols)
        g_cost = self._global_cost(n_eval, ncols, n_func)
        chosen = "local" if 2 * t_cost < g_cost or self.n > 20000 else "global"
        log.info("spatial solver: %s (estimated cost %.3g local, %.3g global, in factorisation flops)",
                 chosen, t_cost, g_cost)
        self._chosen = chosen
        return chosen, tiles

    # ---- global -------------------------------------------------------------

    def _kernel_matrix(self):
        return imq_matrix(self.psi, self.psi, self.c * self.R0)

    def _global_factor(self):
        if self._global is None:
            t0 = _time.perf_counter()
            ctr = self.psi.mean(axis=0)
            P = monomials(self.psi, ctr, self.R0, 0)
            # threaded BLAS only pays for large matrices (and its first call can
            # cost seconds on a loaded machine)
            with blas_threads(1) if self.n < 4000 else contextlib.nullcontext():
                self._global = (SaddleFactor(self._kernel_matrix(), P, rebuild=self._kernel_matrix), ctr)
            log.info("global factorisation of %d points: %.1f s", self.n, _time.perf_counter() - t0)
        return self._global

    def _eval_global(self, F, pts, kinds):
        fac, ctr = self._global_factor()
        with blas_threads(1) if self.n < 4000 else contextlib.nullcontext():
            alpha, beta = fac.coefficients(F)
        p = self.psi
        out = [np.empty((pts.shape[0], F.shape[1])) for _ in kinds]
        step = max(1, _BLOCK_BYTES // (8 * self.n))
        for i in range(0, pts.shape[0], step):
            q = pts[i:i + step]
            m, m1, m2 = imq_planar(q[:, None, 0] - p[None, :, 0], q[:, None, 1] - p[None, :, 1], self.c, self.R0,
                                 any(k > 0 for k in kinds))
            rows = {0: m, 1: m1, 2: m2}
            for o, k in zip(out, kinds):
                o[i:i + step] = rows[k] @ alpha + monomials(q, ctr, self.R0, k) @ beta
        return out

    # ---- local tiles --------------------------------------------------------

    def local_operator(self, psi_eval=None, kinds=(1, 2), g_rows=None, tiles=None):
        """Tile weights for the functionals ``kinds`` at ``psi_eval`` and the rows ``g_rows`` of ``G``.

        Parameters
        ----------
        psi_eval : array_like, shape (n, 2), optional
            Evaluation points; default the points themselves.
        kinds : sequence of {0, 1, 2}
            Value, d/dPsi1, d/dPsi2.
        g_rows : array_like of int, optional
            Points whose rows of the data-to-coefficient map ``G`` are wanted
            (for :meth:`fill`).

        Returns
        -------
        LocalOperator
            Cached on the instance: :meth:`evaluate` and :meth:`fill` reuse it.
        """
        pts = self.psi if psi_eval is None else psi_array(psi_eval, "psi_eval")
        kinds = tuple(int(k) for k in kinds)
        rows = np.unique(np.asarray([] if g_rows is None else g_rows, dtype=np.int64))
        if tiles is None:
            if self.core is not None:
                tiles = self._tiles(self.core)
            else:
                probe = pts if kinds else self.psi[rows]
                tiles = self._choose_core(probe, len(kinds) + (rows.size > 0), 3)[0]
        t0 = _time.perf_counter()
        cells_e = tiles.cells(pts) if kinds else np.zeros((0, 2), np.int64)
        cells_g = tiles.cells(self.psi[rows])
        uc, inv = np.unique(np.concatenate([cells_e, cells_g]), axis=0, return_inverse=True)
        inv = inv.ravel()
        inv_e, inv_g = inv[: len(cells_e)], inv[len(cells_e):]
        order_e = np.argsort(inv_e, kind="stable")
        bounds_e = np.searchsorted(inv_e[order_e], np.arange(len(uc) + 1))
        order_g = np.argsort(inv_g, kind="stable")
        bounds_g = np.searchsorted(inv_g[order_g], np.arange(len(uc) + 1))

        done = [0]

        def work(t):
            idx = order_e[bounds_e[t]:bounds_e[t + 1]]
            grow = rows[order_g[bounds_g[t]:bounds_g[t + 1]]]
            out = (idx, *tile_weights(tiles, uc[t], pts[idx], kinds, grow, self.n), grow)
            done[0] += 1  # a count for the stage's progress lines (racy increments only shift them)
            report("fill", done[0] / len(uc))
            return out

        # the largest tiles first: the pool's last tiles are then short ones, not one left running alone
        with blas_threads(1):
            results = parallel_map(work, np.argsort(-tiles.sizes(uc), kind="stable"))
        G = coefficient_matrix(results, rows, self.n) if rows.size else None
        tiles_e = [(idx, nodes, Wk) for idx, nodes, Wk, _, _ in results if idx.size]
        ksum = sum(r[1].size for r in results)
        log.info("local tiles: %d tiles, mean %d points, core %.2f mm, halo %.2f mm: %.1f s",
                 len(uc), ksum // max(len(uc), 1), tiles.core, tiles.halo, _time.perf_counter() - t0)
        op = LocalOperator(pts.shape[0], kinds, tiles_e, rows, G, psi_eval is None)
        if kinds:  # an operator of G rows alone does not replace the evaluation operator
            self._local = op
            self._local_tiles = tiles  # a rebuild (drop_derivative_weights) takes the same tiles: the same numbers
        if rows.size:
            self._g = (rows, G)
        return op

    def _eval_local(self, F, pts, kinds, tiles, at_nodes):
        op = self._local
        if not (op is not None and op.at_nodes and at_nodes and set(kinds) <= set(op.kinds)):
            if tiles is None and at_nodes:
                tiles = self._local_tiles
            op = self.local_operator(None if at_nodes else pts, kinds, tiles=tiles)
        return op.apply(F, kinds)

    def coefficient_rows(self, rows):
        """Rows of the data-to-RBF-coefficient map ``G`` for the points ``rows``, from local tiles
        (the rows decay like the cardinal functions).

        Parameters
        ----------
        rows : array_like of int
            Point indices.

        Returns
        -------
        rows : ndarray of int
            The sorted rows built so far (those asked for and any built before).
        G : scipy.sparse.csr_matrix, shape (len(rows), N)
        """
        rows = self._rows_to_build(rows)
        if rows is not None:
            self.local_operator(kinds=(), g_rows=rows)
        return self._g

    def _rows_to_build(self, rows):
        """None when the built rows of ``G`` hold ``rows``, else ``rows`` with them (a shared instance keeps them)."""
        rows = np.unique(np.asarray(rows, dtype=np.int64))
        if self._g is None:
            return rows
        return None if np.isin(rows, self._g[0]).all() else np.union1d(rows, self._g[0])

    def local_pass(self, g_rows, tiles=None):
        """Rows ``g_rows`` of ``G`` and the derivative weights at the points, from one pass over the tiles.

        A fill factorises the tiles anyway (:meth:`coefficient_rows`); the same
        factorisations give the weights of ``d/dPsi^alpha`` at the points for a
        fraction more, and an evaluation at the points is then one product per
        tile. So ``"auto"`` resolves to ``"local"`` from then on (no global
        factorisation, no kernel rows rebuilt per evaluation); ``"global"``
        builds the rows of ``G`` only. Nothing built is rebuilt.
        """
        if self.solver == "global":
            self.coefficient_rows(g_rows)
            return
        op = self._local
        built = op is not None and op.at_nodes and {1, 2} <= set(op.kinds)
        rows = self._rows_to_build(g_rows)
        if built and rows is None:
            return
        rows = self._g[0] if rows is None else rows
        self._chosen = "local"
        self.info["solver"] = "local"
        self.local_operator(kinds=(1, 2), g_rows=rows, tiles=tiles)

    # ---- regression ------------------------------------------------------

    def _ls_factor(self):
        with self._ls_lock:
            if self._ls is None:
                self._ls = ls_design(self.psi, self.k, self.h, self.c, self.R0)
            return self._ls

    def _kernel_rows(self, q, kinds):
        """The regression's kernel columns at ``q`` (n, 2): value and, for ``kinds`` with 1 or 2, the
        derivatives (each (n, centres))."""
        centres, R0k, _, _, _ = self._ls_factor()
        return imq_planar(q[:, None, 0] - centres[None, :, 0], q[:, None, 1] - centres[None, :, 1], self.c, R0k,
                          any(k > 0 for k in kinds))

    def _ls_rows(self, q, kinds):
        """Design rows of the regression's functionals ``kinds`` at ``q`` (n, 2): each (n, centres + 3)."""
        m, ctr = self._kernel_rows(q, kinds), self._ls_factor()[2]
        return [np.concatenate([m[k], monomials(q, ctr, self.R0, k)], axis=1) for k in kinds]

    def _eval_ls(self, F, pts, kinds, at_nodes=False):
        centres, _, ctr, Qm, Rm = self._ls_factor()
        coef = scipy.linalg.solve_triangular(Rm, Qm.T @ F, check_finite=False)
        if at_nodes and pts.shape[0] * (len(centres) + 3) * 8 * 3 <= _BLOCK_BYTES:
            # the rows at the points themselves serve every later evaluation there (noise probes, GCV trials)
            with self._ls_lock:
                if self._ls_at is None:
                    self._ls_at = dict(zip((0, 1, 2), self._ls_rows(pts, (0, 1, 2))))
            return [self._ls_at[k] @ coef for k in kinds]
        out = [np.empty((pts.shape[0], F.shape[1])) for _ in kinds]
        # the blocks of all the stage's threads together hold _BLOCK_BYTES per kind (they run on its threads here,
        # or one per worker where a pool's workers each evaluate)
        step = max(1, _BLOCK_BYTES // (8 * max(len(centres), 1) * thread_budget()))
        nc = len(centres)

        def block(i):
            q = pts[i:i + step]
            # the kernel's and the monomials' columns apart: a block's rows are not copied side by side
            m = self._kernel_rows(q, kinds)
            for o, k in zip(out, kinds):
                o[i:i + step] = m[k] @ coef[:nc]
                o[i:i + step] += monomials(q, ctr, self.R0, k) @ coef[nc:]

        # the blocks' kernel columns (one thread's elementwise work each) on the stage's threads
        parallel_map(block, range(0, pts.shape[0], step))
        return out

    # ---- public -----------------------------------------------------------

    def evaluate(self, values, psi_eval=None, *, value=True, derivatives=True):
        """Values and ``d/dPsi^alpha`` of the interpolant (regression) of ``values``.

        Parameters
        ----------
        values : array_like, shape (N, ...)
            Data at the points (finite; fill missing values first with :meth:`fill`).
        psi_eval : array_like, shape (n, 2), optional
            Evaluation points (mm); default the points themselves.
        value, derivatives : bool
            Which results to compute.

        Returns
        -------
        val, d1, d2 : ndarray, shape (n, ...) or None
            The interpolant and its derivatives with respect to ``Psi1``,
            ``Psi2`` (units of ``values`` per mm); None where not asked. At the
            points themselves the interpolant's value is the data.
        """
        F = float_array(values, "values")
        if F.ndim < 1 or F.shape[0] != self.n:
            raise ConfigError(f"values must have N = {self.n} rows (one per point), got shape {F.shape}")
        if not np.isfinite(F).all():
            raise DataError("values contain NaN or inf: fill the missing points first (SpatialInterpolant.fill)")
        tail = F.shape[1:]
        F2 = F.reshape(self.n, -1)
        at_nodes = psi_eval is None
        pts = self.psi if at_nodes else psi_array(psi_eval, "psi_eval")
        if not np.isfinite(pts).all():
            raise ConfigError("psi_eval must be finite")
        kinds = []
        exact_value = value and at_nodes and self.k == 1.0
        if value and not exact_value:
            kinds.append(0)
        if derivatives:
            kinds += [1, 2]
        res = {0: None, 1: None, 2: None}
        if kinds:
            if self.k > 1.0:
                solver = "regression"
                outs = self._eval_ls(F2, pts, kinds, at_nodes)
            else:
                solver, tiles = self.resolve(pts.shape[0], F2.shape[1], len(kinds), pts)
                if solver == "global":
                    outs = self._eval_global(F2, pts, kinds)
                else:
                    outs = self._eval_local(F2, pts, kinds, tiles, at_nodes)
            self.info["solver"] = solver
            res.update(dict(zip(kinds, outs)))
        if exact_value:
            res[0] = F2.copy()
        shape = (pts.shape[0],) + tail
        return tuple(None if res[k] is None else res[k].reshape(shape) for k in (0, 1, 2))

    def fill(self, values, valid):
        """Fill missing points per stage from that stage's valid points.

        Parameters
        ----------
        values : array_like, shape (M, N, ...)
            Stage data (NaN where missing).
        valid : array_like of bool, shape (M, N)
            True where a point is valid in a stage.

        Returns
        -------
        filled : ndarray, shape (M, N, ...)
            ``values`` with the missing entries replaced by the value of the
            interpolant of the stage's valid points (module Notes).
        was_filled : ndarray of bool, shape (M, N)

        Raises
        ------
        DataError
            A stage whose valid points are fewer than 6 or on a line.
        """
        X = float_array(values, "values")
        V = np.asarray(valid, dtype=bool)
        if X.ndim < 2 or X.shape[1] != self.n or V.shape != X.shape[:2]:
            raise ConfigError(f"values must be (M, N = {self.n}, ...) and valid (M, N); got {X.shape}, {V.shape}")
        out = X.copy()
        miss = ~V
        rows = np.flatnonzero(miss.any(axis=0))
        if rows.size == 0:
            return out, miss
        for m in np.flatnonzero(miss.any(axis=1)):
            nv = int(V[m].sum())
            if nv < MIN_POINTS:
                raise DataError(f"stage {m}: {nv} valid point(s); filling the others needs at least {MIN_POINTS}")
        t0 = _time.perf_counter()
        rows, G = self.coefficient_rows(rows)
        pos = np.full(self.n, -1)
        pos[rows] = np.arange(rows.size)
        tail = X.shape[2:]
        width = int(np.prod(tail, dtype=np.int64))
        stages = np.flatnonzero(miss.any(axis=1))
        batch = max(1, (1 << 23) // max(1, self.n * width))  # stages per right-hand side block: ~64 MB
        # stages with the same missing points share one factorisation (noise probes repeat each pattern)
        for ms in same_patterns(miss[stages]):
            ms = stages[ms]
            Q = np.flatnonzero(miss[ms[0]])
            GQ = G[pos[Q]]
            lu = self._fill_factor(G, GQ, Q, ms[0], int(V[ms[0]].sum()))
            for b in range(0, ms.size, batch):
                mb = ms[b:b + batch]
                f = np.where(V[mb].reshape(V[mb].shape + (1,) * len(tail)), X[mb], 0.0).reshape(mb.size, self.n, -1)
                rhs = -(GQ @ f.transpose(1, 0, 2).reshape(self.n, -1))
                fq = lu_solve(lu, rhs).reshape(Q.size, mb.size, width)
                out[mb[:, None], Q] = fq.transpose(1, 0, 2).reshape((mb.size, Q.size) + tail)
        log.info("filled %d missing (stage, point) values in %d stage(s): %.1f s", int(miss.sum()),
                 int(miss.any(axis=1).sum()), _time.perf_counter() - t0)
        return out, miss

    def _fill_factor(self, G, GQ, Q, stage, n_valid):
        """LU of ``G_QQ`` for the missing points ``Q``, kept for the next fill with the same points and ``G``.

        A stage run fills the same few hundred missing patterns (a moving
        specimen's outline) in every regression and noise probe; their LU
        factorisations were the fill's cost (moving tube, 25,960 points: 67 s
        of 350 s). Kept up to :data:`_FILL_LU_BYTES` in all, and only with
        the rows of ``G`` they came from (more rows are built with other tiles).
        """
        cache = self._fill_lu
        if cache[0] is not G:
            cache = self._fill_lu = [G, {}, 0]
        key = Q.tobytes()
        lu = cache[1].get(key)
        if lu is not None:
            return lu
        try:
            with warnings.catch_warnings():  # a zero pivot warns; it is the DataError below
                warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
                lu = scipy.linalg.lu_factor(GQ[:, Q].toarray(), check_finite=False)
            if not np.all(np.isfinite(lu[0])) or np.any(np.diag(lu[0]) == 0):
                raise np.linalg.LinAlgError
        except (np.linalg.LinAlgError, ValueError):
            raise DataError(
                f"stage {stage}: the {n_valid} valid points do not determine the {Q.size} missing ones "
                "(valid points on a line?)"
            ) from None
        # a running total: fills on worker threads may insert while another counts
        if cache[2] + lu[0].nbytes <= _FILL_LU_BYTES:
            cache[1][key] = lu
            cache[2] += lu[0].nbytes
        return lu


def shared_interpolant(cache: dict, psi, **kw) -> SpatialInterpolant:
    """The :class:`SpatialInterpolant` of ``kw`` on ``psi``, from ``cache`` when one was built there for the
    same points and settings (its factorisations, tiles and rows of ``G`` are cached on the instance).

    One stage run owns the ``cache`` (a plain dict): its spatial operators
    (the surface fit, the GCV trials, the temperature regressions, the noise
    probes, the fill of missing points) are then factorised once. Settings
    left out take :class:`SpatialInterpolant`'s defaults, so equal operators
    share one entry however they were asked for. At most 4 point sets are
    kept per setting (a chunk's window and the record's first stages).
    """
    kw = {"c": 0.95, "R0": 1.0, "solver": "auto", "halo": None, "core": None, **kw}
    kw["smoothing"] = smoothing_factor(kw.get("smoothing"), "smoothing", allow_gcv=False)
    built = cache.setdefault(tuple(sorted(kw.items())), [])
    for p, sp in built:
        if p is psi or np.array_equal(p, psi):
            return sp
    sp = SpatialInterpolant(psi, **kw)
    built.append((psi, sp))
    del built[:-4]
    return sp


def drop_derivative_weights(cache: dict) -> None:
    """Free the local tiles' derivative weights of the interpolants in ``cache`` (:func:`shared_interpolant`).

    The weights make an evaluation of an exact interpolant's derivatives at
    the points one product per tile (:meth:`SpatialInterpolant.local_pass`);
    at paper scale they are the cache's largest entry (0.68 GB at 25,960
    points). A stage that evaluates only regressions from some point on frees
    them there; the rows of ``G`` that fill missing points stay, and an
    evaluation that needs the weights after all builds them again on the
    same tiles (the same numbers, the tiles' time again).
    """
    for built in cache.values():
        for _, sp in built:
            sp._local = None
