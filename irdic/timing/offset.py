"""The offset between the IR and the DIC clock, estimated from the data.

A wrong offset moves every DIC point in the IR image by its image velocity
times the error, so the IR frames show a temperature pattern that no longer
moves with the material. This module finds the offset ``tau`` (seconds
added to the IR times, as a configured ``time_offset``) at which the IR
frames and the DIC motion agree best.

Criterion
---------
For a candidate ``tau`` every IR frame ``k`` (time ``t_k`` on the IR clock)
is sampled bilinearly at the positions the DIC points have in the image at
the DIC time ``t_k + tau``; the positions are interpolated between the DIC
stages by a cubic spline in time. Row ``k`` of the matrix ``X(tau)`` (frames
x points) is then what frame ``k`` shows at the material points. A pattern
carried by the material has, at the right offset, the same shape in every
frame up to a level and an amplitude, ``X_k = a_k + b_k P + noise``; at a
wrong offset every frame is sampled displaced by its image velocity times the
error, and since the velocity changes during the test, the pattern seen in
the material drifts from frame to frame. The criterion is the misfit of the
rank-one model,

``J(tau) = ||X_c||^2 - s_1^2(X_c)``,

with ``X_c`` the rows of ``X`` less their means and ``s_1`` its largest
singular value. The samples are taken at the DIC points and at nodes
between them (about one smoothing width apart, :func:`irdic.timing.samples.prepared`), so that
every pixel of the specimen counts. ``J`` is evaluated on a grid of
candidates over a quarter of the record each way, each on the frames it
places inside the DIC record; its few best local minima are refined and
compared pairwise on the frames both place inside the record (frames with
little motion fit any offset, so candidates judged on different frames are
not comparable), and the winner is refined by Gauss-Newton steps on the score ``Y . R(tau) = 0``, with ``R`` the
rank-one residual and ``Y`` the derivative of the rank-one *model* (the
pattern, averaged over the other frames, moved along the image velocity):
the frames' own derivative carries the smoothed noise's gradient, whose
share grows as the pattern weakens. The positions are continuous in time:
no frame grid limits the resolution. The standard uncertainty comes from
``Y`` and the pixel noise (Notes of :func:`estimate_offset`).

When it cannot work: a static specimen (no motion: every offset fits the
same), a uniform temperature (no pattern to carry), or motion too small for
the noise (the uncertainty exceeds :data:`MAX_STD_FRAMES` IR frame periods):
:class:`~irdic.errors.DataError` naming the configuration key, with the
motion found and the uncertainty it allows.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.optimize import minimize_scalar

from ..errors import DataError
from .samples import Criterion, Sampler, prepared, rank_one, score_parts

__all__ = ["ClockOffset", "estimate_offset", "crop_box", "MAX_STD_FRAMES", "MAX_POINTS", "MAX_FRAMES", "SMOOTHING_PX", "MODEL_STD_FRAMES", "MIN_MOTION_PX",
           "MIN_MOTION_JITTERS"]

log = logging.getLogger(__name__)

#: an estimate whose standard uncertainty exceeds this many IR frame periods is refused
MAX_STD_FRAMES = 0.25
#: points used (evenly spread over the cloud's order): the criterion's noise falls as 1/sqrt(points)
MAX_POINTS = 8000
#: frames used (evenly spread over the record)
MAX_FRAMES = 600
#: Gaussian smoothing of the frames (px) before they are sampled
SMOOTHING_PX = 1.5
#: an offset is estimated only where the points move at least this much in the image (px) ...
MIN_MOTION_PX = 0.5
#: ... and at least this many times their scatter from stage to stage (DIC noise)
MIN_MOTION_JITTERS = 20.0
#: the criterion's own bias, in IR frame periods, added in quadrature to the noise's share of the uncertainty:
#: on noise-free synthetic scenes (smoothed frames of a moving, foreshortened pattern; positions interpolated
#: between DIC stages by a cubic spline) the estimates lie within 0.03 frame periods of the truth
MODEL_STD_FRAMES = 0.03
#: the rank-one misfit at the estimate may exceed the frames' pixel noise by this factor at most ...
FIT_RATIO = 1.5
#: ... with this floor (K) under the noise (noise-free exports)
FIT_FLOOR_K = 0.005
#: a Gauss-Newton step from one frame period either side of the estimate must return to within this many
#: frame periods of it, or this many of its standard uncertainties
BASIN_FRAMES, BASIN_STDS = 0.5, 4.0
#: coarse candidates at most (the refinement is continuous)
_MAX_CANDIDATES = 31
#: points of the coarse search at most (it only has to find the basin)
_COARSE_POINTS = 1500
#: basins (local minima of the coarse criterion) refined and compared at most
_STARTS = 3
#: Gauss-Newton steps of the refinement at most
_GN_STEPS = 8


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
        Residual of the rank-one model per sample at the estimate (K).
    candidates, criterion : numpy.ndarray
        The coarse grid (s) and ``J`` per sample on it (K^2).
    frames, points : int
        IR frames and DIC points the estimate used.
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
                    centre: float = 0.0, parameter: str = "ir.time_offset", smoothing_px: float = SMOOTHING_PX,
                    max_points: int = MAX_POINTS, max_frames: int = MAX_FRAMES) -> ClockOffset:
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
        at fewer than half of the times, or nearer the cloud's outline than
        3 smoothing widths + 1 px, are left out).
    centre : float
        Middle of the searched offsets (s); the search covers a quarter of the
        shorter record each way.
    parameter : str
        The configuration key named in errors.
    smoothing_px : float
        Standard deviation (px) of the Gaussian smoothing of the frames.
    max_points, max_frames : int
        Points and frames used at most (evenly spread).
    Returns
    -------
    ClockOffset

    Raises
    ------
    DataError
        Not identifiable: too few points or frames, a static specimen or too
        little motion for the noise (uncertainty above :data:`MAX_STD_FRAMES`
        frame periods), or the best candidate at the end of the range.

    Notes
    -----
    Near the root the samples are ``X(tau) = X(tau*) + X' d + e`` with
    ``d = tau - tau*``. After removing the directions the rank-one model
    absorbs (row means, ``u w^T`` and ``z v^T`` for the fitted singular
    vectors ``u``, ``v``), ``Y = (I - u u^T) X'_c (I - v v^T)``, with ``X'``
    the model's derivative ``u_k s_1 grad(v^(-k)) . w`` (the pattern
    ``v^(-k)`` from all frames but ``k``, its gradient from local planes
    through each sample's neighbours, ``w`` the image velocity), and the
    Gauss-Newton root has ``var(d) = var(Y . e) / ||Y||^4``. The sample errors
    are ``e = B G n``: pixel errors ``n`` of variance ``sigma^2``, smoothed (``G``)
    and sampled bilinearly (``B``), so ``var(Y . e) = sigma^2 ||G B^T Y||^2``.
    ``sigma^2`` is the raw samples' rank-one misfit, each over its bilinear
    noise gain, per degree of freedom.
    :data:`MODEL_STD_FRAMES` frame
    periods of model error are added in quadrature.
    """
    t_ir, t_dic = np.asarray(t_ir, float), np.asarray(t_dic, float)
    # the smoothing kernel of a kept point stays on the specimen
    inset = np.ceil(3 * smoothing_px) + 1 if smoothing_px > 0 else 0.0
    pos = prepared(np.asarray(positions, float), t_dic, max_points, inset, smoothing_px)
    period = float(np.median(np.diff(t_ir))) if t_ir.size > 1 else np.nan
    _check_sizes(pos, t_dic, t_ir, parameter)
    motion, jitter = _motion(pos)
    if t_ir.size > max_frames:
        keep = np.linspace(0, t_ir.size - 1, max_frames).round().astype(int)
        frames, t_ir = frames[keep], t_ir[keep]
    _check_motion(motion, jitter, parameter)
    sampler = Sampler(frames, t_ir, t_dic, pos, smoothing_px)
    tau, J, grid, crit = _search(sampler, centre, period, motion, parameter)
    std, noise = _uncertainty(sampler, J, tau, period)
    _check_identified(std, period, motion, parameter)
    _check_fit(noise, _frame_noise(sampler.raw), tau, period, parameter)
    _check_basin(sampler, tau, std, period, parameter)
    std = float(np.hypot(std, MODEL_STD_FRAMES * period))
    log.info("IR clock offset from the data: %.5g s +- %.2g s (%.3f +- %.3f IR frames; %d frames x %d points, "
             "motion up to %.3g px, pixel noise %.3g K)", tau, std, tau / period, std / period, J.idx.size,
             pos.shape[1], motion, noise)
    return ClockOffset(tau, std, period, motion, noise, grid, crit, int(J.idx.size), int(pos.shape[1]))


