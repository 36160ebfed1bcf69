"""Markers the detector missed, searched for where the first camera predicts them.

On a wing seen at 70-75 deg from its normal a faint marker is a thin
ellipse whose response to the detector's circular filters is too weak, so a
fit from the detected markers rests mostly on the other wing. Once the
correspondence has given a first camera (the DLT of the matched markers,
:func:`irdic.calibration.correspondence.propagate`), every marker's image
position and elliptical shape are known (:func:`projected_ellipses`);
:func:`find_missing` looks for each matched-filter response there with a
template of that shape and measures the centre of each clear one, and of
every marker the detector found, by a least-squares fit of that template
(amplitude and shift). The templates' size is the marker radius fitted to
the matched markers themselves (:func:`_template_scales`).
"""

from __future__ import annotations

import logging

import numpy as np
import xarray as xr

from ..camera import CameraModel
from ..errors import CalibrationError
from ..noise import mad_std
from .bias import plane_normals, projected_ellipses
from .correspondence import predicted_spacing, propagate
from .detection import DETECTION_FIELDS, plane_fit
from .image import image_array

__all__ = ["find_missing", "search_predicted", "estimate_radius", "check_radius", "MIN_SNR", "WINDOW_FRACTION",
           "MAX_WINDOW_PX", "MIN_SIZE_FITS", "RADIUS_TOLERANCE"]

log = logging.getLogger(__name__)

#: Smallest matched-filter signal-to-noise of a marker found at its predicted position. Pure noise
#: exceeds 6 in a search window (a few tens of independent positions) with a probability ~1e-8.
MIN_SNR = 6.0
#: Search window radius as a fraction of the distance to the nearest other predicted marker (below
#: one half, so the peak of a neighbour can never lie inside it).
WINDOW_FRACTION = 0.4
#: Largest search window radius, px: the first camera predicts the markers to a fraction of a pixel.
MAX_WINDOW_PX = 3.0
#: Distance (px) from a marker's ellipse beyond which its blurred edge no longer reaches.
_EDGE_PX = 1.5
#: Fewest free-size template fits from which the marker radius is measured (and a given one judged).
MIN_SIZE_FITS = 6
#: Relative disagreement between a given marker radius and the measured one allowed beyond the fits' scatter.
RADIUS_TOLERANCE = 0.05


def estimate_radius(model: CameraModel, x: np.ndarray, det: xr.Dataset, di: np.ndarray) -> float:
    """Marker radius (mm) from the detected size: half-contrast radius / sqrt(axis ratio) x depth / f."""
    q = np.clip(det["semi_minor_px"].values[di] / det["semi_major_px"].values[di], 0.2, 1.0)
    a_px = det["radius_px"].values[di] / np.sqrt(q)
    f = model.decompose().focal_length_px
    return float(np.median(a_px * model.depth(x) / f))


