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
(:func:`_model_order`).

When it cannot work: a static specimen (no motion: every offset fits the
same), a uniform temperature (no pattern to carry), or motion too small for
the noise (the uncertainty exceeds :data:`MAX_STD_FRAMES` IR frame periods):
:class:`~irdic.errors.DataError` naming the configuration key, with the
motion found and the uncertainty it allows.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from ..errors import DataError
from .nodes import Mesh, Nodes
from .samples import Criterion, Sampler, leading, prepared
from .score import Score, Uncertainty, secant, solve, uncertainty

__all__ = ["ClockOffset", "estimate_offset", "crop_box", "MAX_STD_FRAMES", "MAX_FRAMES", "WIDEN_SAMPLES", "MAX_SAMPLES",
           "SMOOTHING_PX", "NODE_SPACING_PX", "GRADIENT_PX", "SPLINE_ORDER", "MIN_MOTION_PX", "MIN_MOTION_JITTERS"]

log = logging.getLogger(__name__)

#: an estimate whose standard uncertainty exceeds this many IR frame periods is refused: two standard
#: uncertainties stay within 0.2 frame periods
MAX_STD_FRAMES = 0.12
#: frames used (evenly spread over the record)
MAX_FRAMES = 600
#: samples (nodes x frames) of the refinement: beyond the first the nodes are spread wider (up to twice), beyond
#: the second frames are left out
WIDEN_SAMPLES, MAX_SAMPLES = 1_000_000, 4_000_000
#: the refinement: Gaussian smoothing of the frames (px), node spacing (px), the pattern gradient's width (px)
SMOOTHING_PX, NODE_SPACING_PX, GRADIENT_PX = 0.5, 1.0, 4.0
#: degree of the spline through the DIC stages that moves the nodes between them
SPLINE_ORDER = 5
#: the search: smoothing (px), nodes and samples (nodes x frames) at most
SEARCH_SMOOTHING_PX, SEARCH_NODES, SEARCH_SAMPLES = 1.5, 1500, 100_000
#: an offset is estimated only where the points move at least this much in the image (px) ...
MIN_MOTION_PX = 0.5
#: ... and at least this many times their scatter from stage to stage (DIC noise)
MIN_MOTION_JITTERS = 20.0
#: the rank-one misfit at the estimate may exceed the frames' pixel noise by this factor at most ...
FIT_RATIO = 1.5
#: ... with this floor (K) under the noise (noise-free exports)
FIT_FLOOR_K = 0.005
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
    p = p[np.isfinite(p).all(axis=1)]
    if not p.size:
        raise DataError("no DIC point projects into the IR frames")
    u0, v0 = np.floor(p.min(axis=0)).astype(int) - margin
    u1, v1 = np.ceil(p.max(axis=0)).astype(int) + margin + 1
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
        The DIC points' (u, v) positions in the cropped frame's pixel
        coordinates (px, pixel (0, 0) = ``frames[:, 0, 0]``) at every DIC
        time, NaN where unknown (gaps are interpolated in time; points known
        at fewer than half of the times are left out).
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
        Not identifiable: too few points or frames, a static specimen or too
        little motion for the noise (uncertainty above :data:`MAX_STD_FRAMES`
        frame periods), the best candidate at the end of the range, or frames
        that do not follow the motion at the best offset.

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
    _check_sizes(pos, t_dic, t_ir, parameter)
    motion, jitter = _motion(pos)
    if t_ir.size > max_frames:
        keep = np.linspace(0, t_ir.size - 1, max_frames).round().astype(int)
        frames, t_ir = frames[keep], t_ir[keep]
    _check_motion(motion, jitter, parameter)
    frames = np.asarray(frames, dtype=np.float32)
    mesh = Mesh(pos, t_dic)
    coarse = _nodes(mesh, SEARCH_SMOOTHING_PX, max(2.0, np.sqrt(mesh.area / SEARCH_NODES)))
    some = _spread_out(t_ir.size, SEARCH_SAMPLES // coarse.M)
    search = Sampler(frames[some], t_ir[some], coarse, SEARCH_SMOOTHING_PX)
    sigma = _frame_noise(frames)
    fits, fine, spacing = _fits(search, frames, t_ir, mesh, centre, period, motion, parameter, sigma)
    rank, shift = _model_order(fits, period)
    tau, score, parts, grid, crit = fits[rank]
    parts = dataclasses.replace(parts, model=shift)
    _check_identified(parts, period, motion, parameter)
    _check_inside(tau, grid, np.nan_to_num(crit, nan=np.nanmax(crit)), motion, parameter)
    _check_fit(_misfit(fine, score.idx[_spread_out(score.idx.size, CHECK_FRAMES)], tau, rank), sigma, tau, period,
               parameter)
    _check_basin(score, tau, parts.std, period, parameter)
    out = ClockOffset(tau, parts.std, period, motion, sigma, grid, crit, int(score.idx.size), int(fine.M), parts, rank)
    log.info("IR clock offset from the data: %.5g s +- %.2g s (%.3f +- %.3f IR frames: noise %.3f, robust %.3f, "
             "motion between DIC stages %.3f; %d frames x %d nodes %.2g px apart, %d pattern component%s, motion up "
             "to %.3g px, pixel noise %.3g K)", tau, parts.std, tau / period, parts.std / period, parts.noise / period,
             parts.robust / period, parts.interpolation / period, out.frames, out.points, spacing, rank,
             "s" if rank > 1 else "", motion, sigma)
    return out


def _fits(search, frames, t_ir, mesh, centre, period, motion, parameter, sigma):
    """The estimates of the models with one component and, where it leaves structure, two and three:
    {rank: (tau, score, Uncertainty, grid, criterion)}, the refinement's sampler and its node spacing (px)."""
    fits, failed, fine, spacing = {}, None, None, np.nan
    for rank in range(1, MAX_RANK + 1):
        try:
            roots, grid, crit = _search(search, centre, period, motion, parameter, rank)
            if fine is None:
                fine, spacing = _refinement_sampler(frames, t_ir, mesh, max(search.inside(r, r).size for r in roots)
                                                    * t_ir.size // search.t_ir.size)
            # the minima compared on the refinement's nodes: more samples, less smoothing, more power
            tau0 = _tournament(fine, roots, rank)
            tau, score, slope = _refined(fine, tau0, period, motion, parameter, rank)
        except DataError as exc:
            failed = failed or exc
            if rank > 1:
                break
            continue
        fits[rank] = (tau, score, uncertainty(score, tau, slope, sigma), grid, crit)
        if rank == 1 and not _structured(fits[1][2], period):
            break
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


def _refined(sampler: Sampler, tau0: float, period: float, motion: float, parameter: str, rank: int):
    """The root of the fixed-weight score from ``tau0``: the weights fitted at ``tau0``, refitted at the secant's
    root where it lies more than :data:`REFIT_FRAMES` frame periods away (weights fitted off the root lose
    precision on a weak pattern); (tau, score, slope)."""
    tau, score, slope = np.nan, None, np.nan
    idx = sampler.inside(tau0, tau0, SLACK_FRAMES * period)
    if idx.size >= 4:
        score = Score(sampler, idx, tau0, GRADIENT_PX, rank)
        start, rate = secant(score, tau0, period)
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


def _check_sizes(pos, t_dic, t_ir, parameter):
    if pos.shape[1] < 10 or t_dic.size < 2 or t_ir.size < 4:
        raise DataError(f"{parameter}: auto needs at least 10 DIC points seen at half the DIC times or more, 2 DIC "
                        f"times and 4 IR frames; found {pos.shape[1]} points, {t_dic.size} DIC times, "
                        f"{t_ir.size} IR frames: set {parameter} to a number (s)")


def _check_motion(motion, jitter, parameter):
    if not motion >= max(MIN_MOTION_PX, MIN_MOTION_JITTERS * jitter):
        raise DataError(
            f"{parameter}: auto cannot estimate the clock offset from the data: the DIC points move at most "
            f"{motion:.2g} px in the IR image over the record (their positions scatter by {jitter:.2g} px from "
            f"stage to stage), less than {MIN_MOTION_PX:g} px or {MIN_MOTION_JITTERS:g} times that scatter: a static "
            f"specimen carries no timing information. Set {parameter} to a number (s; docs/time-sync.md)")


def _check_identified(parts, period, motion, parameter):
    std = parts.std
    if np.isfinite(std) and std <= MAX_STD_FRAMES * period:
        return
    if parts.model > max(parts.noise, parts.robust, parts.interpolation):
        why = (f"the temperature pattern changes its shape on the material (heat flowing in from a grip, a "
               f"travelling band): models of two and three pattern components "
               + (f"put the offset {parts.model:.3g} s apart" if np.isfinite(parts.model) else "do not fit")
               + ", so the motion cannot be told from the pattern's change")
    else:
        why = ("the offset shows where the image velocity changes (the motion starts, stops or turns) on a "
               "temperature pattern; a static specimen, motion at a constant rate, a uniform temperature or too "
               "little motion for the record's noise carry no timing information")
    raise DataError(
        f"{parameter}: auto cannot estimate the clock offset from the data: the DIC points move at most "
        f"{motion:.3g} px in the IR image over the record, and the temperature pattern they carry fixes the "
        f"offset only to {_fmt_std(std, period)}, more than {MAX_STD_FRAMES:g} IR frame period ({period:.4g} s): "
        f"{why}. Set {parameter} to a number (s; docs/time-sync.md)")


def _check_inside(tau, grid, crit, motion, parameter):
    """The refined offset must lie inside the searched range (not at its end: the minimum may lie beyond)."""
    tol = 0.02 * (grid[1] - grid[0])
    if not grid[0] + tol < tau < grid[-1] - tol and np.ptp(crit) > 1e-12 * max(crit.max(), 1e-300):
        raise DataError(
            f"{parameter}: auto: the best offset lies at the end of the searched range {grid[0]:.4g}..{grid[-1]:.4g} s "
            f"(the DIC points move at most {motion:.3g} px in the IR image): the clocks differ by more than a "
            f"quarter of the record, or the data do not fix the offset; set {parameter} to a number (s)")


def _frame_noise(frames: np.ndarray, max_frames: int = 20) -> float:
    """Pixel noise (K) of the frames whatever the offset: the robust spread of each pixel less the mean of its
    four neighbours (``sigma^2 (1 + 1/4)`` for white noise; a smooth pattern cancels, edges are few)."""
    f = frames[np.unique(np.linspace(0, frames.shape[0] - 1, min(max_frames, frames.shape[0])).round().astype(int))]
    f = f.astype(np.float64)
    r = f[:, 1:-1, 1:-1] - 0.25 * (f[:, :-2, 1:-1] + f[:, 2:, 1:-1] + f[:, 1:-1, :-2] + f[:, 1:-1, 2:])
    return float(1.4826 * np.median(np.abs(r)) / np.sqrt(1.25)) if r.size else np.nan


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


def _check_fit(misfit, noise, tau, period, parameter):
    """At the estimate the rank-one model must explain the frames to their pixel noise: a larger misfit means a
    wrong basin (an offset beyond the searched range) or a pattern that does not move with the material."""
    if misfit > FIT_RATIO * np.hypot(noise, FIT_FLOOR_K):
        raise DataError(
            f"{parameter}: auto cannot estimate the clock offset from the data: at the best offset found "
            f"({tau:.4g} s, {tau / period:.2f} IR frames) the frames do not follow the DIC motion (the specimen's "
            f"temperature pattern misfits by {misfit:.3g} K against a pixel noise of {noise:.3g} K): the offset lies "
            f"beyond the searched quarter of the record, or the pattern changes on the material. Set {parameter} "
            f"to a number (s; docs/time-sync.md)")


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


def _fmt_std(std: float, period: float) -> str:
    if not np.isfinite(std):
        return "no precision at all (the criterion is flat)"
    return f"+- {std:.3g} s ({std / period:.2f} IR frames)"


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
    first where fewer than 4 are common)."""
    best = roots[0]
    for r in roots[1:]:
        idx = sampler.inside(min(best, r), max(best, r))
        if idx.size >= 4:
            J = Criterion(sampler, idx, rank)
            if J(r) < J(best):
                best = r
    return best


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
