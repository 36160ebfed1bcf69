"""Noise levels estimated from the data themselves, and the ``auto`` smoothing rule.

IR frames
    Temporal noise: a fourth divided difference over five consecutive frames
    at each specimen pixel, with weights of unit sum of squares, so that
    white noise of standard deviation σ gives residuals of standard
    deviation σ while a field cubic in time gives none (a pattern moving
    across the pixels, as a band does on the specimen, leaves little of
    itself: :func:`temporal_residual`). Spatial noise: the same with a
    five-point Laplacian (:func:`spatial_noise`). σ is the residuals' standard
    deviation within 4 robust ones (:func:`clipped_std`), so that edge pixels,
    hot spots and the odd dead pixel do not inflate it.
    Quantisation: the export's step, the smallest non-zero difference of the
    values when every value is a multiple of it.

DIC coordinates
    At every point the k nearest neighbours of a stage define a local frame
    (PCA); the normal coordinate is fitted by a quadric in the two tangent
    coordinates over the neighbours without the point, and the point's
    leave-one-out residual, divided by ``sqrt(1 + h)`` (h: the prediction's
    leverage), has standard deviation σ for isotropic coordinate noise σ.
    Only the normal direction is observable from one stage's shape; σ is
    reported per component on the assumption of isotropic noise.

The ``auto`` rule (:func:`choose_smoothing`)
    Exact interpolation passes the noise to a derivative with a gain of
    about ``sqrt(2) / spacing`` (a difference of two independent samples one
    sample spacing apart). When that noise exceeds :data:`NOISE_TO_SIGNAL`
    of the derivative's typical magnitude (its RMS over the data), the
    regression (GCV) is chosen; otherwise the paper's interpolation.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

__all__ = ["IRNoise", "NoiseGains", "interpolation_noise_gains", "ir_noise", "quantisation_step", "spatial_noise",
           "noise_levels", "temporal_residual", "TEMPORAL_ORDER", "dic_noise", "choose_smoothing", "mad_std",
           "clipped_std", "CLIP_SIGMAS", "NOISE_TO_SIGNAL", "STRAIN_NOISE_FLOOR", "auto_smoothing"]

log = logging.getLogger(__name__)

#: relative noise of a derivative above which ``auto`` regresses instead of interpolating
NOISE_TO_SIGNAL = 0.02
#: strain noise (interpolated coordinates) above which ``auto`` regresses the surface
STRAIN_NOISE_FLOOR = 1e-4
_MAD = 1.482602218505602  # 1 / Phi^-1(3/4): MAD -> standard deviation for Gaussian data
_MAX_FRAMES = 64


def mad_std(r) -> float:
    """Robust standard deviation ``1.4826 median|r - median r|`` of the finite values of ``r`` (NaN if none)."""
    r = np.asarray(r, dtype=float).ravel()
    r = r[np.isfinite(r)]
    if r.size == 0:
        return float("nan")
    return float(_MAD * np.median(np.abs(r - np.median(r))))


#: robust standard deviations beyond which :func:`clipped_std` leaves a value out (a Gaussian loses 0.05 % of its std)
CLIP_SIGMAS = 4.0


def clipped_std(r) -> float:
    """Standard deviation of the finite values of ``r`` within :data:`CLIP_SIGMAS` robust standard deviations
    (:func:`mad_std`) of their median (NaN if none).

    As robust to outliers (dead pixels, reflections) as the MAD, but not
    quantised by exported rounding: residuals of values rounded to 0.01 K
    take a few discrete values, and their median with them (white noise of
    0.02 / 0.05 / 0.1 K at 2 decimals: the MAD's estimate 10 % / 3 % low,
    3 % high; this one within 0.3 %). Where the MAD is 0 (noise below the
    rounding) the plain standard deviation.
    """
    r = np.asarray(r, dtype=float).ravel()
    r = r[np.isfinite(r)]
    if r.size == 0:
        return float("nan")
    d = r - np.median(r)
    s = mad_std(r)
    if s > 0:
        d = d[np.abs(d) <= CLIP_SIGMAS * s]
    return float(np.sqrt(np.mean(np.square(d - d.mean()))))


@dataclass(frozen=True)
class IRNoise:
    """Noise of the IR frames at the specimen pixels (K); NaN where it could not be estimated."""

    temporal: float
    spatial: float
    quantisation: float
    pixels: int

    @property
    def level(self) -> float:
        """The frame-to-frame noise (NETD) and, failing that, the spatial estimate (K)."""
        return self.temporal if np.isfinite(self.temporal) else self.spatial


def quantisation_step(values) -> float:
    """Quantisation step of exported values (K), 0 when the values are not on a grid.

    Parameters
    ----------
    values : array_like
        Temperatures (any shape; NaN ignored).

    Returns
    -------
    float
        The smallest positive difference ``q`` of the distinct values when all
        values are integer multiples of ``q`` (to 2 % of ``q``, float32
        storage), snapped to 1, 2 or 5 times a power of ten within 1 %;
        otherwise 0.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size < 3:
        return 0.0
    u = np.unique(v)
    if u.size < 2:
        return 0.0
    # float32 storage blurs steps by its resolution (a few ulp): steps that small are no export step
    tol = 16 * np.finfo(np.float32).eps * max(1.0, float(np.max(np.abs(u))))
    d = np.diff(u)
    d = d[d > tol]
    if d.size == 0:
        return 0.0
    q = float(np.min(d))
    if q < 4 * tol:
        return 0.0
    # snap to a decimal step (1, 2 or 5 times a power of ten) first: float32 storage blurs the differences
    e = 10.0 ** np.floor(np.log10(q))
    for m in (1.0, 2.0, 5.0, 10.0):
        if abs(q / (m * e) - 1) < 0.01:
            q = float(m * e)
            break
    k = u / q
    if np.max(np.abs(k - np.rint(k))) > 0.02 + tol / q:
        return 0.0
    return q


