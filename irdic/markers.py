"""Calibration-target markers in an IR image: detection, perspective bias, correspondence.

The markers of the reference object differ from its body in emissivity, so
they appear colder ("dark") or warmer ("bright") than the body although the
target is at one temperature. :func:`detect_markers` finds them with
sub-pixel centres; :func:`match_seeds` and :func:`match_lattice` pair the
detections with the marker IDs of the DIC export; :func:`perspective_bias`
corrects the centres once the camera is known (the centre of an imaged circle
is not the image of its centre).

Pixel convention: ``u`` = column, ``v`` = row, full-sensor coordinates,
0-based, pixel centres on integers (a cropped image keeps its offset).
"""

from __future__ import annotations

import itertools
import logging
import warnings
from typing import Mapping

import numpy as np
import xarray as xr
from scipy import ndimage
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree
from skimage.morphology import convex_hull_image

from .camera import CameraModel, degeneracy, dlt, planarity
from .errors import CalibrationError, ConfigError, DataError, IrdicWarning

__all__ = [
    "detect_markers",
    "image_array",
    "assign",
    "match_seeds",
    "match_lattice",
    "propagate",
    "plane_normals",
    "perspective_bias",
    "SEEDS_HINT",
    "MAX_INVALID_FRACTION",
]

log = logging.getLogger(__name__)

SEEDS_HINT = (
    "add approximate pixel positions of at least 6 markers, spread over both wings, to the setup in the "
    "configuration:\n  seeds: {<marker id>: [u, v], <marker id>: [u, v], ...}\n"
    "(read u = column and v = row off the detection figure)"
)


#: Largest fraction of NaN (invalid) pixels accepted in a calibration target
#: image. Markers whose measurement window touches a NaN pixel are left out;
#: beyond a few percent of scattered NaN pixels that leaves too few markers,
#: or markers in a biased part of the image, for a trustworthy camera.
MAX_INVALID_FRACTION = 0.05

# ----------------------------------------------------------------------------- image


def image_array(image) -> tuple[np.ndarray, int, int]:
    """A single IR frame as a 2-D float64 array plus its sensor offset.

    Parameters
    ----------
    image : xarray.DataArray or array_like
        Dims ``("v", "u")`` (°C) with integer, consecutive full-sensor pixel
        coordinates; a plain 2-D array is taken as a full frame at (0, 0).
        A ``time`` dimension of length 1 is dropped.

    Returns
    -------
    values : ndarray (H, W)
    u0, v0 : int
        Sensor column and row of ``values[0, 0]``.
    """
    if isinstance(image, xr.DataArray):
        da = image
        if "time" in da.dims:
            if da.sizes["time"] != 1:
                raise ConfigError(f"target image has {da.sizes['time']} frames; give one frame (or their mean)")
            da = da.isel(time=0)
        if set(da.dims) != {"u", "v"}:
            raise ConfigError(f"target image must have dims ('v', 'u'), got {da.dims}")
        da = da.transpose("v", "u")
        offs = []
        for d in ("u", "v"):
            c = np.asarray(da[d].values) if d in da.coords else np.arange(da.sizes[d])
            if len(c) > 1 and not np.all(np.diff(c) == 1):
                raise ConfigError(f"target image coordinate {d!r} must be consecutive integer pixels")
            if len(c) and c[0] != np.round(c[0]):
                raise ConfigError(f"target image coordinate {d!r} must be integer (pixel centres), got {c[0]}")
            offs.append(int(c[0]) if len(c) else 0)
        values = np.asarray(da.values, dtype=np.float64)
        return values, offs[0], offs[1]
    values = np.asarray(image, dtype=np.float64)
    if values.ndim != 2:
        raise ConfigError(f"target image must be 2-D (v, u), got shape {values.shape}")
    return values, 0, 0


def _noise_sigma(img: np.ndarray) -> float:
    """Pixel noise (K) from the median absolute difference of horizontal neighbours."""
    d = np.diff(img, axis=1)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return 0.0
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / np.sqrt(2.0))


def _check_image(img: np.ndarray, min_contrast_k: float, where: str = "") -> tuple[np.ndarray, dict, np.ndarray]:
    """Refuse blank or invalid images; fill NaN pixels for the morphology only.

    Returns the image with NaN pixels set to the median (the top-hat needs a
    value everywhere), the clipping statistics and the mask of NaN pixels,
    which :func:`_measure` uses to reject every marker that touches one.
    """
    finite = np.isfinite(img)
    if finite.mean() < 0.5:
        raise CalibrationError(f"{where}target image is mostly invalid: only {finite.mean():.0%} of its pixels are finite")
    bad_frac = 1.0 - float(finite.mean())
    if bad_frac > MAX_INVALID_FRACTION:
        raise CalibrationError(
            f"{where}target image has {bad_frac:.1%} invalid (NaN) pixels, more than the {MAX_INVALID_FRACTION:.0%} "
            "accepted; markers touching invalid pixels cannot be measured, so record the target again (or export "
            "it without masked or dead pixels)"
        )
    vals = img[finite]
    lo, hi = np.percentile(vals, [0.1, 99.9])
    # pure Gaussian noise spans 6.2 sigma between these percentiles
    noise = _noise_sigma(img)
    if hi - lo < max(min_contrast_k, 7.0 * noise):
        raise CalibrationError(
            f"target image is blank: its temperatures span only {hi - lo:.3f} K (0.1 to 99.9 percentile, "
            f"{lo:.2f} to {hi:.2f} °C), less than min_contrast_k = {min_contrast_k:g} K or 7 x the pixel noise "
            f"({noise:.3f} K); markers cannot be seen"
        )
    return_clip = {name: (float(level), float(np.mean(vals == level)))
                   for name, level in (("maximum", vals.max()), ("minimum", vals.min()))}
    if not finite.all():
        img = np.where(finite, img, np.median(vals))
    return img, return_clip, ~finite


def _saturation_error(clip: dict) -> CalibrationError | None:
    """An error naming the clipped extreme when a sizeable part of the image sits exactly on it."""
    name, (level, frac) = max(clip.items(), key=lambda kv: kv[1][1])
    if frac < 0.01:
        return None
    return CalibrationError(
        f"target image is saturated: {frac:.0%} of its pixels sit at the {name} {level:.2f} °C (clipped at the "
        "end of the camera's measurement range) and no markers were found; record the target with a range "
        "that covers its temperature"
    )


# ----------------------------------------------------------------------------- detection


def _candidates(img: np.ndarray, sign: float, size: int, thr: float) -> tuple[np.ndarray, int]:
    """Labelled compact blobs of one polarity (top-hat with a square of side ``size``)."""
    if sign > 0:
        th = img - ndimage.grey_opening(img, size=(size, size))
    else:
        th = ndimage.grey_closing(img, size=(size, size)) - img
    # the opening of a noisy background lies a few sigma below its mean: measure that offset
    base = float(np.median(th))
    labels, n = ndimage.label(th > base + thr, structure=np.ones((3, 3)))
    return labels, n


