"""Inverse-multiquadric (IMQ) interpolation of pixel temperatures in space and time.

The paper's interpolant of the infrared data (eq:Theta_RBFInterp) is a tensor
product: in the image an IMQ radial basis function ``m(r) = c / sqrt(c^2 + r^2)``,
``r = distance / R0``, on every (masked) pixel plus the monomials {1, u, v}
(c = 2, R0 = 1 px), and in time the same kernel on every frame time plus {1, t}
(c = 1, R0 = 1 s). With the data matrix ``F`` (pixels x frames) this reads
``Theta(x, t) = l_s(x)^T F l_t(t)`` with the spatial cardinal functions ``l_s``
of the pixel set and the temporal ones ``l_t`` of the frame times. Hence, at an
evaluation time ``t_k``, ``Theta(., t_k)`` is the spatial interpolant of the
combined frame ``G_k = F l_t(t_k)`` and ``dTheta/dt(., t_k)`` the spatial
interpolant of ``G'_k = F l_t'(t_k)``.

This module knows kernels and interpolants only (no cameras, no files):

* :func:`imq`, :func:`imq_dr`: the kernel and its radial derivative.
* :class:`TemporalInterpolant`: cardinal weights of the frame times (and their
  time derivative) for any evaluation times.
* :class:`MaskedGridInterpolant` (alias :data:`MaskedGridRBF`): interpolation
  of one or many fields given on the masked pixels of a regular grid, with
  ``d/du`` and ``d/dv``, at arbitrary subpixel points; ``method="rbf"`` (the
  paper's global IMQ interpolant over the masked pixels, computed fast),
  ``"bilinear"`` or ``"cubic"`` (for comparison).
* :func:`evaluate_series`: the use case of the couple stage. Frames, frame
  times, evaluation times and points per evaluation time in; ``Theta``,
  ``dTheta/du``, ``dTheta/dv``, ``dTheta/dt`` and the distance to the mask edge
  per (time, point) out.
* :func:`exact_global_interpolant`: the dense saddle-point solve over all
  masked pixels, the reference for tests (small cases only).

Conventions: ``u`` = column, ``v`` = row, 0-based, pixel centres on integer
coordinates; points are arrays ``[..., (u, v)]``. A point belongs to the pixel
whose centre is nearest (``rint``); it is inside the mask when that pixel is.

Notes
-----
**How the global spatial interpolant is made fast** (``method="rbf"``).
The exact interpolant over ``n_mask`` ~ 50,000 pixels would need a dense
50k x 50k saddle-point solve (20 GB). Its cardinal functions, however, decay
exponentially (IMQ, c = 2 on a unit grid: ~1e-1 at 2.5 px, ~1e-3 at 8.5 px,
~4e-5 at 12.5 px), so away from the mask edge the value at a point is
determined, to ~1e-5 of the local data variation, by the masked pixels within
``halo`` = 12 px. Two cases:

* *Interior* (every pixel within ``halo`` of the point's pixel is masked): the
  local system is the same for every such pixel (the grid is shift
  invariant), so it is solved once (per ``c*R0`` and ``halo``, cached) for
  the cardinal weights ``w(delta)`` of the disc of 441 pixels as functions of
  the subpixel offset ``delta`` in [-1/2, 1/2]^2. ``w`` is analytic in
  ``delta``; it is stored as tensor Chebyshev series of degree 5 on 4 x 4
  sub-cells of the pixel (36 coefficient stencils per sub-cell; the series
  reproduce the weights to 3e-7 (value) and 7e-5 (d/du, d/dv) in l1 norm, and
  reproduce linear fields exactly). Evaluating a field costs one gather of the
  25 x 25 pixels around the point and one (625 x 36) matrix product per point,
  in float32 relative to the central pixel (rounding ~1e-6 K), in BLAS; value,
  ``d/du`` and ``d/dv`` follow from the same 36 coefficients.
* *Near the mask edge*: overlapping tiles, a core of ``tile`` x ``tile`` pixels
  plus every masked pixel within ``halo`` of the core (~600 px). One Cholesky
  factorisation per tile (IMQ is positive definite; the monomials enter through
  a 3 x 3 Schur complement) serves every field and time while the mask is
  unchanged; points are evaluated directly from the tile's RBF coefficients.
  Factorisations are cached by the tile's local mask pattern, so a moving edge
  refactorises only the tiles whose pattern changed (~5 ms each).

*Accuracy* against :func:`exact_global_interpolant` (tests, benchmark), fields
of tens of K with 0.05 K noise: ~3e-5 K and ~6e-5 K/px from ``halo`` px off the
edge on; ~1e-3 K at 5-12 px, ~1e-2 K at 2-5 px, ~3e-2 K at 0.5-2 px and up to
~0.2 K in the outer half pixel (extrapolation). The near-edge differences do
not shrink with a larger halo (24 px: -15 %): there the global interpolant
depends on distant data through the RBF boundary error of a flat kernel with
linear monomials, and against the analytic truth both are off by similar
amounts (on the test fields the local one was 8 x better on one and 1.5 x
worse on another). Every point carries its distance to the mask edge.

*Alternatives weighed* (2-core VM, 47k masked px, 10k points, per time):
tiles everywhere with direct kernel evaluation cost ~10 ns per (point, tile
pixel), ~60 ms per time against ~25 ms for the interior stencils; a global
CG solve with an FFT (BTTB) product needs ~100-1000 FFTs of a padded 512^2
grid per field (condition 1e5-1e6) and then still a 50k-centre sum at every
point, whose 1/r tail defeats truncation; per-point local solves cost a
(441 + 3)^2 product per point. The stencils plus edge tiles win by > 5 x.

*Cost* (``benchmarks/bench_rbf.py``, 2-core VM shared with other jobs, one
BLAS thread): 500 frames, 10,000 points, 47k masked px in a 1024 x 768 frame:
38 s wall (32 s CPU) for Theta, d/du, d/dv, d/dt at all (time, point) pairs,
1.2 GB beyond the frames (0.7 GB of it tile factors); ~2.5 s of it is the
per-mask setup (~250 edge tiles), the rest ~60 ms per time, linear in frames
and about linear in points. scipy's ``RBFInterpolator(neighbors=50)`` per
frame with difference-quotient derivatives: ~1900 s, 50 x slower, and 200 x
farther (7e-3 K) from the global interpolant in the interior.
BLAS threads: every stage limits BLAS to the threads it was given
(:mod:`irdic.threads`); the ~600 x 600 Cholesky factorisations gain nothing
from more than one.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from collections import OrderedDict
from functools import lru_cache
from typing import NamedTuple

import numpy as np
import scipy.linalg
from numpy.lib.stride_tricks import sliding_window_view
from scipy import ndimage
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from ._checks import float_array as _float_array
from ._checks import increasing_times as _increasing_times
from ._checks import positive as _positive
from .errors import ConfigError, DataError, IrdicWarning
from .logs import Progress

__all__ = [
    "METHODS",
    "imq",
    "imq_dr",
    "TemporalInterpolant",
    "MaskedGridInterpolant",
    "MaskedGridRBF",
    "Evaluation",
    "SeriesEvaluation",
    "exact_global_interpolant",
    "evaluate_series",
]

log = logging.getLogger(__name__)

METHODS = ("rbf", "bilinear", "cubic")

# Interior stencils: tensor Chebyshev degree and sub-cells per pixel side.
# Degree 5 on 4 x 4 sub-cells represents the cardinal weights to 3e-7 (value)
# and 7e-5 (d/du, d/dv) in l1 norm at 36 coefficients; degree 8 on the whole
# cell needs 81 for the same accuracy.
_CHEB_DEGREE = 5
_CHEB_SUB = 4
# Points per block in the interior path: the float32 patches (block x 625)
# stay in the CPU cache.
_INTERIOR_BLOCK = 512
# Rows per block in the direct (edge tile) evaluation: keeps the temporaries in
# the CPU cache.
_EDGE_BLOCK = 128
# Background margin (px) around the mask. rbf: the interior stencils gather a
# (2 halo + 1)^2 box (disc weights, zero in the corners), which must stay in
# the grid; cubic: B-spline prefiltering is a recursive filter with pole
# -0.268, 0.268^12 < 2e-7.
_MARGIN = {"bilinear": 2, "cubic": 12}
# Edge distances (px) below this are exact; beyond, to ~0.03 px.
_EDGE_EXACT = 16.0
# Frame times closer than this (in units of R0) to an evaluation time are
# taken as equal: the cardinal weights are then the identity row.
_TIME_SNAP = 1e-9


# --------------------------------------------------------------------------
# kernel
# --------------------------------------------------------------------------


def imq(r, c=2.0):
    """Inverse multiquadric ``m(r) = c / sqrt(c^2 + r^2)``.

    Parameters
    ----------
    r : array_like
        Normalised distance ``distance / R0`` (dimensionless; may be signed).
    c : float
        Shape parameter (dimensionless), c > 0.

    Returns
    -------
    ndarray
        ``m(r)``, same shape as ``r``; ``m(0) = 1``.
    """
    r = np.asarray(r, dtype=float)
    return c / np.sqrt(c * c + r * r)


def imq_dr(r, c=2.0):
    """Derivative ``dm/dr = -c r / (c^2 + r^2)^(3/2)`` of :func:`imq`.

    With a signed ``r = (t - t_j) / R0`` this is ``R0 * dm/dt``.

    Parameters
    ----------
    r : array_like
        Normalised (signed) distance.
    c : float
        Shape parameter, c > 0.

    Returns
    -------
    ndarray
        Same shape as ``r``.
    """
    r = np.asarray(r, dtype=float)
    q = c * c + r * r
    return -c * r / (q * np.sqrt(q))


# --------------------------------------------------------------------------
# argument checks
# --------------------------------------------------------------------------


def _integer(name, value, lo):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{name} must be an integer >= {lo}, got {value!r}")
    if value < lo:
        raise ConfigError(f"{name} must be an integer >= {lo}, got {value}")
    return int(value)


def _method(value):
    if value not in METHODS:
        raise ConfigError(f"method must be one of {', '.join(map(repr, METHODS))}, got {value!r}")
    return value


def _check_mask(mask, name="mask"):
    try:
        m = np.asarray(mask)
    except Exception as exc:  # pragma: no cover - exotic array-likes
        raise ConfigError(f"{name} must be a 2-D boolean array: {exc}") from None
    if m.ndim != 2:
        raise ConfigError(f"{name} must be a 2-D boolean array (rows, columns), got shape {m.shape}")
    if m.dtype != bool:
        if m.dtype.kind not in "biuf" or not np.isin(m, (0, 1)).all():
            raise ConfigError(
                f"{name} must be boolean (or 0/1), got dtype {m.dtype} with other values"
            )
        m = m.astype(bool)
    return m


def _check_unisolvent(u, v, what):
    """Raise DataError unless the pixels admit the monomials {1, u, v}."""
    n = len(u)
    if n >= 3:
        P = np.c_[np.ones(n), u - u.mean(), v - v.mean()]
        sv = np.linalg.svd(P, compute_uv=False)
        if sv[-1] > 1e-8 * sv[0]:
            return
    raise DataError(
        f"{what}: {n} pixel(s){' on one line' if n >= 3 else ''}; the linear "
        "monomials {1, u, v} need at least 3 pixels not on one line"
    )


# --------------------------------------------------------------------------
# saddle-point systems
# --------------------------------------------------------------------------


class _SaddleFactor:
    """Factorised ``[[A, P], [P^T, 0]]`` with A symmetric positive definite.

    Cholesky of A (the IMQ kernel matrix is positive definite) and the small
    Schur complement ``S = P^T A^-1 P``; ``P`` must have full column rank.
    """

    def __init__(self, A, P):
        self.cho = scipy.linalg.cho_factor(A, lower=True, overwrite_a=True, check_finite=False)
        self.P = P
        self.Y = scipy.linalg.cho_solve(self.cho, P, check_finite=False)
        self.S_inv = np.linalg.inv(P.T @ self.Y)
        self.nbytes = A.nbytes + P.nbytes + self.Y.nbytes

    def solve(self, F, Q=None):
        """Solve ``A x + P y = F, P^T x = Q`` (Q = 0 when None); F (n, k)."""
        X = scipy.linalg.cho_solve(self.cho, F, check_finite=False)
        rhs = self.P.T @ X
        if Q is not None:
            rhs -= Q
        y = self.S_inv @ rhs
        X -= self.Y @ y
        return X, y


def _imq_matrix(xa, xb, ce):
    """``ce / sqrt(ce^2 + |xa_i - xb_j|^2)`` for 2-D points (n, 2), (m, 2)."""
    m = cdist(xa, xb, "sqeuclidean")
    m += ce * ce
    np.sqrt(m, out=m)
    np.divide(ce, m, out=m)
    return m


# --------------------------------------------------------------------------
# time
# --------------------------------------------------------------------------


class TemporalInterpolant:
    """IMQ interpolation in time over the frame times, with monomials {1, t}.

    Parameters
    ----------
    times : array_like, shape (n_frames,)
        Frame times in s, strictly increasing (irregular spacing, e.g. dropped
        frames, is fine); at least 2.
    c : float
        Shape parameter of the temporal IMQ (the paper: 1).
    R0 : float
        Distance normalisation in s (the paper: 1 s).

    Notes
    -----
    The (n+2) saddle-point system is factorised once (Cholesky of the kernel
    matrix plus a 2 x 2 Schur complement); fine up to a few thousand frames.
    Evaluation times outside ``[times[0], times[-1]]`` give NaN weights: the
    interpolant is not meant to extrapolate. Use :meth:`in_span` to tell which.
    """

    def __init__(self, times, *, c=1.0, R0=1.0):
        self.c = _positive("c", c)
        self.R0 = _positive("R0", R0)
        t = _increasing_times("times", times, "n_frames")
        if t.size < 2:
            raise DataError(
                f"times: {t.size} frame time(s); the temporal interpolant with monomials "
                "{1, t} needs at least 2 frames"
            )
        self.times = t
        self._t_mid = 0.5 * (t[0] + t[-1])
        self._s = (t - self._t_mid) / self.R0
        A = imq(self._s[:, None] - self._s[None, :], self.c)
        P = np.c_[np.ones(t.size), self._s]
        self._fac = _SaddleFactor(A, P)

    @property
    def n_frames(self):
        """Number of frame times."""
        return self.times.size

    @property
    def span(self):
        """``(first, last)`` frame time in s."""
        return float(self.times[0]), float(self.times[-1])

    def in_span(self, t_eval):
        """Boolean array: which evaluation times lie within the frame span.

        Parameters
        ----------
        t_eval : array_like
            Evaluation times in s, any shape.

        Returns
        -------
        ndarray of bool
            Same shape as ``t_eval``; False for NaN.
        """
        te = _float_array("t_eval", t_eval)
        tol = _TIME_SNAP * self.R0
        with np.errstate(invalid="ignore"):
            return (te >= self.times[0] - tol) & (te <= self.times[-1] + tol)

    def weights(self, t_eval, derivative=0):
        """Cardinal weights: ``f(t) = weights(t) @ f(times)``.

        Parameters
        ----------
        t_eval : array_like, shape (n_eval,) or scalar
            Evaluation times in s, any order.
        derivative : {0, 1}
            0 for the interpolant, 1 for its time derivative (weights in 1/s).

        Returns
        -------
        ndarray, shape (n_eval, n_frames)
            Rows for times outside the frame span (or NaN) are NaN. For
            ``derivative=0`` the row of a frame time is the identity row.
        """
        if derivative not in (0, 1) or isinstance(derivative, bool):
            raise ConfigError(f"derivative must be 0 or 1, got {derivative!r}")
        te = np.atleast_1d(_float_array("t_eval", t_eval))
        if te.ndim != 1:
            raise ConfigError(f"t_eval must be a scalar or 1-D, got shape {te.shape}")
        ok = self.in_span(te)
        W = np.full((te.size, self.n_frames), np.nan)
        if not ok.any():
            return W
        s = (te[ok] - self._t_mid) / self.R0
        d = s[:, None] - self._s[None, :]
        if derivative == 0:
            B = imq(d, self.c)
            Q = np.stack([np.ones_like(s), s])
        else:
            B = imq_dr(d, self.c) / self.R0
            Q = np.stack([np.zeros_like(s), np.full_like(s, 1.0 / self.R0)])
        X, _ = self._fac.solve(B.T, Q)
        Wok = X.T
        if derivative == 0:
            # Exactly the frame at a frame time (the solve leaves ~1e-13).
            j = np.clip(np.searchsorted(self.times, te[ok]), 0, self.n_frames - 1)
            jm = np.clip(j - 1, 0, self.n_frames - 1)
            for jj in (j, jm):
                hit = np.abs(self.times[jj] - te[ok]) <= _TIME_SNAP * self.R0
                if hit.any():
                    Wok[hit] = 0.0
                    Wok[np.flatnonzero(hit), jj[hit]] = 1.0
        W[ok] = Wok
        return W

    def __call__(self, values, t_eval, derivative=0):
        """Interpolate ``values`` (n_frames, ...) at ``t_eval`` (n_eval,).

        Returns
        -------
        ndarray, shape (n_eval, ...)
            NaN outside the frame span.
        """
        f = _float_array("values", values)
        if f.ndim < 1 or f.shape[0] != self.n_frames:
            raise ConfigError(
                f"values must have n_frames = {self.n_frames} rows, got shape {f.shape}"
            )
        W = self.weights(t_eval, derivative)
        return np.tensordot(W, f, axes=(1, 0))


# --------------------------------------------------------------------------
# space: interior stencils
# --------------------------------------------------------------------------


class _Stencil(NamedTuple):
    halo: int
    ce: float
    degree: int
    sub: int
    W32: np.ndarray  # (sub*sub, (2 halo + 1)^2, Q) float32, zero outside the disc


def _chebyshev(x, degree):
    """``T_k(x)`` and ``T_k'(x)`` for k = 0..degree; x (n,) -> two (n, degree+1)."""
    T = np.empty((x.size, degree + 1))
    D = np.empty((x.size, degree + 1))
    T[:, 0] = 1.0
    D[:, 0] = 0.0
    if degree >= 1:
        T[:, 1] = x
        D[:, 1] = 1.0
    for k in range(1, degree):
        T[:, k + 1] = 2 * x * T[:, k] - T[:, k - 1]
        D[:, k + 1] = 2 * T[:, k] + 2 * x * D[:, k] - D[:, k - 1]
    return T, D


