"""The offset's score with fixed weights: its root, slope and standard uncertainty.

Near the true offset ``tau*`` the samples are ``X(tau) = a 1^T + b P^T +
X' (tau - tau*) + e`` (the rank-one model, its derivative along the motion,
the smoothed pixel noise). :class:`Score` fixes weights ``Y`` (frames x
nodes) at a trial offset: the model's derivative ``u_k grad(p) . r_kj``
(the fitted pattern's reference gradient along the node's reference
velocity, scaled by the frame's amplitude) with every direction the model
absorbs projected out (row means, ``u z^T`` and ``z v^T`` for the fitted
singular vectors ``u``, ``v``). Then ``S(tau) = sum(Y * X(tau))`` needs no
refit: the rank-one part of ``X`` is orthogonal to ``Y``. Its root is the
estimate; with fixed weights the score is a smooth, near-linear function of
the offset (the noise enters once, through the samples, not through the
weights of every trial), so a secant gives the slope and Newton steps the
root.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .samples import Sampler, leading

__all__ = ["Score", "solve", "Uncertainty", "uncertainty"]

#: the slope is the secant over this many IR frame periods either side
SECANT_FRAMES = 0.25
#: Newton steps at most, and the step (IR frame periods) that ends them
NEWTON_STEPS, NEWTON_TOL = 6, 5e-3
#: image tiles (px) of the robust variance: residuals correlated within a tile (over all its frames) are summed
TILE_PX = 16


class Score:
    """``S(tau) = sum(Y * X(tau))`` with weights ``Y`` fixed at ``tau_w`` on frames ``idx``.

    Parameters
    ----------
    sampler : Sampler
    idx : numpy.ndarray of int
        The frames (contiguous).
    tau_w : float
        Offset (s) at which the rank-one model and the weights are fitted.
    bandwidth : float
        Gaussian width (px of the reference image) of the pattern's gradient fit.

    Attributes
    ----------
    last : (float, numpy.ndarray)
        The last offset evaluated and its samples (n, M).
    rate : numpy.ndarray
        After :func:`solve`: each sample's share of the slope, ``Y dX/dtau`` (n, M), from the secant.
    """

    def __init__(self, sampler: Sampler, idx: np.ndarray, tau_w: float, bandwidth: float, rank: int = 1):
        self.sampler, self.idx, self.tau_w, self.rank = sampler, idx, float(tau_w), rank
        X = sampler(tau_w, idx)
        Xc = X - X.mean(axis=1, keepdims=True)
        _, U, V = leading(Xc, rank)
        _, r = sampler.nodes.motion(sampler.t_ir[idx] + tau_w)
        Y = np.zeros_like(Xc)
        for i in range(rank):  # the model sum_i u_i p_i^T, each pattern moved along the motion
            g = sampler.nodes.gradient(Xc.T @ U[:, i], bandwidth)
            Y += U[:, i, None] * (g[None, :, 0] * r[..., 0] + g[None, :, 1] * r[..., 1])
        Y -= Y.mean(axis=1, keepdims=True)
        Y -= U @ (U.T @ Y)
        Y -= (Y @ V) @ V.T
        self.Y, self.V = Y, V
        self.last, self.rate = (self.tau_w, X), None

    def samples(self, tau: float) -> np.ndarray:
        if self.last[0] != tau:
            self.last = (float(tau), self.sampler(tau, self.idx))
        return self.last[1]

    def __call__(self, tau: float, nodes=None) -> float:
        X = self.samples(tau) if nodes is None else self.sampler(tau, self.idx, nodes=nodes)
        return float(np.sum(self.Y * X))

    def residual(self) -> np.ndarray:
        """The samples of the last offset evaluated less the model fitted to them (n, M), K."""
        X = self.last[1]
        Xc = X - X.mean(axis=1, keepdims=True)
        s2, U, V = leading(Xc, self.rank, self.V)
        return Xc - (U * np.sqrt(s2)) @ V.T


def solve(score: Score, tau0: float, period: float) -> tuple[float, float]:
    """The root of ``score`` near ``tau0`` (s) and the score's slope there (per s): the secant over
    :data:`SECANT_FRAMES` frame periods either side, then Newton steps with that slope until a step is below
    :data:`NEWTON_TOL` frame periods (its samples, :attr:`Score.last`, are those of the offset before it)."""
    d = SECANT_FRAMES * period
    lo = score.samples(tau0 - d)
    hi = score.samples(tau0 + d) - lo
    score.rate = score.Y * hi / (2.0 * d)
    slope = float(np.sum(score.rate))
    if not slope > 0:
        return np.nan, slope
    tau = tau0 - (float(np.sum(score.Y * lo)) + 0.5 * slope * 2.0 * d) / slope
    for _ in range(NEWTON_STEPS):
        step = float(np.clip(-score(tau) / slope, -2 * period, 2 * period))
        tau += step
        if abs(step) <= NEWTON_TOL * period:
            break
    return tau, slope


@dataclass(frozen=True)
class Uncertainty:
    """The parts of the estimate's standard uncertainty (s).

    Attributes
    ----------
    noise : float
        From white pixel noise of the measured level (the linear score's exact variance).
    robust : float
        From the residuals themselves, summed per image tile over all frames (any correlation within a tile,
        in space or in time, counted).
    interpolation : float
        The change of the estimate with the spline of the motion two degrees lower.
    model : float
        Where the pattern changes its shape on the material: the change of the estimate between models of two
        and three pattern components (0 for a pattern that only scales).
    std : float
        The standard uncertainty: the larger of the first two, the others in quadrature.
    """

    noise: float
    robust: float
    interpolation: float
    model: float = 0.0

    @property
    def std(self) -> float:
        return float(np.sqrt(max(self.noise, self.robust) ** 2 + self.interpolation**2 + self.model**2))


def uncertainty(score: Score, tau: float, slope: float, sigma: float) -> Uncertainty:
    """The standard uncertainty of the root ``tau`` (s) of ``score`` (solved) with slope ``slope``, pixel noise
    ``sigma`` (K).

    Notes
    -----
    The root's error is ``-S(tau*) / S'`` and ``S(tau*) = sum(Y * e)`` with
    ``e = G B n`` the pixel noise ``n`` smoothed (``G``) and sampled
    bilinearly (``B``), so for white noise ``var = sigma^2 ||G B^T Y||^2 / S'^2``.
    The robust variance sums ``Y * R`` (``R`` the rank-one residual at the
    root, as last evaluated) per tile of :data:`TILE_PX` px over all frames and adds the squares,
    each over ``1 - h`` with ``h`` the tile's share of the slope (the root
    absorbs that share of its residual). The interpolation part is the root's
    shift, ``S_lower(tau) / S'`` (``S(tau) = 0``), when the nodes move by the
    spline two degrees lower (one for a quadratic or cubic).
    """
    sampler, idx, Y = score.sampler, score.idx, score.Y
    noise = sigma * float(np.sqrt(np.sum(sampler.spread(tau, idx, Y) ** 2))) / slope
    # tiles of the reference image: a node's every frame in one tile (the rank-one fit's share of a node's
    # residual over the frames is orthogonal to its weights)
    ref = sampler.nodes.reference
    cell = np.floor((ref - ref.min(axis=0)) / TILE_PX).astype(np.int64)
    tile = np.broadcast_to(cell[:, 1] * (cell[:, 0].max() + 1) + cell[:, 0], Y.shape).ravel()
    sums = np.bincount(tile, (Y * score.residual()).ravel())
    share = np.bincount(tile, score.rate.ravel(), sums.size) / slope
    robust = float(np.sqrt(np.sum(sums**2 / np.clip(1.0 - share, 0.5, None)))) / slope
    order = sampler.nodes.order
    interpolation = 0.0
    if order >= 2:
        lower = sampler.nodes.with_order(order - 2 if order >= 4 else 1)
        interpolation = abs(score(tau, nodes=lower) - score(tau)) / slope
    return Uncertainty(noise, robust, interpolation)
