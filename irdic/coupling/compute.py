"""DIC points + IR frames + calibration -> temperatures at material points.

For every DIC time the valid DIC points are projected into the IR image with
the calibrated camera; points behind the camera, outside the IR frame or on
surface facing away from it are flagged not visible. Only pixels on the
specimen feed the interpolant: a mask per time from the projected point cloud
(:mod:`irdic.footprint.visibility`, eroded by ``mask_erosion_px``), also
intersected with the masks of the neighbouring DIC times so that pixels the
moving edge crosses are left out. The pixel temperatures are interpolated in
space and time (:func:`irdic.image_rbf.evaluate_series`, IMQ with the paper's
shape factors by default) and evaluated at the projected points: temperature,
pixel gradient and local rate ∂Θ/∂t at the fixed pixel.

Points that project just outside the mask (the outermost DIC points lie on
the specimen edge, so they always do) are extrapolated linearly from the
nearest masked pixel, up to ``max_extrapolation_px``; their signed distance to
the mask edge is stored (negative = extrapolated), so users see which values
are not interpolated (:mod:`irdic.footprint.extrapolation`).

``status`` codes (:class:`irdic.vocabulary.Status`; CF ``flag_values``/``flag_meanings`` in its attributes):

== ==================================================================
0  interpolated inside the specimen mask
1  extrapolated from the mask edge (≤ max_extrapolation_px)
2  DIC point missing at this time
3  behind the IR camera or outside the IR frame
4  surface facing away from the IR camera
5  outside the specimen mask, farther than max_extrapolation_px
6  DIC time outside the IR time span
== ==================================================================
"""

from __future__ import annotations

import logging
import time as _time
import warnings

import numpy as np
import xarray as xr

from ..camera import load_camera
from ..chunks import chunk_slice, window
from ..errors import ConfigError, DataError
from ..footprint.extrapolation import extrapolate, extrapolation_samples, in_mask
from ..footprint.temperature import FootprintOperator, footprint_side
from ..footprint.visibility import Projection, masks_and_facing, project_points
from ..image_rbf import evaluate_series
from ..noise import interpolation_noise_gains, ir_noise as estimate_ir_noise
from ..numerics.temporal import kernel_R0, temporal_window
from ..numerics.threads import map_beside, parallel_map
from ..parameters import settings
from ..timing.clock import ir_clock
from ..timing.offset import MIN_MOTION_PX
from ..logs import StageProgress, report, reweigh
from ..threads import thread_budget
from ..vocabulary import Status, cf_attrs
from .dataset import count_attrs, points_dataset

__all__ = ["couple"]

log = logging.getLogger(__name__)


def _check_params(method, mask_erosion_px, max_extrapolation_px, max_view_angle_deg):
    if method not in ("rbf", "bilinear", "cubic"):
        raise ConfigError(f"interpolation.method must be rbf, bilinear or cubic, got {method!r}")
    if not mask_erosion_px >= 0:
        raise ConfigError(f"interpolation.mask_erosion_px must be >= 0 px, got {mask_erosion_px}")
    if not max_extrapolation_px >= 0:
        raise ConfigError(f"interpolation.max_extrapolation_px must be >= 0 px, got {max_extrapolation_px}")
    if not 0 < max_view_angle_deg <= 90:
        raise ConfigError(f"interpolation.max_view_angle_deg must lie in (0, 90], got {max_view_angle_deg}")