@lru_cache(maxsize=8)
def _interior_stencil(ce, halo, degree=_CHEB_DEGREE, sub=_CHEB_SUB):
    """Cardinal weights of the fully masked disc as Chebyshev series in the offset.

    For a point ``p + delta`` (p a pixel, delta in [-1/2, 1/2]^2) the local
    interpolant over the pixels ``p + k``, ``|k| <= halo``, is
    ``sum_k w_k(delta) f_(p+k)``. On each of ``sub x sub`` sub-cells,
    ``w_k(delta) = sum_ab C[ab, k] T_a(xi) T_b(eta)`` with (xi, eta) the
    sub-cell coordinates in [-1, 1]^2 (tensor Chebyshev interpolation at
    Chebyshev points of the first kind).
    """
    k = np.arange(-halo, halo + 1)
    KV, KU = np.meshgrid(k, k, indexing="ij")
    keep = KU**2 + KV**2 <= halo**2
    off_u, off_v = KU[keep], KV[keep]
    n = off_u.size
    cen = np.c_[off_u, off_v].astype(float)
    fac = _SaddleFactor(_imq_matrix(cen, cen, ce), np.c_[np.ones(n), cen])

    nodes = np.cos(np.pi * (np.arange(degree + 1) + 0.5) / (degree + 1))
    Vinv = np.linalg.inv(_chebyshev(nodes, degree)[0])  # V[i, a] = T_a(node_i)
    h = 0.5 / sub
    NU, NV = np.meshgrid(nodes, nodes, indexing="ij")
    Q = (degree + 1) ** 2
    W = np.empty((sub * sub, n, Q))
    for iu in range(sub):
        for iv in range(sub):
            du = -0.5 + h * (2 * iu + 1) + h * NU.ravel()
            dv = -0.5 + h * (2 * iv + 1) + h * NV.ravel()
            X = np.c_[du, dv]
            B = _imq_matrix(cen, X, ce)
            w, _ = fac.solve(B, np.stack([np.ones_like(du), du, dv]))
            w = w.reshape(n, degree + 1, degree + 1)
            C = np.einsum("ai,bj,kij->kab", Vinv, Vinv, w)
            W[iu * sub + iv] = C.reshape(n, Q)
    # Embedded in the (2 halo + 1)^2 box (row-major: v outer, u inner): one
    # strided gather per point is faster than 2 halo + 1 row gathers.
    box = np.zeros((sub * sub, (2 * halo + 1) ** 2, Q), np.float32)
    box[:, np.flatnonzero(keep.ravel())] = W
    return _Stencil(halo, ce, degree, sub, box)


