"""The temperature fields: in-plane gradient, material rate and denoised value, by interpolation or regression.

The paper's relations on the interpolated pixel gradients, or, where the
smoothing is on, the regression in space of each time
(:mod:`irdic.fields.spatial`) then in time of each point's series
(:func:`space_time`); and their uncertainties
(:func:`irdic.uncertainty.model.uncertainties`).
"""

from __future__ import annotations

import numpy as np

from ..camera import load_camera
from ..footprint.fields import paper_value
from ..gradient import material_rate, surface_gradient
from ..logs import report
from ..numerics.series import fill_series, smooth_series
from ..numerics.temporal import rate_reference_weights
from ..numerics.temporal_choice import gcv_temporal
from ..uncertainty.model import paper_std, uncertainties
from ..uncertainty.regression_bias import first_mode_bias, reference_spacing
from .smoothing import guarded_time_smoothing, rate_smoothing, regression_noise_var, value_time_smoothing
from .spatial import RISK_DESIGNS, regressed_gradient, space_gcv

__all__ = ["space_time", "temperature_fields"]


def temperature_fields(points, calibration, sf, geo, t, p, noise_attrs, series=None, ops=None):
    """In-plane gradient (T, N, 3) K/mm, material rate with its local and convective parts (T, N) K/s,
    and the best estimate of the temperature (T, N) degC (denoised where smoothing is on); last the
    uncertainties of :func:`irdic.uncertainty.model.uncertainties`, the strain's pending
    (:func:`~irdic.uncertainty.model.with_strain_std`); and the spacings the regressions used
    (:func:`space_time`'s ``chosen``).

    The projection Jacobian of the calibrated camera at the surface points
    turns pixel gradients into surface ones (see the module docstring).
    ``series`` (:class:`~irdic.uncertainty.model.Window`): a time chunk's window around the times
    ``t``, for the regression in time and the uncertainty probes.
    """
    T, N = sf.x.shape[:2]
    camera = load_camera(calibration)
    flat = sf.x.reshape(-1, 3)
    ok = np.isfinite(flat).all(axis=1)
    J = np.full((T * N, 2, 3), np.nan)
    J[ok] = camera.jacobian(flat[ok])
    J = J.reshape(T, N, 2, 3)
    # the store's own array where it is float already (not a copy: nothing here writes to it)
    g_pix = np.asarray(points["temperature_pixel_gradient"].transpose("time", "point", "axis").values, dtype=float)
    local = points["temperature_local_rate"].values.astype(float)
    theta = points["temperature"].values.astype(float)
    grad = surface_gradient(g_pix, J, sf.tangents)
    report("regression", 0.0)
    rate = material_rate(local, g_pix, J, sf.velocity)
    # the Jacobian's last use: what the uncertainty needs of it, so that it is not held through the regressions
    paper = list(paper_std(points, sf, J))  # a list: the uncertainty empties it once they are replaced
    del J
    total, loc = rate.rate, rate.local
    visible = np.isfinite(theta)
    best = theta
    chosen_k = {"temperature_smoothing": None, "temperature_smoothing_space": None}
    spatial = None
    ops = {} if ops is None else ops  # the spatial operators of the regressions and their probes, factorised once
    if p["temperature_smoothing_space"] is not None:
        def noise_var(ks):  # the regressed gradient's and value's noise, for the choice of the smoothing in time
            return regression_noise_var(points, sf.psi, geo.dual, ks, p, ops)

        def regress(th, ser, q=p):
            return space_time(th, t, sf, geo, q, ser, rate.convective, visible, (total, loc), ops,
                              noise_var if ser is None else None)
        grad, total, loc, best, spatial, chosen_k = regress(theta, series)
        if "temperature_paper" in points:  # footprint temperatures: the value from the paper's, same spacings
            best, spatial = paper_value(points, series, lambda th, ser: regress(th, ser, {**p, **chosen_k}), spatial)
    elif p["temperature_smoothing"] is not None:
        # a chunk regresses its window's series and evaluates it at its own times
        th, ts = (series.theta, series.t) if series is not None else (theta, t)
        fit = smooth_series(th, ts, t if series is not None else None, smoothing=p["temperature_smoothing"],
                            c=p["c_time"], R0=p["R0_time"], record_times=t if series is None else series.record)
        chosen_k["temperature_smoothing"] = fit.smoothing
        total = np.where(visible, fit.rate, np.nan)
        loc = total - rate.convective
        best = np.where(visible, fit.value, np.nan)

    def regress_space(th, dual, k):
        return regressed_gradient(th, sf.psi, dual, k, c=p["c_space"], R0=p["R0_space"], ops=ops)[:2]

    # the paper's rate and the points' local rate are replaced by now (or live on as total, loc)
    rate, local = rate._replace(rate=None, local=None), None
    report("regression", 1.0)
    report("uncertainty", 0.0)
    unc = uncertainties(points.assign_attrs(dic_noise_mm=noise_attrs.get("dic_noise_mm", np.nan)), sf, geo, paper,
                        grad, g_pix, t, p, chosen_k, regress_space, window=series, spatial=spatial, ops=ops)
    return grad, total, loc, rate.convective, best, unc, chosen_k


