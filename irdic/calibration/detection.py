"""Detection of the circular markers of a calibration target in an IR image.

The markers of the reference object differ from its body in emissivity, so
they appear colder ("dark") or warmer ("bright") than the body although the
target is at one temperature. :func:`detect_markers` finds them with
sub-pixel centres.

Compact blobs are found on a morphological top-hat (square structuring
element larger than the largest marker); markers too faint for it
(contrast/noise down to ~3) are found as peaks of a bank of matched filters
(disc-sized square minus its surrounding ring, which removes the local
background level and gradient; radii from ``min_radius_px`` to
``max_radius_px``). Each blob is then measured on the image itself after
subtracting a background plane fitted on an annulus around it: contrast,
region above half contrast (radius, moment ellipse, eccentricity, solidity)
and an iterative intensity weighted centroid of the background-subtracted
contrast in a soft circular window.

NaN pixels are never measured: they are filled with the image median for
the top-hat only, and a candidate whose window (blob, blur margin and
background annulus) contains one is rejected (``n_rejected_invalid``).

Pixel convention: ``u`` = column, ``v`` = row, full-sensor coordinates,
0-based, pixel centres on integers (a cropped image keeps its offset).
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
import xarray as xr
from scipy import ndimage
from skimage.morphology import convex_hull_image

from ..errors import CalibrationError, ConfigError, IrdicWarning
from .image import check_image, image_array, noise_sigma, saturation_error

__all__ = ["detect_markers", "centre_weights", "centre_covariances", "DETECTION_FIELDS", "CENTRE_FLOOR_PX"]

log = logging.getLogger(__name__)

# ----------------------------------------------------------------------------- candidates



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


def plane_fit(uu, vv, vals, noise=0.0):
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
    coef = plane_fit(uu[ann] - uc, vv[ann] - vc, patch[ann], noise)
    s = sign * (patch - (coef[0] + coef[1] * (uu - uc) + coef[2] * (vv - vc)))
    s_shape = ndimage.gaussian_filter(s, smooth, mode="nearest") if smooth > 0 else s
    core = dist <= max(0.5 * r0, 1.0)
    contrast = float(np.median(s_shape[core]))
    if not contrast > 0:
        return None, "contrast"
    # region at half contrast, the component that holds the blob
    lab, _ = ndimage.label(s_shape > 0.5 * contrast)
    li = lab[int(round(vc)) - v_lo, int(round(uc)) - u_lo]
    if li == 0:
        return None, "shape"
    region = lab == li
    if (region & (dist > r_in)).any():
        return None, "shape"  # spills into the background annulus: not an isolated blob
    shape = _region_shape(region, uu, vv)
    snr = contrast / noise if noise > 0 else np.inf
    centre = _windowed_centroid(s, uu, vv, lab, li, shape, snr, noise)
    if centre is None:
        return None, "contrast"
    cu, cv, sig = centre
    if np.hypot(cu - shape["mu"], cv - shape["mv"]) > 0.5 * shape["semi_minor_px"] + 0.5:
        return None, "shape"
    evecs = shape["axes"]
    return {
        "u": cu, "v": cv, "radius_px": np.sqrt(shape["area_px"] / np.pi), "semi_major_px": shape["semi_major_px"],
        "semi_minor_px": shape["semi_minor_px"], "orientation_rad": float(np.arctan2(evecs[1, 1], evecs[0, 1])),
        "eccentricity": shape["eccentricity"], "solidity": shape["solidity"], "contrast_k": contrast,
        "area_px": shape["area_px"], "snr": snr, "sigma_px": float(sig),
        # the windowed centroid's uncertainty is known as a total only: split evenly between the axes
        "cov_uu_px2": float(sig) ** 2 / 2, "cov_vv_px2": float(sig) ** 2 / 2, "cov_uv_px2": 0.0,
    }, None


def _region_shape(region: np.ndarray, uu: np.ndarray, vv: np.ndarray) -> dict:
    """Area, mean position, moment ellipse and solidity of a pixel region (px)."""
    area = float(region.sum())
    ru, rv = uu[region], vv[region]
    mu, mv = ru.mean(), rv.mean()
    cov = np.cov(np.vstack([ru - mu, rv - mv]), bias=True) + np.eye(2) / 12.0
    evals, evecs = np.linalg.eigh(cov)
    lam2, lam1 = max(evals[0], 1e-12), max(evals[1], 1e-12)
    # solidity: area over convex hull area (pixel squares)
    hull = convex_hull_image(region)
    return {"area_px": area, "mu": mu, "mv": mv, "axes": evecs, "region": region,
            "eccentricity": float(np.sqrt(max(0.0, 1.0 - lam2 / lam1))),
            "semi_major_px": 2.0 * np.sqrt(lam1), "semi_minor_px": 2.0 * np.sqrt(lam2),
            "solidity": float(area / max(hull.sum(), 1))}


def _windowed_centroid(s, uu, vv, lab, li, shape: dict, snr: float, noise: float):
    """Iterative windowed centroid ``(u, v, sigma_px)`` of the contrast ``s``; None without positive weight.

    The window is the moment ellipse of ``shape`` grown by a margin (a
    circle would reach the close neighbours of foreshortened markers); its
    soft edge makes the estimate continuous in the centre (no pull to
    integer pixels). ``sigma_px`` is the standard uncertainty of the
    centroid from pixel noise.
    """
    e1 = shape["axes"][:, 1]
    region, area = shape["region"], shape["area_px"]
    # The margin beyond the moment ellipse holds the blur tails but, at low
    # contrast/noise, mostly noise, which the lever arm r amplifies: 2 px
    # above contrast/noise 20, 0.75 px below 10 (the imaged disc is centrally
    # symmetric, so a tight window centred on it costs no bias), linear between.
    margin = 0.75 + 1.25 * float(np.clip((snr - 10.0) / 10.0, 0.0, 1.0))
    A, B = shape["semi_major_px"] + margin, shape["semi_minor_px"] + margin
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

    cu, cv = shape["mu"], shape["mv"]
    for _ in range(30):
        wgt = s * window(cu, cv)
        tot = wgt.sum()
        if not tot > 0:
            return None
        nu, nv = (wgt * uu).sum() / tot, (wgt * vv).sum() / tot
        moved = np.hypot(nu - cu, nv - cv)
        cu, cv = nu, nv
        if moved < 1e-6:
            break
    wsum = window(cu, cv)
    sig = noise * np.sqrt(((wsum * (uu - cu)) ** 2 + (wsum * (vv - cv)) ** 2).sum()) / tot
    return cu, cv, sig


DETECTION_FIELDS = {
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
    "sigma_px": ("px", "standard uncertainty of the centre from pixel noise (root of the covariance's trace)"),
    "cov_uu_px2": ("px^2", "variance of the centre's u from pixel noise"),
    "cov_vv_px2": ("px^2", "variance of the centre's v from pixel noise"),
    "cov_uv_px2": ("px^2", "covariance of the centre's u and v from pixel noise"),
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
        if invalid is not None and _touches(invalid, vc, uc, 3.0 * r + 6.0):
            # the filter answers the edges of a filled NaN hole: no evidence of a marker
            continue
        n += 1
        # the matched filter is circular; a foreshortened marker is up to 1/sqrt(0.26) ~ 2x longer
        m, why = _measure_at(img, sign, vc, uc, r, 2.0 * r, others, noise, smooth=1.0, invalid=invalid)
        _accept(m, why, rows, rejected, min_r, max_r, max_ecc, min_sol, min_contrast)
    return rows, rejected, n


def _touches(mask: np.ndarray, vc: float, uc: float, half: float) -> bool:
    """True when ``mask`` has a pixel in the box of half-width ``half`` (px) around (``uc``, ``vc``)."""
    h = int(np.ceil(half))
    v, u = int(round(vc)), int(round(uc))
    return bool(mask[max(v - h, 0):v + h + 1, max(u - h, 0):u + h + 1].any())


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

    Top-hat blobs and faint matched-filter peaks, each measured against a
    local background plane (see the module docstring for the method).

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
    """
    _check_settings(polarity, min_radius_px, max_radius_px, min_contrast_k, threshold_sigma, matched_sigma)
    where, img, u0, v0, clip, invalid = _prepared_image(image, min_contrast_k)
    n_invalid = int(invalid.sum())
    noise = noise_sigma(np.where(invalid, np.nan, img) if n_invalid else img)
    thr = max(threshold_sigma * noise, 0.5 * min_contrast_k)
    kw = dict(size=2 * int(np.ceil(max_radius_px)) + 3, thr=thr, noise=noise, min_r=min_radius_px,
              max_r=max_radius_px, min_contrast=min_contrast_k, max_ecc=max_eccentricity, min_sol=min_solidity,
              mf_sigma=matched_sigma, invalid=invalid if n_invalid else None)
    pol, (rows, rejected, n_cand) = _best_polarity(img, polarity, kw)
    if n_invalid:
        warnings.warn(
            f"{where}target image has {n_invalid} invalid (NaN) pixels ({n_invalid / invalid.size:.2%}); "
            f"{rejected['invalid']} marker candidate(s) touching them were left out",
            IrdicWarning, stacklevel=2)
    if not rows:
        raise saturation_error(clip) or CalibrationError(
            f"no marker-like blobs found in the target image (polarity {polarity}, noise {noise:.3f} K, threshold "
            f"{thr:.3f} K, {n_cand} candidates, rejected: {rejected}); check polarity, min_contrast_k and the "
            f"radius range [{min_radius_px}, {max_radius_px}] px"
        )
    ds = _detections_dataset(_dedupe(rows), u0, v0)
    ds.attrs.update(polarity=pol, noise_k=noise, threshold_k=thr, n_candidates=int(n_cand),
                    sensor_u0=u0, sensor_v0=v0, image_height=int(img.shape[0]), image_width=int(img.shape[1]),
                    **{f"n_rejected_{k}": int(v) for k, v in rejected.items()})
    log.info("%d markers detected (%s, noise %.3f K, %d candidates)", ds.sizes["detection"], pol, noise, n_cand)
    return ds


