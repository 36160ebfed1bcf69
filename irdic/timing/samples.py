"""The IR frames sampled at material nodes that move with the DIC points, and the rank-one model of them.

:class:`Sampler` gives ``X(tau)`` (frames x nodes): every IR frame ``k``
sampled bilinearly, after a light Gaussian smoothing, at the positions the
nodes (:class:`~irdic.timing.nodes.Nodes`) have at the DIC time
``t_k + tau``; :meth:`Sampler.spread` is its adjoint (weights on the samples
to weights on the pixels), for the noise of anything linear in the samples.
:class:`Criterion` is the misfit of the rank-one model ``X_k = a_k + b_k P``
that the offset search minimises (``X_k = a_k + sum_i b_ik P_i`` with more
components where the pattern changes its shape on the material).
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.ndimage import gaussian_filter

from ..numerics.series import valid_neighbours
from .nodes import Nodes

__all__ = ["Sampler", "Criterion", "leading", "prepared", "BLOCK_SAMPLES"]

#: samples (frames x nodes) computed at once: the temporaries of a block stay in the CPU's cache and are reused
#: from the allocator's heap, where arrays of all the samples (tens of MB at paper scale) were mapped afresh
#: from the system on every call, and their page faults cost as much system time as the arithmetic took
BLOCK_SAMPLES = 1 << 17


class Sampler:
    """``X(tau)``: the frames, smoothed by a Gaussian of ``smoothing`` px, sampled at the nodes at ``t_ir + tau``.

    Parameters
    ----------
    frames : numpy.ndarray, shape (F, h, w)
        IR frames (K), finite.
    t_ir : numpy.ndarray, shape (F,)
        Their times on the IR clock (s).
    nodes : Nodes
        The material nodes, in the frames' pixel coordinates.
    smoothing : float
        Standard deviation (px) of the Gaussian smoothing: sampled at positions that move with the offset, raw
        pixel noise makes any criterion a rough function of the offset.
    """

    def __init__(self, frames: np.ndarray, t_ir: np.ndarray, nodes: Nodes, smoothing: float):
        self.raw = np.asarray(frames, dtype=np.float32)  # as stored: half the memory; sums are float64
        self.smoothing = float(smoothing)
        self.frames = self._smoothed(self.raw)
        self.t_ir, self.nodes = np.asarray(t_ir, float), nodes
        self.t0, self.t1 = float(nodes.t_dic[0]), float(nodes.t_dic[-1])
        _, self.h, self.w = self.frames.shape
        self._cache: dict = {}

    @property
    def M(self) -> int:
        return self.nodes.M

    def copy(self) -> "Sampler":
        """The same sampler with a cache of its own (the frames and nodes shared): for another thread."""
        out = copy.copy(self)
        out._cache = {}
        return out

    def with_noise(self, sigma: float, rng: np.random.Generator) -> "Sampler":
        """The same sampler on the frames with another realisation of white pixel noise of ``sigma`` K added
        (the nodes' positions, which do not depend on the frames, shared with this one)."""
        out = copy.copy(self)
        out.raw = self.raw + rng.standard_normal(self.raw.shape, dtype=np.float32) * np.float32(sigma)
        out.frames = self._smoothed(out.raw)
        return out

    def _smoothed(self, raw: np.ndarray) -> np.ndarray:
        """``raw`` (F, h, w) smoothed in each frame by the Gaussian of :attr:`smoothing` px (as is where 0)."""
        return gaussian_filter(raw, (0, self.smoothing, self.smoothing), mode="nearest") if self.smoothing > 0 else raw

    def inside(self, tau_lo: float, tau_hi: float, slack: float = 0.0) -> np.ndarray:
        """Frames every offset in [tau_lo, tau_hi] places inside the DIC record (widened by ``slack`` s)."""
        eps = 1e-9 * max(1.0, abs(self.t1)) + slack
        return np.flatnonzero((self.t_ir + tau_lo >= self.t0 - eps) & (self.t_ir + tau_hi <= self.t1 + eps))

    def positions(self, tau: float, idx: np.ndarray, nodes: Nodes | None = None):
        """The flat index (n, M) of the upper left pixel of each node's position in frames ``idx`` at ``tau``, and
        its fractions (u, v) to the next (float32, exact): the last few are kept."""
        nodes = nodes or self.nodes
        key = (float(tau), np.asarray(idx, np.int64).tobytes(), id(nodes))
        if key not in self._cache:
            n, t = idx.size, self.t_ir[idx] + tau
            # 32-bit indices where they reach: half the memory traffic
            kind = np.int32 if self.frames.size < 2**31 else np.int64
            base, fu, fv = np.empty((n, nodes.M), kind), np.empty((n, nodes.M), np.float32), np.empty((n, nodes.M),
                                                                                                     np.float32)
            for rows, q in nodes.blocks(t, _rows(nodes.M)):
                # float32 positions: 1e-5 px at 500 px; u - j is then exact in float32
                u = np.clip(q[..., 0], 0.0, self.w - 1.001).astype(np.float32)
                v = np.clip(q[..., 1], 0.0, self.h - 1.001).astype(np.float32)
                j, i = u.astype(kind), v.astype(kind)
                np.subtract(u, j, out=fu[rows], casting="unsafe")
                np.subtract(v, i, out=fv[rows], casting="unsafe")
                i *= kind(self.w)
                i += j
                i += (idx[rows, None] * (self.h * self.w)).astype(kind)
                base[rows] = i
            if len(self._cache) >= 3:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = (base, fu, fv)
        return self._cache[key]

    def __call__(self, tau: float, idx: np.ndarray, raw: bool = False, nodes: Nodes | None = None) -> np.ndarray:
        """The samples (n, M) of frames ``idx`` (smoothed, or ``raw``), at the nodes' positions
        (another interpolant in time with ``nodes``)."""
        base, fu, fv = self.positions(tau, idx, nodes)
        f = (self.raw if raw else self.frames).reshape(-1)
        out = np.empty(base.shape)
        for rows in _blocks(base.shape[0], base.shape[1]):
            _bilinear(f, base[rows], fu[rows], fv[rows], self.w, out[rows])
        return out

    def gain(self, tau: float, idx: np.ndarray, rows: slice = slice(None)) -> np.ndarray:
        """Each sample's noise variance (n, M) relative to a sample at a pixel's centre, for white pixel noise
        (of the frames ``rows`` of ``idx`` only, where given).

        Notes
        -----
        A sample ``(1-f) p_0 + f p_1`` (per axis) of the smoothed frame has the
        variance ``(1-f)^2 + f^2 + 2 f (1-f) c`` of one pixel's (``c`` the
        correlation of neighbouring smoothed pixels), so samples between
        pixels are less noisy than samples on them: a criterion that weighs
        every sample alike would prefer offsets that put static frames
        between pixels.
        """
        _, fu, fv = self.positions(tau, idx)
        c = self._neighbour_correlation

        def axis(f):  # (1 - f)^2 + f^2 + 2 f (1 - f) c
            g = 1.0 - f.astype(np.float64)
            g *= f
            g *= -2.0 * (1.0 - c)
            g += 1.0
            return g

        out = axis(fu[rows])
        out *= axis(fv[rows])
        return out

    @property
    def _neighbour_correlation(self) -> float:
        if self.smoothing <= 0:
            return 0.0
        k = gaussian_filter(np.eye(1, 41, 20).ravel(), self.smoothing, mode="constant")
        return float(np.sum(k[1:] * k[:-1]) / np.sum(k * k))

    def spread(self, tau: float, idx: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """``G B^T Y``: weights ``Y`` (n, M) on the samples of frames ``idx`` as weights on their pixels
        (n, h, w); ``sum(Y * X) = sum(spread * frames[idx])`` for the raw frames."""
        base, fu, fv = self.positions(tau, idx)
        fu, fv = fu.astype(float), fv.astype(float)
        base = base - (idx * (self.h * self.w))[:, None] + (np.arange(idx.size) * (self.h * self.w))[:, None]
        size = idx.size * self.h * self.w
        acc = np.zeros(size)
        for off, wt in ((0, (1 - fu) * (1 - fv)), (1, fu * (1 - fv)), (self.w, (1 - fu) * fv), (self.w + 1, fu * fv)):
            acc += np.bincount((base + off).ravel(), (wt * Y).ravel(), size)
        acc = acc.reshape(idx.size, self.h, self.w)
        if self.smoothing > 0:
            acc = gaussian_filter(acc, (0, self.smoothing, self.smoothing), mode="constant")
        return acc


def _rows(M: int) -> int:
    """Frames per block of :data:`BLOCK_SAMPLES` samples of ``M`` nodes (at least one)."""
    return max(1, BLOCK_SAMPLES // max(M, 1))


def _blocks(n: int, M: int):
    """Slices of ``n`` frames, :func:`_rows` each."""
    rows = _rows(M)
    return [slice(r, min(r + rows, n)) for r in range(0, n, rows)]


def _bilinear(f: np.ndarray, base: np.ndarray, fu: np.ndarray, fv: np.ndarray, w: int, out: np.ndarray):
    """``out`` = the bilinear samples of the flat frames ``f`` at pixels ``base`` (upper left) and fractions
    ``fu``, ``fv`` (float32, exact): ``top + fv (bottom - top)``, ``top = a + fu (b - a)``, ``bottom = c + fu
    (d - c)``, in place in float64."""
    a, b = np.take(f, base), np.take(f, base + 1)
    b -= a
    top = np.multiply(fu, b, dtype=np.float64)
    top += a
    c, d = np.take(f, base + w), np.take(f, base + (w + 1))
    d -= c
    np.multiply(fu, d, out=out, dtype=np.float64)
    out += c
    out -= top
    out *= fv
    out += top


def leading(Xc: np.ndarray, rank: int = 1, start: np.ndarray | None = None, iters: int = 300, tol: float = 1e-13):
    """The ``rank`` largest singular values squared (rank,) of ``Xc`` (n, m) and their left (n, rank) and right
    (m, rank) unit vectors.

    One component: by power iteration from ``start`` (m, 1) if given, until the value changes by less than
    ``tol`` relative or after ``iters`` steps (the pattern's value stands far above the noise's, so a few steps
    do). More: exactly, from the eigenvectors of the smaller Gram matrix (``Xc Xc^T`` or ``Xc^T Xc``) and a
    Rayleigh-Ritz step on the subspace they span (``start``, ``iters`` and ``tol`` unused).

    Notes
    -----
    A second or third component follows the pattern's change of shape, often barely above the noise: a
    subspace iteration then converges at the ratio of its value to the noise's next one and needs hundreds of
    steps, each ``4 rank n m`` operations, where the Gram matrix costs ``min(n, m) n m`` once. The values'
    error is that of the Gram matrix's eigenvalues, about ``1e-16`` of the largest: far below the criterion's
    differences between offsets.
    """
    n, m = Xc.shape
    if rank > 1:
        small = Xc @ Xc.T if n <= m else Xc.T @ Xc
        Q = np.linalg.eigh(small)[1][:, :-rank - 1:-1]  # the top eigenvectors, largest first
        if n <= m:
            P, s, Wt = np.linalg.svd(Q.T @ Xc, full_matrices=False)
            return s**2, Q @ P, Wt.T
        U, s, Wt = np.linalg.svd(Xc @ Q, full_matrices=False)
        return s**2, U, Q @ Wt.T
    V = start if start is not None and start.shape == (m, 1) else np.ones((m, 1)) / np.sqrt(m)
    total = 0.0
    for _ in range(iters):
        W = Xc.T @ (Xc @ V)
        norm = float(np.linalg.norm(W))
        if norm == 0.0:
            return np.zeros(1), np.zeros((n, 1)), V
        V, new = W / norm, norm
        if abs(new - total) <= tol * new:
            break
        total = new
    B = Xc @ V
    s = np.linalg.norm(B, axis=0)
    return s**2, B / np.where(s > 0, s, 1.0), V


class Criterion:
    """``J(tau)`` per sample on a fixed set of frames, with a warm start for the power iteration (one component)."""

    def __init__(self, sampler: Sampler, idx: np.ndarray, rank: int = 1):
        self.sampler, self.idx, self.rank = sampler, idx, rank
        self.start = None

    def __call__(self, tau: float) -> float:
        """The misfit of the rank-``rank`` model per sample (K^2), each sample's residual squared over its noise
        gain (:meth:`Sampler.gain`)."""
        sampler = self.sampler
        Xc = sampler(tau, self.idx)
        Xc -= Xc.mean(axis=1, keepdims=True)
        # the criterion compares candidates whose misfits differ by far more than 1e-10 of the samples' power
        s2, U, V = leading(Xc, self.rank, self.start, tol=1e-10)
        self.start = V
        B, total = U * np.sqrt(s2), 0.0
        for rows in _blocks(*Xc.shape):
            R = Xc[rows] - B[rows] @ V.T
            R *= R
            R /= sampler.gain(tau, self.idx, rows)
            total += float(np.sum(R))
        return total / self.idx.size / sampler.M


def prepared(positions: np.ndarray, t_dic: np.ndarray) -> np.ndarray:
    """Points (n_t, N', 2) seen at half the DIC times or more, their gaps interpolated linearly in time (held at
    the nearest time seen before the first and after the last, as :func:`numpy.interp`)."""
    ok_t = np.isfinite(positions).all(axis=2)
    ok = ok_t.sum(axis=0) >= max(2, (t_dic.size + 1) // 2)
    pos = positions[:, ok].copy()
    seen = ok_t[:, ok]
    if seen.all():
        return pos
    # each gap's last time seen before it and first after it, for all points at once
    before, after = valid_neighbours(seen)
    i, j = np.nonzero(~seen)
    lo, hi = before[i, j], after[i, j]
    lo, hi = np.where(lo < 0, hi, lo), np.where(hi >= t_dic.size, lo, hi)
    span = t_dic[hi] - t_dic[lo]
    w = np.divide(t_dic[i] - t_dic[lo], span, out=np.zeros_like(span), where=span > 0)[:, None]
    pos[i, j] = pos[lo, j] * (1.0 - w) + pos[hi, j] * w
    return pos