def couple(dic: xr.Dataset, ir: xr.Dataset, calibration: xr.Dataset, *, chunk: tuple[int, int] | None = None,
           experiment: str | None = None, **params) -> xr.Dataset:
    """Temperatures, pixel gradients and local rates at the DIC points.

    Parameters
    ----------
    dic : xarray.Dataset
        ``dic.zarr``: ``x(time, point, component)`` mm.
    ir : xarray.Dataset
        ``ir.zarr``: ``temperature(time, v, u)`` °C with full-sensor ``u``, ``v``.
    calibration : xarray.Dataset
        ``calibration.zarr`` of the setup the experiment was recorded with.
    experiment : str, optional
        The experiment's name, for ``experiments.<name>.ir.time_offset`` in
        messages about the IR clock (:mod:`irdic.timing.clock`: with
        ``ir.zarr``'s ``time_offset`` ``auto`` the offset is estimated from the
        whole record, so every time chunk gets the same).
    chunk : (index, count), optional
        Only the DIC times of this time chunk (:mod:`irdic.chunks`), from
        the IR frames within the temporal kernel's reach of them; the result
        equals the same times of the whole-record result to ~1e-4 K except
        within that reach of the record's ends (see
        :func:`irdic.numerics.temporal.temporal_reach`).
    **params
        The ``interpolation`` section of the configuration; absent keys take
        the schema's defaults:

        - ``method`` {"rbf", "bilinear", "cubic"}: spatial interpolant (the
          paper's IMQ RBF by default);
        - ``c_space``, ``R0_space`` (px): IMQ shape factor and distance
          normalisation in the image;
        - ``c_time``, ``R0_time`` (s): the same in time;
        - ``mask_erosion_px``: erosion of the specimen mask (px);
        - ``max_edge_factor``: triangles longer than this multiple of the
          point spacing are not specimen;
        - ``max_view_angle_deg``: points whose surface normal makes a larger
          angle with the line of sight to the IR camera are not visible;
        - ``max_extrapolation_px``: how far outside the mask (px) points are
          still extrapolated;
        - ``halo`` (px): half-width of the local windows that reproduce the
          global interpolant.

    Returns
    -------
    xarray.Dataset
        The content of ``points.zarr`` (see the module docstring and README).
    """
    p = settings("interpolation", params)
    _check_params(p["method"], p["mask_erosion_px"], p["max_extrapolation_px"], p["max_view_angle_deg"])
    only = None if chunk is None else _chunk_times(dic, chunk)
    n_t = dic.sizes["time"] if only is None else only.stop - only.start
    with StageProgress("couple", stage_costs(n_t, dic.sizes["point"], ir.sizes["time"], n_record=dic.sizes["time"]),
                       threads=thread_budget(),
                       shares=STAGE_SHARES, logger=log, beside=("clock",)):
        def the_clock(pr):
            report("clock", 0.0)
            out = ir_clock(dic, ir, calibration, experiment, projection=pr)
            report("clock", 1.0)
            return out

        # the masks and the IR clock (one thread) on one pool: neither depends on the other
        footprint, (ir, clock) = _footprint(dic, ir, calibration, p, only, beside=the_clock)
        # the interpolation prepares (frames read, stencils and edge windows factorised) before its first time:
        # running from here, its silence moves the ETA on
        report("interpolation", 0.0)
        ds = _couple_chunk(dic, ir, calibration, chunk, p, footprint) if chunk is not None else \
            _couple(dic, ir, calibration, p, footprint=footprint)
        report("rest", 1.0)
    ds.attrs.update(clock)
    return ds


