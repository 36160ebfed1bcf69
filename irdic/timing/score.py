"""The offset's score with fixed weights: its root, slope and standard uncertainty.

Near the true offset ``tau*`` the samples are ``X(tau) = a 1^T + U P^T +
X' (tau - tau*) + e`` (the model: a level per frame and ``r`` patterns
``P`` with amplitudes ``U`` per frame, usually one; its derivative along the
motion; the smoothed pixel noise). :class:`Score` fixes weights ``Y``
(frames x nodes) at a trial offset: the model's derivative
``sum_i u_ik grad(p_i) . r_kj`` (each fitted pattern's reference gradient
along the node's reference velocity, scaled by the frame's amplitude) with
every direction the model absorbs projected out (row means, ``U Z^T`` and
``Z V^T`` for the fitted singular vectors ``U``, ``V``). Then
``S(tau) = sum(Y * X(tau))`` needs no refit: the model's part of ``X`` is
orthogonal to ``Y``. Its root is the
estimate; with fixed weights the score is a smooth, near-linear function of
the offset (the noise enters once, through the samples, not through the
weights of every trial), so a secant gives the slope and Newton steps the
root.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .samples import Sampler, leading

__all__ = ["Score", "secant", "solve", "Uncertainty", "uncertainty"]

#: the slope is the secant over this many IR frame periods either side
SECANT_FRAMES = 0.25
#: Newton steps at most, and the step (IR frame periods) that ends them
NEWTON_STEPS, NEWTON_TOL = 6, 0.02
#: frames on which the white-noise gain of the weights is measured at most
GAIN_FRAMES = 16
#: tiles (px of the reference image) of the robust variance: residuals within a tile, over all frames, are summed
TILE_PX = 16
#: the variance from the residuals summed per frame counts where it exceeds the white-noise variance by more than
#: this many standard deviations of its own estimate
FRAME_SIGNIFICANCE = 3.0


class Score:
    """``S(tau) = sum(Y * X(tau))`` with weights ``Y`` fixed at ``tau_w`` on frames ``idx``.

    Parameters
    ----------
    sampler : Sampler
    idx : numpy.ndarray of int
        The frames (contiguous).
    tau_w : float
        Offset (s) at which the model and the weights are fitted.
    bandwidth : float
        Gaussian width (px of the reference image) of the pattern's gradient fit.
    rank : int
        Pattern components of the model.

    Attributes
    ----------
    last : (float, numpy.ndarray)
        The last offset evaluated and its samples (n, M).
    rate : numpy.ndarray
        After :func:`solve`: each sample's share of the slope, ``Y dX/dtau`` (n, M).
    dX : numpy.ndarray
        After :func:`solve`: the samples' rate of change ``dX/dtau`` (n, M, per s) it was given.
    """

    def __init__(self, sampler: Sampler, idx: np.ndarray, tau_w: float, bandwidth: float, rank: int = 1):
        self.sampler, self.idx, self.tau_w, self.rank = sampler, idx, float(tau_w), rank
        X = sampler(tau_w, idx)
        Xc = X - X.mean(axis=1, keepdims=True)
        _, U, V = leading(Xc, rank)
        r = sampler.nodes.reference_velocity(sampler.t_ir[idx] + tau_w)
        Y = np.zeros_like(Xc)
        for i in range(rank):  # the model sum_i u_i p_i^T, each pattern moved along the motion
            g = sampler.nodes.gradient(Xc.T @ U[:, i], bandwidth)
            Y += U[:, i, None] * (g[None, :, 0] * r[..., 0] + g[None, :, 1] * r[..., 1])
        Y -= Y.mean(axis=1, keepdims=True)
        Y -= U @ (U.T @ Y)
        Y -= (Y @ V) @ V.T
        self.Y, self.V = Y, V
        self.last, self.rate, self.dX = (self.tau_w, X), None, None

    def samples(self, tau: float) -> np.ndarray:
        if self.last[0] != tau:
            self.last = (float(tau), self.sampler(tau, self.idx))
        return self.last[1]

    def __call__(self, tau: float, nodes=None) -> float:
        X = self.samples(tau) if nodes is None else self.sampler(tau, self.idx, nodes=nodes)
        return _dot(self.Y, X)

    def residual(self) -> np.ndarray:
        """The samples of the last offset evaluated less the model fitted to them (n, M), K."""
        X = self.last[1]
        Xc = X - X.mean(axis=1, keepdims=True)
        s2, U, V = leading(Xc, self.rank, self.V)
        return Xc - (U * np.sqrt(s2)) @ V.T


def secant(score: Score, tau0: float, period: float) -> tuple[float, np.ndarray]:
    """The root (s) of the line through ``score`` at ``tau0`` +- :data:`SECANT_FRAMES` frame periods, and the
    samples' rate of change (n, M, per s) between the two."""
    d = SECANT_FRAMES * period
    lo = score.samples(tau0 - d)
    rate = (score.samples(tau0 + d) - lo) / (2.0 * d)
    slope = _dot(score.Y, rate)
    return (tau0 - (_dot(score.Y, lo) + slope * d) / slope if slope > 0 else np.nan), rate


