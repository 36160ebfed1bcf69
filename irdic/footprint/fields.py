"""The fields stage's side of the footprint temperatures (:mod:`irdic.footprint.temperature`).

The couple stage writes ``points.temperature_footprint`` and its per-point
noise factor; here the fields stage takes them: as the temperatures its
gradient and rate regress (:func:`footprint_temperatures`), in the noise
probes of their uncertainties (:func:`footprint_probes`, spatially
correlated like the box fits' noise), and with the paper's temperatures for
the denoised value (:func:`paper_value`). Kept apart from the couple side so
that the fields stage does not depend on the projection code (its code hash,
:mod:`irdic.codehash`, stays its own); the probes of the points extrapolated
from the mask edge follow :mod:`irdic.footprint.extrapolation`, so an edit there
re-runs both stages.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..numerics.threads import parallel_map, worker_slices
from ..vocabulary import Status
from .extrapolation import EXTRAP_SAMPLES

__all__ = ["footprint_temperatures", "footprint_noise", "footprint_probes", "paper_value", "pixel_pitch",
           "window_extras"]


def footprint_temperatures(points: xr.Dataset) -> xr.Dataset:
    """``points`` for the fields stage's regression of the gradient and rate: ``temperature_footprint`` as
    ``temperature`` with its noise gain, the paper's value kept as ``temperature_paper`` (the denoised
    temperature is regressed from it); unchanged when the store has none (side 1, or written before it
    existed)."""
    if "temperature_footprint" not in points:
        return points
    return points.assign(temperature=points["temperature_footprint"], temperature_paper=points["temperature"],
                         ).assign_attrs(ir_noise_gain_temperature_paper=points.attrs.get("ir_noise_gain_temperature"),
                                        ir_noise_gain_temperature=points.attrs.get(
                                            "ir_noise_gain_temperature_footprint", np.nan))


def pixel_pitch(points: xr.Dataset, psi) -> float | None:
    """Size (mm) of one IR pixel on the surface: the median of ``|ΔΨ| / |Δpixel|`` over nearest neighbours.

    Point temperatures closer than this share their pixels' noise
    (:func:`irdic.surface.regression.gradient_risk_spatial`, ``separation``).
    Taken at the one of five times spread over the record with the most
    projected points; None when fewer than 6 points are projected there, or
    the store holds no pixel positions.
    """
    from scipy.spatial import cKDTree

    if "pixel" not in points:
        return None
    pix = points["pixel"].transpose("time", "point", "axis")
    psi = np.asarray(psi, dtype=float)
    best = None
    for i in np.unique(np.linspace(0, pix.shape[0] - 1, 5).astype(int)):
        q = np.asarray(pix[i].values, dtype=float)
        ok = np.flatnonzero(np.isfinite(q).all(axis=1) & np.isfinite(psi).all(axis=1))
        if best is None or ok.size > best[1].size:
            best = (q, ok)
    q, ok = best
    if ok.size < 6:
        return None
    d, j = cKDTree(psi[ok]).query(psi[ok], k=2)
    dpx = np.linalg.norm(q[ok] - q[ok[j[:, 1]]], axis=1)
    use = dpx > 0
    return float(np.median(d[use, 1] / dpx[use])) if use.any() else None


def footprint_noise(rng, pixel, side, shape, extrapolated=None, plan=None, amplified=False):
    """White pixel noise (unit variance) through the box mean of ``side`` px about each point's nearest
    pixel, scaled to unit variance: probes (``shape`` (b,) + pixel.shape[:-1]) with the spatial correlation
    of the footprint temperatures' noise (neighbouring points closer than ``side`` px share pixels).

    ``pixel`` (T, N, 2): the points' projected positions (px, NaN: none). ``extrapolated`` (T, N) float,
    optional: for the points the couple stage extrapolated from the mask edge, their distance outside it
    (px, ``-points.edge_distance``), NaN for the others; their probes are extrapolated as the couple stage
    extrapolates their values (:func:`_extrapolated_noise`). ``plan``: a dict the calls on the same
    ``pixel``, ``side`` and ``extrapolated`` share (each time's pixels and extrapolation lines, built once;
    the draws are the same with or without it).

    Notes
    -----
    The interpolation between the pixels' box values is left out: it adds a
    little correlation at sub-box distances only. The extrapolation is not:
    an extrapolated value is a parabola through 9 samples along the line into
    the mask, the same pixels for the neighbouring extrapolated points and
    the points inside. Drawn independently, they left the regressed noise of
    the demo tube (1 in 10 of its point values extrapolated, 7 x the variance
    of the others) 1.2-1.6 x (value) and 1.2-1.7 x (gradient) above the
    probes' at 12 point spacings. Their variance stays the caller's
    (``points.temperature_footprint_noise_factor``), or, with ``amplified``,
    is the extrapolation's: the parabola's weights over the samples' boxes
    (a point L px outside the mask has 1.3 (L = 1) to 2.6 (L = 3) x an inside
    point's noise, :func:`irdic.footprint.extrapolation.extrapolate`).
    """
    b = shape[0]
    T, N = pixel.shape[:2]
    out = np.zeros((b, T, N))
    plan = {} if plan is None else plan
    _plan_times(plan, pixel, side, extrapolated)
    for k in range(T):
        if plan[k] is None:
            continue
        inner, ext, inv, n_pixels, lines = plan[k]
        xi = rng.standard_normal((b, n_pixels))
        box = xi[:, inv].sum(axis=-1) / side
        n_in = int(inner.sum())
        out[:, k, inner] = box[:, :n_in]
        if lines is not None:
            w, std = lines[2:]
            out[:, k, ext] = _extrapolated_noise(box[:, n_in:].reshape(b, -1, EXTRAP_SAMPLES), w,
                                                 1.0 if amplified else std)
    return out


def _plan_times(plan, pixel, side, extrapolated):
    """:func:`_footprint_pixels` of every time of ``pixel`` (T, N, 2) not yet in ``plan``, into it; the times
    split over the stage's threads (each time's on its own: the same as one after the other)."""
    missing = [k for k in range(pixel.shape[0]) if k not in plan]

    def build(ks):
        return [_footprint_pixels(pixel[k], side, None if extrapolated is None else extrapolated[k]) for k in ks]

    blocks = [missing[s] for s in worker_slices(len(missing))]
    for ks, built in zip(blocks, parallel_map(build, blocks)):
        plan.update(zip(ks, built))


def _footprint_pixels(pix, side, extrapolated):
    """One time's boxes of :func:`footprint_noise`: ``(inner, ext, inv, n_pixels, lines)``, the points inside
    and extrapolated (N,) bool, each box's pixels (n, side²) as indices into the ``n_pixels`` distinct ones
    (sorted by pixel), the points inside first and then the extrapolation samples, and
    :func:`_extrapolation_lines` with :func:`_combination_std` last; None where no point has a position.
    ``pix`` (N, 2) px, ``extrapolated`` (N,) px or None."""
    N = pix.shape[0]
    ok = np.isfinite(pix).all(axis=1)
    if not ok.any():
        return None
    h = side // 2
    o = np.arange(-h, h + 1)
    ou, ov = (a.ravel() for a in np.meshgrid(o, o))
    ext = np.zeros(N, bool) if extrapolated is None else ok & np.isfinite(extrapolated)
    inner = ok & ~ext
    centres = np.round(pix[inner])
    lines = None if not ext.any() else _extrapolation_lines(pix, inner, ext, extrapolated[ext])
    if lines is not None:
        # the combinations' std, the same for every probe group: once per time
        lines = lines + (_combination_std(*lines[1:], side),)
        centres = np.concatenate([centres, np.round(lines[0].reshape(-1, 2))])
    c = centres.astype(np.int64)
    keys = (c[:, 0:1] + ou) * 1_000_003 + (c[:, 1:2] + ov)  # (n, side²): the box's pixels
    uniq, inv = np.unique(keys, return_inverse=True)
    return inner, ext, inv.reshape(keys.shape).astype(np.int32), uniq.size, lines


def _extrapolation_lines(pix, inner, ext, L):
    """The couple stage's samples of the extrapolated points ``ext`` at one time, ``L`` (n_ext,) px their
    distances outside the mask: ``(samples (n_ext, S, 2) px, sample offsets (n_ext, S, 2) px, parabola weights
    (n_ext, S))``, or None. The line into the mask runs towards the mean of the 4 nearest points inside (the
    mask is not known here), from ``q`` at ``L`` outside (:func:`irdic.footprint.extrapolation.extrapolate`)."""
    from scipy.spatial import cKDTree

    if inner.sum() < 4:
        return None
    p, q_in = pix[ext], pix[inner]
    towards = q_in[cKDTree(q_in).query(p, k=4)[1]].mean(axis=1) - p
    e = -towards / np.maximum(np.linalg.norm(towards, axis=1), 1e-12)[:, None]
    s = np.arange(EXTRAP_SAMPLES, dtype=float)
    samples = (p - L[:, None] * e)[:, None, :] - s[None, :, None] * e[:, None, :]
    V = np.vander(-s, 3, increasing=True)
    w = np.stack([np.ones_like(L), L, L ** 2], axis=1) @ np.linalg.pinv(V)  # (n_ext, S)
    offsets = np.round(samples) - np.round(samples[:, :1])
    return samples, offsets, w


def _combination_std(offsets, w, side):
    """The std (n_ext,) of the parabola weights ``w`` (n_ext, S) over unit-variance box noise of boxes
    ``offsets`` (n_ext, S, 2) px apart: they share ``(side - |du|)(side - |dv|)`` pixels."""
    d = np.abs(offsets[:, :, None, :] - offsets[:, None, :, :])
    corr = np.prod(np.clip(side - d, 0, None), axis=-1) / side ** 2  # (n_ext, S, S)
    return np.sqrt(np.maximum(np.einsum("ns,nst,nt->n", w, corr, w), 1e-12))


def _extrapolated_noise(box, w, std):
    """Noise of the extrapolated points from their samples' box noise ``box`` (b, n_ext, S): the parabola
    weights ``w`` (n_ext, S) over ``std`` (n_ext,): their combination's std (:func:`_combination_std`) for
    unit variance, 1.0 for the extrapolation's own."""
    return np.einsum("bns,ns->bn", box, w) / std


