"""Extrapolation from the specimen mask edge for DIC points just outside it.

The outermost DIC points lie on the specimen edge, so they always project
just outside the eroded mask. Their values come from a parabola fitted to
samples of the interpolant along the line to the nearest masked pixel
(:func:`extrapolation_samples`, :func:`extrapolate`).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["EXTRAP_SAMPLES", "in_mask", "extrapolation_samples", "extrapolate"]

#: samples (1 px apart, inward from the mask edge) of the extrapolating parabola
EXTRAP_SAMPLES = 9


def in_mask(masks, local):
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


def extrapolation_samples(local, masks, outside, limit):
    """Sample points for :func:`extrapolate`: (S, n_t, Mc, 2) px and the point columns (Mc,)."""
    n_t = outside.shape[0]
    S = EXTRAP_SAMPLES
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


def extrapolate(res, M, cols, pts, local, theta, gu, gv, rate, edge):
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
    ``M`` points followed by the samples ``pts`` of :func:`extrapolation_samples`.
    """
    n_t = theta.shape[0]
    S = EXTRAP_SAMPLES
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
