"""Couple stage: DIC points + IR frames + calibration -> temperatures at material points.

For every DIC time the valid DIC points are projected into the IR image with
the calibrated camera; points behind the camera, outside the IR frame or on
surface facing away from it are flagged not visible. Only pixels on the
specimen feed the interpolant: a mask per time from the projected point cloud
(:func:`irdic.footprint.specimen_mask`, eroded by ``mask_erosion_px``), also
intersected with the masks of the neighbouring DIC times so that pixels the
moving edge crosses are left out. The pixel temperatures are interpolated in
space and time (:func:`irdic.image_rbf.evaluate_series`, IMQ with the paper's
shape factors by default) and evaluated at the projected points: temperature,
pixel gradient and local rate ∂Θ/∂t at the fixed pixel.

Points that project just outside the mask (the outermost DIC points lie on
the specimen edge, so they always do) are extrapolated linearly from the
nearest masked pixel, up to ``max_extrapolation_px``; their signed distance to
the mask edge is stored (negative = extrapolated), so users see which values
are not interpolated.

``status`` codes (CF ``flag_values``/``flag_meanings`` in its attributes):

== ==================================================================
0  interpolated inside the specimen mask
1  extrapolated from the mask edge (≤ max_extrapolation_px)
2  DIC point missing at this time
3  behind the IR camera or outside the IR frame
4  surface facing away from the IR camera
5  outside the specimen mask, farther than max_extrapolation_px
6  DIC time outside the IR time span
== ==================================================================
"""

from __future__ import annotations

import logging
import os
import time as _time
from pathlib import Path

import numpy as np
import xarray as xr
from scipy import ndimage

from .camera import load_camera
from .errors import CalibrationError, ConfigError, DataError
from .footprint import facing_camera, point_normals, specimen_mask
from .image_rbf import evaluate_series
from .noise import ir_noise as estimate_ir_noise
from .store import open_store, write_dataset

__all__ = ["couple", "couple_stores", "STATUS_MEANINGS"]

log = logging.getLogger(__name__)

STATUS_MEANINGS = (
    "interpolated extrapolated_from_edge dic_point_missing outside_ir_frame "
    "facing_away outside_specimen_mask time_outside_ir_span"
)

#: pixel motion (px) below which the mask and normals of the previous time are reused
_MASK_REUSE_PX = 0.2


def _check_params(method, mask_erosion_px, max_extrapolation_px, max_view_angle_deg):
    if method not in ("rbf", "bilinear", "cubic"):
        raise ConfigError(f"interpolation.method must be rbf, bilinear or cubic, got {method!r}")
    if not mask_erosion_px >= 0:
        raise ConfigError(f"interpolation.mask_erosion_px must be >= 0 px, got {mask_erosion_px}")
    if not max_extrapolation_px >= 0:
        raise ConfigError(f"interpolation.max_extrapolation_px must be >= 0 px, got {max_extrapolation_px}")
    if not 0 < max_view_angle_deg <= 90:
        raise ConfigError(f"interpolation.max_view_angle_deg must lie in (0, 90], got {max_view_angle_deg}")


def _fill_in_time(a: np.ndarray) -> np.ndarray:
    """Fill NaN rows of ``a`` (n_t, M, d) per point from the nearest earlier, else later, valid time."""
    ok = np.isfinite(a).all(axis=2)
    n_t = a.shape[0]
    idx = np.where(ok, np.arange(n_t)[:, None], -1)
    fwd = np.maximum.accumulate(idx, axis=0)
    idx_b = np.where(ok, np.arange(n_t)[:, None], n_t)
    bwd = np.minimum.accumulate(idx_b[::-1], axis=0)[::-1]
    src = np.where(fwd >= 0, fwd, bwd)
    src = np.clip(src, 0, n_t - 1)
    return np.take_along_axis(a, src[..., None], axis=0)