# --------------------------------------------------------------------------
# space: edge tiles
# --------------------------------------------------------------------------


class _Tile(NamedTuple):
    pv: np.ndarray  # frame rows of the tile pixels (n_t,)
    pu: np.ndarray  # frame columns
    ov: float  # origin of the local coordinates (core centre), frame px
    ou: float
    cu: np.ndarray  # local coordinates of the centres
    cv: np.ndarray
    fac: _SaddleFactor


class _TileCache:
    """Factorised edge tiles, keyed by position and local mask pattern (LRU by bytes)."""

    def __init__(self, max_bytes=1 << 30):
        self.max_bytes = max_bytes
        self._d = OrderedDict()
        self._bytes = 0
        self.built = 0

    def get(self, key):
        tile = self._d.get(key)
        if tile is not None:
            self._d.move_to_end(key)
        return tile

    def put(self, key, tile):
        self._d[key] = tile
        self._bytes += tile.fac.nbytes
        self.built += 1
        while self._bytes > self.max_bytes and len(self._d) > 1:
            _, old = self._d.popitem(last=False)
            self._bytes -= old.fac.nbytes


# --------------------------------------------------------------------------
# space: the interpolant
# --------------------------------------------------------------------------


class Evaluation(NamedTuple):
    """Result of :meth:`MaskedGridInterpolant.evaluate`.

    ``value`` in the unit of the fields (°C for temperatures), ``du`` and ``dv``
    in that unit per px (None when derivatives were not requested), shapes
    (n_fields, M) or (M,) for a single field; ``edge_distance`` in px, (M,) or
    (n_fields, M) for per-field points: distance from the point to the nearest
    pixel centre outside the mask minus 1/2 (so 0 on the pixel boundary of the
    masked region, 0.5 at the centre of an edge pixel); negative outside the
    mask (where value, du, dv are NaN); NaN for NaN points.
    """

    value: np.ndarray
    du: np.ndarray | None
    dv: np.ndarray | None
    edge_distance: np.ndarray