#: order of the divided difference in time whose residual gives the temporal noise (:func:`temporal_residual`)
TEMPORAL_ORDER = 4


def temporal_residual(f, t) -> np.ndarray:
    """The divided difference of order ``len(t) - 1`` of the values ``f`` (len(t), ...) at times ``t``, scaled to
    unit sum of squares of its weights: white noise of standard deviation σ gives residuals of standard deviation
    σ, a field polynomial in time of a lower order none.

    Notes
    -----
    ``r = Σ_j w_j f_j / |w|`` with ``w_j = 1 / Π_{i≠j} (t_j - t_i)`` (unequal
    frame spacings too). A pattern moving at ``v`` across a pixel gives the
    second difference ``(v h)² f''`` (``h``: the frame period), the fourth
    ``(v h)⁴ f⁽⁴⁾``: of a band 2 mm wide moving 0.1 mm per frame the former
    holds ~(0.1 / 2)² of its amplitude, the latter ~(0.1 / 2)⁴ (the noisy
    family's static barrel with a moving band, drawn-101: the second
    difference read 1.20 x the pixel noise, the fourth 1.003 x). A purely
    temporal residual keeps the noise's level where neighbouring pixels'
    noise is correlated (a real camera's rows: a spatial residual reads half
    the noise there).
    """
    t = np.asarray(t, dtype=float)
    w = np.array([1.0 / np.prod([t[j] - t[i] for i in range(t.size) if i != j]) for j in range(t.size)])
    return np.tensordot(w / np.linalg.norm(w), np.asarray(f, dtype=float), axes=1)