def find_missing(image, det: xr.Dataset, x: np.ndarray, mi: np.ndarray, di: np.ndarray, model: CameraModel, *,
                 radius_mm: float | None = None, min_radius_px: float = 2.0, max_radius_px: float = 30.0,
                 min_contrast_k: float = 0.1, rounds: int = 2):
    """Add the markers found at their predicted positions to the detections and the correspondence.

    Each round predicts every marker's imaged ellipse with the current
    camera, searches for the unmatched ones (:func:`search_predicted`),
    appends what it finds to the detections and grows the correspondence
    again (:func:`~irdic.calibration.correspondence.propagate`, which refits
    the DLT); the next round predicts with that camera. Finally templates
    of free size are fitted to the matched markers (:func:`_template_scales`):
    a given ``radius_mm`` is checked against them (:func:`check_radius`),
    else the marker radius is re-estimated from them and every matched
    detection re-measured with templates of that radius.

    Parameters
    ----------
    image : xarray.DataArray
        The target image (see :func:`~irdic.calibration.detect_markers`).
    det : xarray.Dataset
        Its detections (attrs ``polarity`` and ``noise_k`` needed).
    x : ndarray, shape (M, 3)
        Marker centres, mm.
    mi, di : ndarray of int
        Matched (marker, detection) pairs.
    model : CameraModel
        Camera of the matched pairs.
    radius_mm : float, optional
        Marker radius, mm; estimated from the matched detections when not given.
    min_radius_px, max_radius_px, min_contrast_k : float
        The detection limits: markers predicted smaller or larger are not
        searched for, fainter ones are not accepted.
    rounds : int
        Prediction and search rounds.

    Returns
    -------
    det : xarray.Dataset
        The detections with the found markers appended (variable ``guided``:
        found by the search; ``template_fit``: centre from the template fit;
        attrs ``n_guided``, ``n_template_fit``).
    mi, di : ndarray of int
    model : CameraModel

    Notes
    -----
    Why the detections are re-measured: the windowed centroid takes every
    window pixel's noise with its lever arm, the template fit weighs each
    pixel by its edge derivative (contrast/noise 3, oblique pose: camera
    0.17-0.25 -> ~0.04 px; 55, lab: centre 0.015 -> 0.008 px RMS).

    Why the radius is re-estimated: a template of the wrong size shifts the
    centre with the pixel grid's phase; the detector's sizes are biased low
    at contrast/noise 3 (1.557 instead of 1.6 mm: camera 0.133 -> 0.112 px).
    """
    pol = det.attrs.get("polarity")
    noise = float(det.attrs.get("noise_k", np.nan))
    det = det.assign(guided=("detection", np.zeros(det.sizes["detection"], bool)),
                     template_fit=("detection", np.zeros(det.sizes["detection"], bool)))
    det.attrs.update(n_guided=0, n_template_fit=0)
    if pol not in ("dark", "bright") or not noise > 0:
        return det, mi, di, model  # detections from elsewhere: nothing to search with
    normals = plane_normals(x)
    kw = dict(polarity=pol, noise=noise, min_contrast_k=min_contrast_k)
    for rnd in range(rounds + 1):
        radius = radius_mm if radius_mm is not None else estimate_radius(model, x[mi], det, di)
        centre, shape, fine, window = _predict(model, x, normals, radius, min_radius_px, max_radius_px)
        if rnd == rounds:
            scale = _template_scales(image, det, mi, di, centre, shape, window, fine, kw)
            if radius_mm is not None:
                check_radius(radius_mm, scale)
            elif len(scale) >= MIN_SIZE_FITS:  # fewer: the detector's estimate stands
                radius = float(radius * np.median(scale))
                centre, shape, fine, window = _predict(model, x, normals, radius, min_radius_px, max_radius_px)
            det = _refit_matched(image, det, mi, di, centre, shape, window, fine, kw, every=radius_mm is None)
            break
        det, mi, di, model = _search_round(image, det, x, mi, di, model, centre, shape, window, fine, kw)
    log.info("%d markers found at their predicted positions, %d detections re-measured", det.attrs["n_guided"],
             det.attrs["n_template_fit"] - det.attrs["n_guided"])
    return det, mi, di, model


def _search_round(image, det, x, mi, di, model, centre, shape, window, fine, kw):
    """One round of :func:`find_missing`'s search: the unmatched predicted markers searched for, the
    correspondence grown with what is found; returns ``det, mi, di, model``."""
    D = np.column_stack([det["u"].values, det["v"].values])
    wanted = fine.copy()
    wanted[mi] = False
    for k in np.flatnonzero(wanted):
        # a detection already there was left unmatched for a reason (contested, or far off)
        wanted[k] = not (np.hypot(*(D - centre[k]).T) <= window[k]).any()
    rows = search_predicted(image, centre, shape, window, np.flatnonzero(wanted), fine, **kw)
    if rows:
        det = _append(det, [r for r in rows if r is not None])
        mi, di, model = propagate(model, x, np.column_stack([det["u"].values, det["v"].values]))
    return det, mi, di, model


