"""Interior stencils: cardinal weights of a fully masked disc as Chebyshev series.

Away from the mask edge the local interpolant over the pixels within
``halo`` of a point is the same for every pixel (the grid is shift
invariant), so its cardinal weights are computed once per ``c R0`` and
``halo`` as functions of the subpixel offset (see :mod:`irdic.image_rbf`).
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np

from ..numerics.imq import imq_matrix
from ..numerics.saddle import SaddleFactor
from ..threads import blas_threads

__all__ = ["CHEB_DEGREE", "CHEB_SUB", "Stencil", "chebyshev", "interior_stencil"]

# Tensor Chebyshev degree and sub-cells per pixel side. Degree 5 on 4 x 4
# sub-cells represents the cardinal weights to 3e-7 (value) and 7e-5 (d/du,
# d/dv) in l1 norm at 36 coefficients; degree 8 on the whole cell needs 81
# for the same accuracy.
CHEB_DEGREE = 5
CHEB_SUB = 4


class Stencil(NamedTuple):
    """Interior stencil: ``W32[sub-cell, box pixel, coefficient]`` (float32)."""

    halo: int
    ce: float
    degree: int
    sub: int
    W32: np.ndarray  # (sub*sub, (2 halo + 1)^2, Q) float32, zero outside the disc


def chebyshev(x, degree):
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
def interior_stencil(ce, halo, degree=CHEB_DEGREE, sub=CHEB_SUB):
    """Cardinal weights of the fully masked disc as Chebyshev series in the offset.

    For a point ``p + delta`` (p a pixel, delta in [-1/2, 1/2]^2) the local
    interpolant over the pixels ``p + k``, ``|k| <= halo``, is
    ``sum_k w_k(delta) f_(p+k)``. On each of ``sub x sub`` sub-cells,
    ``w_k(delta) = sum_ab C[ab, k] T_a(xi) T_b(eta)`` with (xi, eta) the
    sub-cell coordinates in [-1, 1]^2 (tensor Chebyshev interpolation at
    Chebyshev points of the first kind).
    """
    # one BLAS thread: threaded BLAS sums in another order, and the float32 weights (cached for the
    # process) would then depend on the thread count of the stage that happened to build them first
    with blas_threads(1):
        return _interior_stencil(ce, halo, degree, sub)


def _interior_stencil(ce, halo, degree, sub):
    k = np.arange(-halo, halo + 1)
    KV, KU = np.meshgrid(k, k, indexing="ij")
    keep = KU**2 + KV**2 <= halo**2
    off_u, off_v = KU[keep], KV[keep]
    n = off_u.size
    cen = np.c_[off_u, off_v].astype(float)
    fac = SaddleFactor(imq_matrix(cen, cen, ce), np.c_[np.ones(n), cen])

    nodes = np.cos(np.pi * (np.arange(degree + 1) + 0.5) / (degree + 1))
    Vinv = np.linalg.inv(chebyshev(nodes, degree)[0])  # V[i, a] = T_a(node_i)
    h = 0.5 / sub
    NU, NV = np.meshgrid(nodes, nodes, indexing="ij")
    Q = (degree + 1) ** 2
    W = np.empty((sub * sub, n, Q))
    for iu in range(sub):
        for iv in range(sub):
            du = -0.5 + h * (2 * iu + 1) + h * NU.ravel()
            dv = -0.5 + h * (2 * iv + 1) + h * NV.ravel()
            X = np.c_[du, dv]
            B = imq_matrix(cen, X, ce)
            w, _ = fac.solve(B, np.stack([np.ones_like(du), du, dv]))
            w = w.reshape(n, degree + 1, degree + 1)
            C = np.einsum("ai,bj,kij->kab", Vinv, Vinv, w)
            W[iu * sub + iv] = C.reshape(n, Q)
    # Embedded in the (2 halo + 1)^2 box (row-major: v outer, u inner): one
    # strided gather per point is faster than 2 halo + 1 row gathers.
    box = np.zeros((sub * sub, (2 * halo + 1) ** 2, Q), np.float32)
    box[:, np.flatnonzero(keep.ravel())] = W
    return Stencil(halo, ce, degree, sub, box)