def ir_noise(frames, times, mask) -> IRNoise:
    """Temporal and spatial noise and quantisation step of IR frames at specimen pixels.

    Parameters
    ----------
    frames : array_like or xarray.DataArray, shape (n_frames, n_v, n_u)
        Temperatures (K or °C); may be lazy, at most 64 frames are read.
    times : array_like, shape (n_frames,)
        Frame times (s), increasing.
    mask : ndarray of bool, shape (n_v, n_u)
        Pixels on the specimen in every frame.

    Returns
    -------
    IRNoise

    Notes
    -----
    Temporal residual of :data:`TEMPORAL_ORDER` + 1 consecutive frames
    (:func:`temporal_residual`), windows spread over the record. Spatial
    residual ``(4 f - f_N - f_S - f_E - f_W) /
    sqrt(20)`` at pixels whose four neighbours are also on the mask. Both
    have standard deviation σ for white noise; the export's rounding adds
    its ``q² / 12`` to σ², as it does to the data. Their spread by
    :func:`clipped_std` (the MAD of rounded exports is itself quantised).
    """
    mask = np.asarray(mask, dtype=bool)
    t = np.asarray(times, dtype=float)
    n = t.size
    npx = int(mask.sum())
    if npx == 0:
        return IRNoise(np.nan, np.nan, 0.0, 0)
    # windows of consecutive frames spread over the record (fewer frames than a window: as many as there are)
    k = min(TEMPORAL_ORDER, n - 1)
    n_win = max(1, min(n // (k + 1), _MAX_FRAMES // (k + 1))) if k >= 2 else 0
    starts = np.unique(np.linspace(0, n - k - 1, n_win).astype(int)) if n_win else np.array([], int)
    idx = np.unique(np.concatenate([starts + j for j in range(k + 1)])) if starts.size else np.arange(min(n, 3))
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    data = np.asarray(frames[idx, box[0], box[1]], dtype=np.float64)
    m = mask[box]
    pos = {int(i): j for j, i in enumerate(idx)}
    tr = [temporal_residual(data[[pos[s + j] for j in range(k + 1)]][:, m], t[s:s + k + 1]) for s in starts]
    temporal = clipped_std(np.concatenate(tr)) if tr else float("nan")
    spatial = spatial_noise(data, m)
    q = quantisation_step(data[:, m])
    return IRNoise(temporal, spatial, q, npx)


def noise_levels(attrs) -> tuple[float, float, float]:
    """``(σ_n, q, σ)`` (K) of a ``points.zarr``'s attrs: the pixels' own noise, the export step and the noise the
    exported values carry, ``σ² = σ_n² + q²/12``.

    ``σ`` is the frame-to-frame estimate (:func:`ir_noise`: ``ir_noise_temporal_k``, else ``ir_noise_k``), whose
    residuals hold the rounding as the data do; ``σ_n = sqrt(max(σ² - q²/12, 0))``. NaN where the attrs hold
    no estimate.
    """
    a = attrs
    q = float(a.get("ir_quantisation_k", 0.0) or 0.0)
    sigma = float(a.get("ir_noise_temporal_k", a.get("ir_noise_k", np.nan)))
    return float(np.sqrt(max(sigma ** 2 - q ** 2 / 12.0, 0.0))) if np.isfinite(sigma) else np.nan, q, sigma


def spatial_noise(frames, mask=None) -> float:
    """Pixel noise (K) of IR frames from their five-point Laplacian: white noise whatever the pattern.

    Parameters
    ----------
    frames : array_like, shape (n_frames, n_v, n_u)
        Temperatures (K or °C); NaN pixels are left out.
    mask : ndarray of bool, shape (n_v, n_u), optional
        The pixels to judge (the specimen's); a pixel counts where its four
        neighbours are on the mask too. Default: every pixel off the frame's
        border (a smooth background cancels as the specimen does, its edges
        are few and :func:`clipped_std` leaves them out).

    Returns
    -------
    float
        The standard deviation of ``(4 f - f_N - f_S - f_E - f_W) / sqrt(20)``
        by :func:`clipped_std`; NaN where no pixel counts.

    Notes
    -----
    For white noise of standard deviation σ the residual has standard
    deviation σ (``(16 + 4) σ² / 20``), and a field linear in the pixel
    coordinates gives none; the export's rounding adds its ``q² / 12``.
    """
    f = np.asarray(frames, dtype=np.float64)
    if f.ndim != 3 or f.shape[1] < 3 or f.shape[2] < 3:
        return float("nan")
    if mask is None:
        inner = np.ones(f.shape[1:], dtype=bool)
    else:
        inner = ndimage.binary_erosion(np.asarray(mask, dtype=bool), structure=ndimage.generate_binary_structure(2, 1))
    mi = inner[1:-1, 1:-1]
    if not mi.any():
        return float("nan")
    lap = 4 * f[:, 1:-1, 1:-1] - f[:, :-2, 1:-1] - f[:, 2:, 1:-1] - f[:, 1:-1, :-2] - f[:, 1:-1, 2:]
    return clipped_std(lap[:, mi] / np.sqrt(20.0))


def dic_noise(x, *, k: int = 20, max_stages: int = 6) -> float:
    """Coordinate noise of DIC points (mm per component) from local quadric fits.

    Parameters
    ----------
    x : array_like, shape (n_stages, N, 3)
        Coordinates (mm), NaN where missing.
    k : int
        Neighbours per local fit (without the point itself).
    max_stages : int
        At most this many stages, spread over the record, are examined.

    Returns
    -------
    float
        Robust standard deviation (MAD) of the normalised leave-one-out
        residuals normal to the surface; NaN with fewer than ``k + 1`` points.

    Notes
    -----
    In the local frame (PCA of the point's neighbourhood: tangents ``e1, e2``,
    normal ``n``) the neighbours' normal coordinates are fitted by
    ``w = a0 + a1 ξ + a2 η + a3 ξ² + a4 ξη + a5 η²`` (least squares). The
    residual ``r = w_0 - ŵ(ξ_0, η_0)`` of the point has variance
    ``σ² (1 + h)``, ``h = φ_0ᵀ (AᵀA)⁻¹ φ_0``; ``r / sqrt(1 + h)`` has variance σ².
    Surface curvature beyond second order biases it by about
    ``ρ⁴ / (8 R³)`` (ρ: neighbourhood radius, R: radius of curvature).
    """
    x = np.asarray(x, dtype=float)
    stages = np.unique(np.linspace(0, x.shape[0] - 1, min(max_stages, x.shape[0])).astype(int))
    res = []
    for s in stages:
        p = x[s][np.isfinite(x[s]).all(axis=1)]
        if p.shape[0] < k + 1:
            continue
        _, nb = cKDTree(p).query(p, k=k + 1)
        q = p[nb[:, 1:]]  # (N, k, 3) neighbours without the point
        c = q.mean(axis=1, keepdims=True)
        cov = np.einsum("nki,nkj->nij", q - c, q - c)
        _, vec = np.linalg.eigh(cov)  # ascending: vec[..., 0] is the normal
        loc = np.einsum("nki,nij->nkj", q - c, vec)
        p0 = np.einsum("ni,nij->nj", p - c[:, 0], vec)
        scale = np.sqrt(np.maximum(np.mean(loc[..., 1] ** 2 + loc[..., 2] ** 2, axis=1), 1e-30))[:, None]

        xi, eta = loc[..., 1] / scale, loc[..., 2] / scale
        A = np.stack([np.ones_like(xi), xi, eta, xi * xi, xi * eta, eta * eta], axis=-1)
        x0, y0 = p0[:, 1:2] / scale, p0[:, 2:3] / scale
        phi = np.concatenate([np.ones_like(x0), x0, y0, x0 * x0, x0 * y0, y0 * y0], axis=1)
        G = np.einsum("nki,nkj->nij", A, A)
        try:
            coef = np.linalg.solve(G, np.einsum("nki,nk->ni", A, loc[..., 0])[..., None])[..., 0]
            Gi_phi = np.linalg.solve(G, phi[..., None])[..., 0]
        except np.linalg.LinAlgError:
            continue
        h = np.einsum("ni,ni->n", phi, Gi_phi)
        r = (p0[:, 0] - np.einsum("ni,ni->n", phi, coef)) / np.sqrt(1 + h)
        res.append(r[np.isfinite(r) & (h < 10)])
    if not res:
        return float("nan")
    return mad_std(np.concatenate(res))


def choose_smoothing(option, *, noise: float, gain: float, signal: float, what: str):
    """Resolve a smoothing option: ``auto`` -> ``"gcv"`` or None, with the reason.

    Parameters
    ----------
    option : None, "gcv", float or "auto"
        The configured value; anything but ``auto`` is returned unchanged.
    noise : float
        Estimated noise of the data (their units).
    gain : float
        Noise gain of the derivative under exact interpolation (1/unit of the
        derivative's variable), so that ``noise * gain`` is the derivative's noise.
    signal : float
        Typical magnitude (RMS) of the derivative, or None for an absolute
        floor (then ``noise * gain`` is compared with :data:`STRAIN_NOISE_FLOOR`).
    what : str
        Name of the derivative for the reason.

    Returns
    -------
    chosen : None, "gcv" or float
    reason : str
    """
    if option != "auto":
        return option, "set in the configuration"
    if not (np.isfinite(noise) and np.isfinite(gain)):
        return None, "auto: the noise could not be estimated; exact interpolation (the paper)"
    d = noise * gain
    if signal is None:
        ratio, limit, lhs = d, STRAIN_NOISE_FLOOR, f"{what} noise {d:.2g}"
    else:
        ratio = d / signal if signal > 0 else np.inf
        limit, lhs = NOISE_TO_SIGNAL, f"{what} noise {d:.3g} / RMS {signal:.3g} = {ratio:.2g}"
    if ratio > limit:
        return "gcv", f"auto: {lhs} > {limit:g}: regression (GCV)"
    return None, f"auto: {lhs} <= {limit:g}: exact interpolation (the paper)"


def auto_smoothing(points, x, options: dict) -> tuple[dict, dict]:
    """Resolve the ``auto`` smoothing options of the fields stage from the data's noise.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr`` (its ``ir_noise_*``/``ir_quantisation_k`` attributes,
        pixel gradients and local rates).
    x : ndarray, shape (n_t, N, 3)
        DIC coordinates (mm).
    options : dict
        ``surface_smoothing``, ``temperature_smoothing``,
        ``temperature_smoothing_space`` as configured.

    Returns
    -------
    chosen : dict
        The same keys, ``auto`` replaced by ``"gcv"`` or None.
    attrs : dict
        ``dic_noise_mm``, ``ir_noise_k`` and ``<option>_chosen``/``<option>_reason``
        for the store.

    Notes
    -----
    Effective IR noise ``σ = sqrt(σ_n² + q²/12)`` (``σ_n``: the pixels' own
    noise, ``q``: export step; the rounding error is noise to a derivative
    even on noise-free data): the frame-to-frame estimate itself
    (:func:`noise_levels`). Gains
    of exact interpolation: ``sqrt(2)/Δt`` for the rate (``Δt``: frame
    spacing), ``sqrt(2)`` px⁻¹ for the pixel gradient, ``sqrt(2)/h`` for the
    strain (``h``: median DIC point spacing); signals: RMS of the local rate
    and of the pixel gradient magnitude; strain against the absolute floor
    :data:`STRAIN_NOISE_FLOOR`.
    """
    a = points.attrs
    # the spatial residual also holds the field's own curvature (on noise-free renderings of the tube
    # it reads 2 mK), so both rules use the frame-to-frame noise, the export's rounding in it
    eff_t = eff_s = noise_levels(a)[2]
    span, frames = a.get("ir_time_span_s"), a.get("ir_frames")
    dt = (float(span[1]) - float(span[0])) / (int(frames) - 1) if span is not None and frames and int(frames) > 1 else np.nan
    rate = np.asarray(points["temperature_local_rate"].values, dtype=float)
    g = np.linalg.norm(np.asarray(points["temperature_pixel_gradient"].values, dtype=float), axis=-1)
    rms_rate = float(np.sqrt(np.nanmean(rate ** 2))) if np.isfinite(rate).any() else np.nan
    rms_grad = float(np.sqrt(np.nanmean(g ** 2))) if np.isfinite(g).any() else np.nan
    sx = dic_noise(x)
    x0 = x[0][np.isfinite(x[0]).all(axis=1)]
    h = float(np.median(cKDTree(x0).query(x0, k=2)[0][:, 1])) if x0.shape[0] > 2 else np.nan
    chosen, attrs = {}, {"dic_noise_mm": float(sx), "ir_noise_k": float(eff_t)}
    rules = {
        "temperature_smoothing": dict(noise=eff_t, gain=np.sqrt(2) / dt, signal=rms_rate, what="rate (K/s)"),
        "temperature_smoothing_space": dict(noise=eff_s, gain=np.sqrt(2), signal=rms_grad, what="pixel gradient (K/px)"),
        "surface_smoothing": dict(noise=sx, gain=np.sqrt(2) / h, signal=None, what="strain"),
    }
    for name, rule in rules.items():
        c, why = choose_smoothing(options.get(name), **rule)
        chosen[name] = c
        attrs[f"{name}_chosen"] = str(c)
        attrs[f"{name}_reason"] = why
        log.info("fields.%s = %s: %s", name, c, why)
    return chosen, attrs


@dataclass(frozen=True)
class NoiseGains:
    """Standard deviations at a point for unit white pixel noise (1 K per pixel and frame)."""

    temperature: float
    """of the interpolated temperature (1)."""
    gradient: float
    """of each component of the pixel gradient (1/px)."""
    rate: float
    """of the local rate (1/s)."""


def interpolation_noise_gains(frame_times, *, method="rbf", c=2.0, R0=1.0, c_time=1.0, R0_time=1.0, halo=12,
                              size=32, points=192, seed=0, footprint=1) -> NoiseGains:
    """Noise gains of the couple stage's pixel interpolation, measured on a probe.

    Parameters
    ----------
    frame_times : array_like, shape (n_frames,)
        IR frame times (s); the first (at most 6) set the temporal spacing.
    method, c, R0, c_time, R0_time, halo
        The interpolation settings of the couple stage
        (:func:`irdic.image_rbf.evaluate_series`).
    size : int
        Side of the probe image (px).
    points : int
        Probe points, at random sub-pixel positions in 16 random times, away
        from the probe's edge.
    seed : int
        Seed of the probe (the gains are a property of the operator, not of
        the data, so a fixed seed keeps the stores reproducible).
    footprint : int
        Side (px) of the box mean the frames go through first (the couple
        stage's ``temperature_footprint``); 1: none.

    Returns
    -------
    NoiseGains

    Notes
    -----
    The interpolation is linear in the pixel values, so for white pixel noise
    of standard deviation σ the point temperature, each pixel-gradient
    component and the local rate carry ``σ g`` with the gains ``g`` measured
    here as the standard deviations of the outputs for a probe movie of unit
    white noise (``points`` samples each: about 5 % relative precision).
    Values near the mask edge (extrapolated points) have other gains; the
    fields stage flags them as bias-dominated instead.
    """
    from .image_rbf import evaluate_series

    t = np.asarray(frame_times, dtype=float)[:6]
    if t.size < 2:
        return NoiseGains(np.nan, np.nan, np.nan)
    rng = np.random.default_rng(seed)
    frames = rng.standard_normal((t.size, size, size))
    if footprint > 1:
        from scipy import ndimage

        frames = ndimage.uniform_filter(frames, (1, int(footprint), int(footprint)), mode="nearest")
    margin = min(halo, size // 4)
    n_t, per = 16, max(1, points // 16)
    te = np.sort(rng.uniform(t[0], t[-1], n_t))
    pts = rng.uniform(margin, size - 1 - margin, (n_t, per, 2))
    res = evaluate_series(frames, t, te, pts, np.ones((size, size), bool), method=method, c=c, R0=R0,
                          c_time=c_time, R0_time=R0_time, halo=halo, name="noise probe")
    th, gu, gv, r = (np.asarray(a) for a in (res.theta, res.dtheta_du, res.dtheta_dv, res.dtheta_dt))
    rms = lambda a: float(np.sqrt(np.nanmean(np.square(a))))  # noqa: E731  (zero-mean noise: RMS = std)
    return NoiseGains(rms(th), rms(np.concatenate([gu, gv])), rms(r))