class MaskedGridInterpolant:
    """Interpolate fields given on the masked pixels of a regular pixel grid.

    Parameters
    ----------
    mask : array_like of bool, shape (H, W)
        Pixels that carry data (the specimen). Only these feed the
        interpolant: the specimen edge is a temperature discontinuity and
        background pixels would make the interpolant ring.
    method : {"rbf", "bilinear", "cubic"}
        ``"rbf"``: the paper's global IMQ interpolant with monomials
        {1, u, v} over all masked pixels, evaluated with local stencils (see the
        module Notes; ~1e-5 K from the exact one in the interior). ``"bilinear"``
        and ``"cubic"``: ``scipy.ndimage`` splines of order 1 and 3 for
        comparison; background pixels are first filled with the value of the
        nearest masked pixel so that they do not enter either.
    c : float
        IMQ shape parameter (dimensionless; the paper: 2).
    R0 : float
        Distance normalisation in px (the paper: 1). Only ``c * R0`` matters.
    halo : int
        Radius in px of the neighbourhood that determines the value at a
        point (>= 12 keeps the distance to the global interpolant ~1e-5 of the
        local data variation; 8 gives ~1e-4).
    tile : int
        Core size in px of the tiles used near the mask edge.

    Attributes
    ----------
    mask : ndarray of bool, shape (H, W)
    shape : tuple
        (H, W).
    n_mask : int
        Number of masked pixels.
    pixels : ndarray of int, shape (n_mask, 2)
        (u, v) of the masked pixels, in the order of ``np.nonzero(mask)``
        (the order of fields given as (n_mask,) vectors).

    Notes
    -----
    Typical use: ``MaskedGridInterpolant(mask).fit(fields).evaluate(points)``.
    The object depends on the mask only; :meth:`fit` may be called again with
    new fields (all setup, including edge factorisations, is reused). Setup
    costs ~2-3 s for a 47k-pixel ellipse (edge tiles factorised on first use).
    """

    def __init__(self, mask, *, method="rbf", c=2.0, R0=1.0, halo=12, tile=8, _tile_cache=None):
        self.method = _method(method)
        self.c = _positive("c", c)
        self.R0 = _positive("R0", R0)
        self.halo = _integer("halo", halo, 1)
        self.tile = _integer("tile", tile, 1)
        self._ce = self.c * self.R0
        m = _check_mask(mask)
        self.mask = m.copy()
        self.shape = m.shape
        vv, uu = np.nonzero(m)
        self.n_mask = vv.size
        _check_unisolvent(uu.astype(float), vv.astype(float), "mask")
        self.pixels = np.c_[uu, vv]

        margin = self.halo if self.method == "rbf" else _MARGIN[self.method]
        self._rv0 = int(vv.min()) - margin
        self._ru0 = int(uu.min()) - margin
        self._Hr = int(vv.max()) - self._rv0 + 1 + margin
        self._Wr = int(uu.max()) - self._ru0 + 1 + margin
        mr = np.zeros((self._Hr, self._Wr), bool)
        mr[vv - self._rv0, uu - self._ru0] = True
        self._mask_r = mr
        self._vr = vv - self._rv0
        self._ur = uu - self._ru0

        # Edge distance: nearest pixel centre on the other side of the edge;
        # that one is always 4-adjacent to the edge, so trees of the boundary
        # pixels give it exactly. A tree query for every point and time costs
        # ~2 us, so inside the mask the nearest background pixels of the
        # point's pixel and its 8 neighbours (feature transform) give an upper
        # bound first (exact to ~0.03 px), and the tree is asked only within
        # _EDGE_EXACT px of the edge.
        pad = np.pad(mr, 1)
        self._feat_bg = ndimage.distance_transform_edt(
            pad, return_distances=False, return_indices=True
        ).astype(np.int32)
        cross = ndimage.generate_binary_structure(2, 1)
        bv, bu = np.nonzero(~pad & ndimage.binary_dilation(pad, cross))
        fv, fu = np.nonzero(pad & ~ndimage.binary_erosion(pad, cross, border_value=0))
        off = np.array([self._ru0 - 1, self._rv0 - 1])
        self._tree_bg = cKDTree((np.c_[bu, bv] + off).astype(float))
        self._tree_fg = cKDTree((np.c_[fu, fv] + off).astype(float))

        if self.method == "rbf":
            self._stencil = _interior_stencil(self._ce, self.halo)
            dist = ndimage.distance_transform_edt(pad)[1:-1, 1:-1]
            # Interior: the whole disc of radius halo is masked (edt is exact
            # for integer squared distances, so the comparison is exact).
            self._interior = mr & (dist > self.halo)
            self._tiles = _tile_cache if _tile_cache is not None else _TileCache()
            log.debug(
                "MaskedGridInterpolant: %d masked px, %d interior (halo %d px)",
                self.n_mask, int(self._interior.sum()), self.halo,
            )
        else:
            idx = ndimage.distance_transform_edt(~mr, return_distances=False, return_indices=True)
            self._fill = (idx[0], idx[1])
        self._nf = None
        self._single = False

    # -- data ---------------------------------------------------------------

    def _field_values(self, fields, name="fields"):
        """(n_fields, n_mask) float64 values at the masked pixels, and single flag."""
        f = _float_array(name, fields)
        if f.ndim >= 2 and f.shape[-2:] == self.shape:
            lead = f.shape[:-2]
            vals = f[..., self.pixels[:, 1], self.pixels[:, 0]]
        elif f.ndim >= 1 and f.shape[-1] == self.n_mask:
            lead = f.shape[:-1]
            vals = f
        else:
            raise ConfigError(
                f"{name} must have shape (n_mask,) = ({self.n_mask},), (H, W) = {self.shape}, "
                f"or one of these with a leading n_fields axis; got {f.shape}"
            )
        if len(lead) > 1:
            raise ConfigError(f"{name} may have at most one leading (n_fields) axis, got shape {f.shape}")
        single = len(lead) == 0
        vals = np.atleast_2d(vals)
        bad = ~np.isfinite(vals)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise DataError(
                f"{name}: field {i} has {int(bad[i].sum())} non-finite value(s) inside the mask, "
                f"first at pixel (u={self.pixels[j, 0]}, v={self.pixels[j, 1]}); every masked "
                "pixel must carry a finite value (remove such pixels from the mask)"
            )
        return vals, single

    def fit(self, fields):
        """Set the data.

        Parameters
        ----------
        fields : array_like
            Values at the masked pixels, shape (n_mask,) (in the order of
            :attr:`pixels`, i.e. ``np.nonzero(mask)``) or (H, W), or either with
            a leading ``n_fields`` axis. Values outside the mask are ignored.

        Returns
        -------
        self
        """
        vals, single = self._field_values(fields)
        self._single = single
        self._fit_values(vals)
        return self

    def _fit_values(self, vals):
        nf = vals.shape[0]
        grid = np.zeros((nf, self._Hr, self._Wr))
        grid[:, self._vr, self._ur] = vals
        self._nf = nf
        self._alpha = {}
        if self.method == "rbf":
            self._grid = grid
            # float32 copy around a per-field offset, for the gathers of the
            # interior path (the central value is added back in float64).
            self._offset = vals.mean(axis=1)
            g32 = (grid - self._offset[:, None, None]).astype(np.float32)
            self._grid32 = g32
            D = 2 * self.halo + 1
            self._box = sliding_window_view(g32, (D, D), axis=(1, 2))
        else:
            filled = grid[:, self._fill[0], self._fill[1]]
            if self.method == "cubic":
                filled = ndimage.spline_filter1d(filled, 3, axis=1, mode="mirror")
                filled = ndimage.spline_filter1d(filled, 3, axis=2, mode="mirror")
            self._grid = filled

    # -- points ---------------------------------------------------------------

    def _check_points(self, points):
        p = _float_array("points", points)
        if p.ndim not in (2, 3) or p.shape[-1] != 2:
            raise ConfigError(
                f"points must have shape (M, 2) or (n_fields, M, 2) with columns (u, v), got {p.shape}"
            )
        if p.ndim == 3 and p.shape[0] != self._nf:
            raise ConfigError(
                f"points with shape (n_fields, M, 2) need n_fields = {self._nf} (the fitted fields), "
                f"got {p.shape[0]}"
            )
        return p

    def edge_distance(self, points):
        """Distance (px) of points to the mask edge; see :class:`Evaluation`.

        Parameters
        ----------
        points : array_like, shape (..., 2)
            (u, v) in px.

        Returns
        -------
        ndarray, shape (...)
        """
        p = _float_array("points", points)
        if p.shape[-1:] != (2,):
            raise ConfigError(f"points must have shape (..., 2) with columns (u, v), got {p.shape}")
        flat = p.reshape(-1, 2)
        loc = self._locate(flat[:, 0], flat[:, 1])
        return self._edge(flat[:, 0], flat[:, 1], loc).reshape(p.shape[:-1])

    def _locate(self, u, v):
        finite = np.isfinite(u) & np.isfinite(v)
        pu = np.zeros(u.shape, np.int64)
        pv = np.zeros(u.shape, np.int64)
        with np.errstate(invalid="ignore"):
            big = finite & (np.abs(u) < 1e9) & (np.abs(v) < 1e9)
        pu[big] = np.rint(u[big]).astype(np.int64) - self._ru0
        pv[big] = np.rint(v[big]).astype(np.int64) - self._rv0
        inside = big & (pu >= 0) & (pu < self._Wr) & (pv >= 0) & (pv < self._Hr)
        inside[inside] = self._mask_r[pv[inside], pu[inside]]
        return finite, inside, pu, pv

    def _edge(self, u, v, loc):
        finite, inside, pu, pv = loc
        out = np.full(u.shape, np.nan)
        if inside.any():
            # padded-grid coordinates of the point's pixel (inside pixels are
            # >= 1 px from the padded border, so the neighbours exist)
            i = np.flatnonzero(inside)
            qv = v[i] - (self._rv0 - 1)
            qu = u[i] - (self._ru0 - 1)
            hv = pv[i] + 1
            hu = pu[i] + 1
            best = np.full(i.size, np.inf)
            fb_v, fb_u = self._feat_bg
            for ov in (-1, 0, 1):
                for ou in (-1, 0, 1):
                    cv = fb_v[hv + ov, hu + ou]
                    cu = fb_u[hv + ov, hu + ou]
                    np.minimum(best, (cv - qv) ** 2 + (cu - qu) ** 2, out=best)
            best = np.sqrt(best)
            near = best < _EDGE_EXACT
            if near.any():
                q = np.c_[u[i[near]], v[i[near]]]
                d = self._tree_bg.query(q, distance_upper_bound=float(best[near].max()) + 1e-6)[0]
                best[near] = np.minimum(best[near], d)
            out[i] = best - 0.5
        outside = finite & ~inside
        if outside.any():
            out[outside] = 0.5 - self._tree_fg.query(np.c_[u[outside], v[outside]])[0]
        return out

    # -- evaluation -------------------------------------------------------------

    def evaluate(self, points, derivatives=True):
        """Evaluate the fitted fields (and d/du, d/dv) at subpixel points.

        Parameters
        ----------
        points : array_like, shape (M, 2) or (n_fields, M, 2)
            (u, v) in px. (M, 2): the same points for every field;
            (n_fields, M, 2): one set of points per field. NaN points give NaN.
        derivatives : bool
            Also return ``d/du`` and ``d/dv`` (per px).

        Returns
        -------
        Evaluation
            value, du, dv with shape (n_fields, M) ((M,) when a single field
            without leading axis was fitted and the points are (M, 2)), NaN
            outside the mask; edge_distance (M,) or (n_fields, M).
        """
        if self._nf is None:
            raise ConfigError("call fit(fields) before evaluate(points)")
        if not isinstance(derivatives, (bool, np.bool_)):
            raise ConfigError(f"derivatives must be True or False, got {derivatives!r}")
        p = self._check_points(points)
        if p.ndim == 2:
            groups, g = 1, self._nf
        else:
            groups, g = self._nf, 1
        M = p.shape[-2]
        val, du, dv, edge = self._evaluate_grouped(
            p.reshape(groups, M, 2), g, (bool(derivatives),) * g
        )
        val = val.reshape(self._nf, M)
        if derivatives:
            du = du.reshape(self._nf, M)
            dv = dv.reshape(self._nf, M)
        else:
            du = dv = None
        edge = edge.reshape(M) if groups == 1 else edge.reshape(groups, M)
        if self._single and p.ndim == 2:
            val = val[0]
            if derivatives:
                du, dv = du[0], dv[0]
        return Evaluation(val, du, dv, edge)

    def _evaluate_grouped(self, pts, g, derivs):
        """Fields ``group * g + slot`` at ``pts[group]``; returns (G, g, M) x 3 and (G, M)."""
        G, M, _ = pts.shape
        flat = pts.reshape(-1, 2)
        u, v = flat[:, 0], flat[:, 1]
        loc = self._locate(u, v)
        edge = self._edge(u, v, loc).reshape(G, M)
        shape = (G * M, g)
        val = np.full(shape, np.nan)
        want = any(derivs)
        du = np.full(shape, np.nan)
        dv = np.full(shape, np.nan)
        _, inside, pu, pv = loc
        idx = np.flatnonzero(inside)
        if idx.size:
            grp = idx // M
            if self.method == "rbf":
                inner = self._interior[pv[idx], pu[idx]]
                self._eval_interior(idx[inner], grp[inner], u, v, pu, pv, g, derivs, val, du, dv)
                self._eval_edge(idx[~inner], grp[~inner], G, u, v, pu, pv, g, derivs, val, du, dv)
            elif self.method == "bilinear":
                self._eval_bilinear(idx, grp, u, v, g, val, du, dv)
            else:
                self._eval_cubic(idx, grp, u, v, g, val, du, dv)
        val = val.reshape(G, M, g).transpose(0, 2, 1)
        du = du.reshape(G, M, g).transpose(0, 2, 1)
        dv = dv.reshape(G, M, g).transpose(0, 2, 1)
        if not want:
            du = dv = None
        return val, du, dv, edge

    def _eval_interior(self, idx, grp, u, v, pu, pv, g, derivs, val, du, dv):
        if idx.size == 0:
            return
        st = self._stencil
        S, d, R = st.sub, st.degree, st.halo
        D = 2 * R + 1
        centre = R * D + R
        fu = (u[idx] - (pu[idx] + self._ru0) + 0.5) * S
        fv = (v[idx] - (pv[idx] + self._rv0) + 0.5) * S
        iu = np.clip(np.floor(fu).astype(np.int64), 0, S - 1)
        iv = np.clip(np.floor(fv).astype(np.int64), 0, S - 1)
        cell = iu * S + iv
        # Group by field set, then by sub-cell: each block gathers from one
        # 2-D grid (cache friendly) and uses one stencil.
        order = np.lexsort((cell, grp))
        idx, grp, cell = idx[order], grp[order], cell[order]
        ru, rv = pu[idx], pv[idx]
        Tu, Du = _chebyshev(2 * (fu[order] - iu[order]) - 1, d)
        Tv, Dv = _chebyshev(2 * (fv[order] - iv[order]) - 1, d)
        Du *= 2 * S  # d xi / d u
        Dv *= 2 * S
        key = grp * (S * S) + cell
        cuts = np.flatnonzero(np.r_[True, key[1:] != key[:-1], True])
        for a, b in zip(cuts[:-1], cuts[1:]):
            W = st.W32[cell[a]]
            for b0 in range(a, b, _INTERIOR_BLOCK):
                b1 = min(b0 + _INTERIOR_BLOCK, b)
                r_v, r_u = rv[b0:b1], ru[b0:b1]
                sel = idx[b0:b1]
                tu, tv = Tu[b0:b1], Tv[b0:b1]
                for f in range(g):
                    row = int(grp[a]) * g + f
                    P = self._box[row][r_v - R, r_u - R].reshape(b1 - b0, D * D)
                    # float32 differences to the central pixel: ~1e-6 K rounding
                    P -= P[:, centre:centre + 1]
                    Z = (P @ W).astype(float).reshape(b1 - b0, d + 1, d + 1)
                    Z[:, 0, 0] += self._grid[row, r_v, r_u]
                    ZTv = np.einsum("nab,nb->na", Z, tv)
                    val[sel, f] = np.einsum("na,na->n", ZTv, tu)
                    if derivs[f]:
                        du[sel, f] = np.einsum("na,na->n", ZTv, Du[b0:b1])
                        dv[sel, f] = np.einsum("nab,na,nb->n", Z, tu, Dv[b0:b1])

    def _get_tile(self, ty, tx):
        C, R = self.tile, self.halo
        H, W = self.shape
        v0, u0 = ty * C, tx * C
        v1, u1 = v0 + C - 1, u0 + C - 1
        a, b = max(v0 - R, 0), min(v1 + R, H - 1)
        l, r = max(u0 - R, 0), min(u1 + R, W - 1)
        # only the masked pixels within R of the core enter: the key is their
        # pattern, so a change in the corners of the crop does not refactorise
        gv = np.arange(a, b + 1)[:, None]
        gu = np.arange(l, r + 1)[None, :]
        dx = np.maximum(np.maximum(u0 - gu, gu - u1), 0)
        dy = np.maximum(np.maximum(v0 - gv, gv - v1), 0)
        crop = self.mask[a:b + 1, l:r + 1] & (dx * dx + dy * dy <= R * R)
        key = (ty, tx, C, R, self._ce, (a, b, l, r), np.packbits(crop).tobytes())
        tile = self._tiles.get(key)
        if tile is not None:
            return tile
        cv, cu = np.nonzero(crop)
        cv = cv + a
        cu = cu + l
        ou, ov = u0 + 0.5 * (C - 1), v0 + 0.5 * (C - 1)
        lu, lv = cu - ou, cv - ov
        _check_unisolvent(
            lu, lv, f"mask: the masked pixels within halo = {R} px of pixels u = {u0}..{u1}, v = {v0}..{v1}"
        )
        cen = np.c_[lu, lv]
        fac = _SaddleFactor(_imq_matrix(cen, cen, self._ce), np.c_[np.ones(lu.size), lu, lv])
        tile = _Tile(cv, cu, ov, ou, lu, lv, fac)
        self._tiles.put(key, tile)
        return tile

    def _tile_alpha(self, key):
        """RBF and monomial coefficients of all fitted fields on a tile."""
        got = self._alpha.get(key)
        if got is None:
            tile = self._get_tile(*key)
            F = self._grid[:, tile.pv - self._rv0, tile.pu - self._ru0].T
            alpha, beta = tile.fac.solve(F)
            got = (tile, np.ascontiguousarray(alpha.T), beta.T)  # (nf, n_t), (nf, 3)
            self._alpha[key] = got
        return got

    def _eval_edge(self, idx, grp, G, u, v, pu, pv, g, derivs, val, du, dv):
        if idx.size == 0:
            return
        C = self.tile
        ty = (pv[idx] + self._rv0) // C
        tx = (pu[idx] + self._ru0) // C
        key = ty * (self.shape[1] // C + 1) + tx
        order = np.argsort(key, kind="stable")
        idx, grp, ty, tx, key = idx[order], grp[order], ty[order], tx[order], key[order]
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        ends = np.r_[starts[1:], key.size]
        ce = self._ce
        ce2 = ce * ce
        want = np.array(derivs, bool)
        for s0, s1 in zip(starts, ends):
            tile, alpha, beta = self._tile_alpha((int(ty[s0]), int(tx[s0])))
            for b0 in range(s0, s1, _EDGE_BLOCK):
                b1 = min(b0 + _EDGE_BLOCK, s1)
                sel = idx[b0:b1]
                xu = u[sel] - tile.ou
                xv = v[sel] - tile.ov
                du_ = xu[:, None] - tile.cu[None, :]
                dv_ = xv[:, None] - tile.cv[None, :]
                s = du_ * du_
                s += dv_ * dv_
                s += ce2
                np.sqrt(s, out=s)
                np.divide(1.0, s, out=s)
                if G == 1:
                    A = alpha.T  # (n_t, g)
                    B = beta  # (g, 3)
                    val[sel] = ce * (s @ A) + B[:, 0] + xu[:, None] * B[:, 1] + xv[:, None] * B[:, 2]
                    if want.any():
                        s3 = s * s
                        s3 *= s
                        T = s3 @ A
                        Tu = (s3 * tile.cu) @ A
                        Tv = (s3 * tile.cv) @ A
                        gu = -ce * (xu[:, None] * T - Tu) + B[:, 1]
                        gv = -ce * (xv[:, None] * T - Tv) + B[:, 2]
                        du[sel[:, None], np.flatnonzero(want)] = gu[:, want]
                        dv[sel[:, None], np.flatnonzero(want)] = gv[:, want]
                else:
                    gb = grp[b0:b1]
                    s3 = None
                    if want.any():
                        s3 = s * s
                        s3 *= s
                    for f in range(g):
                        rows = gb * g + f
                        a = alpha[rows]  # (blk, n_t)
                        B = beta[rows]  # (blk, 3)
                        val[sel, f] = ce * np.einsum("ij,ij->i", s, a) + B[:, 0] + xu * B[:, 1] + xv * B[:, 2]
                        if derivs[f]:
                            a *= s3
                            T = a.sum(axis=1)
                            du[sel, f] = -ce * (xu * T - a @ tile.cu) + B[:, 1]
                            dv[sel, f] = -ce * (xv * T - a @ tile.cv) + B[:, 2]

    def _eval_bilinear(self, idx, grp, u, v, g, val, du, dv):
        x = u[idx] - self._ru0
        y = v[idx] - self._rv0
        i = np.floor(x).astype(np.int64)
        j = np.floor(y).astype(np.int64)
        tx, ty = x - i, y - j
        for f in range(g):
            rows = grp * g + f
            gr = self._grid
            f00 = gr[rows, j, i]
            f01 = gr[rows, j, i + 1]
            f10 = gr[rows, j + 1, i]
            f11 = gr[rows, j + 1, i + 1]
            val[idx, f] = (1 - ty) * ((1 - tx) * f00 + tx * f01) + ty * ((1 - tx) * f10 + tx * f11)
            du[idx, f] = (1 - ty) * (f01 - f00) + ty * (f11 - f10)
            dv[idx, f] = (1 - tx) * (f10 - f00) + tx * (f11 - f01)

    def _eval_cubic(self, idx, grp, u, v, g, val, du, dv):
        x = u[idx] - self._ru0
        y = v[idx] - self._rv0
        i = np.floor(x).astype(np.int64)
        j = np.floor(y).astype(np.int64)
        wx, dwx = _bspline3(x - i)
        wy, dwy = _bspline3(y - j)
        for f in range(g):
            rows = grp * g + f
            # coefficient neighbourhood (n, 4, 4): rows j-1..j+2, columns i-1..i+2
            k = np.arange(-1, 3)
            cf = self._grid[rows[:, None, None], (j[:, None] + k)[:, :, None], (i[:, None] + k)[:, None, :]]
            cy = np.einsum("nab,nb->na", cf, wx)
            val[idx, f] = np.einsum("na,na->n", cy, wy)
            du[idx, f] = np.einsum("nab,na,nb->n", cf, wy, dwx)
            dv[idx, f] = np.einsum("na,na->n", cy, dwy)


MaskedGridRBF = MaskedGridInterpolant
"""Alias of :class:`MaskedGridInterpolant` (``method="rbf"`` is the default)."""


def _bspline3(t):
    """Cubic B-spline weights (n, 4) and their derivatives for offsets -1..2 of floor(x)."""
    t2 = t * t
    t3 = t2 * t
    w = np.stack([(1 - t) ** 3, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1, t3], axis=1) / 6
    d = np.stack([-((1 - t) ** 2), 3 * t2 - 4 * t, -3 * t2 + 2 * t + 1, t2], axis=1) / 2
    return w, d


# --------------------------------------------------------------------------
# exact reference
# --------------------------------------------------------------------------


def exact_global_interpolant(mask, fields, points, *, c=2.0, R0=1.0, max_pixels=12000):
    """The exact global IMQ interpolant over all masked pixels (dense solve).

    The reference for :class:`MaskedGridInterpolant` (``method="rbf"``); cost
    O(n_mask^3) time and O(n_mask^2) memory, so for small cases only.

    Parameters
    ----------
    mask : array_like of bool, shape (H, W)
    fields : array_like
        Shape (n_mask,) or (H, W), optionally with a leading n_fields axis.
    points : array_like, shape (M, 2)
        (u, v) in px.
    c, R0 : float
        Kernel shape parameter and distance normalisation (px).
    max_pixels : int
        Refuse larger masks (memory 8 n_mask^2 bytes).

    Returns
    -------
    Evaluation
        value, du, dv with shape (n_fields, M) or (M,); NaN for points outside
        the mask; edge_distance (M,).
    """
    interp = MaskedGridInterpolant(mask, method="bilinear", c=c, R0=R0)
    max_pixels = _integer("max_pixels", max_pixels, 3)
    if interp.n_mask > max_pixels:
        raise ConfigError(
            f"exact_global_interpolant: the mask has {interp.n_mask} pixels, more than "
            f"max_pixels = {max_pixels} (the dense system needs 8 n^2 bytes)"
        )
    vals, single = interp._field_values(fields)
    p = _float_array("points", points)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ConfigError(f"points must have shape (M, 2) with columns (u, v), got {p.shape}")
    ce = interp.c * interp.R0
    cen = interp.pixels.astype(float)
    origin = cen.mean(axis=0)
    cen = cen - origin
    fac = _SaddleFactor(_imq_matrix(cen, cen, ce), np.c_[np.ones(len(cen)), cen])
    alpha, beta = fac.solve(vals.T)  # (n, nf), (3, nf)
    loc = interp._locate(p[:, 0], p[:, 1])
    inside = loc[1]
    nf, M = vals.shape[0], p.shape[0]
    val = np.full((nf, M), np.nan)
    gu = np.full((nf, M), np.nan)
    gv = np.full((nf, M), np.nan)
    q = p[inside] - origin
    out = np.flatnonzero(inside)
    for b0 in range(0, q.shape[0], 256):
        qb = q[b0:b0 + 256]
        du_ = qb[:, None, 0] - cen[None, :, 0]
        dv_ = qb[:, None, 1] - cen[None, :, 1]
        s = 1.0 / np.sqrt(ce * ce + du_ * du_ + dv_ * dv_)
        s3 = s**3
        o = out[b0:b0 + 256]
        val[:, o] = (ce * s @ alpha + beta[0] + qb[:, :1] * beta[1] + qb[:, 1:] * beta[2]).T
        gu[:, o] = (-ce * (s3 * du_) @ alpha + beta[1]).T
        gv[:, o] = (-ce * (s3 * dv_) @ alpha + beta[2]).T
    edge = interp._edge(p[:, 0], p[:, 1], loc)
    if single:
        val, gu, gv = val[0], gu[0], gv[0]
    return Evaluation(val, gu, gv, edge)


# --------------------------------------------------------------------------
# space-time series
# --------------------------------------------------------------------------


class SeriesEvaluation(NamedTuple):
    """Result of :func:`evaluate_series`; arrays (n_times, M) unless noted.

    theta : temperature (unit of the frames, °C)
    dtheta_du, dtheta_dv : spatial derivatives, K/px
    dtheta_dt : local time derivative at fixed pixel position, K/s
    edge_distance : px from the mask edge (see :class:`Evaluation`)
    in_span : (n_times,) bool, False where the time lies outside the frame
        span (all values NaN there)
    """

    theta: np.ndarray
    dtheta_du: np.ndarray
    dtheta_dv: np.ndarray
    dtheta_dt: np.ndarray
    edge_distance: np.ndarray
    in_span: np.ndarray


def evaluate_series(
    frames,
    frame_times,
    eval_times,
    points,
    mask,
    *,
    method="rbf",
    c=2.0,
    R0=1.0,
    c_time=1.0,
    R0_time=1.0,
    halo=12,
    tile=8,
    chunk=32,
):
    """Temperatures, gradients and rates at moving points over a frame series.

    For each evaluation time ``t_k`` the frames are combined by the temporal
    cardinal weights, ``G_k = F l_t(t_k)`` and ``G'_k = F l_t'(t_k)``, and both
    are interpolated in space at the points ``P_k`` (see the module docstring).

    Parameters
    ----------
    frames : array_like, shape (n_frames, H, W)
        Pixel temperatures (°C). Any array-like with numpy slicing (numpy,
        zarr, memmap); it is read frame block by frame block, and only the
        masked pixels are kept.
    frame_times : array_like, shape (n_frames,)
        Frame times in s, strictly increasing.
    eval_times : array_like, shape (n_times,)
        Evaluation times in s, any order. Times outside the frame span give
        NaN (an :class:`~irdic.errors.IrdicWarning` names them).
    points : array_like, shape (n_times, M, 2) or (M, 2)
        (u, v) in px per evaluation time (or fixed). NaN points give NaN.
    mask : array_like of bool, shape (H, W) or (n_times, H, W)
        Pixels on the specimen, fixed or per evaluation time. Consecutive
        identical masks share all setup. A change costs the refactorisation of
        the edge tiles whose local mask pattern changed (~5 ms each) plus the
        edge-distance structures (~10 ms): ~0.5 s when half the edge of the
        paper-scale ellipse moves, against ~45 ms per time otherwise; so prefer
        masks that stay fixed over runs of times (e.g. the intersection of the
        per-frame masks over a run). Every masked pixel (of any time) must have
        finite values in every frame.
    method : {"rbf", "bilinear", "cubic"}
        Spatial method; the temporal one is always the IMQ interpolant.
    c, R0 : float
        Spatial IMQ shape parameter and normalisation (px): 2, 1 in the paper.
    c_time, R0_time : float
        Temporal IMQ shape parameter and normalisation (s): 1, 1 in the paper.
    halo, tile : int
        See :class:`MaskedGridInterpolant`.
    chunk : int
        Evaluation times processed together (memory ~ chunk x 2 x bounding box
        of the mask x 12 B).

    Returns
    -------
    SeriesEvaluation

    Notes
    -----
    With a moving mask the tensor product ansatz interpolates each pixel's
    time series over all frames, so pixels that changed between specimen and
    background within a few frames of ``t_k`` carry mixed values in ``G_k``;
    an eroded mask avoids that.
    """
    method = _method(method)
    chunk = _integer("chunk", chunk, 1)
    shape = getattr(frames, "shape", None)
    if shape is None:
        frames = np.asarray(frames)
        shape = frames.shape
    if len(shape) != 3:
        raise ConfigError(f"frames must have shape (n_frames, H, W), got {tuple(shape)}")
    n_frames, H, W = shape
    ft = _float_array("frame_times", frame_times)
    if ft.shape != (n_frames,):
        raise ConfigError(
            f"frame_times must have shape (n_frames,) = ({n_frames},) like frames, got {ft.shape}"
        )
    temporal = TemporalInterpolant(ft, c=c_time, R0=R0_time)
    te = _float_array("eval_times", eval_times)
    if te.ndim != 1:
        raise ConfigError(f"eval_times must be 1-D (n_times,), got shape {te.shape}")
    n_times = te.size
    pts = _float_array("points", points)
    if pts.ndim == 2 and pts.shape[1] == 2:
        pts = np.broadcast_to(pts, (n_times,) + pts.shape)
    if pts.ndim != 3 or pts.shape[0] != n_times or pts.shape[2] != 2:
        raise ConfigError(
            f"points must have shape (n_times, M, 2) = ({n_times}, M, 2) or (M, 2), got {pts.shape}"
        )
    M = pts.shape[1]
    mk = np.asarray(mask)
    if mk.ndim == 2:
        masks = [_check_mask(mk)]
        mask_of = np.zeros(n_times, np.int64)
    elif mk.ndim == 3 and mk.shape[0] == n_times:
        masks, mask_of = [], np.empty(n_times, np.int64)
        for k in range(n_times):
            m = _check_mask(mk[k], f"mask[{k}]")
            if masks and np.array_equal(m, masks[-1]):
                mask_of[k] = len(masks) - 1
            else:
                masks.append(m)
                mask_of[k] = len(masks) - 1
    else:
        raise ConfigError(f"mask must have shape (H, W) or (n_times, H, W) = ({n_times}, H, W), got {mk.shape}")
    for i, m in enumerate(masks):
        if m.shape != (H, W):
            raise ConfigError(f"mask must have the frame shape (H, W) = ({H}, {W}), got {m.shape}")

    in_span = temporal.in_span(te)
    if not in_span.all():
        out = np.flatnonzero(~in_span)
        shown = ", ".join(f"{te[i]:g}" for i in out[:5]) + (", ..." if out.size > 5 else "")
        warnings.warn(
            f"eval_times: {out.size} of {n_times} time(s) lie outside the frame span "
            f"[{ft[0]:g}, {ft[-1]:g}] s ({shown}); their results are NaN",
            IrdicWarning,
            stacklevel=2,
        )

    union = masks[0].copy()
    for m in masks[1:]:
        union |= m
    uv, uu = np.nonzero(union)
    n_u = uv.size
    if n_u == 0:
        raise DataError("mask: no pixel is masked; at least 3 pixels not on one line are needed")
    # Pixel time series of the masked pixels (n_u, n_frames), block by block.
    F = np.empty((n_u, n_frames))
    step = max(1, int(2**27 // max(1, H * W * 4)))
    for f0 in range(0, n_frames, step):
        block = np.asarray(frames[f0:f0 + step])
        F[:, f0:f0 + block.shape[0]] = block[:, uv, uu].T
    bad = ~np.isfinite(F)
    if bad.any():
        j, n = np.argwhere(bad)[0]
        raise DataError(
            f"frames: {int(bad.sum())} non-finite value(s) at masked pixels, first in frame {n} "
            f"at pixel (u={uu[j]}, v={uv[j]}); every masked pixel needs finite values in every frame"
        )
    lookup = np.full((H, W), -1, np.int64)
    lookup[uv, uu] = np.arange(n_u)

    theta = np.full((n_times, M), np.nan)
    gu = np.full((n_times, M), np.nan)
    gv = np.full((n_times, M), np.nan)
    rate = np.full((n_times, M), np.nan)
    edge = np.full((n_times, M), np.nan)

    cache = _TileCache()
    interps = {}
    ks = np.flatnonzero(in_span)
    # Runs of consecutive in-span times with the same mask, cut into chunks.
    pieces = []
    if ks.size:
        cut = np.flatnonzero((np.diff(ks) != 1) | (np.diff(mask_of[ks]) != 0)) + 1
        for run in np.split(ks, cut):
            pieces.extend(run[i:i + chunk] for i in range(0, run.size, chunk))
    Wv = temporal.weights(te[ks], 0) if ks.size else None
    Wd = temporal.weights(te[ks], 1) if ks.size else None
    row_of = np.full(n_times, -1, np.int64)
    row_of[ks] = np.arange(ks.size)
    progress = Progress(ks.size, "evaluate_series", unit="times", logger=log)
    done = 0
    for ch in pieces:
        mi = int(mask_of[ch[0]])
        interp = interps.get(mi)
        if interp is None:
            interps.clear()  # masks come in runs: keep only the current one
            interp = MaskedGridInterpolant(
                masks[mi], method=method, c=c, R0=R0, halo=halo, tile=tile, _tile_cache=cache
            )
            interps[mi] = interp
        sel = lookup[interp.pixels[:, 1], interp.pixels[:, 0]]
        if sel.size == n_u:
            sel = slice(None)  # the mask is the union: no copy
        r = row_of[ch]
        vals = np.empty((ch.size, 2, interp.n_mask))
        for j, Wt in enumerate((Wv[r], Wd[r])):
            # the temporal cardinal weights decay like the spatial ones: only
            # frames where they exceed 1e-15 of the largest enter (error ~1e-13 K)
            big = np.flatnonzero((np.abs(Wt) > 1e-15 * np.abs(Wt).max()).any(axis=0))
            c0, c1 = big[0], big[-1] + 1
            vals[:, j] = (F[:, c0:c1] @ Wt[:, c0:c1].T)[sel].T
        interp._fit_values(vals.reshape(2 * ch.size, interp.n_mask))
        val, du, dv, ed = interp._evaluate_grouped(pts[ch], 2, (True, False))
        theta[ch] = val[:, 0]
        gu[ch] = du[:, 0]
        gv[ch] = dv[:, 0]
        rate[ch] = val[:, 1]
        edge[ch] = ed
        done += ch.size
        progress.update(done)
    log.info(
        "evaluate_series: %d times x %d points, %d masked px (union), %d mask(s), %d edge tiles factorised",
        n_times, M, n_u, len(masks), cache.built,
    )
    return SeriesEvaluation(theta, gu, gv, rate, edge, in_span)
