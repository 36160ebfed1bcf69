"""The fields' smoothing settings: checked, and every "gcv" resolved once for the whole record.

A regression's smoothing is a centre spacing factor (>= 1), ``null`` (the
paper's interpolation), ``"auto"`` (resolved from the estimated noise by
:func:`irdic.noise.auto_smoothing`) or ``"gcv"``. GCV chooses on the record's
first :data:`GCV_STAGES` stages, so that every time chunk and the
whole-record run regress with the same smoothing.
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import ConfigError, DataError
from ..footprint.fields import pixel_pitch
from ..numerics.series import gcv_columns
from ..numerics.temporal_choice import gcv_temporal, rate_risk_temporal
from ..numerics.temporal_risk import CP_LIMIT, bias_ratio
from ..parameters import settings
from ..surface import fit_surface
from .spatial import judged_points, regressed_gradient, space_gcv

__all__ = ["GCV_STAGES", "SMOOTHING", "checked_settings", "resolve_gcv", "surface_kw", "guarded_time_smoothing",
           "parameter_dual", "rate_smoothing", "regression_noise_var",
           "value_time_smoothing"]

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
    # the candidates' designs kept from the first choice for the second (the same points)
    space = dict(c=p["c_space"], R0=p["R0_space"], ops=ops, separation=pixel_pitch(points, psi), designs={})
    if p["temperature_smoothing_space"] == "gcv":
        k = space_gcv(theta, psi, **space)
        if k is not None:  # no time with 6 visible points among them: each chunk chooses its own
            p["temperature_smoothing_space"] = k
    chosen, kt = {}, p["temperature_smoothing"]
    if kt == "gcv":
        chosen = _time_smoothing(points.isel(time=w), theta, t[w], psi, p, ops)
        kt = chosen["temperature_smoothing"]
    again = "temperature_smoothing_space" in gcv and p["temperature_smoothing_space"] != "gcv"
    if again and kt is not None and float(kt) > 1.0:  # 1: a centre at every stage, no regression in time
        # judged again after the regression in time that the fields' gradient has (spatial._after_time)
        k = space_gcv(theta, psi, after=(t[w], float(kt), p["c_time"], p["R0_time"], p["temperature_smoothing_space"]),
                      **space)
        if k != p["temperature_smoothing_space"]:
            p["temperature_smoothing_space"] = k
            chosen = _time_smoothing(points.isel(time=w), theta, t[w], psi, p, ops) if chosen else chosen
    p.update(chosen)
    log.info("fields: smoothing chosen once on DIC times %d..%d: %s", w.start, w.stop - 1,
             ", ".join(f"{k} {p[k]}" for k in gcv))
    return p


def _time_smoothing(points, theta, t, psi, p, ops):
    """The smoothings in time chosen on ``theta`` (T, N) at ``t`` after the spatial regression
    ``p["temperature_smoothing_space"]``: ``temperature_smoothing`` (GCV, guarded), and with a spatial regression
    ``temperature_smoothing_value`` and ``temperature_smoothing_rate`` (dict)."""
    grad = value = None
    out = {}
    ks = p["temperature_smoothing_space"]
    if ks not in (None, "gcv"):
        # judged on the spatially regressed series, as the fields regress them (the field also where a point has
        # no temperature: irdic.fields.space_time.space_time); the gradient in the surface parameters (no
        # surface yet) for the guard below
        dual = parameter_dual(psi.shape[0])
        grad, value = regressed_gradient(theta, psi, dual, ks, c=p["c_space"], R0=p["R0_space"], ops=ops,
                                         everywhere=True)[:2]
        theta = value
        noise_var, value_var = regression_noise_var(points, psi, dual, ks, p, ops)
    # what smooth_series(theta, smoothing="gcv") would choose, at the cost of the series GCV judges; once
    # for both choices below
    theta = gcv_columns(theta, t, c=p["c_time"], R0=p["R0_time"])
    k = gcv_temporal(t, theta, c=p["c_time"], R0=p["R0_time"])[0]
    out["temperature_smoothing"] = k if grad is None else guarded_time_smoothing(k, t, grad, psi, noise_var, p)
    if grad is not None:  # the value's own (irdic.fields.space_time.space_time)
        out["temperature_smoothing_value"] = value_time_smoothing(out["temperature_smoothing"], t, value, psi,
                                                                  value_var, p)
    if ks is not None:  # the rate's own spacing (see irdic.fields.space_time)
        out["temperature_smoothing_rate"] = rate_smoothing(t, theta, k, p)
    return out


def rate_smoothing(t, series, value_k, p) -> float:
    """The rate's temporal spacing: least estimated risk of the rate
    (:func:`~irdic.numerics.temporal_choice.rate_risk_temporal`) on the complete ``series`` (M, n) at ``t``, at
    most GCV's spacing of the value ``value_k``, so that the rate's regression is at most as smooth as GCV would
    make the value's (:func:`irdic.fields.space_time._rate_series`). Where GCV had no candidate for the value
    (``value_k`` None or 1: too few stages for its 1/2 parameters per stage, 9 and fewer) the rate's own choice
    stands, among candidates up to :data:`~irdic.numerics.temporal_choice.RATE_MAX_FRACTION`.

    Notes
    -----
    GCV's spacing, not the value's after :func:`guarded_time_smoothing`: where the guard interpolates the value
    in time (a narrow band passing each point within two DIC times, the noisy family's drawn-101), the rate of the
    interpolation erred by 10.1 % against 9.1 % from the regression; without a bound the rate's risk took 16
    stages on the static shell-edge (0.37 % against 0.26 % at GCV's 12, 45 % of it flagged bias-dominated against
    10 %)."""
    k = float(rate_risk_temporal(t, series, c=p["c_time"], R0=p["R0_time"])[0])
    return min(k, float(value_k)) if value_k is not None and value_k > 1.0 else k


#: times of the points' noise through the spatial regression that give its noise (:func:`regression_noise_var`)
NOISE_TIMES = 4


def parameter_dual(n):
    """A dual basis (1, n, 2, 3) that makes :func:`~irdic.fields.spatial.regressed_gradient` return the gradient in the
    surface parameters, ``(d/dPsi1, d/dPsi2, 0)``."""
    dual = np.zeros((1, n, 2, 3))
    dual[..., 0, 0] = dual[..., 1, 1] = 1.0
    return dual


def regression_noise_var(points, psi, dual, ks, p, ops=None) -> tuple[float, float]:
    """The mean noise variances of the spatial regression's gradient (per component, K²/mm²) and of its value
    (K²), spacing ``ks``, the dual basis ``dual`` of the first times, from the point temperatures' noise:
    :data:`NOISE_TIMES` times of the pixels' noise at the points (neighbours share pixels: correlated in space,
    :func:`~irdic.footprint.fields.footprint_probes`) through the regression. NaN where the noise is not
    recorded; the value's also without pixel positions (white probes: its noise 3.7 x too low at 20 spacings on
    the noisy family's drawn-1006, which would take the regression's noise for a bias).
    """
    from ..footprint.fields import footprint_probes
    from ..uncertainty.model import point_noise

    s_T = point_noise(points.attrs)
    sub = points.isel(time=slice(0, NOISE_TIMES))
    seen = np.isfinite(sub["temperature"].values)
    rng = np.random.default_rng(0)
    fp = footprint_probes(sub, None, 1.0)
    unit = rng.standard_normal(seen.shape) if fp is None else np.array(fp[0](rng, 1), dtype=float)[0]
    g, f, _ = regressed_gradient(np.where(seen, unit, np.nan), psi, dual[:NOISE_TIMES], ks, c=p["c_space"],
                                 R0=p["R0_space"], ops=ops)
    ok = np.isfinite(g).all(axis=-1) & seen
    if not ok.any():
        return float("nan"), float("nan")
    value_var = float("nan") if fp is None else s_T ** 2 * float(np.mean(np.square(f[ok])))
    return s_T ** 2 * float(np.mean(np.square(g[ok]))), value_var


def _guarded(k, t, series, psi, noise_var, p, name, outcome):
    """``k``, or 1.0 where the regression in time ``k`` of ``series`` (T, N, ...) leaves more than
    :data:`~irdic.numerics.temporal_risk.CP_LIMIT` x its noise ``noise_var`` in its residual
    (:func:`~irdic.numerics.temporal_risk.bias_ratio`), judged over the points more than
    :data:`~irdic.fields.spatial.JUDGED_MARGIN` spacings inside the cloud's edge with a value at every time (6 at
    least); ``name`` and ``outcome`` for the log."""
    if not k > 1:
        return k
    have = np.isfinite(psi).all(axis=1)
    inner = np.zeros(have.shape, bool)
    inner[have] = judged_points(psi[have])
    cols = inner & np.isfinite(series.reshape(t.size, inner.size, -1)).all(axis=(0, 2))
    if cols.sum() < 6:
        return k
    ratio = bias_ratio(t, series[:, cols].reshape(t.size, -1), k, noise_var, c=p["c_time"], R0=p["R0_time"])
    if not ratio > CP_LIMIT:
        return k
    log.info("temperature_smoothing: the regression in time with centres every %.3g times leaves %.3g x the "
             "%s's noise in its residual (more than %g: its bias outweighs the noise it removes): %s", k, ratio,
             name, CP_LIMIT, outcome)
    return 1.0


def value_time_smoothing(k, t, value, psi, noise_var, p):
    """The value's temporal spacing: ``k`` (the gradient's, :func:`guarded_time_smoothing`), or 1.0
    (interpolation) where that regression's bias outweighs the noise it removes from the value
    (:func:`~irdic.numerics.temporal_risk.bias_ratio` above :data:`~irdic.numerics.temporal_risk.CP_LIMIT`).

    ``value`` (T, N) is the spatially regressed value at times ``t``, ``noise_var`` its noise variance
    (:func:`regression_noise_var`); judged as :func:`guarded_time_smoothing` judges the gradient.

    Notes
    -----
    A spacing of its own, not the gradient's, because the two fail apart: a heating uniform over the patch
    whose rate jumps from one DIC time to the next biases the value and leaves the gradient alone (the noisy
    family's drawn-1006, 17 stages at 4 Hz: the value's ratio 27, the denoised temperature 0.022 K), while the
    regression the gradient needs (its noise is ~1 / h² of the value's) may leave the value a bias of a few
    times its small noise; one spacing for both, interpolated where either ratio exceeded 2, took drawn-808's
    gradient error from 2.3 to 3.1 % (its temperature's from 0.0069 to 0.0042 K, as now).
    """
    return _guarded(k, t, value, psi, noise_var, p, "value", "the value interpolated in time, its gradient regressed")


def guarded_time_smoothing(k, t, grad, psi, noise_var, p):
    """GCV's temporal spacing ``k``, or 1.0 (interpolation) where the regression's bias outweighs the noise it
    removes from the gradient (:func:`~irdic.numerics.temporal_risk.bias_ratio` above
    :data:`~irdic.numerics.temporal_risk.CP_LIMIT`).

    ``grad`` (T, N, C) is the spatially regressed gradient at times ``t``, ``noise_var`` its noise variance per
    component (:func:`regression_noise_var`). Judged on the points more than
    :data:`~irdic.fields.spatial.JUDGED_MARGIN` spacings inside the cloud's edge, with a value at every time:
    at the edge of a moving specimen the mixed pixels change from stage to stage, which no noise model holds
    (the family's twisting members: 2.1-3.0 x with them, 0.4-0.7 without).
    """
    return _guarded(k, t, grad, psi, noise_var, p, "gradient", "interpolating in time")
