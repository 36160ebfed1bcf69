"""Material samples of the specimen that move with the DIC points: a regular grid in the reference image.

The clock estimate compares every IR frame with the pattern the material
carries, so it samples the frames at material points. :class:`Nodes` puts
them on a regular grid of the *reference image* (the DIC points' image
positions at the first DIC time) and moves them with the points: each node
keeps its barycentric coordinates in the triangle of the points'
triangulation that holds it, so its image position at any time is the same
combination of the corners' positions, interpolated between the DIC stages
by a spline in time. On the grid, a field over the nodes is an image, and its
gradient a local linear fit (:meth:`Nodes.gradient`).
"""

from __future__ import annotations

import copy
import logging

import numpy as np
from scipy.interpolate import BSpline, make_interp_spline
from scipy.ndimage import distance_transform_edt, gaussian_filter
from scipy.sparse import csr_matrix
from scipy.spatial import Delaunay, QhullError, cKDTree

from ..errors import DataError
from ..surface.parametrisation import median_spacing

__all__ = ["Mesh", "Nodes", "thinned", "MAX_EDGE_FACTOR", "POINT_SPACING_PX"]

log = logging.getLogger(__name__)

#: triangles with an edge longer than this many median point spacings are not specimen (holes, concave outlines)
MAX_EDGE_FACTOR = 3.0
#: times per block of the nodes' reference velocities
TIME_BLOCK = 16
#: the nodes' own spline in time (their positions at the stages combined once) where its coefficients take at
#: most this many bytes: it costs about as much per node as the points' spline per point, and spares the
#: barycentric combination of the points' positions at every time, which costs twice as much per node
NODE_SPLINE_BYTES = 128 << 20
#: DIC points closer than this (px, median distance to the nearest in the reference image) are thinned to points
#: this far apart at least (:func:`thinned`): the nodes' positions are interpolated between them, linearly over a
#: triangle, which a smooth motion allows over a few pixels, while the splines in time through every point cost in
#: proportion to the points (26,180 points on 14,300 specimen pixels: 8 of the clock's 9 s)
POINT_SPACING_PX = 1.5


def thinned(positions: np.ndarray) -> np.ndarray:
    """``positions`` (n_t, N, 2), without gaps, thinned where they lie closer than :data:`POINT_SPACING_PX`
    (median, in the reference image: the first time's) to points more than that far apart, every point left
    out within that distance of one kept (as given elsewhere).

    Notes
    -----
    Each point in turn (in the order given) is kept unless a kept one lies within the spacing: the kept points
    cover the cloud as evenly as a grid would, without its pairs across the cells' sides, so that the
    triangulation's edges stay within about twice the spacing and no triangle of the specimen is taken for a
    hole (:class:`Mesh`).
    """
    ref = positions[0]
    if ref.shape[0] < 3 or median_spacing(ref) >= POINT_SPACING_PX:
        return positions
    free = np.ones(ref.shape[0], dtype=bool)
    kept = []
    for i, others in enumerate(cKDTree(ref).query_ball_point(ref, POINT_SPACING_PX)):
        if free[i]:
            kept.append(i)
            free[others] = False
    log.info("IR clock: %d of the %d DIC points, at least %.3g px apart in the IR image", len(kept), ref.shape[0],
             POINT_SPACING_PX)
    return positions[:, kept]