def _matched_response(img: np.ndarray, noise: float, min_r: float, max_r: float) -> tuple[np.ndarray, np.ndarray]:
    """Signal-to-noise of a bank of matched filters for bright blobs: ``(snr, radius_px)`` per pixel.

    Each filter is the mean over a square of the area of a disc of radius
    ``r`` minus the mean over the surrounding square ring three times as
    wide. The ring removes the local background (level and linear
    gradient: the kernel is symmetric and sums to zero), so no separate
    background model is needed. Radii form a geometric bank from ``min_r``
    to ``max_r`` (ratio 1.5); per pixel the best radius is kept. Dark
    blobs: call with ``-img``.

    Notes
    -----
    With ``n_in`` pixels in the square and ``n_ring`` in the ring, white
    noise of standard deviation ``sigma`` gives the response the standard
    deviation ``sigma sqrt(1/n_in + 1/n_ring)``; a marker of contrast ``c``
    filling the square responds with ``c``, so the filter's signal-to-noise
    is about ``sqrt(n_in)`` times the pixel contrast/noise: 3 on a marker
    of 3 px radius becomes ~15. Box sums come from one summed-area table.
    """
    radii = [min_r]
    while radii[-1] * 1.5 < max_r:
        radii.append(radii[-1] * 1.5)
    sides = [2 * int(round(0.886 * r)) + 1 for r in radii]  # square of the disc's area, odd side
    pad = (3 * max(sides)) // 2 + 1
    sat = np.pad(img, pad, mode="edge").cumsum(axis=0).cumsum(axis=1)
    sat = np.pad(sat, ((1, 0), (1, 0)))
    H, W = img.shape

    def box_mean(a):
        h = a // 2
        r0, c0 = pad - h, pad - h
        return (sat[r0 + a:r0 + a + H, c0 + a:c0 + a + W] - sat[r0:r0 + H, c0 + a:c0 + a + W]
                - sat[r0 + a:r0 + a + H, c0:c0 + W] + sat[r0:r0 + H, c0:c0 + W]) / (a * a)

    best = np.full(img.shape, -np.inf)
    best_r = np.zeros(img.shape)
    for r, a in zip(radii, sides):
        b = 3 * a
        s_in, s_out = box_mean(a), box_mean(b)
        n_in, n_ring = a * a, b * b - a * a
        snr = (s_in - (s_out * b * b - s_in * n_in) / n_ring) / (noise * np.sqrt(1.0 / n_in + 1.0 / n_ring))
        better = snr > best
        best[better] = snr[better]
        best_r[better] = r
    return best, best_r


def _matched_peaks(snr: np.ndarray, radius: np.ndarray, thr_sigma: float) -> list[tuple[float, float, float]]:
    """Local maxima ``(v, u, radius_px)`` of a matched-filter response above ``thr_sigma``."""
    peak = (snr >= thr_sigma) & (snr == ndimage.maximum_filter(snr, size=5))
    vv, uu = np.nonzero(peak)
    return [(float(v), float(u), float(radius[v, u])) for v, u in zip(vv, uu)]


def _plane_fit(uu, vv, vals, noise=0.0):
    """Least-squares plane a + b u + c v with one 3-sigma rejection pass.

    Values more than 8 x ``noise`` (K) from the median are left out first
    (when at least half remain): a step such as the edge of the target
    against the room would tilt the first least-squares plane so much that
    the rejection pass cannot recover.
    """
    if noise > 0:
        ok = np.abs(vals - np.median(vals)) <= 8.0 * noise
        if 2 * ok.sum() >= len(vals) and not ok.all():
            uu, vv, vals = uu[ok], vv[ok], vals[ok]
    A = np.column_stack([np.ones_like(uu), uu, vv])
    coef, *_ = np.linalg.lstsq(A, vals, rcond=None)
    r = vals - A @ coef
    s = 1.4826 * np.median(np.abs(r)) + 1e-12
    ok = np.abs(r) < 3 * s
    if ok.sum() >= 6 and not ok.all():
        coef, *_ = np.linalg.lstsq(A[ok], vals[ok], rcond=None)
    return coef


def _measure(img, sign, lab_mask, sl, others_mask, noise, max_radius_px, invalid=None):
    """Sub-pixel centre and shape of one candidate blob; None when it cannot be measured."""
    rr, cc = np.nonzero(lab_mask[sl])
    rr = rr + sl[0].start
    cc = cc + sl[1].start
    area0 = len(rr)
    r0 = np.sqrt(area0 / np.pi)
    if r0 > 1.5 * max_radius_px + 3:
        return None, "size"
    vc, uc = rr.mean(), cc.mean()
    # window: blob (its semi-major axis: foreshortened markers are long) + blur margin + background annulus
    if area0 >= 3:
        a0 = 2.0 * np.sqrt(max(np.linalg.eigvalsh(np.cov(np.vstack([cc, rr]), bias=True))[-1], 0.0) + 1 / 12)
    else:
        a0 = r0
    return _measure_at(img, sign, vc, uc, r0, max(a0, r0), others_mask, noise, invalid=invalid)


def _measure_at(img, sign, vc, uc, r0, a0, others_mask, noise, smooth=0.0, invalid=None):
    """Sub-pixel centre and shape of the blob near (``uc``, ``vc``) of equivalent radius ``r0`` and
    semi-major axis ``a0`` (px); None when it cannot be measured.

    ``smooth`` > 0 (px, Gaussian sigma) finds the blob's half-contrast region
    on a smoothed copy of the background-subtracted patch: at a
    contrast/noise of a few the unsmoothed region is ragged with noise
    (its shape tests would fail). The centroid is always taken on the
    unsmoothed contrast.
    """
    H, W = img.shape
    r_in = a0 + 3.0
    r_out = r_in + max(3.0, 0.5 * a0)
    half = int(np.ceil(r_out)) + 1
    v_lo, v_hi = int(np.floor(vc)) - half, int(np.ceil(vc)) + half + 1
    u_lo, u_hi = int(np.floor(uc)) - half, int(np.ceil(uc)) + half + 1
    if v_lo < 0 or u_lo < 0 or v_hi > H or u_hi > W:
        return None, "border"
    if invalid is not None and invalid[v_lo:v_hi, u_lo:u_hi].any():
        # the filled value would bias the background plane and the centroid
        return None, "invalid"
    patch = img[v_lo:v_hi, u_lo:u_hi]
    vv, uu = np.mgrid[v_lo:v_hi, u_lo:u_hi].astype(np.float64)
    dist = np.hypot(uu - uc, vv - vc)
    ann = (dist >= r_in) & (dist <= r_out) & ~others_mask[v_lo:v_hi, u_lo:u_hi]
    if ann.sum() < 12:
        return None, "crowded"
    coef = _plane_fit(uu[ann] - uc, vv[ann] - vc, patch[ann], noise)
    s = sign * (patch - (coef[0] + coef[1] * (uu - uc) + coef[2] * (vv - vc)))
    s_shape = ndimage.gaussian_filter(s, smooth, mode="nearest") if smooth > 0 else s
    core = dist <= max(0.5 * r0, 1.0)
    contrast = float(np.median(s_shape[core]))
    if not contrast > 0:
        return None, "contrast"
    # region at half contrast, the component that holds the blob
    half_mask = s_shape > 0.5 * contrast
    lab, _ = ndimage.label(half_mask)
    li = lab[int(round(vc)) - v_lo, int(round(uc)) - u_lo]
    if li == 0:
        return None, "shape"
    region = lab == li
    if (region & (dist > r_in)).any():
        return None, "shape"  # spills into the background annulus: not an isolated blob
    area = float(region.sum())
    ru, rv = uu[region], vv[region]
    mu, mv = ru.mean(), rv.mean()
    cov = np.cov(np.vstack([ru - mu, rv - mv]), bias=True) + np.eye(2) / 12.0
    evals, evecs = np.linalg.eigh(cov)
    lam2, lam1 = max(evals[0], 1e-12), max(evals[1], 1e-12)
    ecc = float(np.sqrt(max(0.0, 1.0 - lam2 / lam1)))
    a_mom, b_mom = 2.0 * np.sqrt(lam1), 2.0 * np.sqrt(lam2)
    # solidity: area over convex hull area (pixel squares)
    hull = convex_hull_image(region)
    solidity = float(area / max(hull.sum(), 1))
    # iterative windowed centroid of the unclipped contrast. The window is the
    # moment ellipse grown by a margin (a circle would reach the close
    # neighbours of foreshortened markers); its soft edge makes the estimate
    # continuous in the centre (no pull to integer pixels).
    e1 = evecs[:, 1]
    # The margin beyond the moment ellipse holds the blur tails but, at low
    # contrast/noise, mostly noise, which the lever arm r amplifies: 2 px
    # above contrast/noise 20, 0.75 px below 10 (the imaged disc is centrally
    # symmetric, so a tight window centred on it costs no bias), linear between.
    snr = contrast / noise if noise > 0 else np.inf
    margin = 0.75 + 1.25 * float(np.clip((snr - 10.0) / 10.0, 0.0, 1.0))
    A, B = a_mom + margin, b_mom + margin
    # On a wing seen at 70-75 deg the neighbours across the short axis are
    # only ~1.5 marker widths away and their blur reaches into the window:
    # pixels nearer to a neighbouring blob (of at least a third of this
    # one's area) than to this blob carry no weight. Isolated markers are
    # unaffected (the split lies beyond the window).
    sizes = np.bincount(lab.ravel())
    near = (lab > 0) & (lab != li) & (sizes[lab] >= area / 3.0)
    keep = np.ones_like(region, dtype=np.float64)
    if near.any():
        keep = (ndimage.distance_transform_edt(~region) <= ndimage.distance_transform_edt(~near)).astype(np.float64)

    def window(cu, cv):
        du, dv = uu - cu, vv - cv
        p1 = du * e1[0] + dv * e1[1]
        p2 = -du * e1[1] + dv * e1[0]
        d_ell = np.sqrt((p1 / A) ** 2 + (p2 / B) ** 2)
        return np.clip((1.0 - d_ell) * B + 0.5, 0.0, 1.0) * keep

    cu, cv = mu, mv
    for _ in range(30):
        wgt = s * window(cu, cv)
        tot = wgt.sum()
        if not tot > 0:
            return None, "contrast"
        nu, nv = (wgt * uu).sum() / tot, (wgt * vv).sum() / tot
        moved = np.hypot(nu - cu, nv - cv)
        cu, cv = nu, nv
        if moved < 1e-6:
            break
    if np.hypot(cu - mu, cv - mv) > 0.5 * b_mom + 0.5:
        return None, "shape"
    wsum = window(cu, cv)
    # standard uncertainty of the centroid from pixel noise
    sig = noise * np.sqrt(((wsum * (uu - cu)) ** 2 + (wsum * (vv - cv)) ** 2).sum()) / tot
    return {
        "u": cu, "v": cv, "radius_px": np.sqrt(area / np.pi), "semi_major_px": a_mom,
        "semi_minor_px": b_mom, "orientation_rad": float(np.arctan2(evecs[1, 1], evecs[0, 1])),
        "eccentricity": ecc, "solidity": solidity, "contrast_k": contrast, "area_px": area,
        "snr": contrast / noise if noise > 0 else np.inf, "sigma_px": float(sig),
    }, None


