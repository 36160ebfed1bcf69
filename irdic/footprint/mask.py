"""Where the specimen is in an IR frame: normals, visibility, pixel mask, edge distance.

Only pixels that lie on the specimen may feed the temperature interpolant:
the specimen edge is a temperature discontinuity (specimen against a hot
plate or a cool room), and an interpolant that uses background pixels rings
(docs/method.md: up to 38 K at edge points). The mask is built from the
projected DIC point cloud itself: its triangulation, with triangles longer
than a few point spacings removed (so concave outlines and holes stay
open), rasterised on the pixel centres triangle by triangle (cost linear in
the points) and eroded by about one pixel.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import Delaunay, QhullError, cKDTree

from ..errors import ConfigError, GeometryError
from ..pointcloud import local_normals

__all__ = ["point_normals", "facing_camera", "specimen_mask", "edge_distance"]


def point_normals(x: np.ndarray, *, k: int = 12, towards: np.ndarray | None = None,
                  neighbours: np.ndarray | None = None) -> np.ndarray:
    """Unit surface normals of a point cloud by local principal component analysis.

    Parameters
    ----------
    x : ndarray, shape (N, 3)
        Point coordinates (mm); NaN rows are missing points (normal NaN).
    k : int
        Number of neighbours (including the point) for each local plane fit.
    towards : ndarray, shape (3,), optional
        A location (e.g. a camera centre) the normals are oriented towards;
        without it the orientation is made consistent with the mean normal.
    neighbours : ndarray of int, shape (n_finite, k), optional
        Each finite row's neighbours, as indices among the finite rows (the
        same material points' neighbours in a reference configuration:
        :func:`irdic.pointcloud.nearest_neighbours`); default the ``k``
        nearest in ``x`` itself.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ConfigError(f"x must have shape (N, 3), got {x.shape}")
    ok = np.isfinite(x).all(axis=1)
    n = np.full_like(x, np.nan)
    pts = x[ok]
    if pts.shape[0] < 3:
        raise GeometryError(f"need at least 3 valid points to estimate surface normals, got {pts.shape[0]}")
    if neighbours is not None and len(neighbours) != pts.shape[0]:
        raise ConfigError(f"neighbours must have one row per finite point ({pts.shape[0]}), got {len(neighbours)}")
    normals = local_normals(pts, k, neighbours)
    if towards is not None:
        sign = np.sign(np.einsum("ni,ni->n", normals, np.asarray(towards, float) - pts))
    else:
        sign = np.sign(normals @ normals.mean(axis=0))
    sign[sign == 0] = 1.0
    n[ok] = normals * sign[:, None]
    return n


def facing_camera(x: np.ndarray, normals: np.ndarray, centre: np.ndarray, *, max_angle_deg: float = 80.0) -> np.ndarray:
    """True where the surface at ``x`` faces the camera at ``centre``.

    A point is visible when the angle between its normal and the direction to
    the camera is below ``max_angle_deg`` (grazing views are unreliable: the
    emissivity drops and a pixel averages over a long stretch of surface).
    """
    d = np.asarray(centre, float) - np.asarray(x, float)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    cosang = np.einsum("...i,...i->...", d, normals)
    with np.errstate(invalid="ignore"):
        return np.nan_to_num(cosang, nan=-1.0) > np.cos(np.deg2rad(max_angle_deg))