def solve(score: Score, start: float, rate: np.ndarray, period: float) -> tuple[float, float]:
    """The root of ``score`` from ``start`` (s) and the score's slope (per s) from the samples' ``rate``:
    Newton steps with that slope until a step is below :data:`NEWTON_TOL` frame periods (the samples of the
    offset before it are :attr:`Score.last`)."""
    score.dX, score.rate = rate, score.Y * rate
    slope = float(np.sum(score.rate))
    if not slope > 0:
        return np.nan, slope
    tau = start
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
        From the residuals themselves, summed per tile of the material over all frames (any correlation within
        a tile, in space or in time, counted).
    interpolation : float
        The change of the estimate with the spline of the motion two degrees lower.
    model : float
        Where the pattern changes its shape on the material: the change of the estimate between models of two
        and three pattern components (0 for a pattern that only scales).
    frames : float
        As ``robust``, the residuals summed per frame over all nodes instead (a misfit the whole frame shares:
        a pattern whose change of shape the model does not follow, which the motion partly mimics); 0 where
        not significantly above ``noise`` (:data:`FRAME_SIGNIFICANCE`).
    std : float
        The standard uncertainty: the largest of ``noise``, ``robust`` and ``frames``, the others in
        quadrature.
    """

    noise: float
    robust: float
    interpolation: float
    model: float = 0.0
    frames: float = 0.0

    @property
    def std(self) -> float:
        return float(np.sqrt(max(self.noise, self.robust, self.frames) ** 2 + self.interpolation**2
                             + self.model**2))


def uncertainty(score: Score, tau: float, slope: float, sigma: float) -> Uncertainty:
    """The standard uncertainty of the root ``tau`` (s) of ``score`` (solved) with slope ``slope``, pixel noise
    ``sigma`` (K).

    Notes
    -----
    The root's error is ``-S(tau*) / S'`` and ``S(tau*) = sum(Y * e)`` with
    ``e = G B n`` the pixel noise ``n`` smoothed (``G``) and sampled
    bilinearly (``B``), so for white noise ``var = sigma^2 ||G B^T Y||^2 / S'^2``
    (the gain ``||G B^T Y_k||^2 / ||Y_k||^2`` measured on :data:`GAIN_FRAMES`
    frames).
    The robust variance sums ``Y * R`` (``R`` the model's residual at the
    root, as last evaluated) per tile of :data:`TILE_PX` px of the reference
    image over all frames and adds the squares, each over ``1 - h`` with
    ``h`` the tile's share of the slope (the root absorbs that share of its
    residual); the frames part the same per frame over all nodes. The
    interpolation part is the root's
    shift, ``S_lower(tau) / S'`` (``S(tau) = 0``), when the nodes move by the
    spline two degrees lower (one for a quadratic or cubic).
    """
    sampler, idx, Y = score.sampler, score.idx, score.Y
    # the noise gain of the weights, sum ||G B^T Y_k||^2 / sum ||Y_k||^2, is the same in every frame up to the
    # nodes' places between the pixels: it is measured on at most GAIN_FRAMES frames spread over the record
    power = np.sum(Y * Y, axis=1)
    some = np.flatnonzero(power > 0)
    some = some[np.unique(np.linspace(0, some.size - 1, min(GAIN_FRAMES, some.size)).round().astype(int))]
    gain = float(np.sum(sampler.spread(tau, idx[some], Y[some]) ** 2)) / float(np.sum(power[some]))
    noise = sigma * float(np.sqrt(gain * np.sum(power))) / slope
    # tiles of the reference image: a node's every frame in one tile (the rank-one fit's share of a node's
    # residual over the frames is orthogonal to its weights)
    nodes = sampler.nodes
    ref = nodes.reference
    cell = np.floor((ref - ref.min(axis=0)) / TILE_PX).astype(np.int64)
    tile = cell[:, 1] * (cell[:, 0].max() + 1) + cell[:, 0]
    YR = Y * score.residual()
    # each node's sum over the frames first: a tile holds whole nodes
    robust = _robust(np.bincount(tile, YR.sum(axis=0)), np.bincount(tile, score.rate.sum(axis=0)), slope)
    # a variance from a few frames' sums scatters widely (one degree of freedom per frame): it counts where it
    # exceeds the white-noise one by more than three of its own standard deviations
    frames = _robust(YR.sum(axis=1), score.rate.sum(axis=1), slope)
    if frames**2 <= noise**2 * (1.0 + FRAME_SIGNIFICANCE * np.sqrt(2.0 / max(np.count_nonzero(power), 1))):
        frames = 0.0
    interpolation = 0.0
    if nodes.order >= 2:
        lower = nodes.with_order(nodes.order - 2 if nodes.order >= 4 else 1)
        interpolation = abs(score(tau, nodes=lower) - score(tau)) / slope
    return Uncertainty(noise, robust, interpolation, frames=frames)


def _dot(A: np.ndarray, B: np.ndarray) -> float:
    """``sum(A * B)`` of two arrays of one shape, without the product's temporary."""
    return float(np.vdot(A.ravel(), B.ravel()))


def _robust(sums: np.ndarray, rates: np.ndarray, slope: float) -> float:
    """The root's standard uncertainty (s) from the score's sums over groups of samples, each group's square over
    ``1 - h`` (``h`` its share of the slope, from its ``rates``: the root absorbs that share of its residual; at
    least 1/2)."""
    share = rates / slope
    return float(np.sqrt(np.sum(sums**2 / np.clip(1.0 - share, 0.5, None)))) / slope