def _predict(model, x, normals, radius, min_radius_px, max_radius_px):
    """Predicted ``(centre, shape, searchable, window)`` of every marker (see :func:`projected_ellipses`)."""
    centre, shape = projected_ellipses(model, x, normals, radius)
    with np.errstate(invalid="ignore"):
        eq_r = np.sqrt(np.sqrt(np.abs(np.linalg.det(shape))))
        fine = np.isfinite(centre).all(axis=1) & (eq_r >= min_radius_px) & (eq_r <= max_radius_px)
    window = np.minimum(WINDOW_FRACTION * predicted_spacing(np.where(fine[:, None], centre, np.nan)),
                        MAX_WINDOW_PX)
    return centre, shape, fine, window


def _matched_starts(det, mi, di, n):
    """Start of each marker's template fit (n, 2) px: its matched detection (a grid search would find what
    the detector found); NaN for the unmatched."""
    start = np.full((n, 2), np.nan)
    start[mi] = np.column_stack([det["u"].values, det["v"].values])[di]
    return start


def _template_scales(image, det, mi, di, centre, shape, window, fine, kw) -> np.ndarray:
    """Size of each matched marker's template fitted freely, over the predicted size (both semi-axes).

    The marker radius is the predicting radius times their median. The
    detector's half-contrast sizes behind :func:`estimate_radius` are
    biased at low contrast/noise (-2.7 % at 3, lab pose of the calibration
    benchmark), and a template of the wrong size biases the centre with the
    pixel phase and wastes the edge's information (noise-free 0.005 ->
    0.011 px RMS, centre variance +20 %). Each template's size is well
    determined (its derivative is even, the shift's odd: the two are
    uncorrelated), their median over the markers more so.
    """
    rows = search_predicted(image, centre, shape, window, mi[fine[mi]], fine, fit_scale=True,
                            start=_matched_starts(det, mi, di, centre.shape[0]), **kw)
    return np.array([r["scale"] for r in rows])


def check_radius(radius_mm: float, scale: np.ndarray) -> None:
    """Refuse a given marker radius that the free-size template fits contradict.

    Parameters
    ----------
    radius_mm : float
        The given marker radius, mm (the templates' sizes were predicted with it).
    scale : ndarray, shape (n,)
        Fitted over predicted template size of each matched marker
        (:func:`_template_scales`); fewer than :data:`MIN_SIZE_FITS` are not judged.

    Raises
    ------
    CalibrationError
        ``|median(scale) - 1|`` exceeds :data:`RADIUS_TOLERANCE` plus 5 standard
        errors of the median.

    Notes
    -----
    The standard error of the median is ``1.2533 x 1.4826 MAD / sqrt(n)``
    (normal scatter); 5 of them keep a false alarm below 1e-6. The relative
    allowance covers what the template (a sharp ellipse, area coverage) does
    not describe in a real image, e.g. the optics' blur, which moves the
    half-contrast edge of a 4 px disc inward by ~3 % at a 1 px blur; on the
    calibration benchmark the median is within 0.7 % of the truth.
    """
    n = len(scale)
    if n < MIN_SIZE_FITS:
        return
    med = float(np.median(scale))
    se = 1.2533 * mad_std(scale) / np.sqrt(n)
    tol = RADIUS_TOLERANCE + 5.0 * se
    if abs(med - 1.0) > tol:
        raise CalibrationError(
            f"`marker_radius_mm` (calibration.marker_radius_mm) is {radius_mm:.3g} mm, but the markers in the "
            f"target image measure {radius_mm * med:.3f} mm: templates of free size fitted to the {n} matched "
            f"markers are {100 * (med - 1):+.1f} % of the given size (median; tolerance +-{100 * tol:.1f} % = "
            f"{100 * RADIUS_TOLERANCE:.0f} % + 5 standard errors of the median). The radius sets the perspective "
            f"correction of every marker centre: measure the painted markers and give their radius (or null, "
            f"None in `irdic.calibration.calibrate`, to take it from the image)")


