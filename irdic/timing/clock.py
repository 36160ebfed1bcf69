"""The IR clock of the couple stage: the configured ``time_offset``, or the one the data give (``auto``).

``ir.zarr`` says in its attribute ``time_offset`` what ingest did: a number
(s, already added to its times) or ``"auto"`` (times kept on the IR clock).
With ``auto`` the offset is estimated from the data
(:func:`irdic.timing.estimate_offset`), logged, added to the IR times for
the coupling and written into ``points.zarr`` with its standard
uncertainty; the data must fix it, else the stage stops with the reason.
With a number the data are asked as well, where they fix the offset, and an
:class:`~irdic.errors.IrdicWarning` says when the two differ by more than
three standard uncertainties.
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
import xarray as xr

from ..camera import load_camera
from ..errors import DataError, IrdicWarning
from .offset import MAX_FRAMES, crop_box, estimate_offset
from ..footprint.visibility import project_points

__all__ = ["ir_clock", "estimate_from_stores", "CHECK_SIGMAS"]

log = logging.getLogger(__name__)

#: a configured offset further than this many standard uncertainties from the data's is warned about
CHECK_SIGMAS = 3.0


def estimate_from_stores(dic: xr.Dataset, ir: xr.Dataset, calibration: xr.Dataset, key: str, projection=None,
                         **options):
    """:func:`irdic.timing.estimate_offset` on the stores: points projected with the calibration, frames cropped.

    ``key`` is the configuration key named in errors; ``projection``: the
    points of every DIC time already projected into ``ir``'s frames
    (:func:`irdic.footprint.visibility.project_points`; the couple stage has
    them); ``options`` go to :func:`~irdic.timing.estimate_offset`
    (``centre``, ``max_frames``).
    """
    u, v = ir["u"].values, ir["v"].values
    pr = project_points(load_camera(calibration), dic, u, v) if projection is None else projection
    # points that leave the frame at some time are left out; missing ones are interpolated in time
    seen_always = (pr.in_frame | ~pr.valid).all(axis=0)
    local = np.where(seen_always[None, :, None] & pr.valid[..., None], pr.local, np.nan)
    rows, cols = crop_box(local, (v.size, u.size))
    # at most MAX_FRAMES frames, evenly spread, are read (the region the points cover only)
    n = ir.sizes["time"]
    keep = np.unique(np.linspace(0, n - 1, min(n, MAX_FRAMES)).round().astype(int))
    frames = np.asarray(ir["temperature"].isel(time=keep, v=rows, u=cols).values, dtype=np.float32)
    finite = np.isfinite(frames).all(axis=(1, 2))
    if not finite.all():
        log.info("IR clock: %d of %d frames with NaN pixels over the specimen are left out", (~finite).sum(),
                 finite.size)
    return estimate_offset(frames[finite], ir["time"].values.astype(float)[keep][finite],
                           dic["time"].values.astype(float), local - [cols.start, rows.start], parameter=key,
                           **options)


def ir_clock(dic: xr.Dataset, ir: xr.Dataset, calibration: xr.Dataset, experiment: str | None = None,
             projection=None):
    """``ir`` on the DIC clock and the ``points.zarr`` attributes that say how.

    Parameters
    ----------
    dic, ir, calibration : xarray.Dataset
        The couple stage's inputs (the whole record).
    experiment : str, optional
        The experiment's name, for the configuration key in messages.
    projection : irdic.footprint.visibility.Projection, optional
        The DIC points of every time projected into ``ir``'s frames, where
        the caller has them (projected here without).

    Returns
    -------
    ir : xarray.Dataset
        With ``time`` on the DIC clock (the estimate added where the offset is ``auto``).
    attrs : dict
        ``ir_time_offset`` (s), ``ir_time_offset_std`` (s; 0 for a configured
        number), ``ir_time_offset_source`` ("estimated" or "configured");
        with a configured number the data's view where they fix it,
        ``ir_time_offset_estimate`` and ``ir_time_offset_estimate_std`` (s).

    Raises
    ------
    DataError
        ``auto`` and the data do not fix the offset (the message names
        ``experiments.<name>.ir.time_offset`` and says why).
    """
    key = f"experiments.{experiment or '<name>'}.ir.time_offset"
    mode = ir.attrs.get("time_offset")
    if mode == "auto":
        est = estimate_from_stores(dic, ir, calibration, key, projection)
        log.info("couple: IR clock offset estimated from the data: %.6g s +- %.2g s (%.3f +- %.3f IR frames), "
                 "added to the IR times", est.offset, est.std, est.offset / est.frame_period,
                 est.std / est.frame_period)
        ir = ir.assign_coords(time=ir["time"].values.astype(float) + est.offset)
        return ir, {"ir_time_offset": est.offset, "ir_time_offset_std": est.std,
                    "ir_time_offset_source": "estimated"}
    configured = float(mode) if mode is not None else None
    attrs = {"ir_time_offset": configured, "ir_time_offset_std": 0.0, "ir_time_offset_source": "configured"} \
        if configured is not None else {}
    try:
        est = estimate_from_stores(dic, ir, calibration, key, projection)
    except DataError as exc:
        log.info("couple: the data do not check the IR clock offset (%s)", exc)
        return ir, attrs
    # the stored times carry the configured offset: the estimate is the correction to it
    total = (configured or 0.0) + est.offset
    attrs.update(ir_time_offset_estimate=total, ir_time_offset_estimate_std=est.std)
    if abs(est.offset) > CHECK_SIGMAS * est.std:
        warnings.warn(
            f"{key}: the data put the IR clock {est.offset:+.4g} s ({est.offset / est.frame_period:+.2f} IR frames) "
            f"from the configured offset{'' if configured is None else f' {configured:g} s'}: {total:.6g} s +- "
            f"{est.std:.2g} s. Check the offset (docs/time-sync.md), or set it to auto", IrdicWarning, stacklevel=3)
    else:
        log.info("couple: the data agree with the IR clock offset: correction %.3g s +- %.2g s", est.offset, est.std)
    return ir, attrs