def space_time(theta, t, sf, geo, p, series, convective, visible, paper_rate, ops=None, noise_var=None):
    """Gradient, rate (material, local) and value of the space-time regression of the point temperatures.

    Parameters
    ----------
    theta : ndarray, shape (T, N)
        Point temperatures (degC) at the DIC times ``t`` (s).
    sf, geo
        The fitted surface and its geometry (surface parameters, dual basis).
    p : dict
        The fields settings; ``temperature_smoothing_space`` is set.
    series : Window or None
        A time chunk's window (its regressions run over the window).
    convective : ndarray, shape (T, N)
        Convective part of the rate (K/s).
    visible : ndarray of bool, shape (T, N)
    paper_rate : (total, local)
        The paper's rate and local part, kept when there is no regression in time.
    ops : dict, optional
        Cache of the spatial operators (:func:`irdic.surface.shared_interpolant`).
    noise_var : callable, optional
        ``noise_var(ks)``: the noise variances (K²/mm² per component, K²) of the gradient and the value
        regressed with spacing ``ks`` (:func:`~irdic.fields.smoothing.regression_noise_var`); with it a ``"gcv"``
        smoothing in time is guarded (:func:`~irdic.fields.smoothing.guarded_time_smoothing`), the value's own
        (:func:`~irdic.fields.smoothing.value_time_smoothing`).

    Returns
    -------
    grad (T, N, 3) K/mm, total (T, N) K/s, local (T, N) K/s, value (T, N) degC,
    spatial (the inputs of the regression's bias estimate, see
    :func:`irdic.uncertainty.model.uncertainties`), chosen (the spacings used).

    Notes
    -----
    Space first, then time, then space again. The tube's temperature is smooth in space (a quadratic axial
    profile) but changes within a few DIC stages in time, so a point's own series, with the full 0.05 K noise,
    makes GCV in time choose centres every 4 stages, whose bias alone is 7 % of the rate. The spatial regression
    of each stage removes most of the noise first; GCV of the regressed series in time then judges a nearly
    noise-free signal and chooses the light smoothing the signal needs. A spacing the gradient's risk chose is
    judged again on the series regressed in time (:func:`_spacing_after_time`). The gradient is the spatial
    regression's derivative of the temporally regressed values, the rate the temporal derivative of the spatially
    regressed series, by a lighter regression in time (:func:`_rate_series`), the value that field's or the
    spatially regressed series (:func:`~irdic.fields.smoothing.value_time_smoothing`)."""
    kw = dict(c=p["c_space"], R0=p["R0_space"], ops=ops)
    # also where a point has no temperature: its series in time holds the time's field there (docs/method.md, 4)
    grad, field, ks = regressed_gradient(theta, sf.psi, geo.dual, p["temperature_smoothing_space"], everywhere=True,
                                         **kw)
    designs = None if ops is None else ops.pop(RISK_DESIGNS, None)  # its choice's, for _spacing_after_time
    value = np.where(np.isfinite(theta), field, np.nan)
    chosen = {"temperature_smoothing": None, "temperature_smoothing_space": ks}
    total, loc = paper_rate
    if p["temperature_smoothing"] is None:
        return grad, total, loc, value, (theta, grad, theta, value, theta), chosen
    # a chunk regresses its window's series (in space at each stage, then in time) and evaluates at its own times
    if series is not None:
        th_in, ts_in, t_eval, record = series.theta, series.t, t, series.record
        _, th_s, _ = regressed_gradient(th_in, sf.psi, None, ks, everywhere=True, **kw)
    else:
        th_in, ts_in, t_eval, record, th_s = theta, t, None, t, field
    tkw = dict(c=p["c_time"], R0=p["R0_time"], record_times=record)
    # the gaps filled once, together, for the regressions in time below; with the rate's spatial reference
    th_s, th_in, *th_ref = fill_series([th_s, th_in] + _half_spacing(th_in, sf.psi, ks, kw), ts_in, **tkw)
    k, k_gcv, k_value = _time_spacing(th_s, ts_in, grad, sf.psi, p, ks, noise_var)
    if (after := _spacing_after_time(theta, t, sf.psi, p, ks, k, series, kw, designs)) is not None:
        return space_time(theta, t, sf, geo, {**p, "temperature_smoothing_space": after}, series, convective,
                          visible, paper_rate, ops, noise_var)
    fit = smooth_series(th_s, ts_in, t_eval, smoothing=k, **tkw)
    rate_fit = _rate_series(th_s, ts_in, t_eval, p, fit, tkw, fit.smoothing if k_gcv == "gcv" else k_gcv)
    chosen["temperature_smoothing"], chosen["temperature_smoothing_rate"] = fit.smoothing, rate_fit.smoothing
    total = np.where(visible, rate_fit.rate, np.nan)
    smoothed = np.where(visible, fit.value, np.nan)
    grad, field_value, _ = regressed_gradient(smoothed, sf.psi, geo.dual, ks, **kw)
    chosen["temperature_smoothing_value"] = fit.smoothing if k_value is None else float(k_value)
    value = field_value
    if chosen["temperature_smoothing_value"] != fit.smoothing:  # the value's own, lighter regression in time
        smoothed = np.where(visible, smooth_series(th_s, ts_in, t_eval, smoothing=k_value, **tkw).value, np.nan)
        value = regressed_gradient(smoothed, sf.psi, None, ks, **kw)[1]
    bias_inputs = _bias_inputs(theta, grad, field_value, total, smoothed, (th_in, th_s, ts_in, t_eval, *th_ref),
                               visible, (fit.smoothing, rate_fit.smoothing), tkw)
    return grad, total, total - convective, value, bias_inputs, chosen