#: The cost model of the stage's progress lines (:class:`irdic.logs.StageProgress`), in seconds of one core:
#: per DIC time and point (the projections, the rest); per mask built and point (the masks: the points' normals
#: and facing flags dominate; a mask is reused while the outline moves less than
#: :data:`~irdic.footprint.visibility.MASK_REUSE_PX`) plus :data:`MASK_PLAN_COST`; per DIC time of the whole
#: record and point it keeps (:data:`CLOCK_POINTS_PER_PIXEL`) plus per IR frame (at most
#: :data:`irdic.timing.offset.MAX_FRAMES`) and specimen pixel (the IR clock, which reads the whole record in every
#: time chunk); per DIC time and point plus per DIC time and
#: pixel of the specimen's outline plus per mask built and pixel of the outline (the interpolation: its edge
#: windows, factorised again for each new mask; :data:`PIXEL_COSTS`, :data:`MASK_OUTLINE_COST`). The masks and
#: the clock fitted on three tubes (benchmarks/README.md), the clock x 0.48 since it runs beside the masks (the
#: pool's phase on the sweep tube grew by 5.6 s with it, :data:`STAGE_SHARES`), then x 0.75 for its faster
#: sampling (the clock alone 0.58-0.88 x on four stores); the set-up and the
#: interpolation on the benchmarks' tube at 6,552, 13,104 and 26,180 points (14,300 px, outline 490 px, 56 masks
#: built), the sweep tube (60,000 px, outline 1,000 px, 300 masks) and the static half-shell of 9,875 points
#: (53,000 px, outline 930 px, one mask): their ratios are what the ETA rests on. After the masks' normals and the
#: clock's blocked sampling the masks (x 0.65), the clock (x 0.6) and the interpolation's outline term (x 1.25)
#: were refitted on the progress reports of five of those stores replayed (the three tubes, the sweep tube's still
#: and 2 px/frame rows; benchmarks/README.md). ``write`` is the stage's
#: store, written after :func:`couple` returns (never reported: the ETA includes it)
STAGE_COSTS = {"setup": 3.5e-7, "masks": 5.7e-6, "clock": 4.4e-7, "interpolation": 8.1e-6, "rest": 3e-8,
               "write": 3e-7}
#: seconds of one core per IR frame and specimen pixel (the IR clock: its frames smoothed and sampled on nodes
#: 1-2 px apart) and per DIC time and pixel of the specimen's outline (the interpolation's edge windows, whose
#: cost follows the outline, not the area)
PIXEL_COSTS = {"clock": 1.9e-7, "interpolation": 4.1e-5}
#: seconds of one core per mask built and pixel of its outline in the interpolation (the edge windows of a new
#: mask factorised; a reused mask reuses them)
MASK_OUTLINE_COST = 6.2e-5
#: seconds of one core per DIC time of the whole record and point of the masks' plan (the positions filled in
#: time, the masks each time reuses), before the first mask
MASK_PLAN_COST = 3.2e-7
#: the part of the IR clock's cost spent on a specimen whose points stay within
#: :data:`irdic.timing.offset.MIN_MOTION_PX` of their first position in the image: its frames are read and
#: the positions prepared, then the motion check refuses it before the search (the sweep tube's still row:
#: 2.2 of the ~10 s of its moving rows)
STILL_CLOCK_SHARE = 0.2
#: specimen pixels per DIC point assumed until the points are projected (the benchmarks' tubes: 1 to 4)
PIXELS_PER_POINT = 2
#: DIC points per specimen pixel the IR clock keeps at most (those at least
#: :data:`irdic.timing.nodes.POINT_SPACING_PX` apart: 5,031 of 26,180 points on 14,300 px)
CLOCK_POINTS_PER_PIXEL = 0.36
#: the part of each that runs on the stage's threads (from wall and CPU seconds on 2 threads; the IR clock, one
#: thread, on the masks' pool beside them: it takes a share of the pool's threads)
STAGE_SHARES = {"setup": 0.0, "masks": 0.95, "clock": 1.0, "interpolation": 0.9, "rest": 0.3, "write": 0.0}


