"""The offset between the IR and the DIC clock, estimated from the data.

A wrong offset moves every DIC point in the IR image by its image velocity
times the error, so the IR frames show a temperature pattern that no longer
moves with the material. This module finds the offset ``tau`` (seconds
added to the IR times, as a configured ``time_offset``) at which the IR
frames and the DIC motion agree best, and its standard uncertainty.

Model
-----
For a candidate ``tau`` every IR frame ``k`` (time ``t_k`` on the IR clock)
is sampled at the positions that material nodes have in the image at the DIC
time ``t_k + tau`` (:mod:`irdic.timing.nodes`: a regular grid of the
reference image carried by the DIC points' triangulation, interpolated
between the DIC stages by a spline in time). Row ``k`` of ``X(tau)``
(frames x nodes) is what frame ``k`` shows at the material nodes. A pattern
carried by the material has, at the right offset, the same shape in every
frame up to a level and an amplitude, ``X_k = a_k + b_k P + noise``; at a
wrong offset every frame is sampled displaced by its image velocity times the
error, and since the velocity changes during the test, the pattern seen in
the material drifts from frame to frame.

Search, then refinement
-----------------------
The misfit of the rank-one model ``J(tau) = ||X_c||^2 - s_1^2`` (``X_c`` the
rows less their means, ``s_1`` the largest singular value) on a coarse set
of nodes and strongly smoothed frames is evaluated on a grid of candidates
over a quarter of the record each way; its few best local minima are refined
and compared on the frames both place inside the DIC record (frames with
little motion fit any offset, so candidates judged on different frames are
not comparable). From the winner, the estimate is the root of a score with
fixed weights on every node about one pixel apart and lightly smoothed
frames (:mod:`irdic.timing.score`): the rank-one model's derivative with
respect to the offset, with everything the model absorbs projected out. That
estimator is linear in the pixel noise, so its variance is exact for white
noise, and it comes close to the precision the frames allow (the
Cramér-Rao bound of the rank-one model with a free pattern), short of it
mostly by the few pixels along the cloud's outline that the smoothing must
leave out.

A pattern that changes its shape on the material (a second pattern with a
history of its own, heat flowing in from a grip) is not rank-one: where the
one-component model's residuals hold structure, models of two and three
components (``X_k = a_k + sum_i b_ik P_i``) are fitted as well, and the
distance between their estimates is part of the uncertainty
(:func:`_model_order`). The components beyond the first follow the
pattern's change, which is weak: where they absorb nearly all of the
motion's signal, the estimate rests on what the noise leaves of their
fitted shape, so the refinement is repeated on the frames with their noise
drawn again and must stay within its stated uncertainty
(:func:`_check_stable`).

When it cannot work: a static specimen (no motion: every offset fits the
same), a uniform temperature (no pattern to carry), motion too small for
the noise (the uncertainty exceeds :data:`MAX_STD_FRAMES` IR frame periods),
or a pattern whose change of shape the motion mimics:
:class:`~irdic.errors.DataError` naming the configuration key, with the
motion found and the uncertainty it allows (:mod:`irdic.timing.checks`).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from ..errors import DataError
from ..noise import spatial_noise
from ..numerics.threads import both
from .checks import (MAX_STD_FRAMES, MIN_MOTION_JITTERS, MIN_MOTION_PX, check_fit, check_identified, check_inside,
                     check_motion, check_single, check_sizes)
from .nodes import Mesh, Nodes, thinned
from .samples import Criterion, Sampler, leading, prepared
from .score import Score, Uncertainty, secant, solve, uncertainty

__all__ = ["ClockOffset", "estimate_offset", "crop_box", "MAX_STD_FRAMES", "MAX_FRAMES", "WIDEN_SAMPLES", "MAX_SAMPLES",
           "SMOOTHING_PX", "NODE_SPACING_PX", "GRADIENT_PX", "SPLINE_ORDER", "MIN_MOTION_PX", "MIN_MOTION_JITTERS",
           "STABLE_DRAWS", "STABLE_STDS", "STABLE_FRAMES"]

log = logging.getLogger(__name__)

#: frames used (evenly spread over the record)
MAX_FRAMES = 600
#: frames (evenly spread over the record) the pixel noise is estimated on, whatever the offset
#: (irdic.noise.spatial_noise)
NOISE_FRAMES = 20
#: samples (nodes x frames) of the refinement: beyond the first the nodes are spread wider (up to twice), beyond
#: the second frames are left out
WIDEN_SAMPLES, MAX_SAMPLES = 1_000_000, 4_000_000
#: the refinement: Gaussian smoothing of the frames (px), node spacing (px), the pattern gradient's width (px)
SMOOTHING_PX, NODE_SPACING_PX, GRADIENT_PX = 0.5, 1.0, 4.0
#: degree of the spline through the DIC stages that moves the nodes between them
SPLINE_ORDER = 5
#: the search: smoothing (px), nodes and samples (nodes x frames) at most
SEARCH_SMOOTHING_PX, SEARCH_NODES, SEARCH_SAMPLES = 1.5, 1500, 100_000
#: the score from one frame period either side of the estimate must point back to within this many frame
#: periods of it, or this many of its standard uncertainties
BASIN_FRAMES, BASIN_STDS = 0.5, 4.0
#: pattern components at most: where the residuals of the one-component model hold structure (their robust
#: variance over this factor times the white-noise one, which it stays below for white noise, and over this many
#: frame periods), models of two and three are fitted (:func:`_model_order`)
MAX_RANK, STRUCTURE_RATIO, STRUCTURE_FRAMES = 3, 1.25, 0.03
#: frames within this many frame periods outside the DIC record at the estimate still count (positions
#: extrapolated by the spline)
SLACK_FRAMES = 0.25
#: frames (spread over the record) on which the fit and the basin are checked at most
CHECK_FRAMES = 16
#: the refinement is repeated from the estimate on the frames with this many fresh realisations of their pixel
#: noise added; the RMS of its moves may reach this many of the white-noise part of its standard uncertainty plus
#: this many frame periods (a refinement restarted without noise need not land on its own root exactly)
STABLE_DRAWS, STABLE_STDS, STABLE_FRAMES = 3, 3.0, 0.05
#: the refinement's weights are fitted again at the secant's root where it lies this many frame periods away
REFIT_FRAMES = 0.1
#: coarse candidates at most
_MAX_CANDIDATES = 31
#: basins (local minima of the coarse criterion) refined and compared at most
_STARTS = 3


@dataclass(frozen=True)
class ClockOffset:
    """The estimated offset of the IR clock.

    Attributes
    ----------
    offset : float
        Seconds to add to the IR times (as ``time_offset``).
    std : float
        Its standard uncertainty (s).
    frame_period : float
        Median IR frame spacing (s).
    motion_px : float
        Largest displacement of a DIC point in the IR image over the record (px).
    noise : float
        Pixel noise of the frames (K).
    candidates, criterion : numpy.ndarray
        The coarse grid (s) and ``J`` per sample on it (K^2).
    frames, points : int
        IR frames and material nodes the estimate used.
    parts : Uncertainty
        The parts of ``std``.
    rank : int
        Pattern components of the model (1: a pattern that only scales).
    """

    offset: float
    std: float
    frame_period: float
    motion_px: float
    noise: float
    candidates: np.ndarray
    criterion: np.ndarray
    frames: int
    points: int
    parts: Uncertainty
    rank: int = 1


def crop_box(positions: np.ndarray, shape: tuple[int, int], margin: int = 12) -> tuple[slice, slice]:
    """(rows, columns) slices of a frame of ``shape`` (H, W) around every finite position (..., 2) (u, v) px."""
    p = positions.reshape(-1, 2)
    # fmin / fmax pass over NaN: no copy of the finite rows (millions at paper scale); a row is finite or NaN
    lo, hi = np.fmin.reduce(p, axis=0), np.fmax.reduce(p, axis=0)
    if not np.isfinite(lo).all():
        raise DataError("no DIC point projects into the IR frames")
    u0, v0 = np.floor(lo).astype(int) - margin
    u1, v1 = np.ceil(hi).astype(int) + margin + 1
    H, W = shape
    return slice(max(v0, 0), min(v1, H)), slice(max(u0, 0), min(u1, W))


def estimate_offset(frames: np.ndarray, t_ir: np.ndarray, t_dic: np.ndarray, positions: np.ndarray, *,
                    centre: float = 0.0, parameter: str = "ir.time_offset",
                    max_frames: int = MAX_FRAMES) -> ClockOffset:
    """Offset of the IR clock (s added to the IR times) that aligns the IR frames with the DIC motion.

    Parameters
    ----------
    frames : numpy.ndarray, shape (F, h, w)
        IR frames (K or deg C), cropped to the region the points cover
        (:func:`crop_box`); finite.
    t_ir : numpy.ndarray, shape (F,)
        IR frame times on the IR clock (s), increasing.
    t_dic : numpy.ndarray, shape (n_t,)
        DIC times (s), increasing.
    positions : numpy.ndarray, shape (n_t, N, 2)
        The DIC points' (u, v) positions in the cropped frame's pixel coordinates (px, pixel (0, 0) =
        ``frames[:, 0, 0]``) at every DIC time, NaN where unknown (gaps are interpolated in time; points known at
        fewer than half of the times are left out; dense ones thinned, :func:`~irdic.timing.nodes.thinned`).
    centre : float
        Middle of the searched offsets (s); the search covers a quarter of the
        shorter record each way.
    parameter : str
        The configuration key named in errors.
    max_frames : int
        Frames used at most (evenly spread).

    Returns
    -------
    ClockOffset

    Raises
    ------
    DataError
        Not identifiable: too few points or frames, a static specimen or too little motion for the noise
        (uncertainty above :data:`MAX_STD_FRAMES` frame periods), another minimum that fits as well, the best
        candidate at the end of the range, frames that do not follow the motion at the best offset, or an
        estimate that does not survive a redraw of the noise (:func:`_check_stable`).

    Notes
    -----
    The standard uncertainty (:func:`irdic.timing.score.uncertainty`) is the
    larger of the white-noise variance of the linear score (exact for pixel
    noise of the level measured on the frames) and a robust one from the
    residuals summed per image tile over all frames (spatially or temporally
    correlated noise, a pattern the rank-one model does not describe), with
    the shift of the estimate under a spline of lower degree through the DIC
    stages (how well the motion between them is known) in quadrature.
    """
    t_ir, t_dic = np.asarray(t_ir, float), np.asarray(t_dic, float)
    pos = prepared(np.asarray(positions, float), t_dic)
    period = float(np.median(np.diff(t_ir))) if t_ir.size > 1 else np.nan
    check_sizes(pos, t_dic, t_ir, parameter)  # on the points given: the user's count, not the kept one
    motion, jitter = _motion(pos := thinned(pos))
    if t_ir.size > max_frames:
        keep = np.linspace(0, t_ir.size - 1, max_frames).round().astype(int)
        frames, t_ir = frames[keep], t_ir[keep]
    check_motion(motion, jitter, parameter)
    frames = np.asarray(frames, dtype=np.float32)
    mesh = Mesh(pos, t_dic)
    coarse = _nodes(mesh, SEARCH_SMOOTHING_PX, max(2.0, np.sqrt(mesh.area / SEARCH_NODES)))
    some = _spread_out(t_ir.size, SEARCH_SAMPLES // coarse.M)
    search = Sampler(frames[some], t_ir[some], coarse, SEARCH_SMOOTHING_PX)
    sigma = spatial_noise(frames[_spread_out(frames.shape[0], NOISE_FRAMES)])
    fits, fine, spacing = _fits(search, frames, t_ir, mesh, centre, period, motion, parameter, sigma)
    rank, shift = _model_order(fits, period)
    tau, score, parts, grid, crit, rivals = fits[rank]
    parts = dataclasses.replace(parts, model=shift)
    check_identified(parts, period, motion, parameter)
    check_single(tau, rivals, parts.std, period, motion, parameter)  # rivals: two or three components only
    check_inside(tau, grid, np.nan_to_num(crit, nan=np.nanmax(crit)), motion, parameter)
    check_fit(_misfit(fine, score.idx[_spread_out(score.idx.size, CHECK_FRAMES)], tau, rank), sigma, tau, period,
               parameter)
    _check_basin(score, tau, parts.std, period, parameter)
    # a second or third component is fitted to the pattern's change, which is weak next to the pattern: its
    # fitted shape, and the weights built on it, carry the noise (one component is fitted at full strength)
    redrawn = _check_stable(score, tau, sigma, parts, period, motion, parameter) if rank > 1 else np.nan
    out = ClockOffset(tau, parts.std, period, motion, sigma, grid, crit, int(score.idx.size), int(fine.M), parts, rank)
    _log(out, spacing, redrawn)
    return out


def _log(out: ClockOffset, spacing: float, redrawn: float):
    """The estimate and the parts of its uncertainty, in IR frame periods, to the log."""
    parts, period = out.parts, out.frame_period
    log.info("IR clock offset from the data: %.5g s +- %.2g s (%.3f +- %.3f IR frames: noise %.3f, robust per tile "
             "%.3f and per frame %.3f, motion between DIC stages %.3f, pattern model %.3f; %d frames x %d nodes %.2g "
             "px apart, %d pattern component%s, motion up to %.3g px, pixel noise %.3g K; under redrawn pixel noise "
             "the refinement moved by %.3f frames RMS, nan: one component, not redrawn)", out.offset, out.std,
             out.offset / period, out.std / period, parts.noise / period, parts.robust / period,
             parts.frames / period, parts.interpolation / period, parts.model / period, out.frames, out.points,
             spacing, out.rank, "s" if out.rank > 1 else "", out.motion_px, out.noise, redrawn / period)


def _fits(search, frames, t_ir, mesh, centre, period, motion, parameter, sigma):
    """The estimates of the models with one component and, where it leaves structure, two and three:
    {rank: (tau, score, Uncertainty, grid, criterion)}, the refinement's sampler and its node spacing (px).

    The models of two and three components are fitted at once where a thread of the stage is free
    (:func:`~irdic.numerics.threads.both`; the clock of the couple stage runs beside its masks, and takes a
    worker they leave), each on its own copy of the samplers."""
    def fit(rank, search, fine):
        """(the fit or the DataError that ended it, the refinement's sampler, its node spacing)"""
        spacing = np.nan
        try:
            roots, grid, crit = _search(search, centre, period, motion, parameter, rank)
            if fine is None:
                fine, spacing = _refinement_sampler(frames, t_ir, mesh, max(search.inside(r, r).size for r in roots)
                                                    * t_ir.size // search.t_ir.size)
            # the minima compared on the refinement's nodes: more samples, less smoothing, more power
            tau0, rivals = _tournament(fine, roots, rank)
            tau, score, slope = _refined(fine, tau0, period, motion, parameter, rank)
        except DataError as exc:
            return exc, fine, spacing
        return (tau, score, uncertainty(score, tau, slope, sigma), grid, crit, rivals), fine, spacing

    one, fine, spacing = fit(1, search, None)
    if not isinstance(one, DataError) and not _structured(one[2], period):
        return {1: one}, fine, spacing
    if fine is None:  # the first fit to pass the search builds the refinement's sampler
        two, fine, spacing = fit(2, search, None)
        three = fit(3, search, fine)[0] if not isinstance(two, DataError) else None
    else:
        (two, _, _), (three, _, _) = both(lambda: fit(2, search, fine),
                                          lambda: fit(3, search.copy(), fine.copy()))
    fits, failed = {}, None
    for rank, got in ((1, one), (2, two), (3, three)):
        if isinstance(got, DataError):
            failed = failed or got
            if rank > 1:  # no third component without a second
                break
        elif got is not None:
            fits[rank] = got
    if not fits:
        raise failed
    return fits, fine, spacing


def _structured(parts: Uncertainty, period: float) -> bool:
    """Whether the residuals hold structure the model misses (module constants :data:`STRUCTURE_RATIO`,
    :data:`STRUCTURE_FRAMES`)."""
    return parts.robust > max(STRUCTURE_RATIO * parts.noise, STRUCTURE_FRAMES * period)


def _model_order(fits: dict, period: float) -> tuple[int, float]:
    """The model kept and the shift (s) of its estimate to that of the neighbouring order: one component
    where it leaves no structure (no shift); else two where they leave none, three otherwise, each with the
    distance between the two- and three-component estimates (infinite where either failed)."""
    if set(fits) == {1} and not _structured(fits[1][2], period):
        return 1, 0.0
    if 2 not in fits or 3 not in fits:
        return max(fits), np.inf
    return (2 if not _structured(fits[2][2], period) else 3), abs(fits[3][0] - fits[2][0])


def _nodes(mesh: Mesh, smoothing: float, spacing: float) -> Nodes:
    """Nodes ``spacing`` px apart, inside the cloud by the reach of a Gaussian smoothing of ``smoothing`` px."""
    return Nodes(mesh, spacing, np.ceil(3 * smoothing) + 1, SPLINE_ORDER)


def _refinement_sampler(frames, t_ir, mesh, n_frames):
    """The refinement's sampler: nodes :data:`NODE_SPACING_PX` apart, wider where nodes x frames would exceed
    :data:`WIDEN_SAMPLES` (at most twice), then frames left out evenly beyond :data:`MAX_SAMPLES`."""
    spacing = NODE_SPACING_PX * float(np.clip(np.sqrt(mesh.area * max(n_frames, 1) / WIDEN_SAMPLES) / NODE_SPACING_PX,
                                              1.0, 2.0))
    smoothing = SMOOTHING_PX * spacing / NODE_SPACING_PX
    nodes = _nodes(mesh, smoothing, spacing)
    if nodes.M * n_frames > MAX_SAMPLES:
        keep = _spread_out(t_ir.size, MAX_SAMPLES // nodes.M)
        frames, t_ir = frames[keep], t_ir[keep]
    return Sampler(frames, t_ir, nodes, smoothing), spacing


def _spread_out(n: int, count: int) -> np.ndarray:
    """At most ``count`` (at least 8) of ``n`` indices, evenly spread, first and last included."""
    return np.unique(np.linspace(0, n - 1, min(n, max(8, count))).round().astype(int))


def _refined(sampler: Sampler, tau0: float, period: float, motion: float, parameter: str, rank: int,
             known: tuple[np.ndarray, np.ndarray] | None = None):
    """The root of the fixed-weight score from ``tau0``: the weights fitted at ``tau0``, refitted at the secant's
    root where it lies more than :data:`REFIT_FRAMES` frame periods away (weights fitted off the root lose
    precision on a weak pattern); (tau, score, slope). ``known``: frames and the samples' rate of change on them
    (the secant's, from a refinement on the same frames), used where they are the frames ``tau0`` places inside
    the record."""
    tau, score, slope = np.nan, None, np.nan
    idx = sampler.inside(tau0, tau0, SLACK_FRAMES * period)
    if idx.size >= 4:
        score = Score(sampler, idx, tau0, GRADIENT_PX, rank)
        rate = known[1] if known is not None and np.array_equal(known[0], idx) else None
        if rate is None:
            start, rate = secant(score, tau0, period)
        else:
            slope = float(np.sum(score.Y * rate))
            start = tau0 - score(tau0) / slope if slope > 0 else np.nan
        if np.isfinite(start) and abs(start - tau0) > REFIT_FRAMES * period:
            again = sampler.inside(start, start, SLACK_FRAMES * period)
            if again.size >= 4:
                score = Score(sampler, again, start, GRADIENT_PX, rank)
                if not np.array_equal(again, idx):
                    rate = secant(score, start, period)[1]
        if np.isfinite(start):
            tau, slope = solve(score, start, rate, period)
    if not np.isfinite(tau):
        raise DataError(f"{parameter}: auto cannot estimate the clock offset from the data: at the best offset "
                        f"found ({tau0:.4g} s) the frames do not change with it (the DIC points move at most "
                        f"{motion:.3g} px in the IR image). Set {parameter} to a number (s; docs/time-sync.md)")
    return tau, score, slope


def _search(sampler: Sampler, centre: float, period: float, motion: float, parameter: str, rank: int):
    """The coarse candidates' best local minima, each refined to a twentieth of a frame period within the
    searched range: (the minima (s), the candidates (s), their criterion)."""
    grid, crit, starts = _coarse(sampler, centre, period, parameter, rank)
    step, bounds = grid[1] - grid[0], (grid[0], grid[-1])
    roots = [_minimum(sampler, grid[i], step, period, bounds, rank) for i in starts]
    roots = [r for r in roots if np.isfinite(r)]
    if not roots:
        raise DataError(f"{parameter}: auto: fewer than 4 IR frames lie inside the DIC record around the best "
                        f"offset ({grid[starts[0]]:.4g} s); set {parameter} to a number (s)")
    return roots, grid, crit


def _motion(pos: np.ndarray) -> tuple[float, float]:
    """Largest displacement of a point from its first position (px), over the record, and the positions'
    scatter from stage to stage (px): the RMS second difference in time over sqrt(6), the noise of white
    position errors (smooth motion adds to it, so it errs high)."""
    disp = np.linalg.norm(pos - pos[:1], axis=-1)
    if pos.shape[0] < 3:
        return float(disp.max()), 0.0
    d2 = pos[2:] - 2 * pos[1:-1] + pos[:-2]
    return float(disp.max()), float(np.sqrt(np.mean(d2**2) / 6.0))


def _misfit(sampler: Sampler, idx: np.ndarray, tau: float, rank: int) -> float:
    """Pixel noise (K) the model of ``rank`` components leaves at ``tau``: the raw samples' misfit, each over
    its bilinear noise gain, per degree of freedom."""
    X = sampler(tau, idx, raw=True)
    Xc = X - X.mean(axis=1, keepdims=True)
    s2, U, V = leading(Xc, rank)
    R = Xc - (U * np.sqrt(s2)) @ V.T
    q = sampler.nodes.at(sampler.t_ir[idx] + tau)
    fu, fv = q[..., 0] % 1.0, q[..., 1] % 1.0
    gain = ((1 - fu) ** 2 + fu**2) * ((1 - fv) ** 2 + fv**2)  # a sample between pixels averages their noise
    n, m = X.shape
    dof = n * m - n - rank * (n + m - rank)
    return float(np.sqrt(np.sum(R * R / gain) / dof)) if dof > 0 else np.nan


def _check_basin(score: Score, tau: float, std: float, period: float, parameter: str):
    """The score from one frame period either side must point back to ``tau``: in the basin of the true offset
    the score is linear in the offset over several frames, at a root the noise made (the true offset beyond
    the searched range, or no pattern to speak of) it is not. Judged on the frames inside the DIC record
    there (each row of the weights is a score of its own: orthogonal to its frame's level and pattern)."""
    sampler = score.sampler
    rows = np.flatnonzero(np.isin(score.idx, sampler.inside(tau - period, tau + period)))
    rows = rows[np.any(score.Y[rows] != 0, axis=1)]
    if rows.size < 4:
        return
    rows = rows[_spread_out(rows.size, CHECK_FRAMES)]
    Y, idx = score.Y[rows], score.idx[rows]
    slope = float(np.sum(score.rate[rows]))
    last, X = score.last  # within a Newton step of tau
    here = float(np.sum(Y * X[rows])) + slope * (tau - last)
    for side in (-1.0, 1.0):
        start = tau + side * period
        back = start - (float(np.sum(Y * sampler(start, idx))) - here) / slope if slope > 0 else np.inf
        if not abs(back - tau) <= max(BASIN_FRAMES * period, BASIN_STDS * std):
            raise DataError(
                f"{parameter}: auto cannot estimate the clock offset from the data: they do not single out one "
                f"offset (from {start:.4g} s the score points to {back:.4g} s, not back to {tau:.4g} s): the offset "
                f"lies beyond the searched quarter of the record, the pattern is too weak for the record's noise, "
                f"or the motion changes too quickly between the DIC stages to be interpolated. Set {parameter} to a "
                f"number (s; docs/time-sync.md)")


def _check_stable(score: Score, tau: float, sigma: float, parts: Uncertainty, period: float, motion: float,
                  parameter: str) -> float:
    """The refinement repeated from the root ``tau`` of ``score`` on the frames with :data:`STABLE_DRAWS` fresh
    realisations of their pixel noise (``sigma`` K, white; a fixed seed) added must move it by no more than the
    white noise's part of the uncertainty allows (module constants :data:`STABLE_STDS`,
    :data:`STABLE_FRAMES`); the RMS of its moves (s).

    The stated uncertainty treats the estimate as linear in the pixel noise, with the pattern and the weights
    fitted once. Where the model absorbs nearly all of the motion's signal (a pattern whose change of shape the
    motion mimics: an edge profile that widens on a stretching specimen) the little that is left rests on the
    fitted pattern, and noise moves the estimate by frames, not by its stated fraction of one. Each move here is
    one draw of the estimate's scatter under the added noise, which for a linear estimator has the standard
    deviation of the white-noise part.
    """
    moves = []
    for draw in range(STABLE_DRAWS):
        noisy = score.sampler.with_noise(sigma, np.random.default_rng([20261206, draw]))
        try:
            moves.append(_refined(noisy, tau, period, motion, parameter, score.rank, (score.idx, score.dX))[0] - tau)
        except DataError:
            moves.append(np.inf)
    rms = float(np.sqrt(np.mean(np.square(moves))))
    if rms <= STABLE_STDS * parts.noise + STABLE_FRAMES * period:
        return rms
    raise DataError(
        f"{parameter}: auto cannot estimate the clock offset from the data: the estimate ({tau:.4g} s, "
        f"{tau / period:.2f} IR frames, +- {parts.noise / period:.2g} frames from the pixel noise) moves by "
        f"{rms / period:.2g} IR frames RMS when the frames' pixel noise ({sigma:.3g} K) is drawn again: the "
        f"temperature pattern changes its shape on the material in step with the motion (an edge profile that "
        f"widens while the specimen stretches), so the frames hardly tell the offset (the DIC points move at most "
        f"{motion:.3g} px in the IR image). Set {parameter} to a number (s; docs/time-sync.md)")


def _coarse(sampler, centre, period, parameter, rank):
    """The candidates (s) over a quarter of the shorter record each way, ``J`` per degree of freedom of each on
    the frames it places inside the DIC record, and the starts: the candidates at its local minima, best
    first (at most :data:`_STARTS`).

    Each candidate is judged on its own frames, so that frames with motion count wherever they lie in the
    record; frames with little motion fit any offset, so the order of the starts is only a first guess
    (:func:`_tournament` decides on common frames).
    """
    t_ir, t0, t1 = sampler.t_ir, sampler.t0, sampler.t1
    span = min(t1 - t0, t_ir[-1] - t_ir[0])
    half = max(0.25 * span, 2.0 * period)
    n = int(np.clip(np.ceil(2 * half / period) + 1, 9, _MAX_CANDIDATES))
    grid = centre + np.linspace(-half, half, n)
    crit = _judged(sampler, grid, rank)
    if not np.isfinite(crit).any():
        raise DataError(f"{parameter}: auto: the IR record ({t_ir[0]:.4g}..{t_ir[-1]:.4g} s) and the DIC record "
                        f"({t0:.4g}..{t1:.4g} s) overlap in fewer than 4 IR frames around an offset of "
                        f"{centre:.4g} s; set {parameter} to a number (s)")
    c = np.where(np.isfinite(crit), crit, np.inf)
    left, right = np.r_[np.inf, c[:-1]], np.r_[c[1:], np.inf]
    minima = np.flatnonzero((c <= left) & (c <= right) & np.isfinite(c))
    return grid, crit, minima[np.argsort(c[minima])][:_STARTS]


def _judged(sampler, grid, rank):
    """``J`` per degree of freedom of the rank-``rank`` fit at each candidate, on its own frames (NaN: fewer
    than half the frames the best-placed candidate has)."""
    frames = [sampler.inside(g, g) for g in grid]
    full = max(idx.size for idx in frames)
    out = np.full(grid.size, np.nan)
    for i, (g, idx) in enumerate(zip(grid, frames)):
        n, m = idx.size, sampler.M
        dof = n * m - n - rank * (n + m - rank)
        if n >= max(4, (full + 1) // 2, 2 * rank + 2) and dof > 0:
            out[i] = Criterion(sampler, idx, rank)(g) * n * m / dof
    return out


def _tournament(sampler, roots, rank):
    """The minimum that fits best, each pair compared on the frames both place inside the DIC record (the
    first where fewer than 4 are common), and (``rank`` > 1) the rivals: ``(root, excess, scale)`` of every
    other minimum compared with the winner, ``excess`` its criterion's relative excess over the winner's on
    their common frames and ``scale`` the relative scatter of a mean of that many squared residuals,
    ``sqrt(2 / (n M))`` (:func:`~irdic.timing.checks.check_single`)."""
    crits, values = {}, {}  # one criterion per pair (its warm start), each root evaluated once on it

    def J(pair, r):
        lo, hi = min(pair), max(pair)
        if (lo, hi) not in crits:
            crits[lo, hi] = Criterion(sampler, sampler.inside(lo, hi), rank)
        if (lo, hi, r) not in values:
            values[lo, hi, r] = crits[lo, hi](r)
        return values[lo, hi, r]

    def common(a, b):
        return sampler.inside(min(a, b), max(a, b)).size

    best = roots[0]
    for r in roots[1:]:
        if common(best, r) >= 4 and J((best, r), r) < J((best, r), best):
            best = r
    # with one component, fitted at full strength, the motion's whole signal tells the minima apart
    rivals = [(r, J((best, r), r) / J((best, r), best) - 1.0, float(np.sqrt(2.0 / (common(best, r) * sampler.M))))
              for r in (roots if rank > 1 else ()) if r != best and common(best, r) >= 4]
    return best, rivals


def _minimum(sampler: Sampler, start: float, step: float, period: float, bounds: tuple[float, float],
             rank: int) -> float:
    """The minimum of ``J`` within ``step`` of ``start`` (on the frames every offset there places inside the
    DIC record), to a twentieth of a frame period; while it lies at an end of the bracket, the bracket moves on
    by one step (at most four times, never beyond ``bounds``). NaN: fewer than 4 frames."""
    lo, hi = max(start - step, bounds[0]), min(start + step, bounds[1])
    tau = np.nan
    for _ in range(4):
        idx = sampler.inside(lo, hi)
        if idx.size < 4:
            break
        tau = float(minimize_scalar(Criterion(sampler, idx, rank), bounds=(lo, hi), method="bounded",
                                    options={"xatol": 0.05 * period}).x)
        up, down = tau >= hi - 0.02 * step and hi < bounds[1], tau <= lo + 0.02 * step and lo > bounds[0]
        if not (up or down):
            break
        lo, hi = (lo + step, min(hi + step, bounds[1])) if up else (max(lo - step, bounds[0]), hi - step)
    return tau