def _search(sampler: Sampler, centre: float, period: float, motion: float, parameter: str):
    """The offset (s) and its criterion: the coarse candidates' basins refined, compared, the winner refined."""
    t_ir, t_dic = sampler.t_ir, sampler.t_dic
    grid, crit, starts, coarse = _coarse(sampler, t_ir, t_dic, centre, period, f"{parameter}: auto", parameter)
    step, bounds = grid[1] - grid[0], (grid[0], grid[-1])
    roots = [_refined(coarse, grid[i], step, period, bounds, newton=False)[0] for i in starts]
    roots = [r for r in roots if np.isfinite(r)]
    if roots:  # located to a twentieth of a frame: Gauss-Newton on every sample from there
        tau, J = _refined(sampler, _tournament(coarse, roots), step, period, bounds, search=False)
    else:
        tau, J = _refined(sampler, grid[starts[0]], step, period, bounds)
    if J is None:
        raise DataError(f"{parameter}: auto: fewer than 4 IR frames lie inside the DIC record around the best "
                        f"offset ({tau:.4g} s); set {parameter} to a number (s)")
    _check_inside(tau, grid, np.nan_to_num(crit, nan=np.nanmax(crit)), motion, parameter)
    return tau, J, grid, crit


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
        raise DataError(f"{parameter}: auto needs at least 10 DIC points seen at every DIC time and away from the "
                        f"cloud's outline, 2 DIC times and 4 IR frames; found {pos.shape[1]} points, {t_dic.size} "
                        f"DIC times, {t_ir.size} IR frames: set {parameter} to a number (s)")