def stage_costs(n_t: int, n_points: int, n_frames: int, n_pixels: float | None = None, *,
                outline: float | None = None, n_masks: int | None = None, n_record: int | None = None,
                still: bool = False) -> dict:
    """Expected seconds of one core of the stage's parts (:data:`STAGE_COSTS`, :data:`PIXEL_COSTS`).

    ``n_t`` DIC times (of the chunk), ``n_points`` points, ``n_frames`` IR
    frames, ``n_pixels`` specimen pixels (default :data:`PIXELS_PER_POINT`
    per point) and ``outline`` pixels of its outline (default that of a
    square of ``n_pixels``); ``n_masks`` masks built (default one per DIC
    time: known once their reuse is planned) and ``n_record`` DIC times of the
    whole record (the IR clock's and the masks' plan; default ``n_t``);
    ``still``: the points stay where the IR clock refuses them
    (:data:`STILL_CLOCK_SHARE`).
    """
    from ..timing.offset import MAX_FRAMES

    px = PIXELS_PER_POINT * float(n_points) if n_pixels is None else float(n_pixels)
    edge = 4.0 * np.sqrt(px) if outline is None else float(outline)
    times = float(n_t if n_record is None else n_record)
    record = times * n_points
    masks = float(n_t if n_masks is None else n_masks)
    # the clock thins points denser than its spacing (irdic.timing.nodes.POINT_SPACING_PX)
    clock = times * min(float(n_points), CLOCK_POINTS_PER_PIXEL * px)
    size = {"masks": masks * n_points, "clock": clock}
    per_pixel = {"clock": float(min(n_frames, MAX_FRAMES)) * px, "interpolation": float(n_t) * edge}
    out = {k: c * size.get(k, float(n_t) * n_points) + PIXEL_COSTS.get(k, 0.0) * per_pixel.get(k, 0.0)
           for k, c in STAGE_COSTS.items()}
    out["masks"] += MASK_PLAN_COST * record
    out["interpolation"] += MASK_OUTLINE_COST * masks * edge
    if still:
        out["clock"] *= STILL_CLOCK_SHARE
    return out


def _motion_px(local) -> float:
    """The largest distance (px) of a point from its first position in the image over the record (``local``
    (T, M, 2); 0 where no point is seen twice)."""
    d = np.full(local.shape[1], 0.0)
    for q in local[1:]:
        np.fmax(d, np.linalg.norm(q - local[0], axis=1), out=d)
    return float(d.max()) if d.size else 0.0


def specimen_extent(local, seen) -> tuple[float, float]:
    """Pixels the specimen covers in the IR image and those of its outline: the area (px²) and perimeter (px)
    of the convex hull of the points seen at their first time with at least 3 (``local`` (T, M, 2) px, ``seen``
    (T, M)); zeros with none."""
    from scipy.spatial import ConvexHull, QhullError

    for q, ok in zip(local, seen):
        pts = q[ok & np.isfinite(q).all(axis=1)]
        if pts.shape[0] >= 3:
            try:
                hull = ConvexHull(pts)
            except QhullError:  # on a line: no area
                return 0.0, 0.0
            return float(hull.volume), float(hull.area)  # in 2-D the hull's "area" is its perimeter
    return 0.0, 0.0


def _chunk_times(dic, chunk) -> slice:
    """The DIC times a time chunk's couple reads: its own with one neighbour each side (a time's mask is
    intersected with its neighbours')."""
    n = dic.sizes["time"]
    sl = chunk_slice(n, *chunk)
    return slice(max(sl.start - 1, 0), min(sl.stop + 1, n))


def _couple_chunk(dic, ir, calibration, chunk, p, footprint=None) -> xr.Dataset:
    """:func:`couple` of one time chunk: its DIC times with one neighbour each side (the masks) and its IR window."""
    t_dic = dic["time"].values.astype(float)
    t_ir = ir["time"].values.astype(float)
    sl = chunk_slice(t_dic.size, *chunk)
    only = _chunk_times(dic, chunk)
    a, b = only.start, only.stop
    reach = temporal_window(t_ir, c=p["c_time"], R0=p["R0_time"])
    frames = window(t_ir, t_dic[sl.start], t_dic[sl.stop - 1], reach)
    if reach is None and chunk[1] > 1:
        log.warning("couple: the temporal kernel (c_time %g, R0_time %g s) reaches over all %d IR frames "
                    "(spacing %.3g s; its window holds at most about 100 frames): every chunk reads the whole IR record, so "
                    "chunking does not bound memory; set execution.chunk_frames: 0",
                    p["c_time"], p["R0_time"], t_ir.size, float(np.median(np.diff(t_ir))))
    log.info("couple: chunk %d of %d, DIC times %d..%d, IR frames %d..%d (kernel reach %s frames)", chunk[0] + 1,
             chunk[1], sl.start, sl.stop - 1, frames.start, frames.stop - 1, "all" if reach is None else reach)
    # the whole record must have a DIC time in the IR span; a chunk outside it is all status 6
    whole = bool(((t_dic >= t_ir[0]) & (t_dic <= t_ir[-1])).any())
    # DIC positions of the whole record (small next to the IR frames): gaps are filled from the nearest valid
    # time and the choice of reused masks runs from the first time
    ds = _couple(dic, ir.isel(time=frames), calibration, p, require_span=not whole, only=only,
                 record_times=t_ir, footprint=footprint)
    ds = ds.isel(time=slice(sl.start - a, sl.stop - a))
    ds.attrs.update(ir_time_span_s=[float(t_ir[0]), float(t_ir[-1])], ir_frames=int(t_ir.size),
                    chunk=[int(chunk[0]), int(chunk[1])])
    return ds