def _spacing_after_time(theta, t, psi, p, ks, k, series, kw, designs=None):
    """The spatial spacing ``ks`` that the gradient's risk chose on single times, judged again on the series
    regressed in time with the spacing ``k`` (:func:`~irdic.fields.spatial.space_gcv`, ``after``), where that
    differs; else None. Only the whole record's own choice: a chunk's is the record's
    (:func:`~irdic.fields.smoothing.resolve_gcv`, which judges it the same way). ``designs``: the first
    choice's (:data:`~irdic.fields.spatial.RISK_DESIGNS`)."""
    if p["temperature_smoothing_space"] != "gcv" or series is not None or k in (None, "gcv") or float(k) <= 1.0:
        return None  # not chosen here, or no regression in time (1: a centre at every stage, the interpolation)
    after = space_gcv(theta, psi, after=(t, float(k), p["c_time"], p["R0_time"], ks), designs=designs, **kw)
    return None if after is None or after == ks else after


def _half_spacing(theta, psi, ks, kw):
    """``[theta]`` (T, N) regressed at half the spatial spacing ``ks`` at each time, the rate's spatial bias
    reference (:func:`_bias_inputs`), or ``[]`` where that reference is the points' own series (``ks`` below 2)."""
    k_ref = reference_spacing(ks)
    return [] if k_ref is None else [regressed_gradient(theta, psi, None, k_ref, everywhere=True, **kw)[1]]