def _masks_and_facing(x, pix, centre, u, v, *, erosion, edge_factor, max_angle):
    """Per DIC time: specimen mask (H, W) and facing flags (M,).

    A point that failed correlation in one stage does not open a hole in the
    specimen: masks and normals are built from positions filled in time from
    the point's nearest valid stage. While the points move less than
    ``_MASK_REUSE_PX`` the previous mask is reused, so a static specimen has
    one mask and the interpolant is set up once.
    """
    n_t, M, _ = x.shape
    xf = _fill_in_time(x)
    pf = _fill_in_time(pix)
    masks = np.zeros((n_t, v.size, u.size), dtype=bool)
    facing = np.zeros((n_t, M), dtype=bool)
    last = None
    rebuilt = 0
    for k in range(n_t):
        ok = np.isfinite(pf[k]).all(axis=1)
        if ok.sum() < 3:
            continue
        if last is not None:
            both = ok & np.isfinite(pf[last]).all(axis=1)
            moved = np.abs(pf[k][both] - pf[last][both]).max() if both.any() else np.inf
            if moved < _MASK_REUSE_PX:
                masks[k] = masks[last]
                facing[k] = facing[last]
                continue
        n = point_normals(xf[k], towards=centre)
        facing[k] = facing_camera(xf[k], n, centre, max_angle_deg=max_angle)
        keep = ok & facing[k]
        masks[k] = specimen_mask(pf[k][keep], u, v, erosion_px=erosion, max_edge_factor=edge_factor)
        last = k
        rebuilt += 1
    # a pixel the moving edge crosses between neighbouring times carries mixed
    # specimen/background values after temporal interpolation: leave it out
    both = masks.copy()
    both[1:] &= masks[:-1]
    both[:-1] &= masks[1:]
    log.info("specimen masks: %d built for %d DIC times, %d to %d px", rebuilt, n_t,
             int(both.sum(axis=(1, 2)).min()), int(both.sum(axis=(1, 2)).max()))
    return both, facing