_FIELDS = {
    "u": ("px", "column of the marker centre (full sensor, intensity-weighted centroid)"),
    "v": ("px", "row of the marker centre (full sensor, intensity-weighted centroid)"),
    "radius_px": ("px", "equivalent radius of the region above half contrast"),
    "semi_major_px": ("px", "semi-major axis from second moments"),
    "semi_minor_px": ("px", "semi-minor axis from second moments"),
    "orientation_rad": ("rad", "direction of the major axis from +u towards +v"),
    "eccentricity": ("1", "eccentricity of the moment ellipse"),
    "solidity": ("1", "area / convex hull area"),
    "contrast_k": ("K", "marker contrast against the local background plane (absolute)"),
    "area_px": ("px^2", "area above half contrast"),
    "snr": ("1", "contrast / pixel noise"),
    "sigma_px": ("px", "standard uncertainty of the centre from pixel noise"),
}


def _detect_polarity(img, sign, *, size, thr, noise, min_r, max_r, min_contrast, max_ecc, min_sol, mf_sigma, mf,
                     invalid=None):
    labels, n = _candidates(img, sign, size, thr)
    slices = ndimage.find_objects(labels)
    others = labels > 0
    others = ndimage.binary_dilation(others, iterations=2)
    rows, rejected = [], {"size": 0, "shape": 0, "contrast": 0, "border": 0, "crowded": 0, "invalid": 0}
    min_area = max(1, int(np.floor(0.25 * np.pi * min_r**2)))
    for lab, sl in enumerate(slices, start=1):
        if sl is None:
            continue
        own = labels[sl] == lab
        if own.sum() < min_area:
            rejected["size"] += 1
            continue
        lab_mask = np.zeros(labels.shape, dtype=bool)
        lab_mask[sl] = own
        # the annulus must not see other blobs (the blob's own dilation is allowed)
        other = others.copy()
        other[sl] &= ~ndimage.binary_dilation(own, iterations=2)
        m, why = _measure(img, sign, lab_mask, sl, other, noise, max_r, invalid)
        _accept(m, why, rows, rejected, min_r, max_r, max_ecc, min_sol, min_contrast)
    # faint markers, below the top-hat threshold: matched-filter peaks away from the blobs found so far
    for vc, uc, r in (_matched_peaks(*mf, mf_sigma) if mf is not None else []):
        if labels[int(vc), int(uc)] > 0 or any(np.hypot(uc - m["u"], vc - m["v"]) <= max(m["semi_major_px"], 2.0)
                                               for m in rows):
            continue
        n += 1
        # the matched filter is circular; a foreshortened marker is up to 1/sqrt(0.26) ~ 2x longer
        m, why = _measure_at(img, sign, vc, uc, r, 2.0 * r, others, noise, smooth=1.0, invalid=invalid)
        _accept(m, why, rows, rejected, min_r, max_r, max_ecc, min_sol, min_contrast)
    return rows, rejected, n


def _accept(m, why, rows, rejected, min_r, max_r, max_ecc, min_sol, min_contrast):
    """Append a measured blob to ``rows`` if it passes the size, shape and contrast limits, else count why not."""
    if m is None:
        rejected[why] += 1
    elif not (min_r <= m["radius_px"] <= max_r):
        rejected["size"] += 1
    elif m["eccentricity"] > max_ecc or m["solidity"] < min_sol:
        rejected["shape"] += 1
    elif m["contrast_k"] < min_contrast:
        rejected["contrast"] += 1
    else:
        rows.append(m)


