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
- Spatial regression and strain: propagated by random probes, ``K`` noise
  realisations run through the same operator with the smoothing parameters
  frozen at the chosen values; the standard deviation over the probes.
- Calibration: the temperature gets ``pixel_std |∇_pix Θ|`` (the projected
  position's uncertainty times the pixel gradient) in quadrature.

Where the method's own bias dominates the noise the std is not a bound on the
error and ``<field>_bias_dominated`` says so: within 2 px of the mask edge or
extrapolated (temperature, gradient, rate), the first and last DIC time
(rate: the one-sided end of the series), the export step larger than the
noise (rounding is then a deterministic error, not noise), and for the strain
points within two point spacings of the point cloud's edge.
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

__all__ = ["uncertainties", "Window", "PROBES", "EDGE_PX"]

log = logging.getLogger(__name__)

#: random probes of the operators propagated by Monte Carlo
PROBES = 16
#: points closer than this to the mask edge (px) have interpolation bias rather than noise
EDGE_PX = 2.0


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


def uncertainties(points, sf, geo, J, g_pix, t, p, chosen_k, regress_space, seed=0, window=None):
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
        ``regress_space(theta (T', N), dual (T', N, 2, 3), k) -> (grad, value)``:
        the spatial regression of the fields stage.
    seed : int
        Seed of the probes (fixed: the stores are reproducible).
    window : Window, optional
        A time chunk's window: the temporal regression's weights and the
        strain probes run over it, as the chunk's fields do, and only the
        record's own ends are flagged as series ends.

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
    temp_std, grad_std, rate_std = _ir_std(sf, J, t, p, chosen_k, regress_space, geo, visible, rng,
                                           s_T, s_g, s_r, window)
    # calibration: the projected position's uncertainty moves the sample along the pixel gradient
    pix_std = points["pixel_std"].values.astype(float) if "pixel_std" in points else np.zeros((T, N))
    cal = np.nan_to_num(pix_std) * np.linalg.norm(np.nan_to_num(g_pix), axis=-1)
    temp_std = np.sqrt(temp_std ** 2 + cal ** 2)
    s_x = float(a.get("dic_noise_mm", np.nan))
    strain_std = _strain_std(points, sf, t, p, s_x, rng, window)
    if not np.isfinite(s_x):
        notes.append("max_principal_strain_std: the DIC noise could not be estimated")
    ends = (True, True) if window is None else (window.first, window.last)
    ir_bias, rate_bias, strain_bias = _bias_flags(points, sf, visible, q, sig_n, notes, ends)
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


def _ir_std(sf, J, t, p, chosen_k, regress_space, geo, visible, rng, s_T, s_g, s_r, window=None):
    """Standard uncertainties of temperature, in-plane gradient and rate from the IR noise."""
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
    W0 = None
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
        if W0 is not None:
            if window is not None:
                # the temporal regression of a chunk mixes its window's noise
                noise = rng.standard_normal((PROBES, window.t.size, N)) * s_T
                noise[:, ~np.isfinite(window.theta)] = np.nan
            smoothed = np.einsum("ij,kjn->kin", W0, np.nan_to_num(noise))
            smoothed[:, ~visible] = np.nan
            _, v_pr = regress_space(smoothed.reshape(PROBES * T, N), dual, ks)
        temp_std = _probe_std(v_pr.reshape(PROBES, T, N), 0.0)
    return temp_std, grad_std, rate_std


def _strain_std(points, sf, t, p, s_x, rng, window=None):
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
    samples = []
    for _ in range(PROBES):
        if window is None:
            pf = fit_surface(x + rng.standard_normal(x.shape) * s_x, t, psi=sf.psi, **kw)
        else:
            pf = _window_probe(window, t, sf.psi, kw, s_x, rng)
        samples.append(strain(pf.tangents, pf.ref_tangents, tensors=False).e_max)
    return _probe_std(np.array(samples), base)


def _window_probe(window, t, psi, kw, s_x, rng):
    """A noisy surface fit of a chunk as the fields stage fits it: over its window, at its times ``t``,
    with the strain's reference from the record's first two stages (noise drawn for those too)."""
    pf = fit_surface(window.x + rng.standard_normal(window.x.shape) * s_x, window.t, psi, t_eval=t,
                     record_times=window.record, **kw)
    if window.t[0] > window.t_ref[0]:
        ref = fit_surface(window.x_ref + rng.standard_normal(window.x_ref.shape) * s_x, window.t_ref, psi,
                          t_eval=window.t_ref[:1], **{**kw, "smoothing_t": None})
        pf = pf._replace(ref_x=ref.ref_x, ref_tangents=ref.ref_tangents)
    return pf


def _bias_flags(points, sf, visible, q, sig_n, notes, ends=(True, True)):
    """Where the method's bias, not the noise, dominates: IR fields, rates, strain (appends to ``notes``)."""
    T, N = sf.x.shape[:2]
    status = points["status"].values
    edge = points["edge_distance"].values.astype(float)
    near_edge = visible & ((status == Status.EXTRAPOLATED_FROM_EDGE) | ~(edge >= EDGE_PX))
    ir_bias = near_edge.copy()
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


def _median(a):
    a = np.asarray(a)[np.isfinite(a)]
    return float(np.median(a)) if a.size else float("nan")


def _spacing(psi):
    from scipy.spatial import cKDTree

    ok = np.isfinite(psi).all(axis=1)
    p = psi[ok]
    return float(np.median(cKDTree(p).query(p, k=2)[0][:, 1])) if p.shape[0] > 2 else np.nan