def couple(
    dic: xr.Dataset,
    ir: xr.Dataset,
    calibration: xr.Dataset,
    *,
    method: str = "rbf",
    c_space: float = 2.0,
    R0_space: float = 1.0,
    c_time: float = 1.0,
    R0_time: float = 1.0,
    mask_erosion_px: float = 1.0,
    max_edge_factor: float = 3.0,
    max_view_angle_deg: float = 80.0,
    max_extrapolation_px: float = 3.0,
    halo: int = 12,
) -> xr.Dataset:
    """Temperatures, pixel gradients and local rates at the DIC points.

    Parameters
    ----------
    dic : xarray.Dataset
        ``dic.zarr``: ``x(time, point, component)`` mm.
    ir : xarray.Dataset
        ``ir.zarr``: ``temperature(time, v, u)`` °C with full-sensor ``u``, ``v``.
    calibration : xarray.Dataset
        ``calibration.zarr`` of the setup the experiment was recorded with.
    method : {"rbf", "bilinear", "cubic"}
        Spatial interpolant (the paper's IMQ RBF by default).
    c_space, R0_space : float
        IMQ shape factor and distance normalisation (px) in the image.
    c_time, R0_time : float
        IMQ shape factor and normalisation (s) in time.
    mask_erosion_px : float
        Erosion of the specimen mask (px).
    max_edge_factor : float
        Triangles longer than this multiple of the point spacing are not specimen.
    max_view_angle_deg : float
        Points whose surface normal makes a larger angle with the line of sight
        to the IR camera are not visible.
    max_extrapolation_px : float
        How far outside the mask (px) points are still extrapolated.
    halo : int
        Half-width (px) of the local windows that reproduce the global interpolant.

    Returns
    -------
    xarray.Dataset
        The content of ``points.zarr`` (see the module docstring and README).
    """
    _check_params(method, mask_erosion_px, max_extrapolation_px, max_view_angle_deg)
    started = _time.perf_counter()
    camera = load_camera(calibration)
    centre = camera.decompose().C
    x = dic["x"].transpose("time", "point", "component").values.astype(float)
    t_dic = dic["time"].values.astype(float)
    u = ir["u"].values
    v = ir["v"].values
    t_ir = ir["time"].values.astype(float)
    n_t, M, _ = x.shape
    sw, sh = calibration.attrs.get("sensor_width"), calibration.attrs.get("sensor_height")
    if sw is not None and sh is not None and (u.max() >= int(sw) or v.max() >= int(sh) or u.min() < 0 or v.min() < 0):
        raise DataError(
            f"the IR frames cover pixels u {u.min()}..{u.max()}, v {v.min()}..{v.max()}, but the calibration "
            f"image was {sw} x {sh} px: the IR exports do not come from the calibrated camera set-up"
        )

    # projection and visibility
    flat = x.reshape(-1, 3)
    pix = np.full((n_t * M, 2), np.nan)
    ok = np.isfinite(flat).all(axis=1)
    if not ok.any():
        raise DataError("dic: no valid DIC point at any time")
    depth = np.full(n_t * M, np.nan)
    depth[ok] = camera.depth(flat[ok])
    front = ok & (depth > 0)
    pix[front] = camera.project(flat[front])
    pix = pix.reshape(n_t, M, 2)
    in_frame = (np.isfinite(pix).all(axis=2) & (pix[..., 0] >= u[0] - 0.5) & (pix[..., 0] <= u[-1] + 0.5)
                & (pix[..., 1] >= v[0] - 0.5) & (pix[..., 1] <= v[-1] + 0.5))
    valid = ok.reshape(n_t, M)
    frac = in_frame.sum() / max(valid.sum(), 1)
    if frac < 0.5:
        raise CalibrationError(
            f"only {100 * frac:.0f} % of the DIC points project into the IR frames (u {u[0]}..{u[-1]}, "
            f"v {v[0]}..{v[-1]}): is the calibration from another setup, or are the DIC coordinates "
            "not in the frame the calibration markers were measured in (rigid body motion compensation)?"
        )
    local = pix - np.array([u[0], v[0]], dtype=float)  # frame-array coordinates
    local_in = np.where(in_frame[..., None], local, np.nan)
    masks, facing = _masks_and_facing(
        x, local_in, centre, np.arange(u.size), np.arange(v.size),
        erosion=mask_erosion_px, edge_factor=max_edge_factor, max_angle=max_view_angle_deg)
    seen = in_frame & facing
    query = np.where(seen[..., None], local, np.nan)

    # Points that project just outside the mask are extrapolated from samples
    # of the interpolant inside it. The samples are evaluated in the same pass
    # as the points: a second pass would factorise every edge tile of every
    # mask again.
    inmask = _in_mask(masks, local)
    outside = seen & ~inmask
    samples, cols = _extrapolation_samples(local, masks, outside, max_extrapolation_px)
    res = evaluate_series(ir["temperature"], t_ir, t_dic, np.concatenate([query] + list(samples), axis=1), masks,
                          method=method, c=c_space, R0=R0_space, c_time=c_time, R0_time=R0_time, halo=halo,
                          u=u, v=v, name="ir: frames")
    theta, gu, gv, rate, edge = (np.array(a[:, :M], dtype=float) for a in
                                 (res.theta, res.dtheta_du, res.dtheta_dv, res.dtheta_dt, res.edge_distance))
    in_span = np.asarray(res.in_span)
    if not in_span.any():
        raise DataError(
            f"no DIC time ({t_dic[0]:g}..{t_dic[-1]:g} s) lies inside the IR time span "
            f"({t_ir[0]:g}..{t_ir[-1]:g} s): check time_offset/time_origin of the experiment"
        )
    extrap = _extrapolate(res, M, cols, samples, local, theta, gu, gv, rate, edge)

    status = np.full((n_t, M), 0, dtype=np.int8)
    status[extrap] = 1
    status[seen & in_span[:, None] & ~np.isfinite(theta)] = 5
    status[~facing & in_frame] = 4
    status[valid & ~in_frame] = 3
    status[~valid] = 2
    status[~in_span[:, None] & (status <= 1)] = 6
    visible = status <= 1
    for a in (theta, gu, gv, rate):
        a[~visible] = np.nan
    edge[~visible] = np.nan
    pix_out = np.where(valid[..., None] & np.isfinite(pix), pix, np.nan)
    # the calibration's share of the position error, for the uncertainty budget downstream
    pix_std = np.full(n_t * M, np.nan)
    if camera.covariance is not None and front.any():
        pix_std[front] = camera.projection_uncertainty(flat[front])
    pix_std = np.where(np.isfinite(pix_out[..., 0]), pix_std.reshape(n_t, M), np.nan)

    # --- issue 15: noise of the IR data at the specimen pixels (feeds the fields stage's auto rule)
    noise = estimate_ir_noise(ir["temperature"], t_ir, np.logical_and.reduce(masks, axis=0))
    log.info("couple: IR noise %.3g K temporal, %.3g K spatial, quantisation %.3g K (%d specimen pixels)",
             noise.temporal, noise.spatial, noise.quantisation, noise.pixels)
    # --- end issue 15

    counts = {name: int((status == i).sum()) for i, name in enumerate(STATUS_MEANINGS.split())}
    log.info("couple: %d DIC times x %d points in %.1f s; %s", n_t, M, _time.perf_counter() - started,
             ", ".join(f"{k} {v}" for k, v in counts.items() if v))

    geo = camera.decompose()
    ds = xr.Dataset(
        {
            "temperature": (("time", "point"), theta.astype(np.float32),
                            {"units": "degC", "long_name": "temperature at the material point"}),
            "pixel": (("time", "point", "axis"), pix_out,
                      {"units": "px", "long_name": "projected position in the IR image (full sensor, u = column, v = row)"}),
            "pixel_std": (("time", "point"), pix_std,
                          {"units": "px", "long_name": "standard uncertainty of the projected position from the "
                           "calibration covariance (radial RMS)"}),
            "temperature_pixel_gradient": (("time", "point", "axis"), np.stack([gu, gv], axis=-1),
                                           {"units": "K/px", "long_name": "temperature gradient in the IR image plane"}),
            "temperature_local_rate": (("time", "point"), rate,
                                       {"units": "K/s", "long_name": "local time derivative of the IR temperature at the fixed pixel"}),
            "visible": (("time", "point"), visible,
                        {"long_name": "the point has a temperature (status 0 or 1)"}),
            "edge_distance": (("time", "point"), edge,
                              {"units": "px", "long_name": "distance to the specimen mask edge (negative: extrapolated)"}),
            "status": (("time", "point"), status,
                       {"long_name": "why a point has or lacks a temperature",
                        "flag_values": list(range(7)), "flag_meanings": STATUS_MEANINGS}),
            "x": (("time", "point", "component"), x, {"units": "mm", "long_name": "current coordinates (from dic.zarr)"}),
            "mask_pixels": (("time",), masks.sum(axis=(1, 2)).astype(np.int64),
                            {"long_name": "number of IR pixels on the specimen mask"}),
        },
        coords={"time": ("time", t_dic, {"units": "s", "long_name": "DIC time"}),
                "point": dic["point"].values, "component": np.array(["x", "y", "z"], dtype=object),
                "axis": np.array(["u", "v"], dtype=object)},
        attrs={
            "calibration_rms_px": float(calibration["rms_px"]) if "rms_px" in calibration else np.nan,
            "calibration_projection_matrix": np.asarray(camera.M).ravel().tolist(),
            "calibration_camera_centre_mm": np.asarray(geo.C).tolist(),
            "calibration_focal_length_px": float(geo.focal_length_px),
            "ir_time_span_s": [float(t_ir[0]), float(t_ir[-1])],
            "ir_frames": int(t_ir.size),
            **{f"count_{k}": v for k, v in counts.items()},
            "ir_noise_k": float(noise.level), "ir_noise_temporal_k": float(noise.temporal),
            "ir_noise_spatial_k": float(noise.spatial), "ir_quantisation_k": float(noise.quantisation),
        },
    )
    return ds