def footprint_probes(points, window, sigma):
    """``(draw, s_paper)`` for the noise probes of :mod:`irdic.uncertainty.model`: ``draw(rng, b)`` gives ``b``
    probes of :func:`footprint_noise` at the record's (or the chunk window's) points. When the fields regress
    footprint temperatures (:func:`footprint_temperatures`) ``s_paper`` (K) is the noise of the paper's point
    temperatures (pixel noise ``sigma`` times their gain), whose regression is the value; without them the
    probes of the paper's temperatures have the nearest pixel's noise (``side`` 1) and ``s_paper`` is None
    (the demo tube forced to side 1: the regressed gradient's noise was 1.9 x white probes'; the paper tube,
    points 0.25 mm apart: ``d`` 1.21 -> 1.07 x its probes' noise). None without pixel positions."""
    if "pixel" not in points:
        return None
    pixel = points["pixel"].transpose("time", "point", "axis").values if window is None else window.pixel
    ext = extrapolated(points) if window is None else window.extrapolated
    plan = {}  # each time's pixels, shared by the probe groups
    if "temperature_paper" not in points:
        # the paper's temperatures alone: points closer than a pixel share its noise, and an extrapolated
        # value has the extrapolation's (no noise factor of the couple stage's for these)
        return (lambda rng, b: footprint_noise(rng, pixel, 1, (b,), ext, plan, amplified=True)), None
    side = int(points.attrs.get("footprint_px", 1))
    if window is None:
        factor = points["temperature_footprint_noise_factor"].values if "temperature_footprint_noise_factor" in \
            points else None
    else:
        factor = window.noise_factor
    factor = 1.0 if factor is None else np.nan_to_num(np.asarray(factor, dtype=float), nan=1.0)
    return (lambda rng, b: footprint_noise(rng, pixel, side, (b,), ext, plan) * factor), sigma * float(
        points.attrs.get("ir_noise_gain_temperature_paper", np.nan))


