"""Per-point standard uncertainty of the fields stage's results.

Every field of ``fields.zarr`` is, for fixed smoothing parameters and fixed
geometry, a linear function of the IR pixel values (temperature, gradient,
rate) or, to first order, of the DIC coordinates (strain). The noise levels
estimated from the data (``points.zarr`` and :func:`irdic.noise.auto_smoothing`)
are propagated through those same operators:

- IR: white pixel noise ``σ = sqrt(σ_n² + q²/12)`` (``σ_n``: the pixels' own
  noise, ``q``: export step; ``σ`` is the frame-to-frame estimate, which holds
  the rounding as the data do, :func:`~irdic.noise.noise_levels`) gives the
  point temperature, each pixel-gradient component and the local rate the
  standard deviations ``σ g`` with the interpolation's noise gains ``g``
  (measured once by the couple stage on a probe,
  :func:`irdic.noise.interpolation_noise_gains`).
- The paper's relations are linear maps of those per point: the gradient
  ``L g_pix`` (``L``: 3 x 2, ``surface_gradient`` of the unit vectors) has
  component variances ``σ_g² Σ_j L_ij²``; the rate ``∂Θ/∂t + c · g_pix``
  (``c = J v``) has ``σ_r² + σ_g² |c|²``.
- Temporal regression: the rate is ``W1 Θ`` per point series, so its
  variance is ``σ_T² Σ_j W1_ij²`` (the weights of the chosen regression).
  With the spatial regression too, the fields regress in space first and
  then in time (:func:`irdic.fields.space_time.space_time`): the rate
  ``W1 (S Θ)``, value and gradient of ``S (W0 (S Θ))``, all by the probes.
- Spatial regression and strain: propagated by random probes, ``K`` noise
  realisations run through the same operator with the smoothing parameters
  frozen at the chosen values; the standard deviation over the probes.
  In a record longer than :data:`~irdic.uncertainty.probes.PROBE_TIMES` DIC
  times the probes are evaluated at that many times spread over it, and
  every other time takes the nearest probed time's standard deviation: the
  noise propagated by a fixed operator follows the geometry, which changes
  slowly from stage to stage, and the probes' cost no longer grows with the
  record. The strain's probes give the covariance of the strain tensor, and
  the max principal strain's std is its RMS error at the tensor estimated
  from it, the upward noise bias of a (near-)degenerate tensor included
  (:mod:`irdic.uncertainty.strain`).
- Calibration: the temperature gets ``pixel_std |∇_pix Θ|`` (the projected
  position's uncertainty times the pixel gradient) in quadrature, and the
  DIC noise ``σ_x |∇Θ|`` (a point's noisy coordinates place its sample);
  the gradient the DIC noise of its tangent plane
  (:func:`~irdic.uncertainty.gradient_geometry.gradient_dic_var`).
- The probes' noise is scaled to the data's: the residuals of each time's
  spatial regression, data over probes
  (:func:`~irdic.uncertainty.regression_bias.noise_scale`).
- Regression bias: a regression's error is noise plus bias. Its difference
  ``d`` to a less biased reference of the same input (value: the points'
  own series; gradient and strain: the regression with half the spacing,
  :func:`~irdic.uncertainty.regression_bias.reference_spacing`; the rate: a
  local polynomial in time, :func:`~irdic.numerics.temporal.rate_reference_stencil`, and the half spacing)
  has ``E d² = b² + b_ref² + v`` (``v``: the noise variance of ``d``, from the same probes through both
  operators); ``b² = <d²> - <v>`` averaged locally, where it exceeds its own scatter on noise
  (:func:`~irdic.uncertainty.regression_bias.local_bias`), is added to the variance.
  The gradient's reference, from 2 point spacings on, is as biased as the
  regression (``b_ref ≈ b``, :func:`~irdic.uncertainty.regression_bias.reference_options`):
  half of that average, where it exceeds two of its standard errors, over
  the whole specimen where no neighbourhood resolves it: there an RMS over
  the region, not a local value. The strain's likewise, at one standard
  error (:func:`~irdic.uncertainty.regression_bias.strain_reference_options`). The rate's temporal
  bias is at least the part the whole patch shares (:func:`~irdic.uncertainty.regression_bias.common_bias`)
  and its bias on the series' first temporal mode (:func:`~irdic.uncertainty.regression_bias.first_mode_bias`).

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

import functools
import logging
from typing import NamedTuple

import numpy as np

from ..gradient import material_rate, surface_gradient
from ..logs import report
from ..noise import noise_levels
from ..numerics.temporal import TemporalInterpolant, rate_reference_weights, temporal_window
from ..numerics.memory import release
from ..numerics.threads import parallel_map, worker_slices
from ..surface import drop_derivative_weights
from ..vocabulary import Status
from ..footprint.fields import footprint_probes
from .gradient_geometry import position_std
from .probes import BIAS_PROBES, PROBE_GROUP, PROBES, SpreadStack, probe_block, probe_times, spread
from .regression_bias import (BIAS_NEIGHBOURS, common_bias, local_bias, noise_scale, patch_halves,
                              reference_options, reference_spacing, scaled_probes)
from .ring import ring_apart, ring_noise_scale, ring_scatter, value_ring
from .strain import noise_floor_note, strain_std

__all__ = ["uncertainties", "with_strain_std", "paper_std", "uncertainty_notes", "Window", "PROBES", "EDGE_PX",
           "BIAS_NEIGHBOURS"]

log = logging.getLogger(__name__)

#: points closer than this to the mask edge (px) have interpolation bias rather than noise
EDGE_PX = 2.0


class Window(NamedTuple):
    """A time chunk's window (:mod:`irdic.chunks`): what the fields of its own times depend on.

    ``theta`` (T_w, N) degC and ``x`` (T_w, N, 3) mm at the window's times
    ``t`` (T_w,) s; ``x_ref``/``t_ref``: the record's first two stages (the
    strain's reference); ``first``/``last``: the chunk holds the record's
    first/last DIC time; ``record`` (M,) s: the whole record's stage times
    (the temporal operator's window). With footprint temperatures
    (:func:`~irdic.footprint.fields.footprint_temperatures`):
    ``theta_paper`` (T_w, N), the paper's point temperatures, and ``pixel``
    (T_w, N, 2) px, the points' projected positions, ``noise_factor`` (T_w, N)
    their footprint temperatures' (``points.temperature_footprint_noise_factor``), ``extrapolated`` (T_w, N)
    where the couple stage extrapolated them from the mask edge.
    """

    theta: np.ndarray
    t: np.ndarray
    x: np.ndarray
    x_ref: np.ndarray
    t_ref: np.ndarray
    first: bool
    last: bool
    record: np.ndarray
    theta_paper: np.ndarray | None = None
    pixel: np.ndarray | None = None
    noise_factor: np.ndarray | None = None
    extrapolated: np.ndarray | None = None


#: the part of :func:`uncertainties`' time done (the fields stage's progress, :func:`irdic.logs.report`) after
#: the IR noise's probes and after the IR noise's whole share (the probes scaled, the bias estimates); the DIC
#: noise's share of temperature, gradient and strain takes the rest (measured on the moving tube of the
#: benchmarks at 6,552 and 26,180 points: after the probes 25 % and 24 %, after the IR share 57 % and 49 %; the
#: strain's probes, whose reference regressions have centres in proportion to the points, take more of it on more
#: points)
PROGRESS = {"probes": 0.25, "ir": 0.52}


def uncertainties(points, sf, geo, paper, grad, g_pix, t, p, chosen_k, regress_space, seed=0, window=None,
                  spatial=None, ops=None):
    """Standard uncertainties and bias flags of the fields (see the module docstring).

    Parameters
    ----------
    points, sf, geo
        ``points.zarr``, the fitted surface and its geometry (dual basis).
    paper : list of ndarray
        The paper's relations' std from the IR noise alone (:func:`paper_std`);
        emptied here (at paper scale 0.3 GB the caller would hold).
    grad, g_pix : ndarray, shape (T, N, 3) and (T, N, 2)
        The fields' in-plane gradient (K/mm) and the pixel gradients (K/px).
    t : ndarray, shape (T,)
        DIC times (s).
    p : dict
        The fields settings, smoothing options resolved.
    chosen_k : dict
        The centre spacing factors used (None: interpolation) by name.
    regress_space : callable
        ``(theta (T', N), dual (T_d, N, 2, 3) or None, k) -> (grad, value)``:
        the fields stage's spatial regression (dual None: values only).
    seed : int
        Seed of the probes (fixed: the stores are reproducible).
    window : Window, optional
        A time chunk's window: the temporal regression's weights and the
        strain probes run over it, as the chunk's fields do, and only the
        record's own ends are flagged as series ends.
    spatial : tuple, optional
        With the spatial regression of the temperatures: ``(theta, grad, value_in, value[, d_rate_t,
        d_rate_s, d_value_t, b_rate_mode], grad_in)`` (T, N[, 3]): the point temperatures, the regressed
        gradient, the value regression's input and output (their difference gives its bias), and last the
        input whose lighter regression is the gradient's bias reference
        (:func:`~irdic.uncertainty.regression_bias.reference_spacing`; the points' own series after the
        regression in time, or the point temperatures); with a regression in time too (``S_t`` in time,
        ``S`` in space, ``P_t`` the rate's reference in time): the rate of ``S_t S Θ`` minus that of
        ``P_t S Θ`` (the temporal bias), minus that of ``S_t`` of the series at half the spatial spacing
        (the spatial one), the value of ``S_t S Θ`` minus ``S Θ``, and the temporal bias on the first
        temporal mode of ``S Θ`` (:func:`~irdic.uncertainty.regression_bias.first_mode_bias`),
        a floor of the first.
    ops : dict, optional
        The stage's spatial operators (:func:`irdic.surface.shared_interpolant`).

    Returns
    -------
    dict
        ``name -> (std array, bias_dominated array)`` for ``temperature``,
        ``temperature_gradient``, ``temperature_rate``; ``"notes"``: list of
        str; ``"strain"``: the max principal strain's part, pending
        (:func:`with_strain_std` runs it once the caller has let go of the
        IR terms' inputs: at paper scale GBs).
    """
    rng = np.random.default_rng(seed)
    a = points.attrs
    visible = np.isfinite(points["temperature"].values.astype(float))
    sig_n, q, sigma, (s_T, _, _) = _ir_noise(a)
    notes = []
    ends = (True, True) if window is None else (window.first, window.last)
    ir_bias, rate_bias, strain_bias = _bias_flags(points, sf, visible, q, sig_n, notes, ends)
    trusted = ~(near_edge(points, sf, visible) | strain_bias)  # the bias references are accurate there
    if ops is not None and _regressions_only(sf, chosen_k.get("temperature_smoothing_space")):
        drop_derivative_weights(ops)  # no exact interpolation's derivatives from here on
    temp_std, grad_std, rate_std, rate_biased = _ir_std(sf, paper, t, p, chosen_k, regress_space, geo, visible, rng,
                                                        s_T, window, spatial, trusted,
                                                        **_probe_inputs(points, sf, window, sigma))
    rate_bias |= _rate_bias_flags(rate_biased, visible, notes)
    report("uncertainty", PROGRESS["ir"])
    s_x = float(a.get("dic_noise_mm", np.nan))
    temp_std, grad_std = position_std(points, sf, geo, grad, g_pix, temp_std, grad_std, s_x, p, spatial is not None,
                                      rng, ops)
    for arr in (temp_std, rate_std, grad_std):
        arr[~visible] = np.nan
    # the strain's probes draw from the same stream after the IR terms' (the record's numbers do not depend on
    # when they run)
    pending = functools.partial(strain_std, points, sf, t, p, s_x, rng, window, ~strain_bias, ops)
    return {"temperature": (temp_std, ir_bias), "temperature_rate": (rate_std, rate_bias),
            "temperature_gradient": (grad_std, np.repeat(ir_bias[..., None], 3, axis=-1)), "notes": notes,
            "strain": (pending, np.array(strain_bias), sigma, s_T, s_x)}


def with_strain_std(unc):
    """The uncertainties ``unc`` of :func:`uncertainties` complete: the max principal strain's std and bias
    flags (``max_principal_strain``) computed, ``notes`` a str for the attrs.

    The strain's probes refit the surface (:func:`~irdic.uncertainty.strain.strain_std`); run apart from
    :func:`uncertainties`, after the caller has let go of the regressions' inputs, the projection and the
    dual basis, they do not add to the IR terms' memory.
    """
    unc = dict(unc)
    pending, strain_bias, sigma, s_T, s_x = unc.pop("strain")
    e_std = pending()
    notes = list(unc["notes"])
    if not np.isfinite(s_x):
        notes.append("max_principal_strain_std: the DIC noise could not be estimated")
    log.info("fields: uncertainty from IR noise %.3g K (point %.3g K) and DIC noise %.3g mm; median std: temperature "
             "%.3g K, rate %.3g K/s, max principal strain %.3g", sigma, s_T, s_x, _median(unc["temperature"][0]),
             _median(unc["temperature_rate"][0]), _median(e_std))
    unc["max_principal_strain"] = (e_std, strain_bias)
    unc["notes"] = "; ".join(notes) if notes else "none"
    return unc


def paper_std(points, sf, J):
    """The std of the paper's temperature (T, N) K, in-plane gradient (T, N, 3) K/mm and rate (T, N) K/s from
    the IR noise alone: the point-level noise of ``points.zarr``'s attrs through the paper's relations.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr`` (its noise attrs: :func:`_ir_noise`).
    sf : SurfaceFit
        The fitted surface (tangents, velocity).
    J : ndarray, shape (T, N, 2, 3)
        The projection Jacobian (px/mm).

    Notes
    -----
    The gradient is ``L g_pix`` with ``L`` = ``surface_gradient`` of the
    unit vectors, so component ``i`` has the variance ``σ_g² Σ_j L_ij²``;
    the rate ``∂Θ/∂t + c · g_pix`` (``c = J v``) has ``σ_r² + σ_g² |c|²``.
    Computed where the Jacobian is at hand, so that it need not be kept for
    the uncertainty (at paper scale 0.36 GB).
    """
    _, _, _, (s_T, s_g, s_r) = _ir_noise(points.attrs)
    T, N = sf.x.shape[:2]
    grad, rate = np.empty((T, N, 3)), np.empty((T, N))

    def block(sl):  # pointwise: blocks of times on the stage's threads give the same numbers
        e = np.zeros(J[sl].shape[:2] + (2,))
        e[..., 0] = 1
        Lu = surface_gradient(e, J[sl], sf.tangents[sl])
        cu = material_rate(np.zeros(e.shape[:2]), e, J[sl], sf.velocity[sl]).convective
        e[..., 0], e[..., 1] = 0, 1
        Lv = surface_gradient(e, J[sl], sf.tangents[sl])
        cv = material_rate(np.zeros(e.shape[:2]), e, J[sl], sf.velocity[sl]).convective
        grad[sl] = s_g * np.sqrt(Lu ** 2 + Lv ** 2)
        rate[sl] = np.sqrt(s_r ** 2 + s_g ** 2 * (cu ** 2 + cv ** 2))

    parallel_map(block, worker_slices(T))
    return np.full((T, N), s_T), grad, rate


def uncertainty_notes(unc, e_max):
    """The store's ``uncertainty_notes``: those of :func:`uncertainties` (``unc``), and where the max principal
    strain ``e_max`` (T, N), which the fields stage computes after them, is below its noise floor
    (:func:`~irdic.uncertainty.strain.noise_floor_note`)."""
    floor = noise_floor_note(e_max, unc["max_principal_strain"][0])
    return "; ".join(n for n in (unc["notes"], floor) if n and n != "none") or "none"


def _rate_bias_flags(rate_biased, visible, notes):
    """Where the temporal regression's estimated bias exceeds the rate's noise (T, N), with its note."""
    if rate_biased is None:
        return np.zeros(visible.shape, bool)
    if rate_biased.any():
        # no count: a time chunk's note becomes the gathered store's
        notes.append("temperature_rate: the temporal regression's estimated bias exceeds the noise where "
                     "temperature_rate_bias_dominated is set; there the std holds the local RMS of that "
                     "estimate, not a Gaussian width")
    return rate_biased & visible


def point_noise(a) -> float:
    """The point temperatures' white noise (K) from ``points.zarr``'s attrs ``a`` (:func:`_ir_noise`); NaN where
    they do not record it."""
    return _ir_noise(a)[3][0]


def _ir_noise(a):
    """Pixel noise (K) of points.zarr's attrs: the pixels' own noise, the export step, the noise the exported values
    carry (:func:`~irdic.noise.noise_levels`), and the point-level noise of temperature, pixel gradient and local
    rate (via the interpolation's noise gains)."""
    # the estimate holds the export's rounding as the data do (irdic.noise.noise_levels): not added once more
    sig_n, q, sigma = noise_levels(a)
    gains = (sigma * float(a.get(f"ir_noise_gain_{g}", np.nan))
             for g in ("temperature", "gradient_per_px", "rate_per_s"))
    return sig_n, q, sigma, tuple(gains)


def _ir_std(sf, paper, t, p, chosen_k, regress_space, geo, visible, rng, s_T, window=None, spatial=None,
            trusted=None, footprint=None, theta_paper=None, apart=0.0):
    """Standard uncertainties of temperature, in-plane gradient and rate from the IR noise and the regressions'
    bias (:func:`~irdic.uncertainty.regression_bias.local_bias`); last, where the rate's estimated bias exceeds
    its noise (T, N), or None. ``paper``: the paper's relations' (:func:`paper_std`), where nothing is regressed;
    ``s_T`` the point temperatures' noise (K).
    ``footprint``: ``(draw, s_paper)`` of :func:`~irdic.footprint.fields.footprint_probes`, with
    ``theta_paper`` (T, N) the paper's point temperatures. The probes' noise is scaled to the data's
    (:func:`~irdic.uncertainty.regression_bias.noise_scale`). ``apart``: the least distance (mm of the surface
    parameters) between the points the value's difference is averaged over
    (:func:`~irdic.uncertainty.ring.ring_apart`)."""
    T, N = visible.shape
    temp_std, grad_std, rate_std = paper
    paper.clear()

    kt, ks = chosen_k.get("temperature_smoothing"), chosen_k.get("temperature_smoothing_space")
    W = rate_biased = None
    if kt is not None:
        # a chunk's regression runs over its window (T_w samples) and is evaluated at its own times
        record = t if window is None else window.record

        def operator(k):  # the record's windowed temporal operator over the regression's samples
            return TemporalInterpolant(t if window is None else window.t, c=p["c_time"], R0=p["R0_time"],
                                       smoothing=k, window=temporal_window(record, c=p["c_time"], R0=p["R0_time"],
                                                                           smoothing=k))

        ts, ti = operator(kt), operator(None)
        # the rate and the value may come from lighter regressions than the gradient
        # (irdic.fields.space_time._rate_series, irdic.fields.smoothing.value_time_smoothing)
        kr = chosen_k.get("temperature_smoothing_rate") or kt
        kv = chosen_k.get("temperature_smoothing_value") or kt
        tr = ts if kr == kt else operator(kr)
        W0 = ts.weights(t, 0)
        # the rate's bias reference: a local polynomial in time (irdic.fields.space_time.space_time)
        W = (W0, tr.weights(t, 1), ti.weights(t, 0), rate_reference_weights(ti.times, t, smoothing=kr),
             W0 if kv == kt else operator(kv).weights(t, 0))
        rate_std = np.broadcast_to(s_T * np.sqrt(np.sum(W[1] ** 2, axis=1))[:, None], (T, N)).copy()
        temp_std = np.broadcast_to(s_T * np.sqrt(np.sum(W[4] ** 2, axis=1))[:, None], (T, N)).copy()
    if ks is not None:
        draw, s_paper = (None, None) if footprint is None else footprint
        pix_draw = None
        if draw is not None and s_paper is None:  # no footprint: one set of probes, with the pixels' correlation
            pix_draw, draw = draw, None
        # the probes' stds replace these: not held through the probes (at paper scale 0.3 GB)
        temp_std = grad_std = None
        rate_std = None if W is not None else rate_std
        # the value is regressed from the paper's temperatures: their own noise through the operators
        # the value's difference is averaged over each point's nearest before it is squared (value_ring)
        ring = value_ring(sf.psi, ks, apart) if spatial is not None else None
        halves = patch_halves(sf.psi) if spatial is not None and W is not None else None  # common_bias's null
        acc = _spatial_probes(t, regress_space, geo, visible, rng, s_T if draw is None else s_paper, ks, W, window,
                              spatial is not None, pix_draw, ring, halves)
        own = None if spatial is None else spatial[0]  # the regressions' input (the footprint's, with one)
        acc = scaled_probes(acc, noise_scale(own if draw is None else theta_paper, acc, regress_space, ks, trusted))
        del acc["res"]  # the residuals' sole use
        if draw is not None:
            # the gradient and rate from the footprint temperatures: their correlated noise, drawn from a stream
            # of its own (the other probes' draws stay as they were); the paper temperatures' of these are
            # dropped first (GBs at paper scale)
            keys = ("g", "g_var", "r", "rt_var", "rs_var", "g_var_null", "rt_var_null", "rs_var_null", "rt_common_null")
            for k in keys:
                acc.pop(k)
            acc_fp = _spatial_probes(t, regress_space, geo, visible, rng.spawn(1)[0], s_T, ks, W, window,
                                     spatial is not None, draw, halves=halves)
            acc_fp = scaled_probes(acc_fp, noise_scale(own, acc_fp, regress_space, ks, trusted))
            del acc_fp["res"]
            acc.update({k: acc_fp[k] for k in keys})
            del acc_fp
        release()  # the probes' groups are freed before the bias estimates' pool
        temp_std, grad_std = np.sqrt(acc.pop("v")), np.sqrt(acc.pop("g"))
        if W is not None:
            rate_std = np.sqrt(acc.pop("r"))
        if spatial is not None:
            temp_std, grad_std, rate_std, rate_biased = _bias_terms(spatial, acc, sf.psi, trusted, ks, regress_space,
                                                                    geo, W is not None, temp_std, grad_std, rate_std,
                                                                    ring)
    release()  # the probes' and bias estimates' blocks are freed: what follows starts on returned pages
    return temp_std, grad_std, rate_std, rate_biased


def _bias_terms(spatial, acc, psi, trusted, ks, regress_space, geo, in_time, temp_std, grad_std, rate_std, ring):
    """Temperature, gradient and rate std with the regressions' estimated bias added
    (:func:`~irdic.uncertainty.regression_bias.local_bias`), and where the rate's temporal bias exceeds its noise
    (T, N) or None; ``spatial`` and ``acc`` as in :func:`_ir_std`, ``in_time``: with a regression in time,
    ``ring``: the mean the value's difference takes before it is squared, as the probes' did, or None
    (:func:`~irdic.uncertainty.ring.value_ring`)."""
    theta, grad, value_in, value = spatial[:4]
    # against the lighter regression of the gradient's input after the same regression in time (the value's
    # reference; the points' own series carried the temporal bias and full noise)
    d_grad = grad - regress_space(spatial[-1], geo.dual, reference_spacing(ks) or 1.0)[0]
    # the interpolation of the input at the points is the input; the estimates (sparse products) on the threads
    nbs = {}  # the neighbourhoods of the points, shared by the bias estimates below
    d_value, scatter = (value - value_in, None) if ring is None else ring_scatter(ring, value - value_in)
    # the probes' noise in the value's ring mean scaled to the data's (ring_noise_scale)
    k2 = ring_noise_scale(scatter, acc.pop("v_spread", None), trusted)
    for key in ("v_var", "v_var_null"):
        if k2 != 1.0 and acc.get(key) is not None:
            acc[key] *= k2
    del scatter
    jobs = [(d_grad, "g_var", reference_options(ks)), (d_value, "v_var", {})]
    temporal = len(spatial) > 5 and in_time
    if temporal:  # the space-time regression's terms (_space_time_bias); the rate's spatial one, as the gradient's
        jobs += [(d, key, reference_options(ks) if key == "rs_var" else {})
                 for d, key in zip(spatial[4:7], ("rt_var", "rs_var", "vt_var"))]
    # one pool for all, the gradient's (three components) first: the threads stay busy to the end
    b = parallel_map(lambda a: local_bias(a[0], acc[a[1]], psi, trusted, acc[a[1] + "_null"], ks, nbs, **a[2]),
                     jobs)
    del jobs, d_grad, d_value  # the differences, each (T, N[, 3]), before the sums below
    grad_std, temp_std = np.hypot(grad_std, b[0]), np.hypot(temp_std, b[1])
    if not temporal:
        return temp_std, grad_std, rate_std, None
    common = common_bias(spatial[4], psi, trusted, acc.get("rt_common_null"))[:, None]
    b[2] = np.maximum(np.maximum(b[2], spatial[7]), common)
    temp_std, rate_std, biased = _space_time_bias(b[2:], temp_std, rate_std)
    return temp_std, grad_std, rate_std, biased


def _spatial_probes(t, regress_space, geo, visible, rng, s_T, ks, W, window, bias, draw=None, ring=None,
                    halves=None):
    """Noise probes through the spatial (and temporal) regression of the temperatures.

    :data:`~irdic.uncertainty.probes.PROBES` white-noise fields of the point noise ``s_T`` (K) run
    through the regressions with the smoothing frozen, :data:`~irdic.uncertainty.probes.PROBE_GROUP` at
    a time (one regression call each, so memory does not grow with the
    probes; a group's probes split over the stage's threads,
    :func:`~irdic.uncertainty.probes.probe_block`). Returns the mean squares over the probes (T, N): ``v`` (value),
    ``g`` (T, N, 3, gradient), ``r`` (rate, with ``W``); with ``bias``, the noise variance of the regression's
    difference to the exact interpolation (``v_var``, ``g_var``; ``rt_var``, ``rs_var``, ``vt_var`` of
    :func:`_space_time_bias`), which :func:`~irdic.uncertainty.regression_bias.local_bias` subtracts.
    The probes are evaluated at the :data:`~irdic.uncertainty.probes.PROBE_TIMES` times of
    :func:`~irdic.uncertainty.probes.probe_times` (the regression in time mixes all of them first);
    every other time takes the nearest one's mean squares (:func:`~irdic.uncertainty.probes.spread`).
    ``draw(rng, b)``: ``b`` unit-variance noise fields (b, T_w, N) with the input's spatial correlation instead
    of white ones; ``halves``: as :func:`~irdic.uncertainty.probes.probe_block`'s (``rt_common_null``).
    """
    T, N = visible.shape
    sub, near = probe_times(T)
    acc = dict.fromkeys(("v", "g", "r", "v_var", "g_var", "rt_var", "rs_var", "vt_var", "res", "v_spread"), 0.0)
    n_bias = 0  # probes through the exact interpolation (whole groups, the first BIAS_PROBES or more)
    # each of the first BIAS_PROBES probes' squared differences: the bias estimates' own scatter on noise
    nulls = {k: [] for k in ("v_var", "g_var", "rt_var", "rs_var", "vt_var", "rt_common")}
    tw, off = _probe_window(rng, t, N, window) if W is not None else (T, 0)
    seen = visible if tw == T else np.isfinite(window.theta)
    for start in range(0, PROBES, PROBE_GROUP):
        b = min(PROBE_GROUP, PROBES - start)
        # scaled in place: a group's noise is GBs at paper scale, a scaled copy as much again
        noise = rng.standard_normal((b, tw, N)) if draw is None else np.array(draw(rng, b), dtype=float)
        noise *= s_T
        noise[:, ~seen] = np.nan
        ref_k = (reference_spacing(ks) or 1.0) if bias and start < BIAS_PROBES else None

        def part(rows):  # the group's probes split over the stage's threads: the group's memory, not more
            return probe_block(noise[rows], regress_space, geo, visible, ks, W, sub, off, bias, ref_k, ring, halves)

        parts = parallel_map(part, worker_slices(b))
        del noise
        for sums, squares in parts:
            for k, a in sums.items():  # the exact interpolation's over the probes that ran through it (below)
                acc[k] = acc[k] + (a if k == "g_var" else a / PROBES)
            for k, a in squares.items():
                nulls[k] += a
        if ref_k is not None:
            n_bias += b
        report("uncertainty", PROGRESS["probes"] * (start + b) / PROBES)
    if n_bias:
        acc["g_var"] = acc["g_var"] / n_bias
    # the noise variances of the bias estimates' differences, and the nulls, stay at the probed times:
    # local_bias reads them a block of times at a time (SpreadStack; ~0.4 GB less at paper scale)
    out = {k: (SpreadStack(a[None], near) if k in nulls else spread(a, near)) if np.ndim(a) else a
           for k, a in acc.items()}
    return {**out, **{f"{k}_null": SpreadStack(np.array(n), near) if n else None for k, n in nulls.items()}}


def _regressions_only(sf, ks):
    """Whether every spatial operator the uncertainty evaluates derivatives with is a regression: the surface's
    (shape and motion) and the strain's reference (:func:`~irdic.uncertainty.strain.strain_std`), the
    temperature's (``ks``) and the gradient's reference; not the exact interpolation (spacing None or 1)."""
    def regression(k):
        return k is not None and float(k) > 1.0

    surface = (sf.info.get("smoothing_shape") or sf.info.get("smoothing"), sf.info.get("smoothing"))
    if not all(map(regression, surface)) or (ks is not None and not regression(ks)):
        return False
    references = list(reference_spacing(surface) or [None]) + ([reference_spacing(ks)] if ks is not None else [])
    return all(map(regression, references))


def _probe_window(rng, t, N, window):
    """The times the probes' temporal regression mixes, and the offset of ``t`` among them: a chunk's window
    (``rng`` then passes over the record-length draw, which a whole record's probes make), or ``t`` itself."""
    if window is None:
        return t.size, 0
    for start in range(0, PROBES, PROBE_GROUP):
        rng.standard_normal((min(PROBE_GROUP, PROBES - start), t.size, N))
    return window.t.size, int(np.searchsorted(window.t, t[0]))


def _probe_inputs(points, sf, window, sigma):
    """The :func:`_ir_std` keywords from the points: the footprint's probes
    (:func:`~irdic.footprint.fields.footprint_probes`), the paper's temperatures, and the ring's least distance
    (:func:`~irdic.uncertainty.ring.ring_apart` of the pixel positions, the chunk window's with one;
    0 without them)."""
    if window is not None and getattr(window, "pixel", None) is not None:
        apart = ring_apart(window.pixel, sf.psi)
    else:
        apart = ring_apart(points["pixel"].transpose("time", "point", "axis").values, sf.psi) if "pixel" in points \
            else 0.0
    return dict(footprint=footprint_probes(points, window, sigma), theta_paper=_values(points, "temperature_paper"),
                apart=apart)


def _values(points, name):
    return points[name].values.astype(float) if name in points else None


def _space_time_bias(b, temp_std, rate_std):
    """Temperature and rate std with the space-time regression's bias added, and where the rate's temporal
    bias exceeds its noise.

    ``b``: :func:`~irdic.uncertainty.regression_bias.local_bias` of ``(d_rate_t, d_rate_s, d_value_t)`` of
    :func:`uncertainties` (T, N) each, with the probes' noise variances of those differences
    (:func:`_spatial_probes`: ``rt_var``, ``rs_var``, ``vt_var``), each through the same operators as the
    difference. The temporal bias is judged against a local polynomial in time of the
    spatially regressed series (:func:`~irdic.numerics.temporal.rate_reference_stencil`;
    the IMQ interpolant was as biased as the regression), whose noise is that
    of the regressed series only: the bias of a fast transient is then
    resolved well below the rate's noise. (Against the points' own series
    its estimate scattered by more than the rate's std.) A slow series'
    regression (centres 6 or more stages apart) is judged against a
    least-squares polynomial over two of its spacings: the quartic through 5
    stages put 9 x the ripple's RMS of noise into the difference, and the
    demo barrel's rate covered 0.63-0.69 / 0.89-0.93 of its errors within 1 /
    2 std (seeds 1, 3, 5, 7); now 0.66-0.73 / 0.92-0.95.
    """
    b_t, b_s, b_v = b
    # only the temporal bias is resolved well enough to flag by (the spatial one scatters with the points' noise)
    biased = b_t > rate_std
    rate_std = np.sqrt(rate_std ** 2 + b_t ** 2 + b_s ** 2)
    return np.hypot(temp_std, b_v), rate_std, biased


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