class Mesh:
    """The DIC points' triangulation in the reference image and their motion between the DIC stages.

    Parameters
    ----------
    positions : numpy.ndarray, shape (n_t, N, 2)
        The DIC points' image positions (px) at every DIC time, without gaps; the first time's are the
        reference image.
    t_dic : numpy.ndarray, shape (n_t,)
        DIC times (s), increasing.

    Attributes
    ----------
    tri : scipy.spatial.Delaunay
        The triangulation of the reference positions.
    good : numpy.ndarray of bool
        Its triangles that are specimen: no edge longer than :data:`MAX_EDGE_FACTOR` median point spacings
        (holes and concave outlines stay open).
    area : float
        Their area (px^2).
    """

    def __init__(self, positions: np.ndarray, t_dic: np.ndarray):
        self.positions, self.t_dic = positions, t_dic
        ref = positions[0]
        try:
            self.tri = Delaunay(ref)
        except QhullError:
            span = np.ptp(ref, axis=0)
            raise DataError(f"the DIC points' image positions are degenerate (collinear or coincident: they span "
                            f"{span[0]:.3g} x {span[1]:.3g} px), so they cover no area of the IR image") from None
        c = ref[self.tri.simplices]
        spacing = np.median(cKDTree(ref).query(ref, k=2)[0][:, 1])
        self.good = np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).max(axis=1) <= MAX_EDGE_FACTOR * spacing
        e0, e1 = c[:, 0] - c[:, 2], c[:, 1] - c[:, 2]
        self.area = float(0.5 * np.abs(e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0])[self.good].sum())
        self._splines: dict = {}

    def spline(self, order: int):
        """The spline of degree ``order`` (at most ``n_t - 1``) through the stages' positions, flattened to
        (n_t, 2 N), its derivative and its degree."""
        k = int(min(order, self.t_dic.size - 1))
        if k not in self._splines:
            spl = make_interp_spline(self.t_dic, self.positions.reshape(self.t_dic.size, -1), k=k, axis=0)
            self._splines[k] = (spl, spl.derivative(), k)
        return self._splines[k]