def _check_motion(motion, jitter, parameter):
    if not motion >= max(MIN_MOTION_PX, MIN_MOTION_JITTERS * jitter):
        raise DataError(
            f"{parameter}: auto cannot estimate the clock offset from the data: the DIC points move at most "
            f"{motion:.2g} px in the IR image over the record (their positions scatter by {jitter:.2g} px from "
            f"stage to stage), less than {MIN_MOTION_PX:g} px or {MIN_MOTION_JITTERS:g} times that scatter: a static "
            f"specimen carries no timing information. Set {parameter} to a number (s; docs/time-sync.md)")


def _check_identified(std, period, motion, parameter):
    if not np.isfinite(std) or std > MAX_STD_FRAMES * period:
        raise DataError(
            f"{parameter}: auto cannot estimate the clock offset from the data: the DIC points move at most "
            f"{motion:.3g} px in the IR image over the record, and the temperature pattern they carry fixes the "
            f"offset only to {_fmt_std(std, period)}, more than {MAX_STD_FRAMES:g} IR frame period ({period:.4g} s); "
            f"a static specimen, a uniform temperature or too little motion for the record's noise carry no "
            f"timing information. Set {parameter} to a number (s; docs/time-sync.md)")


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


def _check_basin(sampler, tau, std, period, parameter):
    """A Gauss-Newton step from one frame period either side must come back to ``tau``: in the basin of the
    true offset the score is linear in the offset over several frames, at a minimum the noise made (the true
    one beyond the searched range, or no pattern to speak of) the steps run off."""
    for side in (-1.0, 1.0):
        start = tau + side * period
        idx = sampler.inside(min(tau, start), max(tau, start))
        if idx.size < 4:
            continue
        Y, R, _ = score_parts(sampler, Criterion(sampler, idx), start)
        S = float(np.sum(Y * Y))
        back = start - float(np.sum(Y * R)) / S if S > 0 else np.inf
        if not abs(back - tau) <= max(BASIN_FRAMES * period, BASIN_STDS * std):
            raise DataError(
                f"{parameter}: auto cannot estimate the clock offset from the data: they do not single out one "
                f"offset (from {start:.4g} s the fit goes to {back:.4g} s, not back to {tau:.4g} s): the offset "
                f"lies beyond the searched quarter of the record, or the pattern is too weak for the record's "
                f"noise. Set {parameter} to a number (s; docs/time-sync.md)")