def _prepared_image(image, min_contrast_k: float):
    """``(where, values, u0, v0, clip, invalid)``: the checked frame (see :func:`check_image`) and its source."""
    img, u0, v0 = image_array(image)
    if min(img.shape) < 8:
        raise ConfigError(f"target image is too small ({img.shape[0]} x {img.shape[1]} px)")
    source = getattr(image, "attrs", {}).get("source")
    where = f"{source}: " if source else ""
    img, clip, invalid = check_image(img, min_contrast_k, where)
    return where, img, u0, v0, clip, invalid


def _check_settings(polarity, min_radius_px, max_radius_px, min_contrast_k, threshold_sigma, matched_sigma) -> None:
    """ConfigError naming the first invalid setting of :func:`detect_markers`."""
    if polarity not in ("auto", "dark", "bright"):
        raise ConfigError(f"`polarity` must be 'auto', 'dark' or 'bright', got {polarity!r}")
    for name, val in (("min_radius_px", min_radius_px), ("max_radius_px", max_radius_px),
                      ("min_contrast_k", min_contrast_k), ("threshold_sigma", threshold_sigma),
                      ("matched_sigma", matched_sigma)):
        if not (np.isfinite(val) and val > 0):
            raise ConfigError(f"`{name}` must be a positive number, got {val!r}")
    if min_radius_px >= max_radius_px:
        raise ConfigError(f"`min_radius_px` ({min_radius_px}) must be smaller than `max_radius_px` ({max_radius_px})")


