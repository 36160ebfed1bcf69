"""Per-point standard uncertainty of the fields stage's results (issue 15, part 4).

Every field of ``fields.zarr`` is, for fixed smoothing parameters and fixed
geometry, a linear function of the IR pixel values (temperature, gradient,
rate) or, to first order, of the DIC coordinates (strain). The noise levels
estimated from the data (``points.zarr`` and :func:`irdic.noise.auto_smoothing`)
are propagated through those same operators:

- IR: white pixel noise ``σ = sqrt(σ_n² + q²/12)`` (``σ_n``: frame-to-frame
  noise, ``q``: export step) gives the point temperature, each pixel-gradient
  component and the local rate the standard deviations ``σ g`` with the
  interpolation's noise gains ``g`` (measured once by the couple stage on a
  probe, :func:`irdic.noise.interpolation_noise_gains`).
- The paper's relations are linear maps of those per point: the gradient
  ``L g_pix`` (``L``: 3 x 2, ``surface_gradient`` of the unit vectors) has
  component variances ``σ_g² Σ_j L_ij²``; the rate ``∂Θ/∂t + c · g_pix``
  (``c = J v``) has ``σ_r² + σ_g² |c|²``.
- Temporal regression: the rate is ``W1 Θ`` per point series, so its
  variance is ``σ_T² Σ_j W1_ij²`` (the weights of the chosen regression).
  With the spatial regression too, the fields regress in space first and
  then in time (:func:`irdic.stages.fields._space_time`): the rate
  ``W1 (S Θ)``, value and gradient of ``S (W0 (S Θ))``, all by the probes.
- Spatial regression and strain: propagated by random probes, ``K`` noise
  realisations run through the same operator with the smoothing parameters
  frozen at the chosen values; the standard deviation over the probes.
- Calibration: the temperature gets ``pixel_std |∇_pix Θ|`` (the projected
  position's uncertainty times the pixel gradient) in quadrature.
- Regression bias: a regression's error is noise plus bias. For the spatial
  temperature regression (value, gradient) and the surface regression
  (strain) the difference ``d`` to the exact interpolation of the same input
  has ``E d² = b² + v`` (``v``: the noise variance of ``d``, from the same
  probes through both operators); ``b² = <d²> - <v>`` averaged locally
  (:func:`_local_bias`) is added to the variance.

Where the method's own bias dominates the noise the std is not a bound on the
error and ``<field>_bias_dominated`` says so: within 2 px of the mask edge or
extrapolated (temperature, gradient, rate), the first and last DIC time
(rate: the one-sided end of the series), the export step larger than the
noise (rounding is then a deterministic error, not noise), the rate where the
space-time regression's estimated temporal bias exceeds its noise
(:func:`_space_time_bias`), and for the strain points within two point
spacings of the point cloud's edge.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from ..gradient import material_rate, surface_gradient
from ..numerics.temporal import TemporalInterpolant, temporal_window
from ..strain import strain
from ..surface import fit_surface
from ..vocabulary import Status

__all__ = ["uncertainties", "Window", "PROBES", "EDGE_PX", "BIAS_NEIGHBOURS"]

log = logging.getLogger(__name__)

#: random probes of the operators propagated by Monte Carlo
PROBES = 16
#: points closer than this to the mask edge (px) have interpolation bias rather than noise
EDGE_PX = 2.0
#: nearest points (surface parameters) over which a regression's bias is averaged, at each time and its neighbours
BIAS_NEIGHBOURS = 32


class Window(NamedTuple):
    """A time chunk's window (:mod:`irdic.chunks`): what the fields of its own times depend on.

    ``theta`` (T_w, N) degC and ``x`` (T_w, N, 3) mm at the window's times
    ``t`` (T_w,) s; ``x_ref``/``t_ref``: the record's first two stages (the
    strain's reference); ``first``/``last``: the chunk holds the record's
    first/last DIC time; ``record`` (M,) s: the whole record's stage times
    (the temporal operator's window).
    """

    theta: np.ndarray
    t: np.ndarray
    x: np.ndarray
    x_ref: np.ndarray
    t_ref: np.ndarray
    first: bool
    last: bool
    record: np.ndarray


def _probe_std(samples, base):
    """Standard deviation over the probe axis 0 of ``samples - base`` (zero-mean by construction)."""
    return np.sqrt(np.mean(np.square(samples - base), axis=0))


def uncertainties(points, sf, geo, J, g_pix, t, p, chosen_k, regress_space, seed=0, window=None, spatial=None):
    """Standard uncertainties and bias flags of the fields (see the module docstring).

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    sf : irdic.surface.SurfaceFields
        The fitted surface.
    geo : irdic.surface.SurfaceGeometry
        Its geometry (dual basis).
    J : ndarray, shape (T, N, 2, 3)
        Projection Jacobian (px/mm).
    g_pix : ndarray, shape (T, N, 2)
        Pixel gradients (K/px).
    t : ndarray, shape (T,)
        DIC times (s).
    p : dict
        The fields settings, smoothing options resolved.
    chosen_k : dict
        ``temperature_smoothing`` and ``temperature_smoothing_space``: the
        centre spacing factors used (None: interpolation).
    regress_space : callable
        ``regress_space(theta (T', N), dual (T', N, 2, 3) or None, k) -> (grad, value)``:
        the spatial regression of the fields stage (dual None: values only).
    seed : int
        Seed of the probes (fixed: the stores are reproducible).
    window : Window, optional
        A time chunk's window: the temporal regression's weights and the
        strain probes run over it, as the chunk's fields do, and only the
        record's own ends are flagged as series ends.
    spatial : tuple, optional
        With the spatial regression of the temperatures: ``(theta (T, N),
        grad (T, N, 3), value_in (T, N), value (T, N)[, d_rate_t, d_rate_s,
        d_value_t (T, N)])``, the point temperatures and the regressed
        gradient, and the regression's input (``theta`` or its temporal
        regression) and output; their differences to the exact interpolation
        give the regression's bias. With a regression in time too
        (:func:`irdic.stages.fields._space_time`, ``S_t`` in time, ``S`` in
        space, ``I_t`` the exact interpolation in time): ``d_rate_t`` the
        rate of ``S_t S Θ`` minus that of ``I_t S Θ`` (the temporal
        regression's bias, against a reference as little noisy as the
        regressed series), ``d_rate_s`` minus that of ``S_t Θ`` (the spatial
        regression's), ``d_value_t`` the value of ``S_t S Θ`` minus ``S Θ``.

    Returns
    -------
    dict
        ``name -> (std array, bias_dominated array)`` for ``temperature``,
        ``temperature_gradient``, ``temperature_rate``,
        ``max_principal_strain``; and ``"notes"``: str for the attrs.
    """
    rng = np.random.default_rng(seed)
    a = points.attrs
    T, N = sf.x.shape[:2]
    visible = np.isfinite(points["temperature"].values.astype(float))
    sig_n, q, sigma, (s_T, s_g, s_r) = _ir_noise(a)
    notes = []
    ends = (True, True) if window is None else (window.first, window.last)
    ir_bias, rate_bias, strain_bias = _bias_flags(points, sf, visible, q, sig_n, notes, ends)
    # the bias is averaged over points where the exact interpolation is itself accurate (unflagged)
    trusted = ~(near_edge(points, sf, visible) | strain_bias)
    temp_std, grad_std, rate_std, rate_biased = _ir_std(sf, J, t, p, chosen_k, regress_space, geo, visible, rng,
                                                        s_T, s_g, s_r, window, spatial, trusted)
    if rate_biased is not None:
        rate_bias |= rate_biased & visible
        if rate_biased.any():
            # no count: a time chunk's note becomes the gathered store's
            notes.append("temperature_rate: the temporal regression's estimated bias exceeds the noise where "
                         "temperature_rate_bias_dominated is set; there the std holds the local RMS of that "
                         "estimate, not a Gaussian width")
    # calibration: the projected position's uncertainty moves the sample along the pixel gradient
    pix_std = points["pixel_std"].values.astype(float) if "pixel_std" in points else np.zeros((T, N))
    cal = np.nan_to_num(pix_std) * np.linalg.norm(np.nan_to_num(g_pix), axis=-1)
    temp_std = np.sqrt(temp_std ** 2 + cal ** 2)
    s_x = float(a.get("dic_noise_mm", np.nan))
    strain_std = _strain_std(points, sf, t, p, s_x, rng, window, ~strain_bias)
    if not np.isfinite(s_x):
        notes.append("max_principal_strain_std: the DIC noise could not be estimated")
    for arr in (temp_std, rate_std):
        arr[~visible] = np.nan
    grad_std[~visible] = np.nan
    log.info("fields: uncertainty from IR noise %.3g K (point %.3g K) and DIC noise %.3g mm; median std: temperature "
             "%.3g K, rate %.3g K/s, max principal strain %.3g", sigma, s_T, s_x, _median(temp_std),
             _median(rate_std), _median(strain_std))
    return {
        "temperature": (temp_std, ir_bias),
        "temperature_gradient": (grad_std, np.repeat(ir_bias[..., None], 3, axis=-1)),
        "temperature_rate": (rate_std, rate_bias),
        "max_principal_strain": (strain_std, np.array(strain_bias)),
        "notes": "; ".join(notes) if notes else "none",
    }


def _ir_noise(a):
    """Pixel noise (K) of points.zarr's attrs: temporal noise, quantisation step, their sum, and the
    point-level noise of temperature, pixel gradient and local rate (via the interpolation's noise gains)."""
    sig_n = float(a.get("ir_noise_temporal_k", a.get("ir_noise_k", np.nan)))
    q = float(a.get("ir_quantisation_k", 0.0) or 0.0)
    sigma = float(np.hypot(sig_n, q / np.sqrt(12)))
    gains = (sigma * float(a.get(f"ir_noise_gain_{g}", np.nan))
             for g in ("temperature", "gradient_per_px", "rate_per_s"))
    return sig_n, q, sigma, tuple(gains)


def _ir_std(sf, J, t, p, chosen_k, regress_space, geo, visible, rng, s_T, s_g, s_r, window=None, spatial=None,
            trusted=None):
    """Standard uncertainties of temperature, in-plane gradient and rate from the IR noise and the regressions'
    bias (:func:`_local_bias`); last, where the rate's estimated bias exceeds its noise (T, N), or None."""
    T, N = sf.x.shape[:2]
    # the paper's relations: exact propagation of the per-point linear maps
    e = np.zeros((T, N, 2))
    e[..., 0] = 1
    Lu = surface_gradient(e, J, sf.tangents)
    cu = material_rate(np.zeros((T, N)), e, J, sf.velocity).convective
    e[..., 0], e[..., 1] = 0, 1
    Lv = surface_gradient(e, J, sf.tangents)
    cv = material_rate(np.zeros((T, N)), e, J, sf.velocity).convective
    grad_std = s_g * np.sqrt(Lu ** 2 + Lv ** 2)
    rate_std = np.sqrt(s_r ** 2 + s_g ** 2 * (cu ** 2 + cv ** 2))
    temp_std = np.full((T, N), s_T)

    kt, ks = chosen_k.get("temperature_smoothing"), chosen_k.get("temperature_smoothing_space")
    W0 = rate_biased = None
    if kt is not None:
        # a chunk's regression runs over its window (T_w samples) and is evaluated at its own times
        record = t if window is None else window.record
        ts = TemporalInterpolant(t if window is None else window.t, c=p["c_time"], R0=p["R0_time"], smoothing=kt,
                                 window=temporal_window(record, c=p["c_time"], R0=p["R0_time"], smoothing=kt))
        W0, W1 = ts.weights(t, 0), ts.weights(t, 1)
        rate_std = np.broadcast_to(s_T * np.sqrt(np.sum(W1 ** 2, axis=1))[:, None], (T, N)).copy()
        temp_std = np.broadcast_to(s_T * np.sqrt(np.sum(W0 ** 2, axis=1))[:, None], (T, N)).copy()
    if ks is not None:
        # probes stacked along time: one regression call for all of them
        noise = rng.standard_normal((PROBES, T, N)) * s_T
        noise[:, ~visible] = np.nan
        dual = np.tile(geo.dual, (PROBES, 1, 1, 1))
        g_pr, v_pr = regress_space(noise.reshape(PROBES * T, N), dual, ks)
        grad_std = _probe_std(g_pr.reshape(PROBES, T, N, 3), 0.0)
        noise_c = noise
        if W0 is not None:
            if window is not None:
                # the temporal regression of a chunk mixes its window's noise
                noise = rng.standard_normal((PROBES, window.t.size, N)) * s_T
                noise[:, ~np.isfinite(window.theta)] = np.nan
                off = int(np.searchsorted(window.t, t[0]))
                noise_c = noise[:, off:off + T]
            # in space at each time first, then in time (irdic.stages.fields._space_time)
            tw = noise.shape[1]
            _, s_pr = regress_space(noise.reshape(PROBES * tw, N), None, ks)
            s_pr = np.nan_to_num(s_pr.reshape(PROBES, tw, N))
            rate_std = _probe_std(np.einsum("ij,kjn->kin", W1, s_pr), 0.0)
            smoothed = np.einsum("ij,kjn->kin", W0, s_pr)
            smoothed[:, ~visible] = np.nan
            g_pr, v_pr = regress_space(smoothed.reshape(PROBES * T, N), dual, ks)
            grad_std = _probe_std(g_pr.reshape(PROBES, T, N, 3), 0.0)
            # the bias is judged against the temporal regression of the points' own series
            value_in_pr = np.einsum("ij,kjn->kin", W0, np.nan_to_num(noise))
        else:
            value_in_pr = noise
        v_pr = v_pr.reshape(PROBES, T, N)
        temp_std = _probe_std(v_pr, 0.0)
        if spatial is not None:
            theta, grad, value_in, value = spatial[:4]
            # the same probes through the exact interpolation (k = 1): the noise expected in the
            # difference regression - interpolation, which is subtracted from the data's difference
            g_int = regress_space(noise_c.reshape(PROBES * T, N), dual, 1.0)[0].reshape(PROBES, T, N, 3)
            g_var = np.mean(np.square(g_pr.reshape(PROBES, T, N, 3) - g_int), axis=0)
            d_grad = grad - regress_space(theta, geo.dual, 1.0)[0]
            grad_std = np.hypot(grad_std, _local_bias(d_grad, g_var, sf.psi, trusted))
            # the exact interpolation of the input at the points is the input itself
            v_var = np.mean(np.square(v_pr - value_in_pr), axis=0)
            temp_std = np.hypot(temp_std, _local_bias(value - value_in, v_var, sf.psi, trusted))
            if len(spatial) > 4 and W0 is not None:
                temp_std, rate_std, rate_biased = _space_time_bias(spatial[4:], ts, t, p, record, s_pr, noise,
                                                                   sf.psi, trusted, temp_std, rate_std)
    return temp_std, grad_std, rate_std, rate_biased


def _space_time_bias(d, ts, t, p, record, s_pr, noise, psi, trusted, temp_std, rate_std):
    """Temperature and rate std with the space-time regression's bias added, and where the rate's temporal
    bias exceeds its noise.

    ``d``: ``(d_rate_t, d_rate_s, d_value_t)`` of :func:`uncertainties`;
    ``ts``: the temporal regression (over the window), evaluated at ``t``;
    ``s_pr`` (K, T_w, N) / ``noise`` (K, T_w, N): noise probes after / before
    the spatial regression. Each difference's noise variance comes from the
    same probes through the same operators (:func:`_local_bias`). The
    temporal bias is judged against the exact interpolation in time of the
    spatially regressed series, whose noise is that of the regressed series
    only: the bias of a fast transient is then resolved well below the
    rate's noise.
    (Against the interpolation of the points' own series its estimate
    scattered by more than the rate's std and was clipped to 0 at half of
    the points.)
    """
    d_rate_t, d_rate_s, d_value_t = d
    W0, W1 = ts.weights(t, 0), ts.weights(t, 1)
    ti = TemporalInterpolant(ts.times, c=p["c_time"], R0=p["R0_time"], smoothing=None,
                             window=temporal_window(record, c=p["c_time"], R0=p["R0_time"]))
    I0, I1 = ti.weights(t, 0), ti.weights(t, 1)
    apply = lambda W, x: np.einsum("ij,kjn->kin", W, x)  # noqa: E731
    var = lambda x: np.mean(np.square(x), axis=0)  # noqa: E731
    b_t = _local_bias(d_rate_t, var(apply(W1 - I1, s_pr)), psi, trusted)
    b_s = _local_bias(d_rate_s, var(apply(W1, s_pr - np.nan_to_num(noise))), psi, trusted)
    # only the temporal bias is resolved well enough to flag by (the spatial one scatters with the points' noise)
    biased = b_t > rate_std
    rate_std = np.sqrt(rate_std ** 2 + b_t ** 2 + b_s ** 2)
    temp_std = np.hypot(temp_std, _local_bias(d_value_t, var(apply(W0 - I0, s_pr)), psi, trusted))
    return temp_std, rate_std, biased


def _local_bias(d, noise_var, psi, trusted=None):
    """Local RMS of a regression's bias from its difference ``d`` to the exact interpolation.

    ``d`` (T, N) or (T, N, C) has the expectation ``b`` (the bias, up to the
    interpolation's own, much smaller, bias) and the noise variance
    ``noise_var`` (same shape, from probes); ``E d² = b² + noise_var``. Both
    are averaged over the :data:`BIAS_NEIGHBOURS` nearest points in the
    surface parameters ``psi`` (N, 2) at the same and the adjacent times
    (the bias varies on the scale of the regression's centre spacing, the
    noise from point to point); ``sqrt(max(0, <d²> - <noise_var>))``, 0 where
    nothing is known. Only ``trusted`` (T, N) points enter the averages: at
    the mask's and the point cloud's edges the interpolation's own error is
    large (those points are flagged as bias-dominated).
    """
    a = np.square(d) - noise_var
    ok = np.isfinite(a)
    if trusted is not None:
        ok &= np.asarray(trusted, dtype=bool).reshape(trusted.shape + (1,) * (a.ndim - 2))
    a = np.where(ok, a, 0.0)
    have = np.flatnonzero(np.isfinite(psi).all(axis=1))
    out = np.zeros_like(a)
    if have.size == 0:
        return out
    from scipy.spatial import cKDTree

    k = min(BIAS_NEIGHBOURS, have.size)
    nb = have[cKDTree(psi[have]).query(psi[have], k=k)[1].reshape(have.size, k)]
    s = np.zeros_like(a)
    n = np.zeros(a.shape)
    s[:, have] = a[:, nb].sum(axis=2)
    n[:, have] = ok[:, nb].sum(axis=2)
    s2, n2 = s.copy(), n.copy()
    s2[1:] += s[:-1]
    s2[:-1] += s[1:]
    n2[1:] += n[:-1]
    n2[:-1] += n[1:]
    np.divide(s2, n2, out=out, where=n2 > 0)
    return np.sqrt(np.maximum(out, 0.0))


def _strain_std(points, sf, t, p, s_x, rng, window=None, trusted=None):
    """Standard uncertainty of the max principal strain: DIC noise probes through the surface fit
    (smoothing frozen) and the strain; NaN when the DIC noise is unknown or zero."""
    T, N = sf.x.shape[:2]
    if not (np.isfinite(s_x) and s_x > 0):
        return np.full((T, N), np.nan)
    x = points["x"].transpose("time", "point", "component").values.astype(float)
    base = strain(sf.tangents, sf.ref_tangents, tensors=False).e_max
    kw = dict(c=p["c_space"], R0=p["R0_space"], c_t=p["c_time"], R0_t=p["R0_time"], solver=p["solver"],
              smoothing=sf.info.get("smoothing", None), smoothing_t=sf.info.get("smoothing_t", None))
    kw = {k: (None if k.startswith("smoothing") and v is not None and v <= 1.0 else v) for k, v in kw.items()}
    if kw["smoothing"] is not None and sf.info.get("smoothing_shape") not in (None, sf.info["smoothing"]):
        # the fit's own pair of spacings (shape, motion), so that the probes regress as the fit did
        kw["smoothing"] = (sf.info["smoothing_shape"], sf.info["smoothing"])
    # every probe fits the same points with the same missing pattern: the spatial factorisations are shared
    kw["operators"] = {}
    # a surface regression's bias: against the exact interpolation of the same coordinates (see _local_bias)
    regressed = kw["smoothing"] is not None or kw["smoothing_t"] is not None
    kws = [kw, {**kw, "smoothing": None, "smoothing_t": None}] if regressed else [kw]
    shape = x.shape if window is None else window.x.shape

    def e_max(kwi, dx, dref):
        pf = fit_surface(x + dx, t, psi=sf.psi, **kwi) if window is None else _window_probe(window, t, sf.psi, kwi,
                                                                                             dx, dref)
        return strain(pf.tangents, pf.ref_tangents, tensors=False).e_max

    bases = [base] + [e_max(kwi, 0.0, 0.0) for kwi in kws[1:]]
    samples = [[] for _ in kws]
    for _ in range(PROBES):
        dx = rng.standard_normal(shape) * s_x
        dref = rng.standard_normal(window.x_ref.shape) * s_x if window is not None else None
        for s, kwi in zip(samples, kws):
            s.append(e_max(kwi, dx, dref))
    std = _probe_std(np.array(samples[0]), base)
    if regressed:
        var = np.mean(np.square((np.array(samples[0]) - base) - (np.array(samples[1]) - bases[1])), axis=0)
        std = np.hypot(std, _local_bias(base - bases[1], var, sf.psi, trusted))
    # the strain is zero by definition at the reference stage (stage 0 of the record): no uncertainty there,
    # whatever rounding the probes leave
    t_ref = t[0] if window is None else window.t_ref[0]
    std[np.asarray(t) == t_ref] = 0.0
    return std


def _window_probe(window, t, psi, kw, dx, dref):
    """A surface fit of a chunk as the fields stage fits it, with the coordinate noise ``dx`` (window) and
    ``dref`` (the record's first two stages) added: over its window, at its times ``t``, with the strain's
    reference from the record's first two stages."""
    dref = np.zeros(window.x_ref.shape) + (0.0 if dref is None else dref)
    pf = fit_surface(window.x + dx, window.t, psi, t_eval=t, record_times=window.record,
                     shape_stage=window.x_ref[0] + dref[0], **kw)
    if window.t[0] > window.t_ref[0]:
        ref = fit_surface(window.x_ref + dref, window.t_ref, psi,
                          t_eval=window.t_ref[:1], **{**kw, "smoothing_t": None})
        pf = pf._replace(ref_x=ref.ref_x, ref_tangents=ref.ref_tangents)
    return pf


def _bias_flags(points, sf, visible, q, sig_n, notes, ends=(True, True)):
    """Where the method's bias, not the noise, dominates: IR fields, rates, strain (appends to ``notes``)."""
    T, N = sf.x.shape[:2]
    ir_bias = near_edge(points, sf, visible)
    if q / np.sqrt(12) > sig_n or not np.isfinite(sig_n):
        ir_bias |= visible
        notes.append(f"IR: the export step {q:g} K exceeds the noise ({sig_n:.3g} K): rounding is a deterministic "
                     "error, the temperature uncertainties do not bound it")
    rate_bias = ir_bias.copy()
    # the one-sided end of the series: only the record's own first and last time (a chunk's window runs on)
    for i, end in zip((0, -1), ends):
        if end:
            rate_bias[i] |= visible[i]
    h = _spacing(sf.psi)
    strain_bias = np.broadcast_to(~(sf.edge_distance >= 2 * h), (T, N)) | sf.filled
    strain_bias = strain_bias & np.isfinite(sf.x).all(axis=-1)
    return ir_bias, rate_bias, strain_bias


def near_edge(points, sf, visible):
    """Visible points within :data:`EDGE_PX` of the mask edge or extrapolated from it (T, N)."""
    status = points["status"].values
    edge = points["edge_distance"].values.astype(float)
    return visible & ((status == Status.EXTRAPOLATED_FROM_EDGE) | ~(edge >= EDGE_PX))


def _median(a):
    a = np.asarray(a)[np.isfinite(a)]
    return float(np.median(a)) if a.size else float("nan")


def _spacing(psi):
    from scipy.spatial import cKDTree

    ok = np.isfinite(psi).all(axis=1)
    p = psi[ok]
    return float(np.median(cKDTree(p).query(p, k=2)[0][:, 1])) if p.shape[0] > 2 else np.nan