def _fmt_std(std: float, period: float) -> str:
    if not np.isfinite(std):
        return "no precision at all (the criterion is flat)"
    return f"+- {std:.3g} s ({std / period:.2f} IR frames)"


def _coarse(sampler, t_ir, t_dic, centre, period, where, parameter):
    """The candidates (s) over a quarter of the shorter record each way, ``J`` per degree of freedom of each on
    the frames it places inside the DIC record, and the starts: the candidates at its local minima, best
    first (at most :data:`_STARTS`), judged with at most :data:`_COARSE_POINTS` points.

    Each candidate is judged on its own frames, so that frames with motion count wherever they lie in the
    record; frames with little motion fit any offset, so the order of the starts is only a first guess
    (:func:`_tournament` decides on common frames).
    """
    span = min(t_dic[-1] - t_dic[0], t_ir[-1] - t_ir[0])
    half = max(0.25 * span, 2.0 * period)
    n = int(np.clip(np.ceil(2 * half / period) + 1, 9, _MAX_CANDIDATES))
    grid = centre + np.linspace(-half, half, n)
    coarse = sampler.subset(_COARSE_POINTS)
    crit = _judged(coarse, grid)
    if not np.isfinite(crit).any():
        raise DataError(f"{where}: the IR record ({t_ir[0]:.4g}..{t_ir[-1]:.4g} s) and the DIC record "
                        f"({t_dic[0]:.4g}..{t_dic[-1]:.4g} s) overlap in fewer than 4 IR frames around an offset "
                        f"of {centre:.4g} s; set {parameter} to a number (s)")
    c = np.where(np.isfinite(crit), crit, np.inf)
    left, right = np.r_[np.inf, c[:-1]], np.r_[c[1:], np.inf]
    minima = np.flatnonzero((c <= left) & (c <= right) & np.isfinite(c))
    starts = minima[np.argsort(c[minima])][:_STARTS]
    return grid, crit, starts, coarse