#: samples (1 px apart, inward from the mask edge) of the extrapolating parabola
_EXTRAP_SAMPLES = 9


def _in_mask(masks, local):
    """(n_t, M) True where a point's nearest pixel (``rint``) is on that time's mask."""
    n_t, H, W = masks.shape
    c = np.rint(local[..., 0])
    r = np.rint(local[..., 1])
    with np.errstate(invalid="ignore"):
        ok = (c >= 0) & (c < W) & (r >= 0) & (r < H)
    tt, pp = np.nonzero(ok)
    out = np.zeros(ok.shape, dtype=bool)
    out[tt, pp] = masks[tt, r[tt, pp].astype(np.int64), c[tt, pp].astype(np.int64)]
    return out


def _extrapolation_samples(local, masks, outside, limit):
    """Sample points for :func:`_extrapolate`: (S, n_t, Mc, 2) px and the point columns (Mc,)."""
    n_t = outside.shape[0]
    S = _EXTRAP_SAMPLES
    # only the few points near the edge (at any time) take part: work on their columns
    cols = np.flatnonzero(outside.any(axis=0)) if limit > 0 else np.zeros(0, np.int64)
    Mc = cols.size
    out_c = outside[:, cols]
    local_c = local[:, cols]
    pts = np.full((S, n_t, Mc, 2), np.nan)
    for k in np.flatnonzero(out_c.any(axis=1)):
        idx = np.flatnonzero(out_c[k])
        p = local_c[k, idx]
        _, (iv, iu) = ndimage.distance_transform_edt(~masks[k], return_indices=True)
        r = np.clip(np.rint(p[:, 1]).astype(int), 0, masks.shape[1] - 1)
        c = np.clip(np.rint(p[:, 0]).astype(int), 0, masks.shape[2] - 1)
        q = np.column_stack([iu[r, c], iv[r, c]]).astype(float)
        d = p - q
        L = np.linalg.norm(d, axis=1)
        near = L <= limit + 0.5
        pts[0, k, idx[near]] = q[near]
        e = d / np.maximum(L, 1e-12)[:, None]
        on = near & (L > 1e-9)
        for j in range(1, S):
            qj = q - j * e
            rj = np.rint(qj[:, 1]).astype(int)
            cj = np.rint(qj[:, 0]).astype(int)
            inside = (rj >= 0) & (rj < masks.shape[1]) & (cj >= 0) & (cj < masks.shape[2])
            on &= inside
            on[inside] &= masks[k][rj[inside], cj[inside]]
            pts[j, k, idx[on]] = qj[on]
    return pts, cols


