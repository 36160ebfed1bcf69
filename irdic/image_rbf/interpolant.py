"""The spatial interpolant of fields on the masked pixels of a regular grid.

See :mod:`irdic.image_rbf` for the method (interior stencils plus edge
tiles) and its accuracy.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import ndimage
from scipy.spatial import cKDTree

from ..errors import ConfigError, DataError
from ..validation import as_int, bool_mask, choice, float_array, positive
from .stencil import chebyshev, interior_stencil
from .batch import EdgeBatch
from .tiles import check_unisolvent, edge_windows

__all__ = ["METHODS", "Evaluation", "MaskedGridInterpolant", "MaskedGridRBF"]

log = logging.getLogger(__name__)

METHODS = ("rbf", "bilinear", "cubic")

# Points per block in the interior path: the float32 patches (block x 625)
# stay in the CPU cache.
_INTERIOR_BLOCK = 512
# Background margin (px) around the mask. rbf: the interior stencils gather a
# (2 halo + 1)^2 box (disc weights, zero in the corners), which must stay in
# the grid; cubic: B-spline prefiltering is a recursive filter with pole
# -0.268, 0.268^12 < 2e-7.
_MARGIN = {"bilinear": 2, "cubic": 12}
# Edge distances (px) below this are exact; beyond, to ~0.03 px.
_EDGE_EXACT = 16.0


class Evaluation(NamedTuple):
    """Result of :meth:`MaskedGridInterpolant.evaluate`.

    ``value`` in the unit of the fields (°C for temperatures), ``du`` and ``dv``
    in that unit per px (None when derivatives were not requested), shapes
    (n_fields, M) or (M,) for a single field; ``edge_distance`` in px, (M,) or
    (n_fields, M) for per-field points: distance from the point to the nearest
    pixel centre outside the mask minus 1/2 (so 0 on the pixel boundary of the
    masked region, 0.5 at the centre of an edge pixel); negative outside the
    mask (where value, du, dv are NaN); NaN for NaN points.
    """

    value: np.ndarray
    du: np.ndarray | None
    dv: np.ndarray | None
    edge_distance: np.ndarray


class MaskedGridInterpolant:
    """Interpolate fields given on the masked pixels of a regular pixel grid.

    Parameters
    ----------
    mask : array_like of bool, shape (H, W)
        Pixels that carry data (the specimen). Only these feed the
        interpolant: the specimen edge is a temperature discontinuity and
        background pixels would make the interpolant ring.
    method : {"rbf", "bilinear", "cubic"}
        ``"rbf"``: the paper's global IMQ interpolant with monomials
        {1, u, v} over all masked pixels, evaluated with local stencils (see the
        module Notes; ~1e-5 K from the exact one in the interior). ``"bilinear"``
        and ``"cubic"``: ``scipy.ndimage`` splines of order 1 and 3 for
        comparison; background pixels are first filled with the value of the
        nearest masked pixel so that they do not enter either.
    c : float
        IMQ shape parameter (dimensionless; the paper: 2).
    R0 : float
        Distance normalisation in px (the paper: 1). Only ``c * R0`` matters.
    halo : int
        Radius in px of the neighbourhood that determines the value at a
        point (>= 12 keeps the distance to the global interpolant ~1e-5 of the
        local data variation; 8 gives ~1e-4).
    tile : int
        Core size in px of the tiles used near the mask edge.
    Attributes
    ----------
    mask : ndarray of bool, shape (H, W)
    shape : tuple
        (H, W).
    n_mask : int
        Number of masked pixels.
    pixels : ndarray of int, shape (n_mask, 2)
        (u, v) of the masked pixels, in the order of ``np.nonzero(mask)``
        (the order of fields given as (n_mask,) vectors).

    Notes
    -----
    Typical use: ``MaskedGridInterpolant(mask).fit(fields).evaluate(points)``.
    The object depends on the mask only; :meth:`fit` may be called again with
    new fields (all setup is reused). The edge tiles' factors are those of the
    process (:func:`~irdic.image_rbf.tiles.edge_windows`, built once per
    ``c * R0``, ``tile`` and ``halo``), whatever the mask.
    """

    def __init__(self, mask, *, method="rbf", c=2.0, R0=1.0, halo=12, tile=8):
        self.method = choice(method, "method", METHODS)
        self.c = positive(c, "c")
        self.R0 = positive(R0, "R0")
        self.halo = as_int(halo, "halo", 1)
        self.tile = as_int(tile, "tile", 1)
        self._ce = self.c * self.R0
        m = bool_mask(mask)
        self.mask = m.copy()
        self.shape = m.shape
        vv, uu = np.nonzero(m)
        self.n_mask = vv.size
        check_unisolvent(uu.astype(float), vv.astype(float), "mask")
        self.pixels = np.c_[uu, vv]

        margin = self.halo if self.method == "rbf" else _MARGIN[self.method]
        self._rv0 = int(vv.min()) - margin
        self._ru0 = int(uu.min()) - margin
        self._Hr = int(vv.max()) - self._rv0 + 1 + margin
        self._Wr = int(uu.max()) - self._ru0 + 1 + margin
        mr = np.zeros((self._Hr, self._Wr), bool)
        mr[vv - self._rv0, uu - self._ru0] = True
        self._mask_r = mr
        self._vr = vv - self._rv0
        self._ur = uu - self._ru0

        # Edge distance: nearest pixel centre on the other side of the edge;
        # that one is always 4-adjacent to the edge, so trees of the boundary
        # pixels give it exactly. A tree query for every point and time costs
        # ~2 us, so inside the mask the nearest background pixels of the
        # point's pixel and its 8 neighbours (feature transform) give an upper
        # bound first (exact to ~0.03 px), and the tree is asked only within
        # _EDGE_EXACT px of the edge.
        pad = np.pad(mr, 1)
        self._feat_bg = ndimage.distance_transform_edt(
            pad, return_distances=False, return_indices=True
        ).astype(np.int32)
        cross = ndimage.generate_binary_structure(2, 1)
        bv, bu = np.nonzero(~pad & ndimage.binary_dilation(pad, cross))
        fv, fu = np.nonzero(pad & ~ndimage.binary_erosion(pad, cross, border_value=0))
        off = np.array([self._ru0 - 1, self._rv0 - 1])
        self._tree_bg = cKDTree((np.c_[bu, bv] + off).astype(float))
        self._tree_fg = cKDTree((np.c_[fu, fv] + off).astype(float))

        if self.method == "rbf":
            self._stencil = interior_stencil(self._ce, self.halo)
            dist = ndimage.distance_transform_edt(pad)[1:-1, 1:-1]
            # Interior: the whole disc of radius halo is masked (edt is exact
            # for integer squared distances, so the comparison is exact).
            self._interior = mr & (dist > self.halo)
            self._windows = edge_windows(self._ce, self.tile, self.halo)
            log.debug(
                "MaskedGridInterpolant: %d masked px, %d interior (halo %d px)",
                self.n_mask, int(self._interior.sum()), self.halo,
            )
        else:
            idx = ndimage.distance_transform_edt(~mr, return_distances=False, return_indices=True)
            self._fill = (idx[0], idx[1])
        self._nf = None
        self._single = False

    # -- data ---------------------------------------------------------------

    def field_values(self, fields, name="fields"):
        """(n_fields, n_mask) float64 values at the masked pixels, and single flag."""
        f = float_array(fields, name)
        if f.ndim >= 2 and f.shape[-2:] == self.shape:
            lead = f.shape[:-2]
            vals = f[..., self.pixels[:, 1], self.pixels[:, 0]]
        elif f.ndim >= 1 and f.shape[-1] == self.n_mask:
            lead = f.shape[:-1]
            vals = f
        else:
            raise ConfigError(
                f"{name} must have shape (n_mask,) = ({self.n_mask},), (H, W) = {self.shape}, "
                f"or one of these with a leading n_fields axis; got {f.shape}"
            )
        if len(lead) > 1:
            raise ConfigError(f"{name} may have at most one leading (n_fields) axis, got shape {f.shape}")
        single = len(lead) == 0
        vals = np.atleast_2d(vals)
        bad = ~np.isfinite(vals)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise DataError(
                f"{name}: field {i} has {int(bad[i].sum())} non-finite value(s) inside the mask, "
                f"first at pixel (u={self.pixels[j, 0]}, v={self.pixels[j, 1]}); every masked "
                "pixel must carry a finite value (remove such pixels from the mask)"
            )
        return vals, single

    def fit(self, fields):
        """Set the data.

        Parameters
        ----------
        fields : array_like
            Values at the masked pixels, shape (n_mask,) (in the order of
            :attr:`pixels`, i.e. ``np.nonzero(mask)``) or (H, W), or either with
            a leading ``n_fields`` axis. Values outside the mask are ignored.

        Returns
        -------
        self
        """
        vals, single = self.field_values(fields)
        self._single = single
        self.fit_values(vals)
        return self

    def fit_values(self, vals):
        """Set the data from checked values ``vals`` (n_fields, n_mask) (see :meth:`field_values`)."""
        nf = vals.shape[0]
        grid = np.zeros((nf, self._Hr, self._Wr))
        grid[:, self._vr, self._ur] = vals
        self._nf = nf
        if self.method == "rbf":
            self._grid = grid
            # float32 copy around a per-field offset, for the gathers of the
            # interior path (the central value is added back in float64).
            self._offset = vals.mean(axis=1)
            g32 = (grid - self._offset[:, None, None]).astype(np.float32)
            self._grid32 = g32
            D = 2 * self.halo + 1
            self._box = sliding_window_view(g32, (D, D), axis=(1, 2))
        else:
            filled = grid[:, self._fill[0], self._fill[1]]
            if self.method == "cubic":
                filled = ndimage.spline_filter1d(filled, 3, axis=1, mode="mirror")
                filled = ndimage.spline_filter1d(filled, 3, axis=2, mode="mirror")
            self._grid = filled

    # -- points ---------------------------------------------------------------

    def _check_points(self, points):
        p = float_array(points, "points")
        if p.ndim not in (2, 3) or p.shape[-1] != 2:
            raise ConfigError(
                f"points must have shape (M, 2) or (n_fields, M, 2) with columns (u, v), got {p.shape}"
            )
        if p.ndim == 3 and p.shape[0] != self._nf:
            raise ConfigError(
                f"points with shape (n_fields, M, 2) need n_fields = {self._nf} (the fitted fields), "
                f"got {p.shape[0]}"
            )
        return p

    def edge_distance(self, points):
        """Distance (px) of points to the mask edge; see :class:`Evaluation`.

        Parameters
        ----------
        points : array_like, shape (..., 2)
            (u, v) in px.

        Returns
        -------
        ndarray, shape (...)
        """
        p = float_array(points, "points")
        if p.shape[-1:] != (2,):
            raise ConfigError(f"points must have shape (..., 2) with columns (u, v), got {p.shape}")
        flat = p.reshape(-1, 2)
        loc = self.locate(flat[:, 0], flat[:, 1])
        return self.edge_from_location(flat[:, 0], flat[:, 1], loc).reshape(p.shape[:-1])

    def locate(self, u, v):
        """Pixel of each point: ``(finite, inside, pu, pv)``, pu/pv relative to the padded grid."""
        finite = np.isfinite(u) & np.isfinite(v)
        pu = np.zeros(u.shape, np.int64)
        pv = np.zeros(u.shape, np.int64)
        with np.errstate(invalid="ignore"):
            big = finite & (np.abs(u) < 1e9) & (np.abs(v) < 1e9)
        pu[big] = np.rint(u[big]).astype(np.int64) - self._ru0
        pv[big] = np.rint(v[big]).astype(np.int64) - self._rv0
        inside = big & (pu >= 0) & (pu < self._Wr) & (pv >= 0) & (pv < self._Hr)
        inside[inside] = self._mask_r[pv[inside], pu[inside]]
        return finite, inside, pu, pv

    def edge_from_location(self, u, v, loc):
        """Edge distance (px, see :class:`Evaluation`) of points already located by :meth:`locate`."""
        finite, inside, pu, pv = loc
        out = np.full(u.shape, np.nan)
        if inside.any():
            # padded-grid coordinates of the point's pixel (inside pixels are
            # >= 1 px from the padded border, so the neighbours exist)
            i = np.flatnonzero(inside)
            qv = v[i] - (self._rv0 - 1)
            qu = u[i] - (self._ru0 - 1)
            hv = pv[i] + 1
            hu = pu[i] + 1
            best = np.full(i.size, np.inf)
            fb_v, fb_u = self._feat_bg
            for ov in (-1, 0, 1):
                for ou in (-1, 0, 1):
                    cv = fb_v[hv + ov, hu + ou]
                    cu = fb_u[hv + ov, hu + ou]
                    np.minimum(best, (cv - qv) ** 2 + (cu - qu) ** 2, out=best)
            best = np.sqrt(best)
            near = best < _EDGE_EXACT
            if near.any():
                q = np.c_[u[i[near]], v[i[near]]]
                d = self._tree_bg.query(q, distance_upper_bound=float(best[near].max()) + 1e-6)[0]
                best[near] = np.minimum(best[near], d)
            out[i] = best - 0.5
        outside = finite & ~inside
        if outside.any():
            out[outside] = 0.5 - self._tree_fg.query(np.c_[u[outside], v[outside]])[0]
        return out

    # -- evaluation -------------------------------------------------------------

    def evaluate(self, points, derivatives=True):
        """Evaluate the fitted fields (and d/du, d/dv) at subpixel points.

        Parameters
        ----------
        points : array_like, shape (M, 2) or (n_fields, M, 2)
            (u, v) in px. (M, 2): the same points for every field;
            (n_fields, M, 2): one set of points per field. NaN points give NaN.
        derivatives : bool
            Also return ``d/du`` and ``d/dv`` (per px).

        Returns
        -------
        Evaluation
            value, du, dv with shape (n_fields, M) ((M,) when a single field
            without leading axis was fitted and the points are (M, 2)), NaN
            outside the mask; edge_distance (M,) or (n_fields, M).
        """
        if self._nf is None:
            raise ConfigError("call fit(fields) before evaluate(points)")
        if not isinstance(derivatives, (bool, np.bool_)):
            raise ConfigError(f"derivatives must be True or False, got {derivatives!r}")
        p = self._check_points(points)
        if p.ndim == 2:
            groups, g = 1, self._nf
        else:
            groups, g = self._nf, 1
        M = p.shape[-2]
        val, du, dv, edge = self.evaluate_grouped(
            p.reshape(groups, M, 2), g, (bool(derivatives),) * g
        )
        val = val.reshape(self._nf, M)
        if derivatives:
            du = du.reshape(self._nf, M)
            dv = dv.reshape(self._nf, M)
        else:
            du = dv = None
        edge = edge.reshape(M) if groups == 1 else edge.reshape(groups, M)
        if self._single and p.ndim == 2:
            val = val[0]
            if derivatives:
                du, dv = du[0], dv[0]
        return Evaluation(val, du, dv, edge)

    def evaluate_grouped(self, pts, g, derivs, edges=None, need=None):
        """Fields ``group * g + slot`` at ``pts[group]``; returns (G, g, M) x 3 and (G, M).

        ``edges``: an :class:`~irdic.image_rbf.batch.EdgeBatch` that collects
        the points near the mask edge instead of evaluating them; the returned
        arrays (views of the ones it writes into) hold their values once
        ``edges.run()`` returns. ``need`` (M,) bool: the points whose
        derivatives are wanted (default all; the others' may be left NaN).
        """
        G, M, _ = pts.shape
        flat = pts.reshape(-1, 2)
        u, v = flat[:, 0], flat[:, 1]
        loc = self.locate(u, v)
        edge = self.edge_from_location(u, v, loc).reshape(G, M)
        shape = (G * M, g)
        val = np.full(shape, np.nan)
        want = any(derivs)
        du = np.full(shape, np.nan)
        dv = np.full(shape, np.nan)
        _, inside, pu, pv = loc
        idx = np.flatnonzero(inside)
        if idx.size:
            grp = idx // M
            if self.method == "rbf":
                inner = self._interior[pv[idx], pu[idx]]
                self._eval_interior(idx[inner], grp[inner], u, v, pu, pv, g, derivs, val, du, dv)
                batch = EdgeBatch() if edges is None else edges
                batch.add(self, idx[~inner], grp[~inner], G, u, v, pu, pv, g, derivs, (val, du, dv),
                          None if need is None else np.tile(np.asarray(need, bool), G))
                if edges is None:
                    batch.run()
            elif self.method == "bilinear":
                self._eval_bilinear(idx, grp, u, v, g, val, du, dv)
            else:
                self._eval_cubic(idx, grp, u, v, g, val, du, dv)
        val = val.reshape(G, M, g).transpose(0, 2, 1)
        du = du.reshape(G, M, g).transpose(0, 2, 1)
        dv = dv.reshape(G, M, g).transpose(0, 2, 1)
        if not want:
            du = dv = None
        return val, du, dv, edge

    def _eval_interior(self, idx, grp, u, v, pu, pv, g, derivs, val, du, dv):
        if idx.size == 0:
            return
        st = self._stencil
        S, d, R = st.sub, st.degree, st.halo
        D = 2 * R + 1
        centre = R * D + R
        fu = (u[idx] - (pu[idx] + self._ru0) + 0.5) * S
        fv = (v[idx] - (pv[idx] + self._rv0) + 0.5) * S
        iu = np.clip(np.floor(fu).astype(np.int64), 0, S - 1)
        iv = np.clip(np.floor(fv).astype(np.int64), 0, S - 1)
        cell = iu * S + iv
        # Group by field set, then by sub-cell: each block gathers from one
        # 2-D grid (cache friendly) and uses one stencil.
        order = np.lexsort((cell, grp))
        idx, grp, cell = idx[order], grp[order], cell[order]
        ru, rv = pu[idx], pv[idx]
        Tu, Du = chebyshev(2 * (fu[order] - iu[order]) - 1, d)
        Tv, Dv = chebyshev(2 * (fv[order] - iv[order]) - 1, d)
        Du *= 2 * S  # d xi / d u
        Dv *= 2 * S
        key = grp * (S * S) + cell
        cuts = np.flatnonzero(np.r_[True, key[1:] != key[:-1], True])
        for a, b in zip(cuts[:-1], cuts[1:]):
            W = st.W32[cell[a]]
            for b0 in range(a, b, _INTERIOR_BLOCK):
                b1 = min(b0 + _INTERIOR_BLOCK, b)
                r_v, r_u = rv[b0:b1], ru[b0:b1]
                sel = idx[b0:b1]
                tu, tv = Tu[b0:b1], Tv[b0:b1]
                for f in range(g):
                    row = int(grp[a]) * g + f
                    P = self._box[row][r_v - R, r_u - R].reshape(b1 - b0, D * D)
                    # float32 differences to the central pixel: ~1e-6 K rounding
                    P -= P[:, centre:centre + 1]
                    Z = (P @ W).astype(float).reshape(b1 - b0, d + 1, d + 1)
                    Z[:, 0, 0] += self._grid[row, r_v, r_u]
                    ZTv = np.einsum("nab,nb->na", Z, tv)
                    val[sel, f] = np.einsum("na,na->n", ZTv, tu)
                    if derivs[f]:
                        du[sel, f] = np.einsum("na,na->n", ZTv, Du[b0:b1])
                        dv[sel, f] = np.einsum("nab,na,nb->n", Z, tu, Dv[b0:b1])

    def _eval_bilinear(self, idx, grp, u, v, g, val, du, dv):
        x = u[idx] - self._ru0
        y = v[idx] - self._rv0
        i = np.floor(x).astype(np.int64)
        j = np.floor(y).astype(np.int64)
        tx, ty = x - i, y - j
        for f in range(g):
            rows = grp * g + f
            gr = self._grid
            f00 = gr[rows, j, i]
            f01 = gr[rows, j, i + 1]
            f10 = gr[rows, j + 1, i]
            f11 = gr[rows, j + 1, i + 1]
            val[idx, f] = (1 - ty) * ((1 - tx) * f00 + tx * f01) + ty * ((1 - tx) * f10 + tx * f11)
            du[idx, f] = (1 - ty) * (f01 - f00) + ty * (f11 - f10)
            dv[idx, f] = (1 - tx) * (f10 - f00) + tx * (f11 - f01)

    def _eval_cubic(self, idx, grp, u, v, g, val, du, dv):
        x = u[idx] - self._ru0
        y = v[idx] - self._rv0
        i = np.floor(x).astype(np.int64)
        j = np.floor(y).astype(np.int64)
        wx, dwx = _bspline3(x - i)
        wy, dwy = _bspline3(y - j)
        for f in range(g):
            rows = grp * g + f
            # coefficient neighbourhood (n, 4, 4): rows j-1..j+2, columns i-1..i+2
            k = np.arange(-1, 3)
            cf = self._grid[rows[:, None, None], (j[:, None] + k)[:, :, None], (i[:, None] + k)[:, None, :]]
            cy = np.einsum("nab,nb->na", cf, wx)
            val[idx, f] = np.einsum("na,na->n", cy, wy)
            du[idx, f] = np.einsum("nab,na,nb->n", cf, wy, dwx)
            dv[idx, f] = np.einsum("na,na->n", cy, dwy)


MaskedGridRBF = MaskedGridInterpolant
"""Alias of :class:`MaskedGridInterpolant` (``method="rbf"`` is the default)."""

def _bspline3(t):
    """Cubic B-spline weights (n, 4) and their derivatives for offsets -1..2 of floor(x)."""
    t2 = t * t
    t3 = t2 * t
    w = np.stack([(1 - t) ** 3, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1, t3], axis=1) / 6
    d = np.stack([-((1 - t) ** 2), 3 * t2 - 4 * t, -3 * t2 + 2 * t + 1, t2], axis=1) / 2
    return w, d

