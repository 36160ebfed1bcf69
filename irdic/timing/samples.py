"""The IR frames sampled at the moving DIC points, and the rank-one model of what they show.

:class:`Sampler` gives ``X(tau)`` (frames x samples): every IR frame ``k``
sampled at the positions the samples have at the DIC time ``t_k + tau``;
the samples are the DIC points and nodes between them
(:func:`prepared`). :class:`Criterion` is the rank-one misfit ``J(tau)``
and :func:`score_parts` the derivative of the rank-one model with the
residual, for the Gauss-Newton steps of :mod:`irdic.timing.offset`.
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.interpolate import make_interp_spline
from scipy.ndimage import distance_transform_edt, gaussian_filter
from scipy.spatial import Delaunay, QhullError, cKDTree

from ..footprint.mask import specimen_mask

__all__ = ["Sampler", "Criterion", "rank_one", "prepared", "score_parts", "model_derivative"]

#: neighbours (the point included) of the local planes that give the pattern's gradient
_NEIGHBOURS = 9


class Sampler:
    """``X(tau)``: the frames sampled at the DIC points' positions at the DIC times ``t_ir + tau``.

    The frames are smoothed by a Gaussian of ``smoothing`` px first: sampled at positions that move with
    the candidate offset, raw pixel noise would make the criterion a rough function of the offset whose
    wiggles (the noise's own gradient along the motion) hide the pattern's misfit.
    """

    def __init__(self, frames, t_ir, t_dic, positions, smoothing: float = 0.0):
        # float32 as stored (half the memory); samples and sums are float64
        self.raw = np.asarray(frames, dtype=np.float32)
        self.smoothing = float(smoothing)
        self.frames = (gaussian_filter(self.raw, (0, self.smoothing, self.smoothing), mode="nearest")
                       if self.smoothing > 0 else self.raw)
        self.t_ir = t_ir
        self.t0, self.t1 = float(t_dic[0]), float(t_dic[-1])
        k = min(3, t_dic.size - 1)
        self.spline = make_interp_spline(t_dic, positions.reshape(t_dic.size, -1), k=k, axis=0)
        self.M = positions.shape[1]
        self.t_dic, self.positions = t_dic, positions
        k = min(_NEIGHBOURS, self.M)
        self.neighbours = cKDTree(positions[0]).query(positions[0], k=k)[1][:, 1:]
        _, self.h, self.w = self.frames.shape

    def subset(self, points: int) -> "Sampler":
        """The same frames with at most ``points`` of the points, evenly spread."""
        if self.M <= points:
            return self
        keep = np.linspace(0, self.M - 1, points).round().astype(int)
        out = copy.copy(self)
        out.spline = make_interp_spline(self.t_dic, self.positions[:, keep].reshape(self.t_dic.size, -1),
                                        k=min(3, self.t_dic.size - 1), axis=0)
        out.positions, out.M = self.positions[:, keep], keep.size
        out.neighbours = cKDTree(out.positions[0]).query(out.positions[0], k=min(_NEIGHBOURS, keep.size))[1][:, 1:]
        return out

    def inside(self, tau_lo: float, tau_hi: float) -> np.ndarray:
        """Frames every offset in [tau_lo, tau_hi] places inside the DIC record."""
        eps = 1e-9 * max(1.0, abs(self.t1))
        return np.flatnonzero((self.t_ir + tau_lo >= self.t0 - eps) & (self.t_ir + tau_hi <= self.t1 + eps))

    def weights(self, tau: float, idx: np.ndarray):
        """Flat pixel indices (n, M, 4) and bilinear weights (n, M, 4) of frames ``idx`` at offset ``tau``."""
        q = self.spline(self.t_ir[idx] + tau).reshape(idx.size, self.M, 2)
        u = np.clip(q[..., 0], 0.0, self.w - 1.000001)
        v = np.clip(q[..., 1], 0.0, self.h - 1.000001)
        j, i = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        fu, fv = u - j, v - i
        base = idx[:, None] * (self.h * self.w) + i * self.w + j
        flat = np.stack([base, base + 1, base + self.w, base + self.w + 1], axis=-1)
        wts = np.stack([(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv], axis=-1)
        return flat, wts

    def __call__(self, tau: float, idx: np.ndarray, raw: bool = False):
        """The samples (n, M) of the smoothed (or ``raw``) frames."""
        flat, wts = self.weights(tau, idx)
        return np.einsum("nmc,nmc->nm", (self.raw if raw else self.frames).reshape(-1)[flat], wts)


def rank_one(Xc: np.ndarray, start: np.ndarray | None = None, iters: int = 300):
    """Largest singular value squared of ``Xc`` and its (left, right) unit vectors, by power iteration."""
    n, m = Xc.shape
    v = np.ones(m) / np.sqrt(m) if start is None or start.size != m else start.copy()
    lam = 0.0
    for _ in range(iters):
        u = Xc @ v
        w = Xc.T @ u
        new = float(np.linalg.norm(w))
        if new == 0.0:
            return 0.0, np.zeros(n), v
        v = w / new
        # new = s1^2 once converged; stop when it changes by less than 1e-14 relative
        if abs(new - lam) <= 1e-14 * new:
            lam = new
            break
        lam = new
    u = Xc @ v
    s = float(np.linalg.norm(u))
    return s * s, (u / s if s > 0 else u), v


class Criterion:
    """``J(tau)`` per sample on a fixed set of frames, with a warm start for the power iteration."""

    def __init__(self, sampler: Sampler, idx: np.ndarray):
        self.sampler, self.idx = sampler, idx
        self.start = None

    def parts(self, tau: float):
        X = self.sampler(tau, self.idx)
        Xc = X - X.mean(axis=1, keepdims=True)
        s2, u, v = rank_one(Xc, self.start)
        self.start = v
        return float(np.sum(Xc * Xc)) - s2, Xc, u, v

    def __call__(self, tau: float) -> float:
        return self.parts(tau)[0] / self.idx.size / self.sampler.M


def prepared(positions, t_dic, max_points, inset=0.0, spacing=0.0):
    """Points seen at half the DIC times or more, their gaps interpolated linearly in time; of those the ones at
    least ``inset`` px inside the cloud's outline at the first and the last time, at most ``max_points``,
    evenly spread. With ``spacing`` (px), samples between the points are added (:func:`_densified`)."""
    ok_t = np.isfinite(positions).all(axis=2)
    ok = ok_t.sum(axis=0) >= max(2, (t_dic.size + 1) // 2)
    pos = positions[:, ok].copy()
    for j in np.flatnonzero(~ok_t[:, ok].all(axis=0)):
        good = ok_t[:, ok][:, j]
        for c in (0, 1):
            pos[:, j, c] = np.interp(t_dic, t_dic[good], pos[good, j, c])
    if spacing > 0 and pos.shape[1] >= 3:
        pos = _densified(pos, spacing)
    keep = np.ones(pos.shape[1], bool)
    if inset > 0 and keep.sum() >= 3:
        for k in (0, -1):
            keep &= _inside_outline(pos[k]) >= inset
    keep = np.flatnonzero(keep)
    if keep.size > max_points:
        keep = keep[np.linspace(0, keep.size - 1, max_points).round().astype(int)]
    return pos[:, keep]


def _densified(pos: np.ndarray, spacing: float, max_factor: int = 4) -> np.ndarray:
    """The points (n_t, N, 2) and samples between them, about ``spacing`` px apart in the first frame.

    Each triangle of the points' triangulation at the first time (without the triangles longer than
    3 median spacings: holes and concave outlines stay open) is divided into ``r^2`` by a barycentric grid
    of ``r + 1`` nodes per edge, ``r`` the points' spacing over ``spacing`` (at most ``max_factor``); a node
    moves with the barycentric mean of its corners, exact where the motion is affine over a triangle.
    Nodes shared by triangles are kept once.
    """
    p0 = pos[0]
    d = cKDTree(p0).query(p0, k=2)[0][:, 1]
    r = int(min(max_factor, np.floor(np.median(d) / spacing)))
    if r < 2:
        return pos
    try:
        tri = Delaunay(p0)
    except QhullError:
        return pos
    c = p0[tri.simplices]
    edges = np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).max(axis=1)
    simp = tri.simplices[edges <= 3.0 * np.median(d)]
    i, j = np.meshgrid(np.arange(r + 1), np.arange(r + 1), indexing="ij")
    sel = (i + j <= r) & ~(((i == 0) | (i == r)) & (j == 0) | ((i == 0) & (j == r)))
    bary = np.stack([r - i[sel] - j[sel], i[sel], j[sel]], axis=1) / r  # (B, 3)
    # a node's key: its corners' indices and weights, sorted, so that a node shared by two triangles is found once
    nodes = simp[:, None, :].repeat(bary.shape[0], axis=1).reshape(-1, 3)
    wts = np.broadcast_to(bary, (simp.shape[0],) + bary.shape).reshape(-1, 3)
    key = np.sort(np.where(wts > 0, nodes, -1) * (r + 1) + np.rint(wts * r).astype(np.int64), axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    nodes, wts = nodes[first], wts[first]
    extra = np.einsum("tnci,nc->tni", pos[:, nodes], wts)
    return np.concatenate([pos, extra], axis=1)


def _inside_outline(p: np.ndarray) -> np.ndarray:
    """Distance (px) of each position (N, 2) to the outline of the cloud of the positions."""
    lo = np.floor(p.min(axis=0)).astype(int) - 2
    hi = np.ceil(p.max(axis=0)).astype(int) + 3
    u, v = np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1])
    inside = distance_transform_edt(specimen_mask(p, u, v, erosion_px=0.0))
    q = np.clip(p.round().astype(int) - lo, 0, [u.size - 1, v.size - 1])
    return inside[q[:, 1], q[:, 0]]


def score_parts(sampler: Sampler, J: Criterion, tau: float):
    """At ``tau``: the model's derivative ``Y`` with the rank-one directions taken out, the residual ``R`` of the
    rank-one fit (both (n, M), K/s and K) and the fitted singular vectors ``(u, v)``."""
    e, Xc, u, v = J.parts(tau)
    s = np.sqrt(max(float(np.sum(Xc * Xc)) - e, 0.0))
    R = Xc - s * np.outer(u, v)
    # frame k's pattern from the other frames (leave one out): its own noise would enter the derivative and the
    # residual at once, and their correlation (one-sided neighbours near the outline) biases the root
    p = Xc.T @ u
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(u * u < 0.999, u / (1.0 - u * u), 0.0)
    Y = model_derivative(sampler, J.idx, tau, scale, p[None, :] - u[:, None] * Xc)
    Y -= Y.mean(axis=1, keepdims=True)
    Y -= np.outer(u, u @ Y)
    Y -= np.outer(Y @ v, v)
    return Y, R, (u, v)


def model_derivative(sampler: Sampler, idx: np.ndarray, tau: float, amplitude: np.ndarray,
                      pattern: np.ndarray) -> np.ndarray:
    """d/dtau of the rank-one model ``amplitude_k pattern_kj`` sampled at the points' positions (n, M), K/s.

    The sample of frame ``k`` moves with the image velocity ``w``; the model's change is
    ``amplitude_k grad(pattern) . w``, with the pattern's gradient in frame ``k``'s image from a local
    least-squares plane through each point's neighbours (at their positions in that frame). The pattern is
    the rank-one fit's, averaged over every frame: its gradient carries a small share of the pixel noise,
    where the frames' own derivative (sampled at moving positions) carries all of it.
    """
    t = sampler.t_ir[idx] + tau
    q = sampler.spline(t).reshape(idx.size, sampler.M, 2)
    w = sampler.spline.derivative()(t).reshape(idx.size, sampler.M, 2)
    nb = sampler.neighbours
    # components apart: einsum over the two-element axes is several times slower
    dx = q[:, nb, 0] - q[:, :, None, 0]                      # (n, M, K)
    dy = q[:, nb, 1] - q[:, :, None, 1]
    dp = pattern[:, nb] - pattern[:, :, None]
    sxx, sxy, syy = (dx * dx).sum(-1), (dx * dy).sum(-1), (dy * dy).sum(-1)
    bx, by = (dx * dp).sum(-1), (dy * dp).sum(-1)
    det = sxx * syy - sxy * sxy
    with np.errstate(invalid="ignore", divide="ignore"):
        g = ((syy * bx - sxy * by) * w[..., 0] + (sxx * by - sxy * bx) * w[..., 1]) / det
    g = np.where(np.isfinite(g), g, 0.0)
    return amplitude[:, None] * g