def _footprint(dic, ir, calibration, p, only=None, beside=None):
    """``((pr, side, masks, facing), result)``: the DIC points projected into the IR frames (of every time), the
    footprint's box side, and the specimen masks and facing flags of the times ``only`` (all: None); ``result``
    that of ``beside(pr)``, a job of one thread run on the masks' pool beside them (the IR clock:
    :func:`~irdic.numerics.threads.map_beside`), or None."""
    camera = load_camera(calibration)
    u, v = ir["u"].values, ir["v"].values
    _check_sensor(calibration, u, v)
    pr = project_points(camera, dic, u, v)
    _check_extent(pr)
    side = footprint_side(pr)  # from the record's first stage: the same in every chunk
    # the clock and the interpolation cost per specimen pixel too, and the masks per mask built: known now that
    # the points are projected, and once the masks' reuse is planned
    n_t = pr.x.shape[0] if only is None else only.stop - only.start
    pixels, outline = specimen_extent(pr.local, pr.in_frame)
    still = _motion_px(pr.local) < MIN_MOTION_PX

    def planned(n_masks):
        reweigh(stage_costs(n_t, pr.x.shape[1], ir.sizes["time"], pixels, outline=outline, n_masks=n_masks,
                            n_record=pr.x.shape[0], still=still))

    planned(None)
    report("setup", 1.0)
    report("masks", 0.0)  # running from here: the masks' sources and first triangulations come before a report
    result = []

    def pool_map(fn, items):
        if beside is None:
            return parallel_map(fn, items)
        done, built = map_beside(lambda: beside(pr), fn, items)  # BLAS on one thread per worker while it runs
        result.append(done)
        return built

    masks, facing = masks_and_facing(
        pr.x, np.where(pr.in_frame[..., None], pr.local, np.nan), camera.decompose().C,
        np.arange(u.size), np.arange(v.size), erosion=p["mask_erosion_px"], edge_factor=p["max_edge_factor"],
        max_angle=p["max_view_angle_deg"], only=only, planned=planned, pool_map=pool_map)
    if beside is not None and not result:  # no mask built
        result.append(beside(pr))
    return (pr, side, masks, facing), result[0] if result else None


