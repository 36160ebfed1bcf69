"""The fields' smoothing settings: checked, and every "gcv" resolved once for the whole record.

A regression's smoothing is a centre spacing factor (>= 1), ``null`` (the
paper's interpolation), ``"auto"`` (resolved from the estimated noise by
:func:`irdic.noise.auto_smoothing`) or ``"gcv"``. GCV chooses on the record's
first :data:`GCV_STAGES` stages, so that every time chunk and the
whole-record run regress with the same smoothing.
"""

from __future__ import annotations

import logging

from ..errors import ConfigError, DataError
from ..footprint.fields import pixel_pitch
from ..numerics.series import gcv_columns
from ..numerics.temporal import RATE_MAX_FRACTION, gcv_temporal
from ..parameters import settings
from ..surface import fit_surface
from .spatial import regressed_gradient, space_gcv

__all__ = ["GCV_STAGES", "SMOOTHING", "checked_settings", "resolve_gcv", "surface_kw"]

log = logging.getLogger(__name__)


#: Smoothing chosen by GCV is chosen on the record's first stages (at most this many), by every time chunk
#: and by the whole-record run alike, so that all of them regress with the same smoothing.
GCV_STAGES = 256


SMOOTHING = ("surface_smoothing", "surface_smoothing_time", "temperature_smoothing", "temperature_smoothing_space")


def _smoothing(name, value):
    number = isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 1
    if not (value is None or value in ("gcv", "auto") or number):
        raise ConfigError(f"fields.{name} must be null (interpolation), 'gcv', 'auto' or a number >= 1, got {value!r}")


def checked_settings(points, params) -> dict:
    """The ``fields`` settings with defaults; ConfigError/DataError for bad smoothing values or a wrong store."""
    p = settings("fields", params)
    for name in SMOOTHING:
        _smoothing(name, p[name])
    missing = [v for v in ("x", "temperature", "temperature_pixel_gradient", "temperature_local_rate")
               if v not in points]
    if missing:
        raise DataError(f"points store lacks {missing}: is it the output of the couple stage?")
    return p


def surface_kw(p):
    return dict(c=p["c_space"], R0=p["R0_space"], c_t=p["c_time"], R0_t=p["R0_time"], solver=p["solver"])


def resolve_gcv(points, x, t, psi, p, ops=None):
    """``p`` with every "gcv" smoothing replaced by the number GCV picks on the record's first
    :data:`GCV_STAGES` stages: the same in every chunk and in the whole-record run."""
    gcv = [k for k in SMOOTHING if p[k] == "gcv"]
    if not gcv:
        return p
    w = slice(0, min(t.size, GCV_STAGES))
    p = dict(p)
    if "surface_smoothing" in gcv or "surface_smoothing_time" in gcv:
        info = fit_surface(x[w], t[w], psi, smoothing=p["surface_smoothing"], smoothing_t=p["surface_smoothing_time"],
                           operators=ops, choose_only=True, **surface_kw(p))
        p["surface_smoothing"] = info["smoothing"] if p["surface_smoothing"] is not None else None
        if p["surface_smoothing"] is not None and "smoothing_shape" in info:
            # GCV chose a spacing for the shape and one for the motion (irdic.surface.fit_surface): keep both
            p["surface_smoothing"] = (info["smoothing_shape"], info["smoothing"])
        p["surface_smoothing_time"] = info["smoothing_t"] if p["surface_smoothing_time"] is not None else None
    theta = points["temperature"].isel(time=w).values.astype(float)
    if p["temperature_smoothing_space"] == "gcv":
        k = space_gcv(theta, psi, c=p["c_space"], R0=p["R0_space"], ops=ops, separation=pixel_pitch(points, psi))
        if k is not None:  # no time with 6 visible points among them: each chunk chooses its own
            p["temperature_smoothing_space"] = k
    if p["temperature_smoothing"] == "gcv":
        if p["temperature_smoothing_space"] not in (None, "gcv"):
            # judged on the spatially regressed series, as the fields regress them (see irdic.fields.space_time.space_time)
            theta = regressed_gradient(theta, psi, None, p["temperature_smoothing_space"], c=p["c_space"],
                                        R0=p["R0_space"], ops=ops)[1]
        # what smooth_series(theta, smoothing="gcv") would choose, at the cost of the series GCV judges; once
        # for both choices below
        theta = gcv_columns(theta, t[w], c=p["c_time"], R0=p["R0_time"])
        p["temperature_smoothing"] = gcv_temporal(t[w], theta, c=p["c_time"], R0=p["R0_time"])[0]
        if p["temperature_smoothing_space"] is not None:  # the rate's own spacing (see irdic.fields.space_time)
            p["temperature_smoothing_rate"] = gcv_temporal(t[w], theta, c=p["c_time"], R0=p["R0_time"],
                                                           max_fraction=RATE_MAX_FRACTION)[0]
    log.info("fields: smoothing chosen once on DIC times %d..%d: %s", w.start, w.stop - 1,
             ", ".join(f"{k} {p[k]}" for k in gcv))
    return p