def _best_polarity(img: np.ndarray, polarity: str, kw: dict) -> tuple[str, tuple[list, dict, int]]:
    """Detect with the given polarity, or with both for "auto" and keep the one with more (stronger) blobs."""
    signs = {"dark": -1.0, "bright": 1.0}
    noise = kw["noise"]
    results = {}
    for pol in (["dark", "bright"] if polarity == "auto" else [polarity]):
        mf = _matched_response(signs[pol] * img, noise, kw["min_r"], kw["max_r"]) if noise > 0 else None
        results[pol] = _detect_polarity(img, signs[pol], mf=mf, **kw)
    if polarity != "auto":
        return polarity, results[polarity]
    pol = max(results, key=lambda p: (len(results[p][0]), sum(r["contrast_k"] for r in results[p][0])))
    other = "bright" if pol == "dark" else "dark"
    log.info("marker polarity: %s (%d blobs; %d as %s)", pol, len(results[pol][0]), len(results[other][0]), other)
    return pol, results[pol]


def _detections_dataset(rows: list[dict], u0: int, v0: int) -> xr.Dataset:
    """The measured blobs as a Dataset over ``detection`` (centres shifted to full-sensor pixels)."""
    data = {k: ("detection", np.array([r[k] for r in rows], dtype=np.float64), {"units": u, "long_name": ln})
            for k, (u, ln) in DETECTION_FIELDS.items()}
    ds = xr.Dataset(data, coords={"detection": np.arange(len(rows))})
    ds["u"] = ds["u"] + u0
    ds["v"] = ds["v"] + v0
    for k in ("u", "v"):
        ds[k].attrs = {"units": "px", "long_name": DETECTION_FIELDS[k][1]}
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