def _couple(dic, ir, calibration, p, require_span=True, only=None, record_times=None, footprint=None) -> xr.Dataset:
    """The couple stage on ``ir``'s frames; ``only`` (a slice of DIC times) and ``record_times`` (the whole
    record's IR frame times, for the noise gains) when ``ir`` is a chunk's window; ``footprint``: what
    :func:`_footprint` gave for ``only`` (computed here without it)."""
    started = _time.perf_counter()
    camera = load_camera(calibration)
    t_ir = ir["time"].values.astype(float)
    pr, side, masks, facing = _footprint(dic, ir, calibration, p, only)[0] if footprint is None else footprint
    n_t, M, _ = pr.x.shape
    if only is not None:
        pr, dic = pr.times(only), dic.isel(time=only)
        n_t = pr.x.shape[0]
    seen = pr.in_frame & facing
    # the temporal operator's window comes from the whole record: every chunk evaluates alike
    p = dict(p, time_window=temporal_window(t_ir if record_times is None else record_times, c=p["c_time"],
                                            R0=p["R0_time"]))
    t_dic = dic["time"].values.astype(float)
    theta, gu, gv, rate, edge, in_span, extrap, footprint = _interpolate(ir, t_dic, pr, masks, seen, p, require_span,
                                                                          side)
    theta_fp, fp_factor = footprint if footprint is not None else (None, None)
    in_span = in_span & ~in_ir_gap(t_dic, t_ir, t_ir if record_times is None else record_times, p)
    status = _status(pr, facing, seen, in_span, extrap, theta)
    visible = status <= Status.EXTRAPOLATED_FROM_EDGE
    if theta_fp is not None:  # where no footprint sample was on the mask: the paper's value
        theta_fp = np.where(np.isfinite(theta_fp), theta_fp, theta)
    for a in (theta, gu, gv, rate, edge) + (() if theta_fp is None else (theta_fp, fp_factor)):
        a[~visible] = np.nan
    # noise of the IR data at the specimen pixels: the fields stage's auto rule and uncertainties use it;
    # a chunk estimates it on its own IR window and masks (run_gather combines the chunks' estimates)
    noise = estimate_ir_noise(ir["temperature"], t_ir, np.logical_and.reduce(masks, axis=0))
    log.info("couple: IR noise %.3g K temporal, %.3g K spatial, quantisation %.3g K (%d specimen pixels)",
             noise.temporal, noise.spatial, noise.quantisation, noise.pixels)
    # the gains are a property of the operator and the record's frame spacing: the same in every chunk
    gains = interpolation_noise_gains(t_ir if record_times is None else record_times, method=p["method"], c=p["c_space"], R0=p["R0_space"], c_time=p["c_time"],
                                      R0_time=p["R0_time"], halo=p["halo"])
    report("rest", 0.5)
    counts = {k[len("count_"):]: n for k, n in count_attrs(status).items()}
    log.info("couple: %d DIC times x %d points in %.1f s; %s", n_t, M, _time.perf_counter() - started,
             ", ".join(f"{k} {v}" for k, v in counts.items() if v))
    fields = dict(theta=theta, gu=gu, gv=gv, rate=rate, edge=edge, status=status, visible=visible, masks=masks)
    ds = points_dataset(dic, calibration, camera, pr, t_ir, counts, noise, gains, **fields)
    ds.attrs["footprint_px"] = int(side)
    if theta_fp is not None:
        # its gain (probe), like the plain one a property of the operator: the same in every chunk
        gain_fp = interpolation_noise_gains(t_ir if record_times is None else record_times, method=p["method"],
                                            c=p["c_space"], R0=p["R0_space"], c_time=p["c_time"], R0_time=p["R0_time"],
                                            halo=p["halo"], footprint=side).temperature
        for name, a in (("temperature_footprint", theta_fp), ("temperature_footprint_noise_factor", fp_factor)):
            ds[name] = (("time", "point"), a.astype(np.float32), cf_attrs("points", name))
        ds.attrs["ir_noise_gain_temperature_footprint"] = float(gain_fp)
    return ds


#: A DIC time is covered by the IR record when an IR frame lies within the larger of the temporal kernel's
#: width (c_time R0_time, s, as the interpolant narrows it on a fast camera) and this many median IR frame
#: steps: never on a regular record (a DIC time lies at most half a step from a frame), always across a
#: stretch where the IR camera stopped recording
GAP_STEPS = 1.5