def window_extras(points, w) -> dict:
    """The :class:`~irdic.uncertainty.model.Window` fields of the noise probes at times ``w``: the footprint's,
    or the pixel positions and extrapolated points alone without it (none without pixel positions)."""
    if "pixel" not in points:
        return {}
    at = points.isel(time=w)
    out = dict(extrapolated=extrapolated(at), pixel=at["pixel"].transpose("time", "point", "axis").values)
    if "temperature_paper" in points:
        factor = at.get("temperature_footprint_noise_factor")
        out.update(theta_paper=at["temperature_paper"].values.astype(float),
                   noise_factor=None if factor is None else factor.values)
    return out


def extrapolated(points):
    """(T, N): for the point values the couple stage extrapolated from the mask edge their distance outside
    it (px), NaN for the others; None without ``status`` and ``edge_distance``."""
    if "status" not in points or "edge_distance" not in points:
        return None
    ext = points["status"].transpose("time", "point").values == Status.EXTRAPOLATED_FROM_EDGE
    return np.where(ext, -points["edge_distance"].transpose("time", "point").values.astype(float), np.nan)


def paper_value(points, series, space_time, spatial):
    """The denoised temperature from the paper's point temperatures, with the inputs of its bias estimate.

    ``space_time(theta, series) -> (grad, total, local, value, spatial, chosen)`` is the fields stage's
    regression (:func:`irdic.fields.space_time.space_time`) with the spacings chosen for the footprint
    temperatures (the noise probes run through one operator), ``spatial`` its inputs of the bias
    estimates on the footprint temperatures. Returns ``(value (T, N) degC, spatial)`` with the value's entries (the
    input, the output, the temporal difference) from the paper's temperatures and the gradient's and
    rate's (the last: the gradient's reference input) from the footprint
    (:func:`irdic.uncertainty.model.uncertainties`).

    Notes
    -----
    The footprint's box offset, ``(side² - 1)/24 ∇²Θ``, is the same in every
    regression of it, so the difference to the exact interpolation of the
    same input (the regressions' bias estimate) cannot see it; regressed
    from the paper's temperatures the value has no such offset.
    """
    theta = points["temperature_paper"].values.astype(float)
    ser = None if series is None else series._replace(theta=series.theta_paper)
    _, _, _, value, own, _ = space_time(theta, ser)
    merged = (spatial[0], spatial[1], own[2], own[3]) + ((spatial[4], spatial[5], own[6], spatial[7])
                                                         if len(spatial) > 5 else ())
    return value, merged + spatial[-1:]