def _refit_matched(image, det, mi, di, centre, shape, window, fine, kw, every: bool = False) -> xr.Dataset:
    """``det`` with the matched detector rows re-measured by the template fit (kept where it fails).

    With ``every`` the rows found by the search are re-measured too (the
    final marker radius differs from the one they were found with).
    """
    todo = fine[mi] if every else ~det["template_fit"].values[di] & fine[mi]
    rows = search_predicted(image, centre, shape, window, mi[todo], fine, keep_misses=True,
                            start=_matched_starts(det, mi, di, centre.shape[0]), **kw)
    cols = {k: det[k].values.copy() for k in (*DETECTION_FIELDS, "template_fit")}
    for d, row in zip(di[todo], rows):
        if row is not None:
            for k in DETECTION_FIELDS:
                cols[k][d] = row[k]
            cols["template_fit"][d] = True
    out = det.assign({k: ("detection", v, det[k].attrs) for k, v in cols.items()})
    out.attrs["n_template_fit"] = int(cols["template_fit"].sum())
    return out


def _append(det: xr.Dataset, rows: list[dict]) -> xr.Dataset:
    """``det`` with ``rows`` appended as guided detections."""
    n0 = det.sizes["detection"]
    new = xr.Dataset({k: ("detection", np.array([r[k] for r in rows], dtype=np.float64)) for k in DETECTION_FIELDS},
                     coords={"detection": np.arange(n0, n0 + len(rows))})
    new["guided"] = ("detection", np.ones(len(rows), bool))
    new["template_fit"] = ("detection", np.ones(len(rows), bool))
    out = xr.concat([det, new], dim="detection", combine_attrs="override")
    for k in DETECTION_FIELDS:
        out[k].attrs = det[k].attrs
    out["guided"].attrs = {"long_name": "found at the position predicted by the first camera"}
    out["template_fit"].attrs = {"long_name": "centre from the least-squares fit of the predicted ellipse"}
    out.attrs["n_guided"] = int(det.attrs.get("n_guided", 0)) + len(rows)
    out.attrs["n_template_fit"] = int(det.attrs.get("n_template_fit", 0)) + len(rows)
    return out