def in_ir_gap(t_dic: np.ndarray, t_ir: np.ndarray, record_times: np.ndarray, p: dict) -> np.ndarray:
    """Which DIC times (n_t,) lie inside the IR time span but too far from every IR frame to interpolate.

    The interpolant bridges such a gap with a smooth curve that no IR frame
    supports; these times get ``TIME_OUTSIDE_IR_SPAN`` instead of a
    temperature, and the run warns with their count.

    Parameters
    ----------
    t_dic : ndarray, shape (n_t,)
        DIC times, s.
    t_ir : ndarray, shape (n_f,)
        IR frame times at hand (the whole record or a time chunk's window), s, increasing.
    record_times : ndarray
        The whole record's IR frame times (its median step), s.
    p : dict
        ``interpolation`` settings (``c_time``, ``R0_time``).

    Notes
    -----
    A time is in a gap when its nearest frame is farther than the temporal
    kernel's width ``c_time R0`` (with ``R0`` as the interpolant narrows it
    on a fast camera, :func:`~irdic.numerics.temporal.kernel_R0`) and
    :data:`GAP_STEPS` median frame steps.
    """
    if t_ir.size < 2:
        return np.zeros(t_dic.shape, dtype=bool)
    # the kernel the interpolant uses: on a fast camera narrower than configured (kernel_R0)
    c = float(p["c_time"])
    kernel = c * kernel_R0(record_times, c, float(p["R0_time"]))
    reach = max(kernel, GAP_STEPS * float(np.median(np.diff(record_times))))
    k = np.clip(np.searchsorted(t_ir, t_dic), 1, t_ir.size - 1)
    nearest = np.minimum(np.abs(t_dic - t_ir[k - 1]), np.abs(t_ir[k] - t_dic))
    gap = (t_dic > t_ir[0]) & (t_dic < t_ir[-1]) & (nearest > reach)
    if gap.any():
        first = int(np.flatnonzero(gap)[0])
        log.warning("couple: %d DIC time(s) lie in a gap of the IR record, farther than %.3g s from every IR frame "
                    "(first t = %.4g s, %.3g s from the nearest frame); they get no temperature (status "
                    "time_outside_ir_span)", int(gap.sum()), reach, t_dic[first], nearest[first])
    return gap


#: Fewest IR pixels that the DIC cloud of one time may span (u and v): a cloud in m instead of mm
#: projects onto one pixel, a specimen seen at all spans tens
MIN_EXTENT_PX = 3.0


def _check_extent(pr: Projection) -> None:
    """DataError when the DIC points of every time project onto a few pixels (coordinates not in mm)."""
    # pixel positions are NaN where a point is invalid or behind the camera; fmax / fmin skip NaN without copies
    if not pr.front.any():
        return  # nothing in front of the camera: the frame coverage check says so
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        span = np.fmax.reduce(pr.pix, axis=1) - np.fmin.reduce(pr.pix, axis=1)  # (n_t, 2)
        size = np.nanmax(np.fmax.reduce(pr.x, axis=1) - np.fmin.reduce(pr.x, axis=1), axis=-1)  # (n_t,)
    widest = float(np.nanmax(span.min(axis=-1)))
    if widest < MIN_EXTENT_PX and int(pr.valid.sum(axis=1).max()) >= 3:
        raise DataError(f"the DIC points span at most {widest:.3g} px of the IR image (their cloud is "
                        f"{np.nanmax(size):.4g} across in the DIC unit); are the DIC coordinates in m instead of "
                        "mm? The calibration markers, and so the projection, are in mm")


def _check_sensor(calibration: xr.Dataset, u: np.ndarray, v: np.ndarray) -> None:
    """DataError when the IR frames reach beyond the sensor the calibration image came from."""
    sw, sh = calibration.attrs.get("sensor_width"), calibration.attrs.get("sensor_height")
    if sw is not None and sh is not None and (u.max() >= int(sw) or v.max() >= int(sh) or u.min() < 0 or v.min() < 0):
        raise DataError(
            f"the IR frames cover pixels u {u.min()}..{u.max()}, v {v.min()}..{v.max()}, but the calibration "
            f"image was {sw} x {sh} px: the IR exports do not come from the calibrated camera set-up"
        )


