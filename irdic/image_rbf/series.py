"""Temperatures, gradients and rates at moving points over a frame series (the couple stage's use).

For each evaluation time ``t_k`` the frames are combined by the temporal
cardinal weights, ``G_k = F l_t(t_k)`` and ``G'_k = F l_t'(t_k)``, and both are
interpolated in space at the points ``P_k`` (see :mod:`irdic.image_rbf`).

With a moving mask the tensor product interpolates each pixel's series over
all frames, so pixels that changed between specimen and background within a
few frames of ``t_k`` carry mixed values in ``G_k``; an eroded mask avoids
that.
"""

from __future__ import annotations

import logging
import threading
import warnings
from typing import NamedTuple

import numpy as np

from ..errors import ConfigError, DataError, IrdicWarning
from ..logs import Progress, report
from ..numerics.temporal import FLAT_KERNEL_SPACINGS, TemporalInterpolant
from ..numerics.threads import parallel_map, workers
from ..threads import blas_threads
from ..validation import as_int, bool_mask, choice, float_array
from .interpolant import METHODS, MaskedGridInterpolant
from .stencil import interior_stencil
from .batch import EdgeBatch
from .tiles import edge_windows


__all__ = ["SeriesEvaluation", "evaluate_series"]

log = logging.getLogger(__name__)

# Bytes of frames read per block (float32 frames: 128 MB).
_READ_BYTES = 2**27


class SeriesEvaluation(NamedTuple):
    """Result of :func:`evaluate_series`; arrays (n_times, M) unless noted.

    theta : temperature (unit of the frames, °C)
    dtheta_du, dtheta_dv : spatial derivatives, K/px
    dtheta_dt : local time derivative at fixed pixel position, K/s
    edge_distance : px from the mask edge (see :class:`Evaluation`)
    in_span : (n_times,) bool, False where the time lies outside the frame
        span (all values NaN there)
    theta_extra : temperature of the frames through ``pixel_operator``
        (None without one)
    """

    theta: np.ndarray
    dtheta_du: np.ndarray
    dtheta_dv: np.ndarray
    dtheta_dt: np.ndarray
    edge_distance: np.ndarray
    in_span: np.ndarray
    theta_extra: np.ndarray | None = None


def _frame_shape(frames):
    shape = getattr(frames, "shape", None)
    if shape is None:
        frames = np.asarray(frames)
        shape = frames.shape
    if len(shape) != 3:
        raise ConfigError(f"frames must have shape (n_frames, H, W), got {tuple(shape)}")
    return frames, shape


def _points(points, n_times):
    pts = float_array(points, "points")
    if pts.ndim == 2 and pts.shape[1] == 2:
        pts = np.broadcast_to(pts, (n_times,) + pts.shape)
    if pts.ndim != 3 or pts.shape[0] != n_times or pts.shape[2] != 2:
        raise ConfigError(
            f"points must have shape (n_times, M, 2) = ({n_times}, M, 2) or (M, 2), got {pts.shape}"
        )
    return pts


def _masks(mask, n_times, H, W):
    """Distinct consecutive masks and the index of each time's mask."""
    mk = np.asarray(mask)
    if mk.ndim == 2:
        masks = [bool_mask(mk)]
        mask_of = np.zeros(n_times, np.int64)
    elif mk.ndim == 3 and mk.shape[0] == n_times:
        masks, mask_of = [], np.empty(n_times, np.int64)
        for k in range(n_times):
            m = bool_mask(mk[k], f"mask[{k}]")
            if not (masks and np.array_equal(m, masks[-1])):
                masks.append(m)
            mask_of[k] = len(masks) - 1
    else:
        raise ConfigError(f"mask must have shape (H, W) or (n_times, H, W) = ({n_times}, H, W), got {mk.shape}")
    for m in masks:
        if m.shape != (H, W):
            raise ConfigError(f"mask must have the frame shape (H, W) = ({H}, {W}), got {m.shape}")
    return masks, mask_of


def _pixel_label(j, uu, uv, u, v):
    """``pixel (u=.., v=..)`` of the frame array, or ``sensor pixel`` with the grid's coordinate labels."""
    if u is None or v is None:
        return f"pixel (u={uu[j]}, v={uv[j]})"
    return f"sensor pixel (u={u[uu[j]]}, v={v[uv[j]]})"