def search_predicted(image, centre: np.ndarray, shape: np.ndarray, window: np.ndarray, which, visible, *,
                     polarity: str, noise: float, min_contrast_k: float = 0.1,
                     keep_misses: bool = False, fit_scale: bool = False, start=None) -> list:
    """Markers found at their predicted positions with a matched filter of their predicted shape.

    Parameters
    ----------
    image : xarray.DataArray
        The target image, dims ``("v", "u")``, °C, full-sensor coordinates.
    centre : ndarray, shape (M, 2)
        Predicted marker centres, px (full sensor).
    shape : ndarray, shape (M, 2, 2)
        Predicted shape matrices, px^2 (see
        :func:`~irdic.calibration.bias.projected_ellipses`).
    window : ndarray, shape (M,)
        Search radius around each prediction, px.
    which : array_like of int
        The markers to search for.
    visible : ndarray of bool, shape (M,)
        Markers predicted in the image (kept out of each other's background).
    polarity : {"dark", "bright"}
    noise : float
        Pixel noise, K.
    min_contrast_k : float
        Smallest accepted contrast, K.
    keep_misses : bool
        Return None for each marker not found (one entry per ``which``).
    fit_scale : bool
        Fit the template's size too (both semi-axes times a common factor).
    start : ndarray, shape (M, 2), optional
        Where the fit of each marker starts, px (a measured centre); without
        it, at the best of a grid search.

    Returns
    -------
    list of dict
        One row of :data:`~irdic.calibration.detection.DETECTION_FIELDS` per
        marker found (``snr`` is the contrast / pixel noise, as for the
        detector's rows; ``sigma_px`` from the fit's covariance; the shape
        fields those of the fitted ellipse) and ``scale``, the fitted size
        over the predicted one (1 without ``fit_scale``).

    Notes
    -----
    Around a prediction ``c`` with shape ``S`` the background plane is
    fitted (:func:`~irdic.calibration.detection.plane_fit`) on a ring
    beyond the search window and the marker's blurred edge, away from every
    other predicted marker; ``r`` is the signed contrast left. The template
    ``t_s`` is the area fraction of each pixel covered by the ellipse moved
    to ``c + s``; its least-squares amplitude is the contrast
    ``k_s = <t_s, r> / <t_s, t_s>`` with signal-to-noise
    ``<t_s, r> / (sigma sqrt(<t_s, t_s>))``. ``s`` runs over a 1 px grid in
    the window (unless ``start`` gives it); from the best, amplitude and shift (with ``fit_scale`` also
    the size) are fitted by least squares (Gauss-Newton). A marker is
    accepted when the fit converges, its signal-to-noise reaches
    :data:`MIN_SNR`, its centre is not on the window's rim (which a
    neighbour's or a stray blob's tail would give) and its contrast reaches
    ``min_contrast_k``.
    """
    img, u0, v0 = image_array(image)
    img = np.asarray(img, dtype=np.float64)
    sign = -1.0 if polarity == "dark" else 1.0
    c_arr = centre - [u0, v0]
    rows = []
    for k in np.asarray(which, dtype=int):
        near = np.flatnonzero(visible & (np.hypot(*(c_arr - c_arr[k]).T) < 4.0 * np.sqrt(
            np.linalg.eigvalsh(shape[k])[-1]) + 40.0))
        near = near[near != k]
        s0 = None if start is None else start[k] - centre[k]
        row = _search_one(img, sign, noise, c_arr[k], shape[k], float(window[k]), c_arr[near], shape[near],
                          min_contrast_k, fit_scale, s0)
        if row is not None:
            row["u"] += u0
            row["v"] += v0
        if row is not None or keep_misses:
            rows.append(row)
    return rows


def _grown_inside(uu, vv, c, shape, grow_px):
    """Pixels whose centres lie inside the ellipse ``(c, shape)`` with both semi-axes grown by ``grow_px``."""
    lam, vec = np.linalg.eigh(shape)
    ax = np.sqrt(np.maximum(lam, 0.0)) + grow_px
    du, dv = uu - c[0], vv - c[1]
    p0 = du * vec[0, 0] + dv * vec[1, 0]
    p1 = du * vec[0, 1] + dv * vec[1, 1]
    return (p0 / ax[0]) ** 2 + (p1 / ax[1]) ** 2 <= 1.0