def _judged(sampler, grid):
    """``J`` per degree of freedom of the rank-one fit at each candidate, on its own frames (NaN: fewer than
    half the frames the best-placed candidate has)."""
    frames = [sampler.inside(g, g) for g in grid]
    full = max(idx.size for idx in frames)
    out = np.full(grid.size, np.nan)
    for i, (g, idx) in enumerate(zip(grid, frames)):
        n, m = idx.size, sampler.M
        if n >= max(4, (full + 1) // 2) and n * m > n + (n + m - 1):
            out[i] = Criterion(sampler, idx).parts(g)[0] / (n * m - n - (n + m - 1))
    return out


def _tournament(sampler, roots):
    """The root that fits best, each pair compared on the frames both place inside the DIC record."""
    best = roots[0]
    for r in roots[1:]:
        idx = sampler.inside(min(best, r), max(best, r))
        if idx.size >= 4:
            J = Criterion(sampler, idx)
            if J(r) < J(best):
                best = r
    return best


def _refined(sampler: Sampler, start: float, step: float, period: float, bounds: tuple[float, float],
             newton: bool = True, search: bool = True):
    """The minimum of ``J`` within ``step`` of ``start`` (on the frames every offset there places inside the
    DIC record), then Gauss-Newton steps on the model's derivative (:func:`model_derivative`) to the root
    of the score; while the minimum lies at an end of the bracket, the bracket moves on by one step (at most
    four times, never beyond ``bounds``); without ``newton`` the minimum only (to a twentieth of a frame),
    without ``search`` the Gauss-Newton steps from ``start`` only."""
    lo, hi = start - step, start + step
    tau, J = start, None
    if not search and sampler.inside(lo, hi).size >= 4:
        J = Criterion(sampler, sampler.inside(lo, hi))
    for _ in range(4 if search else 0):
        idx = sampler.inside(lo, hi)
        if idx.size < 4:
            break
        J = Criterion(sampler, idx)
        tau = float(minimize_scalar(J, bounds=(lo, hi), method="bounded",
                                    options={"xatol": (0.01 if newton else 0.05) * period}).x)
        if lo + 0.02 * step < tau < hi - 0.02 * step or not bounds[0] < tau < bounds[1]:
            break
        shift = step if tau >= hi - 0.02 * step else -step
        lo, hi = lo + shift, hi + shift
    if J is None:
        return np.nan, None
    for _ in range(_GN_STEPS if newton else 0):
        Y, R, _ = score_parts(sampler, J, tau)
        S = float(np.sum(Y * Y))
        if not S > 0:
            break
        new = float(np.clip(tau - float(np.sum(Y * R)) / S, lo, hi))
        done = abs(new - tau) <= 1e-4 * period
        tau = new
        if done:
            break
    return tau, J


def _uncertainty(sampler: Sampler, J: Criterion, tau: float, period: float) -> tuple[float, float]:
    """Standard uncertainty of ``tau`` (s) and the pixel noise (K) (see :func:`estimate_offset`)."""
    Y, _, _ = score_parts(sampler, J, tau)
    flat, wts = sampler.weights(tau, J.idx)
    sigma = _pixel_noise(sampler, J.idx, tau, wts)
    S = float(np.sum(Y * Y))
    if S <= 0 or not np.isfinite(sigma):
        return np.inf, sigma
    # the estimate's error is -sum(Y e) / S with e the smoothed pixel noise at the samples: e = G B n
    acc = np.bincount(flat.ravel(), weights=(wts * Y[..., None]).ravel(), minlength=sampler.frames.size)
    acc = acc.reshape(sampler.frames.shape)  # float64: the weights of all samples on each pixel
    if sampler.smoothing > 0:
        acc = gaussian_filter(acc, (0, sampler.smoothing, sampler.smoothing), mode="constant")
    var = sigma**2 * float(np.sum(acc * acc)) / S**2
    return float(np.sqrt(var)), sigma


def _pixel_noise(sampler: Sampler, idx: np.ndarray, tau: float, wts: np.ndarray) -> float:
    """Pixel noise (K): the raw samples' misfit of the rank-one model, each over its bilinear noise gain."""
    X = sampler(tau, idx, raw=True)
    Xc = X - X.mean(axis=1, keepdims=True)
    s2, u, v = rank_one(Xc)
    R = Xc - np.sqrt(s2) * np.outer(u, v)
    gain = np.einsum("nmc,nmc->nm", wts, wts)  # a sample between pixels averages their noise
    n, m = X.shape
    dof = n * m - n - (n + m - 1)
    return float(np.sqrt(np.sum(R * R / gain) / dof)) if dof > 0 else np.nan
