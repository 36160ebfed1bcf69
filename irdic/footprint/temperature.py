"""Footprint temperatures: the point temperatures of the couple stage from the pixels about each point.

The paper interpolates the IR frame at each projected DIC point, so a point
carries the noise of the few pixels next to it; with points 3 px apart that
is about one ninth of the specimen's pixels. ``points.temperature_footprint``
interpolates, with the same operator and in the same pass
(:func:`irdic.image_rbf.evaluate_series`, ``pixel_operator``), frames whose
pixels were first replaced by a local-linear fit over a box about one point
spacing wide (:func:`footprint_matrix`). The fields stage's spatial
regressions take it for the gradient and the rate
(:func:`irdic.footprint.fields.footprint_temperatures`); ``points.temperature`` stays the paper's,
and the denoised temperature is still regressed from it (the box's offset,
see :func:`footprint_matrix`, does not enter the value).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from .visibility import Projection

__all__ = ["FootprintOperator", "footprint_matrix", "footprint_side", "MAX_SIDE"]

#: largest box side (px). The box's offset, (side² - 1)/24 ∇²Θ px², stays a third of the Laplacian, and the
#: boxes of neighbouring points overlap little; sparser point clouds do not take wider boxes: with 5 px on the
#: tiny tube (points 13 px apart) the gradient's std covered 0.50 / 0.70 of its errors within 1 / 2 std
#: (interpolation 0.64 / 0.89, 3 px 0.59 / 0.80), the offset's gradient being a bias no probe sees
MAX_SIDE = 3


def footprint_side(pr: Projection) -> int:
    """Side (px, odd, 1 .. :data:`MAX_SIDE`) of the pixel box a point's footprint temperature fits: the
    largest odd number not above the median spacing of the projected points at the first stage with 6 or
    more in the frame, so that the boxes of neighbouring points barely overlap (their noise stays nearly
    independent)."""
    from scipy.spatial import cKDTree

    for k in range(pr.in_frame.shape[0]):
        q = pr.local[k][pr.in_frame[k] & np.isfinite(pr.local[k]).all(axis=1)]
        if q.shape[0] >= 6:
            d = float(np.median(cKDTree(q).query(q, k=2)[0][:, 1]))
            return int(min(MAX_SIDE, max(1, 2 * int((d - 1) // 2) + 1)))
    return 1


def footprint_matrix(mask: np.ndarray, pixels: np.ndarray, side: int) -> sparse.csr_matrix:
    """The local-linear box fit as a sparse operator on the values of the masked ``pixels``.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
        The specimen's pixels; only they enter a box.
    pixels : ndarray of int, shape (n, 2)
        (u, v) of the masked pixels, in the order of the value vectors.
    side : int
        Box side (px, odd).

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, n)
        Row ``i``: the weights whose product with the pixel values is the
        plane fitted (least squares) to the masked pixels of the box about
        pixel ``i``, at its centre.

    Notes
    -----
    With moments ``A = Σ m (1, dx, dy)ᵀ(1, dx, dy)`` over the box the
    centre value is ``e₀ᵀ A⁻¹ Σ m (1, dx, dy) Θ``: the weight of pixel ``j``
    is ``w₀ + w₁ dx_j + w₂ dy_j`` with ``w = A⁻¹ e₀``, and white pixel noise
    ``σ`` gives the centre value the variance ``σ² w₀``. Over a whole box it
    is the box mean (``w₀ = 1/side²``), which for a smooth field is the field
    plus ``(side² - 1)/24 ∇²Θ`` (px²): a constant for a quadratic field,
    whose gradient is unchanged. Where the mask's edge cuts the box, the
    plane through the remaining pixels is still evaluated at the centre
    (their plain mean would sit off centre: a bias of the gradient times the
    shift); with fewer than three pixels off a line a pixel keeps its own
    value.
    """
    from scipy import ndimage

    H, W = mask.shape
    m = np.asarray(mask, dtype=float)
    r = np.arange(side, dtype=float) - (side - 1) / 2
    dy, dx = np.meshgrid(r, r, indexing="ij")
    S0, Sx, Sy, Sxx, Sxy, Syy = (ndimage.correlate(m, k, mode="constant")
                                 for k in (np.ones_like(dx), dx, dy, dx * dx, dx * dy, dy * dy))
    u, v = pixels[:, 0], pixels[:, 1]
    A = np.stack([np.stack([S0, Sx, Sy], -1), np.stack([Sx, Sxx, Sxy], -1),
                  np.stack([Sy, Sxy, Syy], -1)], -2)[v, u]
    ok = np.abs(np.linalg.det(A)) > 1e-6 * np.maximum(S0[v, u], 1.0) ** 3
    w = np.zeros((u.size, 3))
    w[ok] = np.linalg.solve(A[ok], np.broadcast_to(np.eye(3)[0], (int(ok.sum()), 3))[..., None])[..., 0]
    index = np.full((H, W), -1, np.int64)
    index[v, u] = np.arange(u.size)
    rows, cols, vals = [np.arange(u.size)[~ok]], [np.arange(u.size)[~ok]], [np.ones(int((~ok).sum()))]
    fit = np.flatnonzero(ok)
    for ox, oy in zip(dx.ravel().astype(int), dy.ravel().astype(int)):
        uj, vj = u[fit] + ox, v[fit] + oy
        inside = (uj >= 0) & (uj < W) & (vj >= 0) & (vj < H)
        j = np.full(fit.size, -1, np.int64)
        j[inside] = index[vj[inside], uj[inside]]
        on = j >= 0
        i = fit[on]
        rows.append(i), cols.append(j[on]), vals.append(w[i, 0] + w[i, 1] * ox + w[i, 2] * oy)
    n = u.size
    return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


class FootprintOperator:
    """The ``pixel_operator`` of :func:`~irdic.image_rbf.evaluate_series` for boxes of ``side`` px:
    ``(mask, pixels) -> footprint_matrix``. The series evaluation applies it on the union of the masks
    of all times: a point's box then holds every pixel about it that was on the specimen at some time
    (the mask of its own time is eroded and shrunk by the motion: the boxes of the points next to its
    edge would be cut to half, with about 3 x the variance)."""

    def __init__(self, side: int):
        self.side = int(side)

    def __call__(self, mask, pixels):
        # kept for the points' noise factors (noise_factor)
        self.mask, self.pixels = np.asarray(mask, bool), np.asarray(pixels)
        self.matrix = footprint_matrix(self.mask, self.pixels, self.side)
        self._index = None
        return self.matrix

    def noise_factor(self, local, res, M, cols, samples):
        """Noise of each point's footprint temperature relative to a whole box's (n_t, M), 1 where unknown.

        Parameters
        ----------
        local : ndarray, shape (n_t, M, 2)
            The points' positions (px of the frame array).
        res, M, cols, samples
            The series evaluation of the points and their extrapolation
            samples, as :func:`irdic.footprint.extrapolation.extrapolate` takes them.

        Notes
        -----
        On the mask: ``side sqrt(Σ_j W_qj²)``, the row of the box fit at the
        nearest pixel ``q`` (1 for a whole box, up to ~3 where the union's
        edge cuts it). Extrapolated from the edge: the extrapolation is
        ``Σ_j a_j f_j`` of the samples ``f_j`` (1 px apart: their boxes
        overlap), so ``sqrt(Σ_jk a_j a_k s_j s_k ρ_jk)`` with ``s_j`` the
        samples' own factors and ``ρ`` the overlap of whole boxes about the
        samples' pixels (:func:`_box_overlap`); the weights ``a_j`` are the
        extrapolation of unit samples (the tube demo: ~2.5, against 1.3-2.6
        for white samples).
        """
        from .extrapolation import extrapolate

        n_t = local.shape[0]
        factor = self._box_factor(local)
        if cols.size == 0:
            return factor
        S = samples.shape[0]
        blank = np.where(np.isfinite(res.theta), 0.0, np.nan)  # the samples' NaN pattern: which are used
        zero = np.zeros_like(res.theta)
        a = np.zeros((S, n_t, cols.size))
        for j in range(S):  # the extrapolation is linear in the samples: a_j from unit samples
            unit = blank.copy()
            block = slice(M + j * cols.size, M + (j + 1) * cols.size)
            unit[:, block] = np.where(np.isfinite(res.theta[:, block]), 1.0, np.nan)
            th = np.zeros((n_t, M))
            scratch = [np.zeros((n_t, M)) for _ in range(4)]
            done = extrapolate(res._replace(theta=unit, dtheta_du=zero, dtheta_dv=zero, dtheta_dt=zero), M, cols,
                               samples, local, th, *scratch)
            a[j] = np.where(done[:, cols], th[:, cols], np.nan)
        pix = np.round(np.nan_to_num(samples)).astype(np.int64)  # (S, n_t, Mc, 2)
        own = np.stack([self._box_factor(samples[j]) for j in range(S)])  # the samples' boxes may be cut
        var = np.zeros((n_t, cols.size))
        for j in range(S):
            for k in range(S):
                var += np.nan_to_num(a[j] * a[k]) * own[j] * own[k] * _box_overlap(pix[j] - pix[k], self.side)
        ext = np.isfinite(a[0])
        tt, pp = np.nonzero(ext)
        factor[tt, cols[pp]] = np.sqrt(var[ext])
        return factor

    def _box_factor(self, local):
        """``side sqrt(Σ_j W_qj²)`` at the nearest pixel ``q`` of each position ``local`` (..., 2); 1 off the mask."""
        if getattr(self, "_index", None) is None:
            self._index = np.full(self.mask.shape, -1, np.int64)
            self._index[self.pixels[:, 1], self.pixels[:, 0]] = np.arange(self.pixels.shape[0])
            self._w2 = np.asarray(self.matrix.multiply(self.matrix).sum(axis=1)).ravel()
        q = _nearest_rows(self._index, local)
        factor = np.ones(q.shape)
        factor[q >= 0] = self.side * np.sqrt(self._w2[q[q >= 0]])
        return factor

    def frames(self, frames, mask):
        """``frames`` (n, H, W) with the masked pixels replaced by their box fit (tests, figures)."""
        vv, uu = np.nonzero(mask)
        out = np.array(frames, dtype=float)
        out[:, vv, uu] = (self(mask, np.c_[uu, vv]) @ out[:, vv, uu].T).T
        return out


def _nearest_rows(index, local):
    """Row of ``index`` (H, W) at the nearest pixel of each position ``local`` (..., 2) px; -1: none."""
    c = np.round(np.nan_to_num(local, nan=-1.0)).astype(np.int64)
    on = (c[..., 0] >= 0) & (c[..., 0] < index.shape[1]) & (c[..., 1] >= 0) & (c[..., 1] < index.shape[0])
    q = np.full(on.shape, -1, np.int64)
    q[on] = index[c[..., 1][on], c[..., 0][on]]
    return q


def _box_overlap(d, side):
    """Correlation of the means of two whole ``side`` x ``side`` boxes ``d`` (..., 2) px apart."""
    o = np.clip(side - np.abs(d), 0, None) / side
    return o[..., 0] * o[..., 1]