def _coverage(uu, vv, c, s_inv):
    """Area fraction of each pixel (centres ``uu``, ``vv``) inside the ellipse ``(c, S)``.

    Notes
    -----
    Each pixel sees the boundary as a straight edge at the first-order
    signed distance ``e = (sqrt(q) - 1) / |grad sqrt(q)|`` (``q = d^T S^-1 d``,
    positive outside) with unit normal ``n``. The unit pixel square
    projected onto ``n`` has a trapezoidal density (the convolution of two
    uniform densities of widths ``|n_u|`` and ``|n_v|``), so the covered
    fraction is its distribution function at ``x = -e``: with
    ``a = max(|n_u|, |n_v|) / 2`` and ``b = min(|n_u|, |n_v|) / 2`` it is
    ``(x + a + b)^2 / (8 a b)`` for ``-(a + b) < x < -(a - b)``, linear
    ``(x + a) / (2 a)`` for ``|x| <= a - b`` and ``1 - (a + b - x)^2 / (8 a b)``
    for ``a - b < x < a + b`` (0 and 1 beyond).
    This is exact for a straight edge at any angle (a ramp across one pixel
    is exact only for an edge along a pixel axis: on the lab pose of the
    calibration benchmark, noise-free, the fitted centres were 0.009 px RMS
    from the truth with the ramp, 0.005 px with this), and continuous in
    ``c``, unlike sampled coverage.
    """
    du, dv = uu - c[0], vv - c[1]
    gu = s_inv[0, 0] * du + s_inv[0, 1] * dv
    gv = s_inv[0, 1] * du + s_inv[1, 1] * dv
    q = np.maximum(du * gu + dv * gv, 1e-12)
    rq = np.sqrt(q)
    g = np.maximum(np.hypot(gu, gv), 1e-12)
    x = -(rq - 1.0) * rq / g
    nu, nv = np.abs(gu) / g, np.abs(gv) / g
    # a >= 1 / (2 sqrt 2) for a unit normal; the floor only guards a pixel centred exactly on c
    a, b = np.maximum(0.5 * np.maximum(nu, nv), 0.25), 0.5 * np.minimum(nu, nv)
    lin = np.clip((x + a) / (2.0 * a), 0.0, 1.0)
    bb = np.maximum(b, 1e-9)  # an axis-aligned edge has no quadratic parts (they are never selected)
    lo = np.clip(x + a + b, 0.0, None) ** 2 / (8.0 * a * bb)
    hi = 1.0 - np.clip(a + b - x, 0.0, None) ** 2 / (8.0 * a * bb)
    return np.clip(np.where(x < -(a - b), lo, np.where(x > a - b, hi, lin)), 0.0, 1.0)


def _search_one(img, sign, noise, c, shape, window, c_nb, shape_nb, min_contrast, fit_scale=False, s0=None):
    """Measured row of one marker searched for around ``c`` (array px), or None."""
    lam, vec = np.linalg.eigh(shape)
    b, a = np.sqrt(np.maximum(lam, 1e-12))
    g_in = window + _EDGE_PX + 0.5
    g_out = g_in + max(3.0, 0.5 * a)
    half = int(np.ceil(a + g_out)) + 1
    H, W = img.shape
    v_lo, u_lo = int(round(c[1])) - half, int(round(c[0])) - half
    v_hi, u_hi = v_lo + 2 * half + 1, u_lo + 2 * half + 1
    if v_lo < 0 or u_lo < 0 or v_hi > H or u_hi > W:
        return None
    patch = img[v_lo:v_hi, u_lo:u_hi]
    if not np.isfinite(patch).all():
        return None  # a NaN hole would bias the background and the template sums
    vv, uu = np.mgrid[v_lo:v_hi, u_lo:u_hi].astype(np.float64)
    others = np.zeros(patch.shape, bool)
    for cj, sj in zip(c_nb, shape_nb):
        if np.hypot(*(cj - c)) < 1.5 * half + np.sqrt(np.linalg.eigvalsh(sj)[-1]) + _EDGE_PX:
            others |= _grown_inside(uu, vv, cj, sj, _EDGE_PX)
    ring = _grown_inside(uu, vv, c, shape, g_out) & ~_grown_inside(uu, vv, c, shape, g_in) & ~others
    if ring.sum() < 12:
        return None
    coef = plane_fit(uu[ring] - c[0], vv[ring] - c[1], patch[ring], noise)
    r = sign * (patch - (coef[0] + coef[1] * (uu - c[0]) + coef[2] * (vv - c[1])))
    s_inv = np.linalg.inv(shape)
    if s0 is None or not np.isfinite(s0).all():
        n = int(np.floor(window))
        grid = [np.array([du, dv], float) for du in range(-n, n + 1) for dv in range(-n, n + 1)
                if np.hypot(du, dv) <= window]
        scores = [_score(uu, vv, c + s, s_inv, r) for s in grid]
        if not grid or max(scores) < MIN_SNR * noise:
            return None
        s0 = grid[int(np.argmax(scores))]
    fit = _template_fit(uu, vv, c, np.asarray(s0, float), s_inv, r, noise, fit_scale=fit_scale)
    if fit is None:
        return None
    s, contrast, cov, rho = fit
    a, b = rho * a, rho * b
    snr_mf = contrast / np.sqrt(cov[0, 0])
    if not (snr_mf >= MIN_SNR and np.hypot(*s) <= window - 0.5 and contrast >= min_contrast):
        return None
    return {**_row(c + s, a, b, vec, contrast, noise, cov), "scale": rho}