def _bias_inputs(theta, grad, value, total, smoothed, series, visible, spacings, tkw):
    """The inputs of the regressions' bias estimates (:func:`irdic.uncertainty.model.uncertainties`); ``smoothed``
    the value's regression in time of the spatially regressed series (its temporal bias is judged against that
    series' interpolation). The value's spatial bias is judged on the gradient's field ``value``
    (where the value has a lighter regression in time of its own, the spatial bias hardly differs, and the
    interpolated points' own series would drown the estimate in their noise: drawn-1005's temperature std 3 x
    its noise part, the RMS of error/std 0.50).

    The rate's temporal bias that a patch heated with one history shares, on the series' first temporal mode
    (:func:`~irdic.uncertainty.regression_bias.first_mode_bias`), comes before the last.

    ``series`` is ``(th_in, th_s, ts_in, t_eval[, th_ref])``: the points' own series, the spatially regressed one,
    their times, the times evaluated, and the series regressed at half the spatial spacing; ``spacings`` the
    temporal spacings of the gradient and of the rate. The rate's spatial bias is judged against the last (as the
    gradient's, :func:`~irdic.uncertainty.regression_bias.reference_spacing`), where there is one: against the
    points' own series, ~15 x noisier than the rate, its estimate needed their noise known to 1 % (the sweep's
    still tube, 300 DIC times: the difference's noise 4-15 % above its probes' took 0.017 K/s for a bias where
    the true one was 1e-4 and the rate erred by 0.002 K/s)."""
    th_in, th_s, ts_in, t_eval, *th_ref = series
    k, k_rate = spacings
    # the spatial regression's bias is judged against the temporal regression of the points' own series
    own = smooth_series(th_in, ts_in, t_eval, smoothing=k, **tkw)
    if th_ref:
        own_rate = smooth_series(th_ref[0], ts_in, t_eval, smoothing=k_rate, **tkw).rate
    else:
        own_rate = own.rate if k_rate == k else smooth_series(th_in, ts_in, t_eval, smoothing=k_rate, **tkw).rate
    # the temporal regressions' bias: against the same (regressed) series, whose noise is small (against the
    # points' own series the estimate drowned in their noise): the rate's against a local polynomial in time
    exact = smooth_series(th_s, ts_in, t_eval, smoothing=None, **tkw)
    own_v = np.where(visible, own.value, np.nan)
    ref = rate_reference_weights(ts_in, t_eval, smoothing=k_rate)
    # the rate's regression in time minus its reference, as weights (T, M)
    difference = smooth_series(np.eye(ts_in.size), ts_in, t_eval, smoothing=k_rate, **tkw).rate - ref
    return (theta, grad, own_v, value, total - ref @ th_s, total - own_rate, smoothed - exact.value,
            first_mode_bias(th_s, difference), own_v)


def _time_spacing(th_s, t, grad, psi, p, ks, noise_var):
    """``temperature_smoothing``, a ``"gcv"`` one resolved where ``noise_var`` is given: GCV's choice on the
    filled series ``th_s`` (as :func:`~irdic.numerics.series.smooth_series` makes it), kept where its bias does not
    outweigh the noise it removes from the gradient ``grad`` (:func:`~irdic.fields.smoothing.guarded_time_smoothing`);
    GCV's choice itself (the rate's regression is at most as smooth: :func:`_rate_series`); and the value's
    spacing (:func:`~irdic.fields.smoothing.value_time_smoothing`; one resolved for the record,
    ``p["temperature_smoothing_value"]``), or None: the gradient's."""
    k = p["temperature_smoothing"]
    if k != "gcv" or noise_var is None:
        return k, k, p.get("temperature_smoothing_value")
    live = np.isfinite(th_s).all(axis=0)
    k_gcv = gcv_temporal(t, th_s[:, live] if live.any() else th_s, c=p["c_time"], R0=p["R0_time"])[0]
    grad_var, value_var = noise_var(ks)
    k = guarded_time_smoothing(k_gcv, t, grad, psi, grad_var, p)
    return k, k_gcv, value_time_smoothing(k, t, th_s, psi, value_var, p)


def _rate_series(th_s, ts_in, t_eval, p, fit, tkw, value_k):
    """The temporal regression of the spatially regressed series ``th_s`` whose derivative is the rate.

    With ``temperature_smoothing`` "gcv": the spacing of least estimated risk of the rate, at most the value's
    GCV spacing ``value_k`` (before the value's guard: :func:`~irdic.fields.smoothing.rate_smoothing`), or that
    resolved for the record (``p["temperature_smoothing_rate"]``); a configured number serves both (``fit``).

    Notes
    -----
    The gradient is that of the field ``S_x S_t2 S_x Θ``; the rate is ``∂_t S_t1 S_x Θ``, ``S_t1`` at most as
    smooth, and the value ``S_x S_t3 S_x Θ``, ``S_t3`` either ``S_t2`` or the interpolation
    (:func:`~irdic.fields.smoothing.value_time_smoothing`); they differ by the heavier one's temporal bias, which
    the value's std holds. A fast
    transient's rate at 2 Hz is bias-limited, the gradient noise-limited (benchmarks/README.md, noisy fields).
    """
    k = p.get("temperature_smoothing_rate") or ("gcv" if p["temperature_smoothing"] == "gcv" else None)
    if k is None:
        return fit
    if k == "gcv":  # the series are filled (space_time): those with a value at every time judge
        live = np.isfinite(th_s).all(axis=0)
        k = rate_smoothing(ts_in, th_s[:, live] if live.any() else th_s, value_k, p)
    return smooth_series(th_s, ts_in, t_eval, smoothing=k, **tkw)
