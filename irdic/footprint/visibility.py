"""Which DIC points the IR camera sees, and which pixels are specimen, per DIC time.

Points behind the camera or outside the IR frame, and points on surface
facing away from it, are not visible. Only pixels on the specimen feed the
interpolant: a mask per time from the projected point cloud
(:func:`irdic.footprint.mask.specimen_mask`), also intersected with the masks of
the neighbouring DIC times so that pixels the moving edge crosses are left
out.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..errors import CalibrationError, DataError
from ..logs import report
from .mask import facing_camera, point_normals, specimen_mask
from ..numerics.series import valid_neighbours
from ..numerics.threads import parallel_map
from ..pointcloud import nearest_neighbours

__all__ = ["Projection", "project_points", "fill_in_time", "masks_and_facing", "MASK_REUSE_PX"]

log = logging.getLogger(__name__)

#: pixel motion (px) below which the mask and normals of the previous time are reused
MASK_REUSE_PX = 0.2
#: points (times x points) projected per block
PROJECT_BLOCK = 500_000


def fill_in_time(a: np.ndarray) -> np.ndarray:
    """Fill NaN rows of ``a`` (n_t, M, d) per point from the nearest earlier, else later, valid time (a copy)."""
    ok = np.isfinite(a).all(axis=2)
    out = a.copy()
    gap_t, gap_p = np.nonzero(~ok)  # few: only these rows are looked up
    if gap_t.size == 0:
        return out
    n_t = a.shape[0]
    fwd, bwd = valid_neighbours(ok)
    f, b = fwd[gap_t, gap_p], bwd[gap_t, gap_p]
    out[gap_t, gap_p] = a[np.clip(np.where(f >= 0, f, b), 0, n_t - 1), gap_p]
    return out


def masks_and_facing(x, pix, centre, u, v, *, erosion, edge_factor, max_angle, only: slice | None = None,
                     planned=None, pool_map=None):
    """Per DIC time: specimen mask (H, W) and facing flags (M,).

    A point that failed correlation in one stage does not open a hole in the
    specimen: masks and normals are built from positions filled in time from
    the point's nearest valid stage. While the points move less than
    ``MASK_REUSE_PX`` the previous mask is reused, so a static specimen has
    one mask and the interpolant is set up once. A point's normal is fitted
    to its 12 nearest material points of the first time (the same
    neighbours at every time).

    ``only`` (a slice of the times): masks and flags of those times alone,
    equal to the same rows of the whole result (a time chunk): which mask a
    time reuses depends on every earlier time, so that choice is made over
    all times (cheap: pixel positions only) and just the masks the slice
    uses are built. ``planned``, if given, is called with the number of
    masks to build once it is known (the couple stage's progress model).
    ``pool_map(fn, items)``, if given, builds the masks instead of
    :func:`~irdic.numerics.threads.parallel_map` (the couple stage runs its
    IR clock on the same pool: :func:`~irdic.numerics.threads.map_beside`).
    """
    n_t, M, _ = x.shape
    xf = fill_in_time(x)
    pf = fill_in_time(pix)
    # the normals' neighbours once, among the material points of the first time (filled in time: the points
    # with coordinates at any time, the same at every time): a surface deforms smoothly, so a point's nearest
    # neighbours stay near it, and a tree per mask cost a fifth of the masks' time
    ref = xf[0][np.isfinite(xf[0]).all(axis=1)]
    neighbours = nearest_neighbours(ref) if ref.shape[0] >= 3 else None
    source = _mask_sources(pf)
    keep_t = np.arange(n_t) if only is None else np.arange(n_t)[only]
    masks = np.zeros((keep_t.size, v.size, u.size), dtype=bool)
    facing = np.zeros((keep_t.size, M), dtype=bool)

    done = [0]
    lock = threading.Lock()

    def build(j):
        n = point_normals(xf[j], towards=centre, neighbours=neighbours)
        f = facing_camera(xf[j], n, centre, max_angle_deg=max_angle)
        keep = np.isfinite(pf[j]).all(axis=1) & f
        out = specimen_mask(pf[j][keep], u, v, erosion_px=erosion, max_edge_factor=edge_factor), f
        with lock:
            done[0] += 1
            report("masks", done[0] / sources.size)
        return out

    sources = np.unique(source[keep_t][source[keep_t] >= 0])
    if planned is not None:
        planned(int(sources.size))
    built = dict(zip(sources.tolist(), (pool_map or parallel_map)(build, sources.tolist())))
    for row, k in enumerate(keep_t):
        if source[k] >= 0:
            masks[row], facing[row] = built[int(source[k])]
    report("masks", 1.0)
    rebuilt = len(built)
    n_t = keep_t.size
    # a pixel the moving edge crosses between neighbouring times carries mixed
    # specimen/background values after temporal interpolation: leave it out
    both = masks.copy()
    both[1:] &= masks[:-1]
    both[:-1] &= masks[1:]
    log.info("specimen masks: %d built for %d DIC times, %d to %d px", rebuilt, n_t,
             int(both.sum(axis=(1, 2)).min()), int(both.sum(axis=(1, 2)).max()))
    return both, facing


def _mask_sources(pf: np.ndarray) -> np.ndarray:
    """Per time the time whose mask it uses (itself when rebuilt; -1: fewer than 3 points, no mask)."""
    n_t = pf.shape[0]
    source = np.full(n_t, -1, np.int64)
    last = None
    for k in range(n_t):
        ok = np.isfinite(pf[k]).all(axis=1)
        if ok.sum() < 3:
            continue
        if last is not None:
            both = ok & np.isfinite(pf[last]).all(axis=1)
            moved = np.abs(pf[k][both] - pf[last][both]).max() if both.any() else np.inf
            if moved < MASK_REUSE_PX:
                source[k] = last
                continue
        source[k] = last = k
    return source


@dataclass
class Projection:
    """The DIC points of every time in the IR image.

    Attributes
    ----------
    x : ndarray, shape (n_t, M, 3)
        DIC coordinates, mm (NaN: point missing).
    flat_x : ndarray, shape (n_t * M, 3)
        ``x`` flattened.
    valid : ndarray of bool, shape (n_t, M)
        The DIC point has coordinates.
    front : ndarray of bool, shape (n_t * M,)
        Valid and in front of the camera.
    pix : ndarray, shape (n_t, M, 2)
        Projected position, full-sensor px (NaN: missing or behind the camera).
    in_frame : ndarray of bool, shape (n_t, M)
        Projected inside the IR frame (half a pixel beyond the outer centres).
    local : ndarray, shape (n_t, M, 2)
        ``pix`` in frame-array coordinates (pixel (0, 0) = the crop corner).
    """

    x: np.ndarray
    flat_x: np.ndarray
    valid: np.ndarray
    front: np.ndarray
    pix: np.ndarray
    in_frame: np.ndarray
    local: np.ndarray

    def times(self, sl: slice) -> "Projection":
        """The projection of the times ``sl`` alone."""
        n_t, M = self.valid.shape
        front = self.front.reshape(n_t, M)[sl]
        return Projection(self.x[sl], self.x[sl].reshape(-1, 3), self.valid[sl], front.ravel(), self.pix[sl],
                          self.in_frame[sl], self.local[sl])


def project_points(camera, dic: xr.Dataset, u: np.ndarray, v: np.ndarray) -> Projection:
    """Project the DIC points of every time into the IR frame (full-sensor pixels ``u``, ``v``).

    Raises
    ------
    DataError
        No DIC point has coordinates at any time.
    CalibrationError
        Fewer than half of the valid points project into the IR frame (the
        calibration of another setup, or DIC coordinates in another frame).
    """
    x = dic["x"].transpose("time", "point", "component").values.astype(float, copy=False)
    n_t, M, _ = x.shape
    valid = np.isfinite(x).all(axis=2)
    if not valid.any():
        raise DataError("dic: no valid DIC point at any time")
    pix = np.full((n_t, M, 2), np.nan)
    front = np.zeros((n_t, M), dtype=bool)
    # a block of times at a time: the record's temporaries at once (1.3 GB at 26k points x 300 times) cost more
    # to allocate than to compute
    step = max(1, PROJECT_BLOCK // max(M, 1))
    for s in range(0, n_t, step):
        xb, ok = x[s:s + step].reshape(-1, 3), valid[s:s + step].ravel()
        depth = np.full(ok.size, np.nan)
        depth[ok] = camera.depth(xb[ok])
        fb = ok & (depth > 0)
        pix[s:s + step].reshape(-1, 2)[fb] = camera.project(xb[fb])
        front[s:s + step] = fb.reshape(-1, M)
    in_frame = (np.isfinite(pix).all(axis=2) & (pix[..., 0] >= u[0] - 0.5) & (pix[..., 0] <= u[-1] + 0.5)
                & (pix[..., 1] >= v[0] - 0.5) & (pix[..., 1] <= v[-1] + 0.5))
    frac = in_frame.sum() / max(valid.sum(), 1)
    if frac < 0.5:
        raise CalibrationError(
            f"only {100 * frac:.0f} % of the DIC points project into the IR frames (u {u[0]}..{u[-1]}, "
            f"v {v[0]}..{v[-1]}): is the calibration from another setup, or are the DIC coordinates "
            "not in the frame the calibration markers were measured in (rigid body motion compensation)?"
        )
    local = pix - np.array([u[0], v[0]], dtype=float)
    return Projection(x, x.reshape(-1, 3), valid, front.ravel(), pix, in_frame, local)