def detect_markers(image, *, polarity: str = "auto", min_radius_px: float = 2.0, max_radius_px: float = 30.0,
                   min_contrast_k: float = 0.1, max_eccentricity: float = 0.98, min_solidity: float = 0.8,
                   threshold_sigma: float = 5.0, matched_sigma: float = 7.0) -> xr.Dataset:
    """Find the circular markers of a calibration target with sub-pixel centres.

    Compact blobs are found on a morphological top-hat (square structuring
    element larger than the largest marker); markers too faint for it
    (contrast/noise down to ~3) are found as peaks of a bank of matched
    filters (disc-sized square minus its surrounding ring, which removes the
    local background level and gradient; radii from ``min_radius_px`` to
    ``max_radius_px``). Each blob is then measured on
    the image itself after subtracting a background plane fitted on an
    annulus around it: contrast, region above half contrast (radius,
    moment ellipse, eccentricity, solidity) and an iterative intensity
    weighted centroid of the background-subtracted contrast in a soft
    circular window.

    Parameters
    ----------
    image : xarray.DataArray
        One IR frame, dims ``("v", "u")``, °C, full-sensor pixel coordinates.
    polarity : {"auto", "dark", "bright"}
        Whether markers look colder ("dark") or warmer ("bright") than the
        target body; "auto" tries both and keeps the one with more accepted
        blobs.
    min_radius_px, max_radius_px : float
        Accepted range of the marker radius in the image, px.
    min_contrast_k : float
        Smallest accepted marker contrast, K.
    max_eccentricity : float
        Largest accepted eccentricity (0 = circle; 0.98 = axis ratio 0.2:
        a disc seen 75 deg from its normal has 0.26).
    min_solidity : float
        Smallest accepted area / convex hull area.
    threshold_sigma : float
        Top-hat segmentation threshold in multiples of the pixel noise (at
        least half of ``min_contrast_k``).
    matched_sigma : float
        Smallest matched-filter response of a faint-marker candidate, in
        multiples of the filter's noise.

    Returns
    -------
    xarray.Dataset
        Dim ``detection``; variables ``u, v`` (px, full sensor), ``radius_px``,
        ``semi_major_px``, ``semi_minor_px``, ``orientation_rad``,
        ``eccentricity``, ``solidity``, ``contrast_k``, ``area_px``, ``snr``
        (contrast / pixel noise), ``sigma_px``; attrs ``polarity``, ``noise_k``, ``threshold_k``,
        rejection counts, ``sensor_u0``, ``sensor_v0``.

    Raises
    ------
    CalibrationError
        Blank or saturated image, more than :data:`MAX_INVALID_FRACTION` NaN
        pixels, or no marker-like blob.

    Warns
    -----
    IrdicWarning
        The image has NaN pixels (their fraction and the number of marker
        candidates left out because their measurement window touches one).

    Notes
    -----
    NaN pixels are never measured: they are filled with the image median for
    the top-hat only, and a candidate whose window (blob, blur margin and
    background annulus) contains one is rejected (``n_rejected_invalid``).
    """
    if polarity not in ("auto", "dark", "bright"):
        raise ConfigError(f"`polarity` must be 'auto', 'dark' or 'bright', got {polarity!r}")
    for name, val in (("min_radius_px", min_radius_px), ("max_radius_px", max_radius_px),
                      ("min_contrast_k", min_contrast_k), ("threshold_sigma", threshold_sigma),
                      ("matched_sigma", matched_sigma)):
        if not (np.isfinite(val) and val > 0):
            raise ConfigError(f"`{name}` must be a positive number, got {val!r}")
    if min_radius_px >= max_radius_px:
        raise ConfigError(f"`min_radius_px` ({min_radius_px}) must be smaller than `max_radius_px` ({max_radius_px})")
    img, u0, v0 = image_array(image)
    if min(img.shape) < 8:
        raise ConfigError(f"target image is too small ({img.shape[0]} x {img.shape[1]} px)")
    source = getattr(image, "attrs", {}).get("source")
    where = f"{source}: " if source else ""
    img, clip, invalid = _check_image(img, min_contrast_k, where)
    n_invalid = int(invalid.sum())
    noise = _noise_sigma(np.where(invalid, np.nan, img) if n_invalid else img)
    thr = max(threshold_sigma * noise, 0.5 * min_contrast_k)
    size = 2 * int(np.ceil(max_radius_px)) + 3
    kw = dict(size=size, thr=thr, noise=noise, min_r=min_radius_px, max_r=max_radius_px,
              min_contrast=min_contrast_k, max_ecc=max_eccentricity, min_sol=min_solidity,
              mf_sigma=matched_sigma, invalid=invalid if n_invalid else None)
    signs = {"dark": -1.0, "bright": 1.0}
    results = {}
    for pol in (["dark", "bright"] if polarity == "auto" else [polarity]):
        mf = _matched_response(signs[pol] * img, noise, min_radius_px, max_radius_px) if noise > 0 else None
        results[pol] = _detect_polarity(img, signs[pol], mf=mf, **kw)
    if polarity == "auto":
        pol = max(results, key=lambda p: (len(results[p][0]), sum(r["contrast_k"] for r in results[p][0])))
        other = "bright" if pol == "dark" else "dark"
        log.info("marker polarity: %s (%d blobs; %d as %s)", pol, len(results[pol][0]), len(results[other][0]), other)
    else:
        pol = polarity
    rows, rejected, n_cand = results[pol]
    if n_invalid:
        warnings.warn(
            f"{where}target image has {n_invalid} invalid (NaN) pixels ({n_invalid / invalid.size:.2%}); "
            f"{rejected['invalid']} marker candidate(s) touching them were left out",
            IrdicWarning, stacklevel=2)
    if not rows:
        sat = _saturation_error(clip)
        if sat is not None:
            raise sat
        raise CalibrationError(
            f"no marker-like blobs found in the target image (polarity {polarity}, noise {noise:.3f} K, threshold "
            f"{thr:.3f} K, {n_cand} candidates, rejected: {rejected}); check polarity, min_contrast_k and the "
            f"radius range [{min_radius_px}, {max_radius_px}] px"
        )
    rows = _dedupe(rows)
    data = {k: ("detection", np.array([r[k] for r in rows], dtype=np.float64), {"units": u, "long_name": ln})
            for k, (u, ln) in _FIELDS.items()}
    ds = xr.Dataset(data, coords={"detection": np.arange(len(rows))})
    ds["u"] = ds["u"] + u0
    ds["v"] = ds["v"] + v0
    for k in ("u", "v"):
        ds[k].attrs = {"units": "px", "long_name": _FIELDS[k][1]}
    ds.attrs.update(polarity=pol, noise_k=noise, threshold_k=thr, n_candidates=int(n_cand),
                    sensor_u0=u0, sensor_v0=v0, image_height=int(img.shape[0]), image_width=int(img.shape[1]),
                    **{f"n_rejected_{k}": int(v) for k, v in rejected.items()})
    log.info("%d markers detected (%s, noise %.3f K, %d candidates)", len(rows), pol, noise, n_cand)
    return ds


def _dedupe(rows: list[dict]) -> list[dict]:
    """Drop a detection whose centre lies within the radius of a stronger one."""
    rows = sorted(rows, key=lambda r: -r["contrast_k"] * r["area_px"])
    kept: list[dict] = []
    for r in rows:
        if all(np.hypot(r["u"] - k["u"], r["v"] - k["v"]) > max(k["radius_px"], 1.0) for k in kept):
            kept.append(r)
    kept.sort(key=lambda r: (r["v"], r["u"]))
    return kept


# ----------------------------------------------------------------------------- perspective bias


def plane_normals(x, *, k: int = 6) -> np.ndarray:
    """Unit normal of the target surface at each marker, from the marker layout.

    Markers on a plane with at least 6 members (the wings of an open book,
    found by RANSAC) get that plane's normal; the others the normal of a
    plane fitted to their ``k`` nearest neighbours.

    Parameters
    ----------
    x : array_like, shape (N, 3)
        Marker centres, mm.

    Returns
    -------
    ndarray, shape (N, 3)
        Unit normals (sign arbitrary).
    """
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    normals = np.full((n, 3), np.nan)
    for members in _planes(x):
        normals[members] = _pca_normal(x[members])
    rest = np.flatnonzero(np.isnan(normals[:, 0]))
    if len(rest):
        tree = cKDTree(x)
        _, idx = tree.query(x[rest], k=min(k + 1, n))
        for i, nb in zip(rest, idx):
            normals[i] = _pca_normal(x[nb])
    return normals


def _pca_normal(p: np.ndarray) -> np.ndarray:
    _, _, vt = np.linalg.svd(p - p.mean(axis=0), full_matrices=False)
    return vt[-1]


def _planes(x: np.ndarray, min_size: int = 6, tol: float | None = None, seed: int = 0) -> list[np.ndarray]:
    """Index sets of the planes (>= min_size points) in a point cloud, largest first (RANSAC)."""
    n = len(x)
    if n < min_size:
        return []
    if tol is None:
        d, _ = cKDTree(x).query(x, k=2)
        tol = 0.1 * float(np.median(d[:, 1]))
    rng = np.random.default_rng(seed)
    remaining = np.arange(n)
    planes = []
    while len(remaining) >= min_size:
        pts = x[remaining]
        best = None
        for _ in range(300):
            i, j, k = rng.choice(len(pts), 3, replace=False)
            nrm = np.cross(pts[j] - pts[i], pts[k] - pts[i])
            ln = np.linalg.norm(nrm)
            if ln < 1e-12:
                continue
            inl = np.abs((pts - pts[i]) @ (nrm / ln)) < tol
            if best is None or inl.sum() > best.sum():
                best = inl
        if best is None or best.sum() < min_size:
            break
        # refit on the inliers, then take the points near the refined plane
        c = pts[best].mean(axis=0)
        nrm = _pca_normal(pts[best])
        best = np.abs((pts - c) @ nrm) < tol
        if best.sum() < min_size:
            break
        planes.append(remaining[best])
        remaining = remaining[~best]
    return planes