def _pixel_series(frames, union, ft, u, v, name):
    """Time series (n_u, n_frames) of the pixels of ``union``, read frame block by frame block."""
    n_frames, H, W = frames.shape
    uv, uu = np.nonzero(union)
    F = np.empty((uv.size, n_frames))
    step = max(1, int(_READ_BYTES // max(1, H * W * 4)))
    for f0 in range(0, n_frames, step):
        block = np.asarray(frames[f0:f0 + step])
        F[:, f0:f0 + block.shape[0]] = block[:, uv, uu].T
    bad = ~np.isfinite(F)
    if bad.any():
        j, n = np.argwhere(bad)[0]
        raise DataError(
            f"{name}: {int(bad.sum())} non-finite value(s) at masked pixels, first in IR frame {n} "
            f"(t = {ft[n]:g} s) at {_pixel_label(j, uu, uv, u, v)}; every masked pixel needs finite values "
            "in every frame (NaN temperatures under the specimen cannot be interpolated)"
        )
    lookup = np.full((H, W), -1, np.int64)
    lookup[uv, uu] = np.arange(uv.size)
    return F, lookup


def _warn_out_of_span(in_span, te, ft):
    """``in_span``, with an IrdicWarning naming the times outside the frame span."""
    if in_span.all():
        return in_span
    out = np.flatnonzero(~in_span)
    shown = ", ".join(f"{te[i]:g}" for i in out[:5]) + (", ..." if out.size > 5 else "")
    warnings.warn(
        f"eval_times: {out.size} of {te.size} time(s) lie outside the frame span "
        f"[{ft[0]:g}, {ft[-1]:g}] s ({shown}); their results are NaN",
        IrdicWarning,
        stacklevel=3,
    )
    return in_span


#: The fewest times in a piece of :func:`_pieces` (below, a piece's edge tiles are too few to share a solve)
MIN_PIECE = 4


def _pieces(ks, chunk, n_workers=1):
    """Runs of consecutive in-span times, cut into pieces of at most ``chunk`` times.

    With several workers the pieces shrink towards the end of each run
    (guided scheduling: at most a ``2 n_workers``-th of what is left, and
    :data:`MIN_PIECE` at least), so that the workers, which take the pieces
    in turn, end about together instead of one running the last whole chunk
    alone.
    """
    pieces = []
    if ks.size:
        cut = np.flatnonzero(np.diff(ks) != 1) + 1
        for run in np.split(ks, cut):
            i = 0
            while i < run.size:
                left = run.size - i
                size = chunk if n_workers == 1 else max(MIN_PIECE, min(chunk, -(-left // (2 * n_workers))))
                pieces.append(run[i:i + size])
                i += size
    return pieces


def _combined_frames(F, sel, Wv, Wd, n_mask, extra=None):
    """``G_k`` and ``G'_k`` of a chunk at the pixels ``sel`` of the rows of ``F``: (chunk, 2, n_mask); with the
    sparse operator ``extra`` (n_u, n_u) on the union's pixels (the rows of ``F``), ``extra G_k`` too:
    (chunk, 3, n_mask)."""
    vals = np.empty((Wv.shape[0], 2 if extra is None else 3, n_mask))
    for j, Wt in enumerate((Wv, Wd)):
        # the temporal cardinal weights decay like the spatial ones: only
        # frames where they exceed 1e-15 of the largest enter (error ~1e-13 K)
        big = np.flatnonzero((np.abs(Wt) > 1e-15 * np.abs(Wt).max()).any(axis=0))
        c0, c1 = big[0], big[-1] + 1
        G = F[:, c0:c1] @ Wt[:, c0:c1].T
        vals[:, j] = G[sel].T
        if j == 0 and extra is not None:
            # the operator is linear in the pixel values: it acts on G_k, not on every frame
            vals[:, 2] = (extra @ G)[sel].T
    return vals


def evaluate_series(frames, frame_times, eval_times, points, mask, *, method="rbf", c=2.0, R0=1.0, c_time=1.0,
                    R0_time=1.0, time_window=None, halo=12, tile=8, chunk=32, u=None, v=None, name="frames",
                    pixel_operator=None, derivatives=None):
    """Temperatures, gradients and rates at moving points over a frame series.

    Parameters
    ----------
    frames : array_like, shape (n_frames, H, W)
        Pixel temperatures (°C); any array-like with numpy slicing (numpy,
        zarr, memmap), read frame block by frame block.
    frame_times : array_like, shape (n_frames,)
        Frame times in s, strictly increasing.
    eval_times : array_like, shape (n_times,)
        Evaluation times in s, any order; outside the frame span NaN (with an
        :class:`~irdic.errors.IrdicWarning`).
    points : array_like, shape (n_times, M, 2) or (M, 2)
        (u, v) in px of the frame array per evaluation time (or fixed); NaN
        points give NaN.
    mask : array_like of bool, shape (H, W) or (n_times, H, W)
        Pixels on the specimen, fixed or per evaluation time. Consecutive
        identical masks share all setup; a change factorises only the edge
        tiles whose local pattern (anywhere in any earlier mask) is new.
        Every masked pixel (of any time) needs finite values in every frame.
    method : {"rbf", "bilinear", "cubic"}
        Spatial method; in time always the IMQ interpolant.
    c, R0 : float
        Spatial IMQ shape parameter and normalisation (px): 2, 1 in the paper.
    c_time, R0_time : float
        Temporal IMQ shape parameter and normalisation (s): 1, 1 in the paper.
    time_window : None or int
        The temporal operator's window (:class:`~irdic.numerics.temporal.TemporalInterpolant`):
        :func:`~irdic.numerics.temporal.temporal_window` of the whole
        record's frame times, also when ``frames`` are a time chunk's.
    halo, tile : int
        See :class:`MaskedGridInterpolant`.
    chunk : int
        Evaluation times processed together (memory ~ chunk x 2 x bounding box
        of the mask x 12 B).
    u, v : array_like of int, shape (W,), (H,), optional
        Full-sensor pixel coordinates of the frame's columns and rows (a crop
        window); given, error messages name sensor pixels, not array indices.
    name : str
        Name of the frames in error messages (e.g. ``"ir: frames"``).
    pixel_operator : callable, optional
        ``(union mask (H, W), its pixels (n, 2) (u, v)) -> sparse (n, n)``, a linear operator on the pixel
        values; the frames through it are interpolated in the same pass, extra right-hand sides of the same
        tile factorisations (``theta_extra``, no derivatives).
    derivatives : array_like of bool, shape (M,), optional
        Points whose ``dTheta/du``, ``dTheta/dv`` are wanted (default all; the others' may be NaN).

    Returns
    -------
    SeriesEvaluation

    Raises
    ------
    DataError
        A masked pixel with a non-finite value (naming the first: frame,
        frame time, pixel), or a mask without 3 pixels off a line.
    """
    method = choice(method, "method", METHODS)
    chunk = as_int(chunk, "chunk", 1)
    frames, (n_frames, H, W) = _frame_shape(frames)
    ft = _frame_times(frame_times, n_frames)
    temporal = TemporalInterpolant(ft, c=c_time, R0=R0_time, window=time_window)
    if temporal.R0 < R0_time:
        log.info("%s: the temporal kernel (c_time %g x R0_time %g s) spans %.0f IR frame spacings; narrowed to %g "
                 "(R0 %.3g s): flatter kernels lose the digits of the interpolant's weights", name, c_time, R0_time,
                 FLAT_KERNEL_SPACINGS * R0_time / temporal.R0, FLAT_KERNEL_SPACINGS, temporal.R0)
    te = _eval_times(eval_times)
    pts = _points(points, te.size)
    masks, mask_of = _masks(mask, te.size, H, W)
    in_span = _warn_out_of_span(temporal.in_span(te), te, ft)
    union = _union(masks)
    F, lookup = _pixel_series(frames, union, ft, *((None, None) if u is None or v is None else (u, v)), name)
    extra = None if pixel_operator is None else pixel_operator(union, np.c_[np.nonzero(union)[::-1]])  # F's rows
    need = _wanted(derivatives, pts.shape[1])
    out = _evaluate(F, lookup, temporal, te, in_span, pts, masks, mask_of, chunk,
                    dict(method=method, c=c, R0=R0, halo=halo, tile=tile), extra, need)
    return SeriesEvaluation(*out[:5], in_span, out[5] if extra is not None else None)


def _wanted(derivatives, M):
    """The points (M,) whose derivatives are wanted, or None for all."""
    if derivatives is None:
        return None
    need = np.asarray(derivatives, dtype=bool)
    if need.shape != (M,):
        raise ConfigError(f"derivatives must have shape (M,) = ({M},) like the points, got {need.shape}")
    return need


def _eval_times(eval_times):
    te = float_array(eval_times, "eval_times")
    if te.ndim != 1:
        raise ConfigError(f"eval_times must be 1-D (n_times,), got shape {te.shape}")
    return te


def _union(masks):
    """The union of the masks (H, W); DataError when it is empty."""
    union = np.logical_or.reduce(masks)
    if not union.any():
        raise DataError("mask: no pixel is masked; at least 3 pixels not on one line are needed")
    return union


def _frame_times(frame_times, n_frames):
    """Checked frame times (n_frames,) s."""
    ft = float_array(frame_times, "frame_times")
    if ft.shape != (n_frames,):
        raise ConfigError(f"frame_times must have shape (n_frames,) = ({n_frames},) like frames, got {ft.shape}")
    return ft


@blas_threads(1)  # many small triangular solves and products: threaded BLAS only synchronises
def _evaluate(F, lookup, temporal, te, in_span, pts, masks, mask_of, chunk, interp_args, extra=None, need=None):
    """theta, d/du, d/dv, d/dt, edge distance and theta through ``extra`` (sparse, on the rows of ``F``)
    (n_times, M) for the in-span times, chunk by chunk.

    The chunks run on the stage's worker threads (:func:`~irdic.numerics.threads.parallel_map`),
    each thread with the interpolant of its current mask; a chunk's edge
    tiles, of all its times whatever their masks, are solved together
    (:class:`~irdic.image_rbf.batch.EdgeBatch`). Chunks write disjoint rows of the results.
    """
    ks = np.flatnonzero(in_span)
    Wv = temporal.weights(te[ks], 0) if ks.size else None
    Wd = temporal.weights(te[ks], 1) if ks.size else None
    row_of = np.full(te.size, -1, np.int64)
    row_of[ks] = np.arange(ks.size)
    g = 2 if extra is None else 3
    # theta, d/du, d/dv, d/dt, edge distance, and theta through extra when there is one
    out = [np.full((te.size, pts.shape[1]), np.nan) for _ in range(5 if extra is None else 6)]
    if interp_args["method"] == "rbf":
        # the shared factors (stencils, edge windows) built here, on one BLAS thread, before the workers start
        interior_stencil(interp_args["c"] * interp_args["R0"], interp_args["halo"])
        edge_windows(interp_args["c"] * interp_args["R0"], interp_args["tile"], interp_args["halo"])
    progress = Progress(ks.size, "evaluate_series", unit="times", logger=log)
    done = [0]
    lock = threading.Lock()
    local = threading.local()

    def interpolant(mi):
        if getattr(local, "mask", None) != mi:  # masks come in runs: a thread keeps only its current one
            local.interp = MaskedGridInterpolant(masks[mi], **interp_args)
            local.mask = mi
        return local.interp

    def work(ch):
        r = row_of[ch]
        G = _combined_frames(F, slice(None), Wv[r], Wd[r], F.shape[0], extra)  # (chunk, g, union pixels)
        edges = EdgeBatch()
        runs = []
        mi = mask_of[ch]
        cut = np.flatnonzero(np.diff(mi)) + 1
        for run in np.split(np.arange(ch.size), cut):
            interp = interpolant(int(mi[run[0]]))
            sel = lookup[interp.pixels[:, 1], interp.pixels[:, 0]]
            vals = G[run] if sel.size == F.shape[0] else G[run][:, :, sel]  # the mask is the union: no copy
            interp.fit_values(vals.reshape(g * run.size, -1))
            runs.append((ch[run], interp.evaluate_grouped(pts[ch[run]], g, (True,) + (False,) * (g - 1),
                                                          edges=edges, need=need)))
        del G
        edges.run()
        for times, (val, du, dv, ed) in runs:
            for o, res in zip(out, (val[:, 0], du[:, 0], dv[:, 0], val[:, 1], ed, val[:, g - 1])):
                o[times] = res
        with lock:
            done[0] += ch.size
            progress.update(done[0])
            report("interpolation", done[0] / ks.size)

    parallel_map(work, _pieces(ks, chunk, workers()))
    log.info("evaluate_series: %d times x %d points, %d masked px (union), %d mask(s)", te.size, pts.shape[1],
             F.shape[0], len(masks))
    return out