def _score(uu, vv, c, s_inv, r) -> float:
    """Matched-filter response ``<t, r> / sqrt(<t, t>)`` of the template at ``c`` (K; / noise = SNR)."""
    t = _coverage(uu, vv, c, s_inv)
    tt = float((t * t).sum())
    return float((t * r).sum()) / np.sqrt(tt) if tt > 0 else -np.inf


def _profiled(uu, vv, c, p, s_inv, r):
    """Template, contrast and residual sum of squares at the parameters ``p`` = (shift u, v[, size factor]).

    The contrast enters linearly and is profiled out:
    ``SSR(p) = <r, r> - <t, r>^2 / <t, t>`` at ``k = <t, r> / <t, t>``.
    """
    t = _coverage(uu, vv, c + p[:2], s_inv / (p[2] ** 2 if len(p) > 2 else 1.0))
    tt, tr = float((t * t).sum()), float((t * r).sum())
    if not tt > 0:
        return t, np.nan, np.inf
    return t, tr / tt, float((r * r).sum()) - tr * tr / tt


def _template_fit(uu, vv, c, s, s_inv, r, noise, h: float = 0.05, fit_scale: bool = False):
    """Least-squares fit of ``k t(c + s)`` to ``r`` over amplitude and shift (Gauss-Newton from ``s``).

    With ``fit_scale`` the ellipse's size is free too: the template is
    ``k t(c + s; rho^2 S)``, both semi-axes times ``rho``.

    Returns ``(s, k, cov, rho)`` with the covariance of ``(k, s_u, s_v)`` for
    white noise ``noise`` (``rho`` = 1 without ``fit_scale``), or None when
    the fit diverges or loses the marker.

    Notes
    -----
    Each Gauss-Newton step ``d`` is followed by a line search on the
    profiled sum of squares (:func:`_line_search`), and the fit has
    converged when the step's predicted decrease of the sum of squares,
    ``-slope / 2`` with ``slope = -2 <res, k dt/dp> . d``, is below
    ``1e-4 noise^2`` (a step of 1 % of the standard deviation in its
    direction; a fit that stalls is accepted up to ``5e-2 noise^2``, a step of
    a fifth of it). Why:
    at contrast/noise 3 the residual's curvature term that Gauss-Newton
    leaves out is comparable to ``J^T J`` across a thin ellipse; the plain
    iteration zig-zagged or crept (successive steps in ratio -0.8 to +0.8),
    and 7 % of the steep wing's fits (oblique pose of the calibration
    benchmark) missed a fixed 1e-3 px step limit after 8 steps: those
    markers kept the detector's centroid (up to 3.5 x the Cramer-Rao
    bound) or were lost.
    """
    p = np.array([*s, 1.0] if fit_scale else s, dtype=np.float64)
    lim = np.array([0.5, 0.5, 0.1])[:len(p)]  # a trust region: the template is narrow across a thin ellipse
    t, k, ssr = _profiled(uu, vv, c, p, s_inv, r)
    done = False
    for _ in range(16):
        if not k > 0:
            return None
        A = _design(uu, vv, c, p, s_inv, t, k, h)
        res = r.ravel() - k * t.ravel()
        ata = A.T @ A
        d = np.clip(np.linalg.lstsq(ata, A.T @ res, rcond=None)[0][1:], -lim, lim)
        gain = float(res @ (A[:, 1:] @ d)) / noise**2  # predicted decrease of SSR / noise^2
        if gain < 1e-4:
            done = True
            break
        step = _line_search(uu, vv, c, p, d, s_inv, r, ssr, -2.0 * gain * noise**2, lim)
        if step is None:  # no decrease along the step: converged within the derivatives' precision, or stuck
            done = gain < 5e-2
            break
        t, k, ssr, d = step
        p = p + d
        if fit_scale:
            p[2] = float(np.clip(p[2], 0.6, 1.6))
    if not (done and k > 0):
        return None
    try:
        cov = noise**2 * np.linalg.inv(ata)[:3, :3]
    except np.linalg.LinAlgError:
        return None
    return p[:2], k, cov, (float(p[2]) if fit_scale else 1.0)


