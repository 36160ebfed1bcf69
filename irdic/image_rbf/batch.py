"""The edge points of one or more interpolants (e.g. the times of a chunk), solved together.

Each edge tile's system comes from the window factors shared by every tile
and mask (:mod:`.tiles`); collecting the tiles of many interpolants first
makes their triangular products wide (BLAS level 3) whatever the masks.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .tiles import check_unisolvent, eval_tiles

__all__ = ["EdgeBatch"]

# Right-hand sides (tiles x fields) per batched solve of the edge tiles: bounds the solve's work arrays
# (a few window x columns x 8 B: ~30 MB each) while keeping the triangular solves wide
_EDGE_COLUMNS = 2048


class EdgeBatch:
    """Points near the mask edge of one or more interpolants (e.g. the times of a chunk), solved together.

    Each tile's saddle system (its window's masked pixels, see
    :mod:`.tiles`) comes from factors shared by all tiles and masks, through
    triangular solves of many tiles at once: collecting the tiles of many
    times first makes those solves wide (BLAS level 3) whatever the masks.
    """

    def __init__(self):
        self._entries = []

    def add(self, interp, idx, grp, G, u, v, pu, pv, g, derivs, out, need=None):
        """Points ``idx`` (groups ``grp`` of ``G``) of ``interp``, to be written into ``out = (val, du, dv)``;
        ``need`` (indexed like ``u``): the points whose derivatives are wanted (default all).

        The interpolant's fitted data are held as they are now (a later
        :meth:`MaskedGridInterpolant.fit` does not change what is solved here).
        """
        if idx.size == 0:
            return
        C = interp.tile
        ty = (pv[idx] + interp._rv0) // C
        tx = (pu[idx] + interp._ru0) // C
        key = ty * (interp.shape[1] // C + 1) + tx
        order = np.argsort(key, kind="stable")
        idx, grp, ty, tx, key = idx[order], grp[order], ty[order], tx[order], key[order]
        starts = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
        ends = np.append(starts[1:], key.size)
        self._entries.append(_EdgeEntry(interp._grid, interp._mask_r, interp._rv0, interp._ru0, interp.tile,
                                        interp.halo, interp._ce, interp._windows, ty[starts], tx[starts], starts,
                                        ends, idx, None if G == 1 else grp, u, v, g, derivs, out,
                                        None if need is None else need[idx]))

    def run(self):
        """Solve every collected tile and evaluate its points."""
        by_nf = {}
        for e in self._entries:
            by_nf.setdefault((e.grid.shape[0], e.windows), []).append(e)
        for (nf, _), entries in by_nf.items():
            # instances (entry, tile) in blocks of at most _EDGE_COLUMNS right-hand sides
            inst = [(e, t) for e in entries for t in range(e.ty.size)]
            step = max(1, _EDGE_COLUMNS // nf)
            for b0 in range(0, len(inst), step):
                self._solve_block(inst[b0:b0 + step], nf)
        self._entries = []

    @staticmethod
    def _solve_block(inst, nf):
        win = inst[0][0].windows
        k, n = len(inst), win.n
        patterns = np.zeros((k, n), bool)
        values = np.zeros((k, n, nf))
        runs = list(_runs(inst))
        for r, r1, e, t in runs:
            C = e.tile
            # window pixels in the interpolant's padded grid (every masked pixel lies inside it)
            gv = (e.ty[t] * C - e.rv0)[:, None] + win.dv
            gu = (e.tx[t] * C - e.ru0)[:, None] + win.du
            Hr, Wr = e.mask_r.shape
            inb = (gv >= 0) & (gv < Hr) & (gu >= 0) & (gu < Wr)
            pat = np.zeros(gv.shape, bool)
            pat[inb] = e.mask_r[gv[inb], gu[inb]]
            patterns[r:r1] = pat
            vals = values[r:r1]
            vals[pat] = e.grid[:, gv[pat], gu[pat]].T
            bad = np.flatnonzero(~win.unisolvent(pat))
            if bad.size:
                i = t[bad[0]]
                u0, v0 = int(e.tx[i] * C), int(e.ty[i] * C)
                check_unisolvent(win.lu[pat[bad[0]]], win.lv[pat[bad[0]]],
                                 f"mask: the masked pixels within halo = {e.halo} px of pixels u = "
                                 f"{u0}..{u0 + C - 1}, v = {v0}..{v0 + C - 1}")
        alpha, beta = win.solve(patterns, values)
        for r, r1, e, t in runs:
            # every point of the entry's tiles in this block, with the tile it lies in
            counts = e.ends[t] - e.starts[t]
            first = np.cumsum(counts) - counts
            pts = np.repeat(e.starts[t] - first, counts) + np.arange(int(counts.sum()))
            c0 = 0.5 * (e.tile - 1)
            eval_tiles(win.P, alpha[r:r1], beta[r:r1], e.ce, e.tx[t] * e.tile + c0, e.ty[t] * e.tile + c0,
                       np.repeat(np.arange(r1 - r), counts), e.u, e.v, e.idx[pts],
                       None if e.grp is None else e.grp[pts], e.g, e.derivs, e.out,
                       None if e.need is None else e.need[pts])


def _runs(inst):
    """``(r, r1, entry, tiles)`` of each run of consecutive instances of one entry."""
    r, k = 0, len(inst)
    while r < k:
        e = inst[r][0]
        r1 = r
        while r1 < k and inst[r1][0] is e:
            r1 += 1
        yield r, r1, e, np.array([i for _, i in inst[r:r1]])
        r = r1


class _EdgeEntry(NamedTuple):
    """The edge points of one :meth:`MaskedGridInterpolant.evaluate_grouped` call, sorted by tile."""

    grid: np.ndarray  # fitted values (n_fields, Hr, Wr) on the padded grid
    mask_r: np.ndarray  # the mask on the padded grid
    rv0: int
    ru0: int
    tile: int
    halo: int
    ce: float
    windows: object  # EdgeWindows
    ty: np.ndarray  # tile rows and columns (one per tile)
    tx: np.ndarray
    starts: np.ndarray  # each tile's points: idx[starts[i]:ends[i]]
    ends: np.ndarray
    idx: np.ndarray  # rows of the output
    grp: np.ndarray | None
    u: np.ndarray
    v: np.ndarray
    g: int
    derivs: tuple
    out: tuple
    need: np.ndarray | None  # per point (like idx): derivatives wanted