#: Floor of a marker centre's standard uncertainty in the camera fit's weights, px (:func:`centre_weights`).
CENTRE_FLOOR_PX = 0.005


def centre_weights(det: xr.Dataset) -> np.ndarray | None:
    """Weight ``1 / sqrt(sigma_px^2 + CENTRE_FLOOR_PX^2)`` (1 / px) of each detection in the camera fit.

    None (equal weights) unless every detection carries a finite positive
    ``sigma_px`` (detections given from elsewhere may not).

    Notes
    -----
    The camera is the generalised least-squares fit of the centres: the
    steep wing's thin markers are up to 2 x less precise than the others
    (oblique pose of the calibration benchmark, contrast/noise 3), and an
    unweighted fit gives them the same say (expected camera error 0.058
    px against 0.054 px weighted). The template fits' ``sigma_px`` is honest
    (error / ``sigma_px`` 1.04-1.06 RMS, 1.01 x the Cramer-Rao bound over
    31 noise fields); the floor stands for the template's own model error
    (noise-free 0.004-0.011 px), which the weights must not undercut at high
    contrast/noise.
    """
    if "sigma_px" not in det:
        return None
    sig = np.asarray(det["sigma_px"].values, dtype=np.float64)
    if not (np.isfinite(sig).all() and (sig > 0).all()):
        return None
    return 1.0 / np.hypot(sig, CENTRE_FLOOR_PX)


def centre_covariances(det: xr.Dataset) -> np.ndarray | None:
    """Covariance (D, 2, 2) px^2 of each detection's centre, with the floor :data:`CENTRE_FLOOR_PX`.

    None unless every detection carries finite ``cov_uu_px2``,
    ``cov_vv_px2`` and ``cov_uv_px2`` (detections from elsewhere, or
    stored before these were measured, may not).

    Notes
    -----
    The floor's variance is split evenly between the axes, so that the
    trace is ``sigma_px^2 + CENTRE_FLOOR_PX^2``, the variance behind
    :func:`centre_weights`. A thin marker's covariance is far from
    isotropic (on a wing seen 74 deg from its normal the centre is ~2 x less
    precise across the ellipse than along it), which the weights, one number
    per marker, leave out; the camera's covariance takes it in.
    """
    keys = ("cov_uu_px2", "cov_vv_px2", "cov_uv_px2")
    if not all(k in det for k in keys):
        return None
    uu, vv, uv = (np.asarray(det[k].values, dtype=np.float64) for k in keys)
    cov = np.stack([np.stack([uu, uv], -1), np.stack([uv, vv], -1)], -2)
    if not (np.isfinite(cov).all() and (uu > 0).all() and (vv > 0).all()):
        return None
    return cov + np.eye(2) * CENTRE_FLOOR_PX**2 / 2