def _interpolate(ir: xr.Dataset, t_dic: np.ndarray, pr: Projection, masks: np.ndarray, seen: np.ndarray, p: dict,
                 require_span: bool = True, side: int = 1):
    """Temperature, pixel gradient (u, v), local rate and edge distance at the seen points, each (n_t, M).

    Points that project just outside the mask are extrapolated from samples
    of the interpolant inside it. The samples are evaluated in the same pass
    as the points: a second pass would factorise every edge tile of every
    mask again. Also returns which DIC times lie in the IR time span (n_t,)
    and which values were extrapolated (n_t, M); last the footprint temperature of boxes of ``side`` px
    (:mod:`irdic.footprint.temperature`, same pass) and its noise factor (n_t, M) each, None for
    side 1.
    """
    u, v = ir["u"].values, ir["v"].values
    t_ir = ir["time"].values.astype(float)
    M = pr.x.shape[1]
    query = np.where(seen[..., None], pr.local, np.nan)
    outside = seen & ~in_mask(masks, pr.local)
    samples, cols = extrapolation_samples(pr.local, masks, outside, p["max_extrapolation_px"])
    # the extrapolation uses the derivatives of its first sample only (at the nearest masked pixel)
    need = np.zeros(M + samples.shape[0] * samples.shape[2], dtype=bool)
    need[:M + samples.shape[2]] = True
    res = evaluate_series(ir["temperature"], t_ir, t_dic, np.concatenate([query] + list(samples), axis=1), masks,
                          method=p["method"], c=p["c_space"], R0=p["R0_space"], c_time=p["c_time"],
                          R0_time=p["R0_time"], time_window=p["time_window"], halo=p["halo"], u=u, v=v,
                          name="ir: frames", pixel_operator=(op := FootprintOperator(side)) if side > 1 else None,
                          derivatives=need)
    theta, gu, gv, rate, edge = (np.array(a[:, :M], dtype=float) for a in
                                 (res.theta, res.dtheta_du, res.dtheta_dv, res.dtheta_dt, res.edge_distance))
    in_span = np.asarray(res.in_span)
    if require_span and not in_span.any():
        raise DataError(
            f"no DIC time ({t_dic[0]:g}..{t_dic[-1]:g} s) lies inside the IR time span "
            f"({t_ir[0]:g}..{t_ir[-1]:g} s): check time_offset/time_origin of the experiment"
        )
    extrap = extrapolate(res, M, cols, samples, pr.local, theta, gu, gv, rate, edge)
    theta_fp = None
    if res.theta_extra is not None:
        # outside the mask: the same parabola through the footprint's samples (the derivatives are scratch)
        theta_fp = np.array(res.theta_extra[:, :M], dtype=float)
        scratch = [np.array(a[:, :M], dtype=float) for a in (res.dtheta_du, res.dtheta_dv, res.dtheta_dt,
                                                             res.edge_distance)]
        extrapolate(res._replace(theta=res.theta_extra), M, cols, samples, pr.local, theta_fp, *scratch)
        theta_fp = (theta_fp, op.noise_factor(pr.local, res, M, cols, samples))
    return theta, gu, gv, rate, edge, in_span, extrap, theta_fp


def _status(pr: Projection, facing, seen, in_span, extrap, theta) -> np.ndarray:
    """``points.status`` (n_t, M) int8; a later rule overrides an earlier one."""
    S = Status
    status = np.full(pr.valid.shape, S.INTERPOLATED, dtype=np.int8)
    status[extrap] = S.EXTRAPOLATED_FROM_EDGE
    status[seen & in_span[:, None] & ~np.isfinite(theta)] = S.OUTSIDE_SPECIMEN_MASK
    status[~facing & pr.in_frame] = S.FACING_AWAY
    status[pr.valid & ~pr.in_frame] = S.OUTSIDE_IR_FRAME
    status[~pr.valid] = S.DIC_POINT_MISSING
    status[~in_span[:, None] & (status <= S.EXTRAPOLATED_FROM_EDGE)] = S.TIME_OUTSIDE_IR_SPAN
    return status