def _extrapolate(res, M, cols, pts, local, theta, gu, gv, rate, edge):
    """Extrapolation from the mask edge for points just outside it (in place).

    For a point ``p`` outside the mask, ``q`` is the nearest masked pixel and
    ``e = (p - q)/|p - q|``. The interpolated values at ``q - j e``,
    j = 0 .. 8 (as long as they lie on the mask, at least 3) are fitted by a
    parabola in the distance along ``e`` (least squares), which is evaluated at
    ``L = |p - q|``. Values, unlike derivatives, stay accurate at the edge of
    the data; the curvature matters (linear extrapolation from ``q`` left
    0.04 K at the heated edge of the demo half-shell), and fitting nine samples
    instead of passing through three keeps the amplification of pixel noise
    at 1.3 (L = 1 px) to 2.6 (L = 3 px) instead of 4 to 19. With fewer than 3
    samples on the mask the extrapolation is linear from the gradient at ``q``.
    The local rate is the one at ``q``. ``res`` holds the interpolant at the
    ``M`` points followed by the samples ``pts`` of :func:`_extrapolation_samples`.
    """
    n_t = theta.shape[0]
    S = _EXTRAP_SAMPLES
    Mc = cols.size
    done_full = np.zeros((n_t, M), dtype=bool)
    if Mc == 0:
        return done_full
    local_c = local[:, cols]
    todo = np.isfinite(pts[0]).all(axis=2)
    if not todo.any():
        return done_full
    f = np.stack([res.theta[:, M + j * Mc:M + (j + 1) * Mc] for j in range(S)])  # (S, n_t, Mc)
    gq_u, gq_v, rq = (a[:, M:M + Mc] for a in (res.dtheta_du, res.dtheta_dv, res.dtheta_dt))
    d = local_c - pts[0]
    L = np.linalg.norm(d, axis=2)
    e = d / np.maximum(L, 1e-12)[..., None]
    lin_slope = gq_u * e[..., 0] + gq_v * e[..., 1]
    # number of leading samples available per (time, point)
    avail = np.cumprod(np.isfinite(f), axis=0).sum(axis=0)
    c0, c1, c2 = f[0].copy(), lin_slope.copy(), np.zeros_like(L)
    for m in range(3, S + 1):
        sel = avail == m
        if not sel.any():
            continue
        V = np.vander(-np.arange(m, dtype=float), 3, increasing=True)  # 1, s, s^2 at s = 0, -1, ...
        coef = np.linalg.pinv(V) @ f[:m, sel]  # (3, n_sel)
        c0[sel], c1[sel], c2[sel] = coef
    th = c0 + c1 * L + c2 * L**2
    done = todo & np.isfinite(th)
    # the gradient at p: along e from the parabola, across e as interpolated at q
    along = c1 + 2 * c2 * L
    tt, pp = np.nonzero(done)
    full = cols[pp]
    theta[tt, full] = th[done]
    gu[tt, full] = (gq_u + (along - lin_slope) * e[..., 0])[done]
    gv[tt, full] = (gq_v + (along - lin_slope) * e[..., 1])[done]
    rate[tt, full] = rq[done]
    edge[tt, full] = -L[done]
    done_full[tt, full] = True
    return done_full


def couple_stores(dic_path, ir_path, calibration_path, out, **params) -> Path:
    """Run :func:`couple` on stores and write ``points.zarr`` atomically."""
    dic = open_store(dic_path)
    ir = open_store(ir_path)
    cal = open_store(calibration_path)
    ds = couple(dic, ir, cal, **params)
    write_dataset(ds, out, stage="couple", params=params,
                  inputs=[os.fspath(dic_path), os.fspath(ir_path), os.fspath(calibration_path)],
                  encoding={"temperature": {"chunks": (1, ds.sizes["point"])}})
    return Path(out)