def specimen_mask(
    pixels: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    *,
    erosion_px: float = 1.0,
    max_edge_factor: float = 3.0,
) -> np.ndarray:
    """Pixels of a frame that lie on the specimen, from its projected point cloud.

    Parameters
    ----------
    pixels : ndarray, shape (N, 2)
        Projected (u, v) of the DIC points in px; NaN rows are ignored.
    u, v : ndarray, shape (W,), (H,)
        Full-sensor pixel coordinates of the frame's columns and rows.
    erosion_px : float
        Distance (px) by which the covered area is shrunk, so that pixels
        that straddle the specimen edge are left out.
    max_edge_factor : float
        Triangles with an edge longer than this multiple of the median
        nearest-neighbour spacing are not part of the specimen (holes,
        concave outlines).

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    if erosion_px < 0:
        raise ConfigError(f"erosion_px must be >= 0, got {erosion_px}")
    if max_edge_factor <= 1:
        raise ConfigError(f"max_edge_factor must be > 1, got {max_edge_factor}")
    p = np.asarray(pixels, float)
    p = p[np.isfinite(p).all(axis=1)]
    u = np.asarray(u)
    v = np.asarray(v)
    mask = np.zeros((v.size, u.size), dtype=bool)
    if p.shape[0] < 3:
        return mask
    try:
        tri = Delaunay(p)
    except QhullError:
        # Qhull's own report (options, input statistics) means nothing to the user
        span = p.max(axis=0) - p.min(axis=0)
        raise GeometryError(
            f"the {p.shape[0]} DIC points seen by the IR camera are degenerate: their projections are collinear "
            f"or coincide (they span {span[0]:.3g} x {span[1]:.3g} px), so they cover no area of the image; check "
            "that the DIC export holds a surface (not a line of points) and that the camera looks at it"
        ) from None
    corners = p[tri.simplices]
    lengths = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)  # (n, 3): edge i from corner i - 1
    if tri.coplanar.size:  # points left out of the triangulation (duplicates): their neighbours by a tree
        spacing = np.median(cKDTree(p).query(p, k=2)[0][:, 1])
    else:
        spacing = np.median(_nearest_distance(tri.simplices, lengths, p.shape[0]))
    edges = lengths.max(axis=1)
    keep = edges <= max_edge_factor * max(spacing, 1e-12)
    # only the bounding box of the cloud needs testing
    iu = np.flatnonzero((u >= p[:, 0].min() - 1) & (u <= p[:, 0].max() + 1))
    iv = np.flatnonzero((v >= p[:, 1].min() - 1) & (v <= p[:, 1].max() + 1))
    if iu.size == 0 or iv.size == 0:
        return mask
    mask[np.ix_(iv, iu)] = _rasterise(corners[keep], u[iu], v[iv])
    if erosion_px > 0:
        # erode by a Euclidean distance rather than a square structuring element: a pixel stays when no
        # unmasked pixel centre lies within erosion_px (beyond the frame counts as masked), i.e. the
        # Euclidean distance transform's ``dist > erosion_px``, as an erosion by the disc of those offsets
        mask = ndimage.binary_erosion(mask, structure=_disc(erosion_px), border_value=1)
    return mask


def _disc(radius):
    """The integer offsets within ``radius`` (px) of the centre, as a structuring element (the same
    comparison as ``distance_transform_edt(...) <= radius``)."""
    r = int(np.floor(radius))
    a = np.arange(-r, r + 1)
    return np.sqrt((a[:, None] ** 2 + a[None, :] ** 2).astype(float)) <= radius


def _nearest_distance(simplices, lengths, n):
    """Distance (px) from each of ``n`` points to its nearest other point: the shortest Delaunay edge at it
    (a point's nearest neighbour is always one of its Delaunay neighbours); ``lengths`` (m, 3) of the edges
    from corner ``i - 1`` to corner ``i`` of each simplex; every point a vertex of some simplex."""
    d = np.full(n, np.inf)
    e = lengths.ravel()
    for a in (simplices, np.roll(simplices, 1, axis=1)):
        np.minimum.at(d, a.ravel(), e)
    return d


def _rasterise(corners: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Pixel centres (``v`` rows x ``u`` columns, consecutive integers) inside any of the triangles.

    ``corners`` (n, 3, 2) in px. Every triangle tests only the pixel centres
    of its bounding box (a few, the triangles being about a point spacing
    across), so the cost is linear in the number of triangles; a point
    location of every pixel in the triangulation (``find_simplex``) costs
    ~50 x more. Closed triangles, with a rounding tolerance of 1e-9 of the
    doubled area, as ``find_simplex`` has.
    """
    out = np.zeros((v.size, u.size), dtype=bool)
    if corners.shape[0] == 0:
        return out
    lo = np.ceil(corners.min(axis=1) - 1e-9).astype(np.int64)  # (n, 2) first candidate (u, v)
    hi = np.floor(corners.max(axis=1) + 1e-9).astype(np.int64)
    span = np.maximum(hi - lo + 1, 0)
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    ok = np.abs(area) > 0
    sgn = np.sign(area)
    tol = 1e-9 * np.abs(area)
    # triangles grouped by bounding-box size: one vectorised test per group
    # one integer key per box size, np.unique on it: not a set of Python
    # tuples (~10^4 triangles per mask), nor np.unique(axis=0) (a slow sort)
    box = np.unique(span[ok, 0] * (int(span[:, 1].max()) + 1) + span[ok, 1])
    for su, sv in zip(*(x.tolist() for x in np.divmod(box, int(span[:, 1].max()) + 1))):
        if su == 0 or sv == 0:
            continue
        sel = np.flatnonzero(ok & (span[:, 0] == su) & (span[:, 1] == sv))
        ou, ov = np.meshgrid(np.arange(su), np.arange(sv))
        pu = lo[sel, 0][:, None] + ou.ravel()[None, :]
        pv = lo[sel, 1][:, None] + ov.ravel()[None, :]
        inside = np.ones(pu.shape, dtype=bool)
        for p, q in ((a, b), (b, c), (c, a)):
            e = ((q[sel, 0] - p[sel, 0])[:, None] * (pv - p[sel, 1][:, None])
                 - (q[sel, 1] - p[sel, 1])[:, None] * (pu - p[sel, 0][:, None]))
            inside &= e * sgn[sel][:, None] >= -tol[sel][:, None]
        cu = pu[inside] - u[0]
        cv = pv[inside] - v[0]
        on = (cu >= 0) & (cu < u.size) & (cv >= 0) & (cv < v.size)
        out[cv[on], cu[on]] = True
    return out


def edge_distance(mask: np.ndarray, pixels: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Distance (px) from points to the edge of ``mask``; negative outside it.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
    pixels : ndarray, shape (N, 2)
        (u, v) in full-sensor px; NaN rows give NaN.
    u, v : ndarray
        Pixel coordinates of the mask's columns and rows (consecutive integers).

    Returns
    -------
    ndarray, shape (N,)
        Bilinearly interpolated signed distance: > 0 inside (distance to the
        nearest pixel outside the mask), < 0 outside.
    """
    inside = ndimage.distance_transform_edt(mask)
    outside = ndimage.distance_transform_edt(~mask)
    signed = np.where(mask, inside - 0.5, -(outside - 0.5))
    p = np.asarray(pixels, float)
    out = np.full(p.shape[0], np.nan)
    ok = np.isfinite(p).all(axis=1)
    cols = p[ok, 0] - u[0]
    rows = p[ok, 1] - v[0]
    out[ok] = ndimage.map_coordinates(signed, [rows, cols], order=1, mode="nearest")
    return out
