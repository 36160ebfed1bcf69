"""The checks of the IR clock's estimate: where the data do not fix the offset, a clear error instead of a number.

Each check raises :class:`~irdic.errors.DataError` naming the configuration
key (``experiments.<name>.ir.time_offset``), what was found and why it does
not fix the offset; :mod:`irdic.timing.offset` calls them in turn.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import DataError

__all__ = ["MAX_STD_FRAMES", "MIN_MOTION_PX", "MIN_MOTION_JITTERS", "FIT_RATIO", "FIT_FLOOR_K", "RIVAL_SCATTERS",
           "check_sizes", "check_motion", "check_identified", "check_single", "check_inside", "check_fit", "fmt_std"]

#: an estimate whose standard uncertainty exceeds this many IR frame periods is refused: 0.2 frame periods
#: (the goal on realistic exports) stay at least 1.67 standard uncertainties
MAX_STD_FRAMES = 0.12
#: an offset is estimated only where the points move at least this much in the image (px) ...
MIN_MOTION_PX = 0.5
#: ... and at least this many times their scatter from stage to stage (DIC noise)
MIN_MOTION_JITTERS = 20.0
#: the rank-one misfit at the estimate may exceed the frames' pixel noise by this factor at most ...
FIT_RATIO = 1.5
#: ... with this floor (K) under the noise (noise-free exports)
FIT_FLOOR_K = 0.005
#: another minimum of the criterion, outside the estimate's basin, must fit worse by this many relative scatters
#: of the criterion (:func:`check_single`)
RIVAL_SCATTERS = 4.0


def check_sizes(pos, t_dic, t_ir, parameter):
    if pos.shape[1] < 10 or t_dic.size < 2 or t_ir.size < 4:
        raise DataError(f"{parameter}: auto needs at least 10 DIC points seen at half the DIC times or more, 2 DIC "
                        f"times and 4 IR frames; found {pos.shape[1]} points, {t_dic.size} DIC times, "
                        f"{t_ir.size} IR frames: set {parameter} to a number (s)")


def check_motion(motion, jitter, parameter):
    if not motion >= max(MIN_MOTION_PX, MIN_MOTION_JITTERS * jitter):
        raise DataError(
            f"{parameter}: auto cannot estimate the clock offset from the data: the DIC points move at most "
            f"{motion:.2g} px in the IR image over the record (their positions scatter by {jitter:.2g} px from "
            f"stage to stage), less than {MIN_MOTION_PX:g} px or {MIN_MOTION_JITTERS:g} times that scatter: a static "
            f"specimen carries no timing information. Set {parameter} to a number (s; docs/time-sync.md)")


def check_identified(parts, period, motion, parameter):
    std = parts.std
    if np.isfinite(std) and std <= MAX_STD_FRAMES * period:
        return
    if parts.model > max(parts.noise, parts.robust, parts.frames, parts.interpolation):
        why = ("the temperature pattern changes its shape on the material (heat flowing in from a grip, a "
               "travelling band): models of two and three pattern components "
               + (f"put the offset {parts.model:.3g} s apart" if np.isfinite(parts.model) else "do not fit")
               + ", so the motion cannot be told from the pattern's change")
    elif parts.frames > max(parts.noise, parts.robust, parts.interpolation) and \
            dataclasses.replace(parts, frames=0.0).std <= MAX_STD_FRAMES * period:
        # the per-frame misfit is the reason only where the estimate would stand without it (noise alone
        # beyond the bound is too little information whatever the pattern does)
        why = ("each frame misfits the pattern model as a whole, differently from frame to frame: the temperature "
               "pattern changes its shape on the material in a way the model does not follow and the motion "
               "partly mimics (an edge profile that widens while the specimen stretches)")
    else:
        why = ("the offset shows where the image velocity changes (the motion starts, stops or turns) on a "
               "temperature pattern; a static specimen, motion at a constant rate, a uniform temperature or too "
               "little motion for the record's noise carry no timing information")
    raise DataError(
        f"{parameter}: auto cannot estimate the clock offset from the data: the DIC points move at most "
        f"{motion:.3g} px in the IR image over the record, and the temperature pattern they carry fixes the "
        f"offset only to {fmt_std(std, period)}, more than {MAX_STD_FRAMES:g} IR frame period ({period:.4g} s): "
        f"{why}. Set {parameter} to a number (s; docs/time-sync.md)")


def check_single(tau, rivals, std, period, motion, parameter):
    """The estimate's basin must fit the frames better than every other minimum of the criterion (models of two
    and three pattern components, which absorb most of the motion's signal).

    ``rivals``: ``(root, excess, scale)`` of the other minima the search found
    (:func:`irdic.timing.offset._tournament`): the criterion's relative excess over the estimate's on their
    common frames, and the relative scatter of a mean of that many squared residuals. A rival more than a frame
    period and 3 standard uncertainties away whose excess stays below :data:`RIVAL_SCATTERS` scatters is an
    equally good offset: the data do not single one out, and the stated uncertainty, which describes the chosen
    basin only, would not cover the truth (family member drawn-404, a stretched plate with a widening edge
    profile, 3.4 frames behind, two components: +7.5 +- 0.07 frames; its rivals fit 0.01-1.1 % worse, 0.1-3
    scatters). With one component the runner-up of a right estimate may fit as little as 0.5 % worse (1.2
    scatters on the tiny tube of a weak pattern, its estimates right): not checked there."""
    for root, excess, scale in rivals:
        if abs(root - tau) > max(period, 3.0 * std) and excess < RIVAL_SCATTERS * scale:
            raise DataError(
                f"{parameter}: auto cannot estimate the clock offset from the data: offsets of {tau:.4g} s and "
                f"{root:.4g} s ({tau / period:.2f} and {root / period:.2f} IR frames; the DIC points move at most "
                f"{motion:.3g} px in the IR image) fit the frames equally well (misfits {100 * excess:.2g} % apart, "
                f"within {RIVAL_SCATTERS:g} times their scatter): the temperature pattern changes on the material in "
                f"a way a shift in time mimics (an edge profile that widens while the specimen stretches). Set "
                f"{parameter} to a number (s; docs/time-sync.md)")


def check_inside(tau, grid, crit, motion, parameter):
    """The refined offset must lie inside the searched range (not at its end: the minimum may lie beyond)."""
    tol = 0.02 * (grid[1] - grid[0])
    if not grid[0] + tol < tau < grid[-1] - tol and np.ptp(crit) > 1e-12 * max(crit.max(), 1e-300):
        raise DataError(
            f"{parameter}: auto: the best offset lies at the end of the searched range {grid[0]:.4g}..{grid[-1]:.4g} s "
            f"(the DIC points move at most {motion:.3g} px in the IR image): the clocks differ by more than a "
            f"quarter of the record, or the data do not fix the offset; set {parameter} to a number (s)")


def check_fit(misfit, noise, tau, period, parameter):
    """At the estimate the rank-one model must explain the frames to their pixel noise: a larger misfit means a
    wrong basin (an offset beyond the searched range) or a pattern that does not move with the material."""
    if misfit > FIT_RATIO * np.hypot(noise, FIT_FLOOR_K):
        raise DataError(
            f"{parameter}: auto cannot estimate the clock offset from the data: at the best offset found "
            f"({tau:.4g} s, {tau / period:.2f} IR frames) the frames do not follow the DIC motion (the specimen's "
            f"temperature pattern misfits by {misfit:.3g} K against a pixel noise of {noise:.3g} K): the offset lies "
            f"beyond the searched quarter of the record, or the pattern changes on the material. Set {parameter} "
            f"to a number (s; docs/time-sync.md)")


def fmt_std(std: float, period: float) -> str:
    if not np.isfinite(std):
        return "no precision at all (the criterion is flat)"
    return f"+- {std:.3g} s ({std / period:.2f} IR frames)"