def _line_search(uu, vv, c, p, d, s_inv, r, ssr, slope, lim):
    """``(t, k, SSR, step)`` at the best of ``p + alpha d`` along a Gauss-Newton step, or None without a decrease.

    ``alpha`` is 1 or the minimum of the parabola through ``SSR(p)``, the
    slope ``slope`` (derivative of SSR at ``alpha = 0``) and ``SSR(p + d)``,
    within [0.1, ``top``] (``top``: 4, or where a component reaches the
    trust region ``lim``; ``top`` itself where the parabola has no minimum);
    then half steps, twice.
    """
    t1, k1, f1 = _profiled(uu, vv, c, p + d, s_inv, r)
    curv = f1 - ssr - slope
    top = float(min(4.0, np.min(lim / np.maximum(np.abs(d), 1e-12))))
    alpha = float(np.clip(-slope / (2.0 * curv), 0.1, max(top, 1.0))) if curv > 0 else max(top, 1.0)
    if abs(alpha - 1.0) > 0.2:
        t2, k2, f2 = _profiled(uu, vv, c, p + alpha * d, s_inv, r)
        if f2 < f1:
            t1, k1, f1, d = t2, k2, f2, alpha * d
    for _ in range(2):
        if f1 < ssr:
            return t1, k1, f1, d
        d = 0.5 * min(alpha, 1.0) * d
        t1, k1, f1 = _profiled(uu, vv, c, p + d, s_inv, r)
    return (t1, k1, f1, d) if f1 < ssr else None


def _design(uu, vv, c, p, s_inv, t, k, h):
    """Design matrix (n_pix, 1 + len(p)) of :func:`_template_fit`: ``t`` and ``k dt/dp`` (central differences)."""
    rho = p[2] if len(p) > 2 else 1.0
    si = s_inv / rho**2
    cols = [t.ravel()]
    for e in ([h, 0.0], [0.0, h]):
        cols.append(k * ((_coverage(uu, vv, c + p[:2] + e, si) - _coverage(uu, vv, c + p[:2] - e, si))
                         / (2 * h)).ravel())
    if len(p) > 2:
        hr = 0.01
        cols.append(k * ((_coverage(uu, vv, c + p[:2], s_inv / (rho + hr) ** 2)
                          - _coverage(uu, vv, c + p[:2], s_inv / (rho - hr) ** 2)) / (2 * hr)).ravel())
    return np.column_stack(cols)


def _row(pos, a, b, vec, contrast, noise, cov) -> dict:
    """A detection row (:data:`~irdic.calibration.detection.DETECTION_FIELDS`) of a template-fitted marker."""
    return {"u": float(pos[0]), "v": float(pos[1]), "radius_px": float(np.sqrt(a * b)), "semi_major_px": float(a),
            "semi_minor_px": float(b), "orientation_rad": float(np.arctan2(vec[1, 1], vec[0, 1])),
            "eccentricity": float(np.sqrt(max(0.0, 1.0 - (b / a) ** 2))), "solidity": 1.0,
            "contrast_k": float(contrast), "area_px": float(np.pi * a * b), "snr": float(contrast / noise),
            "sigma_px": float(np.sqrt(max(cov[1, 1] + cov[2, 2], 0.0))), "cov_uu_px2": float(cov[1, 1]),
            "cov_vv_px2": float(cov[2, 2]), "cov_uv_px2": float(cov[1, 2])}