def perspective_bias(camera: CameraModel, x, normals, radius_mm) -> np.ndarray:
    """Image position of the centre of each imaged circle minus the image of its centre.

    A circle of radius ``radius_mm`` around ``x`` in the plane normal to
    ``normals`` is imaged (pinhole part) as a conic; the centroid of that
    ellipse, which is what a centroid detector measures, is the conic
    centre. Distortion, when present, is applied to both points.

    Parameters
    ----------
    camera : CameraModel
    x : array_like, shape (N, 3)
        Marker centres, mm.
    normals : array_like, shape (N, 3)
        Normals of the marker planes (any length and sign).
    radius_mm : float or array_like (N,)
        Marker radius, mm.

    Returns
    -------
    ndarray, shape (N, 2)
        Bias in px: subtract it from the detected centres.
    """
    x = np.asarray(x, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    rho = np.broadcast_to(np.asarray(radius_mm, dtype=np.float64), (len(x),))
    # orthonormal in-plane basis
    helper = np.where(np.abs(nrm[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(nrm, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(nrm, e1)
    R, C = camera.R, camera.C
    P = np.hstack([R, -(R @ C)[:, None]])  # normalised camera: (x_n, y_n, 1)
    B = np.zeros((len(x), 4, 3))
    B[:, :3, 0], B[:, :3, 1], B[:, :3, 2], B[:, 3, 2] = e1, e2, x, 1.0
    H = np.einsum("ij,njk->nik", P, B)
    Hi = np.linalg.inv(H)
    Cp = np.zeros((len(x), 3, 3))
    Cp[:, 0, 0] = Cp[:, 1, 1] = 1.0
    Cp[:, 2, 2] = -rho**2
    Q = np.einsum("nji,njk,nkl->nil", Hi, Cp, Hi)
    centre = -np.linalg.solve(Q[:, :2, :2], Q[:, :2, 2][..., None])[..., 0]
    h0 = (x - C) @ R.T
    proj = h0[:, :2] / h0[:, 2:3]

    if not camera.has_distortion:
        K = camera.K
        return (centre - proj) @ K[:2, :2].T
    # with distortion the imaged marker is no longer a conic: area centroid of
    # its boundary polygon (256 vertices: error ~1e-5 px at these sizes)
    ang = 2 * np.pi * np.arange(256) / 256
    ring = x[:, None, :] + rho[:, None, None] * (np.cos(ang)[None, :, None] * e1[:, None, :]
                                                 + np.sin(ang)[None, :, None] * e2[:, None, :])
    uv = camera.project(ring.reshape(-1, 3)).reshape(len(x), -1, 2)
    a, b = uv[..., 0], uv[..., 1]
    a1, b1 = np.roll(a, -1, axis=1), np.roll(b, -1, axis=1)
    cross = a * b1 - a1 * b
    area = 0.5 * cross.sum(axis=1)
    cu = ((a + a1) * cross).sum(axis=1) / (6 * area)
    cv = ((b + b1) * cross).sum(axis=1) / (6 * area)
    return np.column_stack([cu, cv]) - camera.project(x)


# ----------------------------------------------------------------------------- correspondence


def assign(predicted, detected, gate_px: float) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one assignment of predicted marker positions to detections.

    Hungarian algorithm on the pixel distances; pairs farther apart than
    ``gate_px`` are not made.

    Parameters
    ----------
    predicted : array_like (M, 2)
        Projected marker positions, px (NaN rows: marker not visible).
    detected : array_like (D, 2)
        Detected centres, px.
    gate_px : float or array_like (M,)
        Largest accepted distance, px (one for all markers or one per marker).

    Returns
    -------
    marker_index, detection_index : ndarray of int
        Matched pairs, sorted by marker index.
    """
    pred = np.asarray(predicted, dtype=np.float64)
    det = np.asarray(detected, dtype=np.float64)
    ok = np.isfinite(pred).all(axis=1)
    if not ok.any() or len(det) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    mi = np.flatnonzero(ok)
    gate = np.broadcast_to(np.asarray(gate_px, dtype=np.float64), (len(pred),))[mi, None]
    d = np.hypot(pred[mi, None, 0] - det[None, :, 0], pred[mi, None, 1] - det[None, :, 1])
    big = 1e6 + d.max()
    cost = np.where(d <= gate, d, big)
    r, c = linear_sum_assignment(cost)
    good = cost[r, c] <= gate[r, 0]
    order = np.argsort(mi[r[good]])
    return mi[r[good]][order], c[good][order]


def _spacing(uv: np.ndarray) -> float:
    """Median nearest-neighbour distance of the detections, px."""
    if len(uv) < 2:
        return np.inf
    d, _ = cKDTree(uv).query(uv, k=2)
    return float(np.median(d[:, 1]))


def _predicted_spacing(pred: np.ndarray) -> np.ndarray:
    """Distance (px) of every predicted marker position from the nearest other one (inf if none)."""
    out = np.full(len(pred), np.inf)
    ok = np.isfinite(pred).all(axis=1)
    if ok.sum() >= 2:
        d, _ = cKDTree(pred[ok]).query(pred[ok], k=2)
        out[ok] = d[:, 1]
    return out


def propagate(model: CameraModel, marker_x, detected_uv, *, gate_px: float | None = None,
              max_iter: int = 20) -> tuple[np.ndarray, np.ndarray, CameraModel]:
    """Grow a correspondence: project all markers, assign detections, refit the DLT, repeat.

    Parameters
    ----------
    model : CameraModel
        Start camera (from seeds or a lattice match).
    marker_x : array_like (M, 3)
        All marker centres, mm.
    detected_uv : array_like (D, 2)
        All detections, px.
    gate_px : float, optional
        Assignment gate, px; default per marker 0.4 x the distance of its
        predicted position from the nearest other predicted marker (on a
        strongly foreshortened wing the markers are much closer than on the
        other; spurious detections must not shrink the gate).

    Returns
    -------
    marker_index, detection_index : ndarray of int
    model : CameraModel
        DLT of the final pairs.
    """
    X = np.asarray(marker_x, dtype=np.float64)
    D = np.asarray(detected_uv, dtype=np.float64)
    prev = None
    mi = di = np.zeros(0, int)
    gate = gate_px
    for _ in range(max_iter):
        pred = model.project(X)
        if gate_px is None:
            gate = 0.4 * _predicted_spacing(pred)
        mi, di = assign(pred, D, gate)
        key = (tuple(mi), tuple(di))
        if key == prev or len(mi) < 6:
            break
        prev = key
        try:
            model = CameraModel(dlt(X[mi], D[di]))
        except CalibrationError:
            break
    if len(mi) < 6:
        g = np.nanmedian(gate) if np.size(gate) else np.nan
        raise CalibrationError(
            f"only {len(mi)} markers could be matched to detections (gate {g:.1f} px); the DLT needs 6. "
            + SEEDS_HINT
        )
    return mi, di, model


def _seed_table(seeds: Mapping, marker_ids) -> tuple[np.ndarray, np.ndarray, list]:
    if not isinstance(seeds, Mapping):
        raise ConfigError(f"`seeds` must be a mapping {{marker_id: [u, v]}}, got {type(seeds).__name__}")
    lookup = {str(m): i for i, m in enumerate(np.asarray(marker_ids).tolist())}
    unknown = [k for k in seeds if str(k) not in lookup]
    if unknown:
        raise ConfigError(
            f"seeds name marker IDs that are not in the marker file: {sorted(map(str, unknown))}; "
            f"known IDs are e.g. {list(lookup)[:8]}"
        )
    idx, uv, keys = [], [], []
    for k, val in seeds.items():
        try:
            pos = np.asarray(val, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            pos = np.zeros(0)
        if pos.shape != (2,) or not np.isfinite(pos).all():
            raise ConfigError(f"seeds[{k!r}] must be a pair [u, v] of pixel positions, got {val!r}")
        idx.append(lookup[str(k)])
        uv.append(pos)
        keys.append(k)
    if len(set(idx)) != len(idx):
        raise ConfigError("seeds name the same marker twice (keys that differ only in type, e.g. 12 and '12')")
    if len(idx) < 6:
        raise ConfigError(f"`seeds` needs at least 6 markers (11 camera parameters), got {len(idx)}")
    return np.array(idx), np.array(uv), keys


def match_seeds(detected_uv, marker_x, marker_ids, seeds: Mapping, *, gate_px: float | None = None,
                seed_tolerance_px: float | None = None) -> tuple[np.ndarray, np.ndarray, CameraModel]:
    """Correspondence from a few user-given marker positions.

    Each seed is snapped to the nearest detection where that is unambiguous;
    the seeds are judged against a camera fitted robustly to all of them
    (RANSAC over 6-seed DLTs, :func:`_robust_seed_fit`): every seed must lie
    within ``seed_tolerance_px`` of it, else the ones that do not are named.
    The DLT through the seeds predicts all markers, and :func:`propagate`
    grows the assignment.

    Parameters
    ----------
    detected_uv : array_like (D, 2)
        Detected centres, px.
    marker_x : array_like (M, 3)
        Marker centres, mm.
    marker_ids : array_like (M,)
        Marker IDs (compared as strings with the seed keys).
    seeds : mapping
        ``{marker_id: (u, v)}`` for at least 6 markers, a few px off at most.
    gate_px : float, optional
        Assignment gate (default per marker: 0.4 x the distance of its
        predicted position from the nearest other predicted marker).
    seed_tolerance_px : float, optional
        Largest accepted distance of a seed from the camera fitted robustly
        to all seeds (default :data:`SEED_TOLERANCE_PX` = 6 px: honest
        clicks are a few px off, a seed on a neighbouring marker a marker
        spacing).

    Returns
    -------
    marker_index, detection_index : ndarray of int
    model : CameraModel

    Raises
    ------
    ConfigError
        Unknown seed IDs, fewer than 6 seeds, coplanar seeds or seeds that
        contradict each other (the worst one is named).
    """
    D = np.asarray(detected_uv, dtype=np.float64)
    X = np.asarray(marker_x, dtype=np.float64)
    idx, suv, keys = _seed_table(seeds, marker_ids)
    tol = float(seed_tolerance_px) if seed_tolerance_px is not None else SEED_TOLERANCE_PX
    if not (np.isfinite(tol) and tol > 0):
        raise ConfigError(f"`seed_tolerance_px` must be a positive number of pixels, got {seed_tolerance_px!r}")
    clicked = suv
    snap = np.zeros(len(suv), bool)
    if len(D) >= 2:
        spacing = _spacing(D)
        d, j = cKDTree(D).query(suv, k=2)
        # a seed several marker spacings away from every blob points at no
        # marker at all (off the target, u and v swapped, a typo): say so
        # rather than letting the fit report the seeds as degenerate. (One
        # spacing is not enough: the neighbours of an undetected marker on a
        # faint or foreshortened wing may be undetected too.)
        far = np.flatnonzero(d[:, 0] > max(3.0 * spacing, 3.0))
        if far.size:
            names = "; ".join(f"seed for marker {keys[f]!r} at ({suv[f, 0]:.1f}, {suv[f, 1]:.1f}) is "
                              f"{d[f, 0]:.1f} px from any detected blob" for f in far[:5])
            raise ConfigError(
                f"{names} (detections are {spacing:.1f} px apart); give the pixel position (u = column, v = row) "
                "of a detected marker, read off the detection figure"
            )
        # snap a click to a detection only where that is unambiguous (the next detection is 3x
        # farther): on a strongly foreshortened wing the neighbours are closer than a click's error
        snap = (d[:, 0] <= 0.5 * spacing) & (d[:, 1] > 3.0 * d[:, 0])
        suv = np.where(snap[:, None], D[j[:, 0]], suv)
    line = degeneracy(X[idx], "seed markers")
    if line is not None and "coplanar" not in line:
        raise ConfigError(f"{line}, so they do not determine a camera; choose seeds spread over both wings of "
                          "the target")
    thick = planarity(X[idx])
    if thick < 1e-3:
        raise ConfigError(
            f"the {len(idx)} seed markers are coplanar (thickness ratio {thick:.1e}), so they do not determine a "
            "camera; choose seeds spread over both wings of the target"
        )
    inl, model, res = _robust_seed_fit(X[idx], suv, tol)
    if model is not None and (snap & ~inl).any():
        # where its marker was not detected, a click may have snapped to a neighbour: the click
        # itself is what the user said
        suv = np.where((snap & ~inl)[:, None], clicked, suv)
        inl, model, res = _robust_seed_fit(X[idx], suv, tol)
    if model is None or not inl.all():
        raise ConfigError(_seed_message(keys, suv, inl, model, res, tol))
    return propagate(model, X, D, gate_px=gate_px)


#: Default largest distance (px) of a clicked seed from the camera fitted to the seeds.
SEED_TOLERANCE_PX = 6.0


def _robust_seed_fit(x: np.ndarray, uv: np.ndarray, tol: float, max_sets: int = 400, seed: int = 0):
    """Seeds that agree on one camera: RANSAC over minimal (6-point) DLT sets.

    Every 6-seed subset (or ``max_sets`` random ones when there are more),
    and with 8 or more seeds every set without one seed and the full set,
    gives a DLT; the one that puts the most seeds within ``tol`` px (ties:
    smallest sum of squared residuals capped at ``tol``) wins, and the DLT
    of its inliers is refitted until the inlier set is stable.

    Returns
    -------
    inliers : ndarray of bool (n,)
    model : CameraModel or None
        DLT of the inliers (None when no subset gives a camera).
    residuals : ndarray (n,)
        Distance of every seed from the projection of its marker by ``model``, px.

    Notes
    -----
    Leave-one-out DLTs through the other seeds do not work here: with 7 or 8
    seeds on an oblique view the system is so ill-conditioned that an
    honest 2 px click error is magnified to tens of px. A minimal set that
    avoids a wrong seed predicts the honest ones within a few px, and the
    wrong one by about a marker spacing.
    """
    n = len(x)
    combos = itertools.combinations(range(n), 6)
    n_sets = int(np.prod(np.arange(n - 5, n + 1)) // 720)
    if n_sets > max_sets:
        rng = np.random.default_rng(seed)
        combos = (np.sort(rng.choice(n, 6, replace=False)) for _ in range(max_sets))
    # the sets without one seed and the full set as well: a 6-point DLT through clicks a few px
    # off can extrapolate poorly on an oblique view, where all honest seeds together fit well
    larger = [[j for j in range(n) if j != i] for i in range(n)] + [list(range(n))] if n >= 8 else []
    best, best_key = None, (-1, -np.inf)
    fatal = None
    for sub in itertools.chain(combos, larger):
        sub = list(sub)
        if planarity(x[sub]) < 1e-3:
            continue
        try:
            res = np.hypot(*(CameraModel(dlt(x[sub], uv[sub])).project(x) - uv).T)
        except CalibrationError as exc:
            # inconsistent seeds put some markers behind the camera; a mirrored
            # image puts all of them there, which no choice of seeds mends
            if getattr(exc, "reason", None) != "inconsistent":
                fatal = fatal or exc
            continue
        res = np.where(np.isfinite(res), res, np.inf)
        inl = res <= tol
        key = (int(inl.sum()), -float(np.minimum(res, tol) ** 2 @ np.ones(n)))
        if key > best_key:
            best, best_key = inl, key
    if best is None and fatal is not None:
        raise fatal
    if best is None or best.sum() < 6:
        return np.zeros(n, bool) if best is None else best, None, np.full(n, np.inf)
    inl = best
    model = None
    for _ in range(5):
        try:
            model = CameraModel(dlt(x[inl], uv[inl]))
        except CalibrationError:
            return inl, None, np.full(n, np.inf)
        res = np.hypot(*(model.project(x) - uv).T)
        new = res <= tol
        if new.sum() < 6 or (new == inl).all():
            break
        inl = new
    return inl, model, res


def _seed_message(keys, suv, inl, model, res, tol) -> str:
    """User message for seeds that do not agree on one camera (culprits named by marker ID)."""
    n = len(keys)
    if model is None:
        return (f"the seeds contradict each other: no 6 of the {n} seeds fit one camera within {tol:.1f} px "
                "(the seed tolerance); check their marker IDs and positions (u = column, v = row)")
    bad = np.flatnonzero(~inl)
    names = " and ".join(f"seed {keys[b]!r} at {suv[b].round(1).tolist()} ({res[b]:.1f} px off)" for b in bad)
    return (f"the seeds contradict each other: {n - len(bad)} of the {n} seeds fit one camera within "
            f"{tol:.1f} px (the seed tolerance), {len(bad)} do not; the worst "
            f"{'is' if len(bad) == 1 else 'are'} {names}, judged by the camera of the other seeds. A seed "
            "that far off is probably on another marker: check its marker ID and position")


# -- automatic correspondence for grid targets


def _homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Normalised DLT homography src -> dst (both (n, 2), n >= 4)."""

    def norm(p):
        c = p.mean(axis=0)
        s = np.sqrt(2) / max(np.sqrt(((p - c) ** 2).sum(axis=1)).mean(), 1e-12)
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])

    Ts, Td = norm(src), norm(dst)
    s = src @ Ts[:2, :2].T + Ts[:2, 2]
    d = dst @ Td[:2, :2].T + Td[:2, 2]
    n = len(s)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = s, 1
    A[0::2, 6:8], A[0::2, 8] = -d[:, :1] * s, -d[:, 0]
    A[1::2, 3:5], A[1::2, 5] = s, 1
    A[1::2, 6:8], A[1::2, 8] = -d[:, 1:] * s, -d[:, 1]
    _, _, vt = np.linalg.svd(A)
    H = np.linalg.solve(Td, vt[-1].reshape(3, 3)) @ Ts
    return H / H[2, 2]


def _apply_h(H: np.ndarray, p: np.ndarray) -> np.ndarray:
    h = p @ H[:, :2].T + H[:, 2]
    return h[:, :2] / h[:, 2:3]


def _grow_lattice(uv: np.ndarray, free: np.ndarray, quad: list[int], tol: float = 0.2) -> dict[int, tuple]:
    """Detections (indices into uv, among ``free``) on the planar lattice started by a unit quad."""
    nodes = {quad[0]: (0, 0), quad[1]: (1, 0), quad[2]: (0, 1), quad[3]: (1, 1)}
    for _ in range(60):
        ids = np.array(list(nodes))
        ij = np.array([nodes[i] for i in ids], dtype=np.float64)
        H = _homography(ij, uv[ids])
        try:
            Hi = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return nodes
        cand = free[~np.isin(free, ids)]
        if len(cand) == 0:
            break
        st = _apply_h(Hi, uv[cand])
        rnd = np.round(st)
        off = np.abs(st - rnd).max(axis=1)
        lo, hi = ij.min(axis=0) - 1, ij.max(axis=0) + 1
        inside = (rnd >= lo).all(axis=1) & (rnd <= hi).all(axis=1)
        taken = {tuple(v) for v in nodes.values()}
        best: dict[tuple, tuple] = {}
        for c, node, o in zip(cand[(off < tol) & inside], rnd[(off < tol) & inside], off[(off < tol) & inside]):
            key = (int(node[0]), int(node[1]))
            if key in taken:
                continue
            if key not in best or o < best[key][1]:
                best[key] = (int(c), o)
        if not best:
            break
        for key, (c, _) in best.items():
            nodes[c] = key
    # final check of every member against the homography of all
    ids = np.array(list(nodes))
    ij = np.array([nodes[i] for i in ids], dtype=np.float64)
    H = _homography(ij, uv[ids])
    off = np.abs(_apply_h(np.linalg.inv(H), uv[ids]) - ij).max(axis=1)
    return {int(i): nodes[i] for i, o in zip(ids, off) if o < tol}


def _image_lattices(uv: np.ndarray, min_size: int = 6, max_starts: int = 25) -> list[dict[int, tuple]]:
    """Planar lattices among the detections, largest first."""
    free = np.arange(len(uv))
    groups = []
    while len(free) >= min_size:
        tree = cKDTree(uv[free])
        kq = min(9, len(free))
        dist, nb = tree.query(uv[free], k=kq)
        best: dict[int, tuple] | None = None
        # starts from the most "interior" detections: small, even neighbour distances
        order = np.argsort(dist[:, min(4, kq - 1)] / np.maximum(dist[:, 1], 1e-9))
        for s in order[:max_starts]:
            q = _unit_quad(uv, free, s, nb[s], dist[s])
            if q is None:
                continue
            g = _grow_lattice(uv, free, q)
            if best is None or len(g) > len(best):
                best = g
            if len(best) >= 0.6 * len(free):
                break
        if best is None or len(best) < min_size:
            break
        groups.append(best)
        free = free[~np.isin(free, list(best))]
    return groups


def _unit_quad(uv, free, s, nb, dist):
    p0 = uv[free[s]]
    if len(nb) < 4:
        return None
    n1 = nb[1]
    v1 = uv[free[n1]] - p0
    for n2 in nb[2:]:
        v2 = uv[free[n2]] - p0
        c = v1 @ v2 / (np.linalg.norm(v1) * np.linalg.norm(v2))
        if abs(c) < 0.7:
            break
    else:
        return None
    target = p0 + v1 + v2
    d4 = np.hypot(*(uv[free] - target).T)
    j = int(np.argmin(d4))
    if d4[j] > 0.25 * min(np.linalg.norm(v1), np.linalg.norm(v2)):
        return None
    return [int(free[s]), int(free[n1]), int(free[n2]), int(free[j])]


def _plane_lattice(x: np.ndarray, tol: float = 0.15) -> np.ndarray | None:
    """Integer lattice indices (n, 2) of coplanar points on a regular grid, or None."""
    c = x.mean(axis=0)
    _, _, vt = np.linalg.svd(x - c, full_matrices=False)
    p = (x - c) @ vt[:2].T
    if len(p) < 4:
        return None
    dist, nb = cKDTree(p).query(p, k=min(7, len(p)))
    vecs = (p[nb[:, 1:]] - p[:, None, :]).reshape(-1, 2)
    lens = np.hypot(*vecs.T)
    spacing = np.median(dist[:, 1])
    short = vecs[lens < 1.25 * spacing]
    ang = np.mod(np.arctan2(short[:, 1], short[:, 0]), np.pi)
    # dominant direction, then the shortest vectors at > 25 degrees from it
    hist, edges = np.histogram(ang, bins=36, range=(0, np.pi))
    a1 = 0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1])
    def along(a, vv, la):
        d = np.abs(np.angle(np.exp(1j * (np.mod(np.arctan2(vv[:, 1], vv[:, 0]), np.pi) - a) * 2))) / 2
        return d
    sel1 = along(a1, short, None) < np.radians(8)
    if sel1.sum() == 0:
        return None
    v = short[sel1]
    v = np.where((v @ np.array([np.cos(a1), np.sin(a1)]))[:, None] < 0, -v, v)
    b1 = v.mean(axis=0)
    other = vecs[along(a1, vecs, None) > np.radians(25)]
    if len(other) == 0:
        return None
    lo = np.hypot(*other.T)
    cand = other[lo < 1.15 * lo.min()]
    a2 = np.mod(np.arctan2(cand[:, 1], cand[:, 0]), np.pi)
    a2m = np.median(a2)
    cand = np.where((cand @ np.array([np.cos(a2m), np.sin(a2m)]))[:, None] < 0, -cand, cand)
    b2 = cand.mean(axis=0)
    B = np.column_stack([b1, b2])
    ref = p[np.argmin(np.hypot(*p.T))]
    ij = np.linalg.solve(B, (p - ref).T).T
    rnd = np.round(ij)
    if np.abs(ij - rnd).max() > tol:
        return None
    # least-squares lattice fit and re-check
    A = np.column_stack([np.ones(len(p)), rnd])
    coef, *_ = np.linalg.lstsq(A, p, rcond=None)
    fit = A @ coef
    if np.hypot(*(fit - p).T).max() > tol * spacing:
        return None
    ij = rnd.astype(int)
    if len({tuple(r) for r in ij}) != len(ij):
        return None
    return ij - ij.min(axis=0)


def _unimodular() -> list[np.ndarray]:
    """Integer 2x2 matrices with entries in {-1, 0, 1} and determinant +-1 (lattice symmetries and shears)."""
    mats = []
    for e in itertools.product((-1, 0, 1), repeat=4):
        G = np.array(e).reshape(2, 2)
        if abs(round(np.linalg.det(G))) == 1:
            mats.append(G)
    return mats


_UNIMODULAR = _unimodular()


def _lattice_candidates(S: np.ndarray, W: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(overlap, G, t) with W ≈ G S + t for the lattice maps of (nearly) largest overlap."""
    out = []
    for G in _UNIMODULAR:
        T = S @ G.T
        diff = (W[None, :, :] - T[:, None, :]).reshape(-1, 2)
        keys, counts = np.unique(diff, axis=0, return_counts=True)
        for k in np.flatnonzero(counts == counts.max()):
            out.append((int(counts[k]), G, keys[k]))
    if not out:
        return []
    best = max(c for c, _, _ in out)
    # an undetected marker or two may cost the true map its first place
    return [o for o in out if o[0] >= best - max(1, int(0.05 * best))]


def match_lattice(detected_uv, marker_x, *, max_rms_px: float = 2.0,
                  ambiguity_ratio: float = 4.0) -> tuple[np.ndarray, np.ndarray, CameraModel]:
    """Automatic correspondence for targets with markers on planar grids (open book).

    The markers are split into planes (RANSAC) and each plane's grid is
    indexed; among the detections the planar lattices are grown from unit
    quads with homographies. Every consistent way of mapping the image
    lattices onto the marker grids (lattice symmetries and shifts, which
    wing is which) is scored by the reprojection RMS of its DLT; the best is
    then grown by :func:`propagate`.

    Parameters
    ----------
    detected_uv : array_like (D, 2)
        Detected centres, px.
    marker_x : array_like (M, 3)
        Marker centres, mm.
    max_rms_px : float
        Largest accepted DLT RMS of the best candidate, px.
    ambiguity_ratio : float
        The second-best distinct candidate must have an RMS at least this
        many times larger than the best (and 0.5 px larger).

    Returns
    -------
    marker_index, detection_index : ndarray of int
    model : CameraModel

    Raises
    ------
    CalibrationError
        When no grid is found or the assignment is not certain; the message
        says which seeds to add to the configuration.
    """
    D = np.asarray(detected_uv, dtype=np.float64)
    X = np.asarray(marker_x, dtype=np.float64)
    planes = [p for p in _planes(X) if len(p) >= 6]
    lattices = []
    for members in planes:
        ij = _plane_lattice(X[members])
        if ij is not None:
            lattices.append((members, ij))
    if len(lattices) < 2:
        raise CalibrationError(
            f"automatic marker correspondence needs markers on at least two planar grids; found "
            f"{len(lattices)} (planes: {[len(p) for p in planes]}). " + SEEDS_HINT
        )
    groups = _image_lattices(D)
    if len(groups) < 2:
        raise CalibrationError(
            f"automatic marker correspondence found {len(groups)} marker grid(s) in the image; it needs two "
            "(both wings). " + SEEDS_HINT
        )
    groups = groups[:3]
    lattices = lattices[:3]
    # candidate maps per (image group, marker plane)
    cands = {}
    for gi, g in enumerate(groups):
        det_ids = np.array(list(g))
        S = np.array([g[i] for i in det_ids])
        for li, (members, W) in enumerate(lattices):
            lut = {tuple(w): m for w, m in zip(W.tolist(), members)}
            lst = []
            for count, G, t in _lattice_candidates(S, W):
                T = S @ G.T + t
                pairs = [(lut[tuple(r)], d) for r, d in zip(T.tolist(), det_ids) if tuple(r) in lut]
                lst.append(np.array(pairs))
            cands[gi, li] = lst
    scored = []
    for (ga, la), (gb, lb) in itertools.permutations(cands, 2):
        if ga >= gb or la == lb:
            continue
        for pa in cands[ga, la]:
            for pb in cands[gb, lb]:
                pairs = np.vstack([pa, pb])
                try:
                    model = CameraModel(dlt(X[pairs[:, 0]], D[pairs[:, 1]]))
                except CalibrationError:
                    continue
                rms = _rms(model, X[pairs[:, 0]], D[pairs[:, 1]])
                if rms <= max_rms_px:
                    scored.append((rms, pairs, model))
    if not scored:
        raise CalibrationError(
            f"automatic marker correspondence found no assignment of the marker grids that fits a camera "
            f"within {max_rms_px} px RMS. " + SEEDS_HINT
        )
    # grow every acceptable candidate over all markers and detections; the
    # true one explains the most detections (a shifted or rotated grid leaves
    # a row or column unmatched), with the smallest RMS
    grown = {}
    for rms, pairs, model in sorted(scored, key=lambda s: s[0])[:20]:
        try:
            mi, di, m = propagate(model, X, D)
        except CalibrationError:
            continue
        key = (tuple(mi), tuple(di))
        if key not in grown:
            grown[key] = (len(mi), _rms(m, X[mi], D[di]), mi, di, m)
    if not grown:
        raise CalibrationError("automatic marker correspondence could not grow any assignment. " + SEEDS_HINT)
    ranked = sorted(grown.values(), key=lambda g: (-g[0], g[1]))
    best = ranked[0]
    if best[1] > max_rms_px:
        raise CalibrationError(
            f"automatic marker correspondence is not sure: the best assignment leaves {best[1]:.2f} px RMS "
            f"(limit {max_rms_px} px). " + SEEDS_HINT
        )
    # when the best assignment explains every detection, an alternative that
    # leaves even one well-formed detection unexplained is decisively worse
    # (that is how an unpainted or coded marker breaks the open book's
    # symmetry); otherwise allow for a few missed or spurious blobs
    slack = 0 if best[0] == len(D) else max(1, int(0.05 * best[0]))
    for n, rms, *_ in ranked[1:]:
        if n >= best[0] - slack and rms < max(ambiguity_ratio * best[1], best[1] + 0.5):
            raise CalibrationError(
                f"automatic marker correspondence is ambiguous: two different assignments fit a camera "
                f"({best[0]} markers at {best[1]:.3f} px RMS and {n} markers at {rms:.3f} px RMS); the target "
                "looks symmetric to the camera. " + SEEDS_HINT
            )
    log.info("automatic correspondence: %d pairs, DLT RMS %.3f px (%d candidates, %d grown)",
             best[0], best[1], len(scored), len(grown))
    return best[2], best[3], best[4]


def _rms(model: CameraModel, x: np.ndarray, uv: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((model.project(x) - uv) ** 2, axis=1))))


def check_ids(marker_ids) -> np.ndarray:
    """Marker IDs as an array, refusing duplicates (DataError naming them)."""
    ids = np.asarray(marker_ids)
    if ids.ndim != 1:
        raise ConfigError(f"marker IDs must be 1-D, got shape {ids.shape}")
    uniq, counts = np.unique(ids.astype(str), return_counts=True)
    if (counts > 1).any():
        raise DataError(f"duplicate marker IDs: {uniq[counts > 1][:10].tolist()}; every marker needs its own ID")
    return ids