class Nodes:
    """Nodes on a regular grid of the reference image, carried by the DIC points' triangulation.

    Parameters
    ----------
    mesh : Mesh
        The DIC points' triangulation and motion.
    spacing : float
        Grid spacing (px of the reference image).
    inset : float
        Nodes nearer the outline of the triangulation than this (px) are left out.
    order : int
        Degree of the spline in time through the DIC stages (at most ``n_t - 1``).

    Attributes
    ----------
    M : int
        Number of nodes.
    order : int
        The spline degree used.
    reference : numpy.ndarray, shape (M, 2)
        The nodes' positions in the reference image (px).
    """

    def __init__(self, mesh: Mesh, spacing: float, inset: float, order: int = 5):
        ref, tri, good = mesh.positions[0], mesh.tri, mesh.good
        lo, hi = np.floor(ref.min(axis=0)) - 1.0, np.ceil(ref.max(axis=0)) + 1.0
        gx, gy = np.arange(lo[0], hi[0] + 1e-9, spacing), np.arange(lo[1], hi[1] + 1e-9, spacing)
        grid = np.stack(np.meshgrid(gx, gy), axis=-1).reshape(-1, 2)
        simplex = tri.find_simplex(grid)
        on = simplex >= 0
        on[on] = good[simplex[on]]
        on = on.reshape(gy.size, gx.size)
        keep = on & (distance_transform_edt(on) * spacing >= inset)
        self.shape, self.spacing = keep.shape, float(spacing)
        self.mask = keep
        self.cells = np.flatnonzero(keep.ravel())
        self.reference = grid[self.cells]
        s = simplex[self.cells]
        T = tri.transform[s]
        b = np.einsum("nij,nj->ni", T[:, :2], self.reference - T[:, 2])
        lam = np.c_[b, 1.0 - b.sum(axis=1)]
        used, self.tri_of = np.unique(s, return_inverse=True)
        self.corners = tri.simplices[used]
        self.M, self.N = self.cells.size, ref.shape[0]
        # node = barycentric combination of its triangle's corners: one sparse (M, N) matrix
        rows = np.arange(0, 3 * s.size + 1, 3)
        self.weights = csr_matrix((lam.ravel(), tri.simplices[s].ravel(), rows), shape=(s.size, self.N))
        # each point's mean over the triangles in use around it
        T = self.corners.size // 3
        around = csr_matrix((np.ones(3 * T), (self.corners.ravel(), np.repeat(np.arange(T), 3))), shape=(self.N, T))
        deg = np.asarray(around.sum(axis=1)).ravel()
        self.around = csr_matrix(around.multiply(1.0 / np.maximum(deg, 1.0)[:, None]))
        cr = ref[self.corners]
        # reference edge matrices [e0 e1] (columns): F^-1 = E_ref E_now^-1 maps image velocities to the reference
        self.e_ref = np.stack([cr[:, 0] - cr[:, 2], cr[:, 1] - cr[:, 2]], axis=-1)
        self.mesh, self.t_dic = mesh, mesh.t_dic
        self.spline, self.velocity, self.order = mesh.spline(order)
        self._own, self._uses = None, 0

    def with_order(self, order: int) -> "Nodes":
        """The same nodes moved by a spline of another degree in time."""
        out = copy.copy(self)
        out.spline, out.velocity, out.order = self.mesh.spline(order)
        out._own, out._uses = None, 0
        return out

    def _own_spline(self):
        """The spline in time through the nodes' positions at the stages (a BSpline over (M, 2) values), built at
        the second call (nodes that move once, e.g. by a spline of another degree for one comparison, do not
        pay for it); None before, and where its coefficients would take more than :data:`NODE_SPLINE_BYTES`
        (the points' spline and the combination at each time then).

        The spline is linear in its values, so its coefficients combined barycentrically are the nodes' spline:
        the same positions up to rounding (1e-13 px)."""
        self._uses += 1
        c = self.spline.c  # (coefficients, 2 N)
        k = c.shape[0]
        if self._own is not None or self._uses < 2 or k * 2 * self.M * c.itemsize > NODE_SPLINE_BYTES:
            return self._own
        own = self.weights @ c.reshape(k, self.N, 2).transpose(1, 0, 2).reshape(self.N, 2 * k)
        own = own.reshape(self.M, k, 2).transpose(1, 0, 2).reshape(k, 2 * self.M)
        self._own = BSpline(self.spline.t, own, self.spline.k, extrapolate=self.spline.extrapolate, axis=0)
        return self._own

    def _combine(self, V: np.ndarray) -> np.ndarray:
        """The nodes' (n, M, 2) barycentric combinations of the points' ``V`` (n, N, 2), one time at a time (a
        product over all times at once needs (N, n, 2) copies of both, which cost more than the products)."""
        out = np.empty((V.shape[0], self.M, 2))
        for i, Vi in enumerate(V):
            out[i] = self.weights @ Vi
        return out

    def at(self, t: np.ndarray) -> np.ndarray:
        """Image positions (n, M, 2) px of the nodes at times ``t`` (n,) s."""
        return self._at(self._own_spline(), np.asarray(t, float))

    def _at(self, own, t: np.ndarray) -> np.ndarray:
        """:meth:`at` from the nodes' own spline ``own``, or from the points' where it is None."""
        if own is not None:
            return own(t).reshape(t.size, self.M, 2)
        return self._combine(self.spline(t).reshape(t.size, self.N, 2))

    def blocks(self, t: np.ndarray, rows: int):
        """The image positions of :meth:`at` a block of ``rows`` times at a time: (slice of ``t``, positions
        (m, M, 2) px) for each (the positions of all times at once are tens of MB at paper scale)."""
        t = np.asarray(t, float)
        own = self._own_spline()
        for s in range(0, t.size, rows):
            yield slice(s, min(s + rows, t.size)), self._at(own, t[s:s + rows])

    def reference_velocity(self, t: np.ndarray, deformations: int = 12) -> np.ndarray:
        """Velocities (n, M, 2) of the nodes in the reference image (px/s) at times ``t`` (n,) s.

        The reference velocity is ``F^-1 w``: the image velocity ``w`` mapped
        back by the local deformation ``F`` (reference to now); along it the
        pattern's reference gradient gives the sample's rate of change. ``F^-1``
        is each triangle's, averaged at the points over the triangles around
        them, at ``deformations`` times spread over ``t`` and linear in time
        between them (the deformation changes slowly next to the motion);
        ``F^-1 w`` at the points is interpolated to the nodes like the
        positions (exact for an affine motion).
        """
        t = np.asarray(t, float)
        n = t.size
        at = np.linspace(t.min(), t.max(), min(n, deformations))
        c = self.spline(at).reshape(at.size, self.N, 2)[:, self.corners]  # (m, T, 3, 2)
        e0, e1 = c[:, :, 0] - c[:, :, 2], c[:, :, 1] - c[:, :, 2]
        det = e0[..., 0] * e1[..., 1] - e1[..., 0] * e0[..., 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.stack([e1[..., 1], -e1[..., 0], -e0[..., 1], e0[..., 0]], axis=-1) / det[..., None]
        E = self.e_ref.reshape(1, -1, 4)
        # F^-1 = E_ref E_now^-1, row-major (m, T, 4), then its mean at the points (N, m, 4)
        Finv = np.stack([E[..., 0] * inv[..., 0] + E[..., 1] * inv[..., 2], E[..., 0] * inv[..., 1] + E[..., 1] * inv[..., 3],
                         E[..., 2] * inv[..., 0] + E[..., 3] * inv[..., 2], E[..., 2] * inv[..., 1] + E[..., 3] * inv[..., 3]],
                        axis=-1)
        Finv = (self.around @ np.nan_to_num(Finv).transpose(1, 0, 2).reshape(-1, at.size * 4)).reshape(self.N, -1, 4)
        out = np.empty((n, self.M, 2))
        # a few times at a time: the (N, times, 4) temporaries of all times at once cost more than the arithmetic
        for s in range(0, n, TIME_BLOCK):
            tb = t[s:s + TIME_BLOCK]
            F = Finv
            if at.size > 1:  # linear in time between the deformations' times
                k = np.clip(np.searchsorted(at, tb) - 1, 0, at.size - 2)
                x = ((tb - at[k]) / (at[k + 1] - at[k]))[None, :, None]
                F = Finv[:, k] * (1.0 - x) + Finv[:, k + 1] * x
            W = self.velocity(tb).reshape(tb.size, self.N, 2).transpose(1, 0, 2)
            R = np.stack([F[..., 0] * W[..., 0] + F[..., 1] * W[..., 1],
                          F[..., 2] * W[..., 0] + F[..., 3] * W[..., 1]], axis=1)  # (N, 2, times)
            out[s:s + tb.size] = self._combine(R.transpose(2, 0, 1))
        return out

    def gradient(self, values: np.ndarray, bandwidth: float) -> np.ndarray:
        """Gradient (M, 2), per px of the reference image, of ``values`` (M,) over the nodes.

        Notes
        -----
        At each node the plane ``c + g . (x - x_0)`` fitted by least squares with
        Gaussian weights of standard deviation ``bandwidth`` (px) over the nodes
        around it: the moments of the weighted fit are Gaussian filters of the
        grid images ``1``, ``x``, ``y``, ``x^2``, ``xy``, ``y^2`` and their
        products with ``values`` (outside the nodes 0), so a node near the
        outline gets a one-sided fit, not the background's.
        """
        M = self.mask.astype(float)
        P = np.zeros(M.size)
        P[self.cells] = values
        P = P.reshape(M.shape)
        y, x = np.mgrid[0:M.shape[0], 0:M.shape[1]].astype(float)
        x -= x.mean()
        y -= y.mean()
        sigma = bandwidth / self.spacing

        def smooth(f):
            return gaussian_filter(f, sigma, mode="constant", truncate=3.0)

        m0, mx, my = smooth(M), smooth(M * x), smooth(M * y)
        with np.errstate(divide="ignore", invalid="ignore"):
            cx, cy = mx / m0, my / m0
            sxx = smooth(M * x * x) / m0 - cx * cx
            sxy = smooth(M * x * y) / m0 - cx * cy
            syy = smooth(M * y * y) / m0 - cy * cy
            f0 = smooth(M * P) / m0
            bx, by = smooth(M * x * P) / m0 - cx * f0, smooth(M * y * P) / m0 - cy * f0
            det = sxx * syy - sxy * sxy
            g = np.stack([(syy * bx - sxy * by) / det, (sxx * by - sxy * bx) / det], axis=-1)
        return np.nan_to_num(g.reshape(-1, 2)[self.cells]) / self.spacing
