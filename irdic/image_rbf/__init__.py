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

This package knows kernels and interpolants only (no cameras, no files):

* :func:`imq`, :func:`imq_dr`: the kernel and its radial derivative
  (:mod:`irdic.numerics.imq`); the temporal operator is
  :class:`irdic.numerics.temporal.TemporalInterpolant`.
* :class:`MaskedGridInterpolant` (alias :data:`MaskedGridRBF`,
  :mod:`.interpolant`): interpolation of one or many fields given on the
  masked pixels of a regular grid, with ``d/du`` and ``d/dv``, at arbitrary
  subpixel points; ``method="rbf"`` (the paper's global IMQ interpolant over
  the masked pixels, computed fast), ``"bilinear"`` or ``"cubic"`` (for
  comparison).
* :func:`evaluate_series` (:mod:`.series`): the use case of the couple stage.
  Frames, frame times, evaluation times and points per evaluation time in;
  ``Theta``, ``dTheta/du``, ``dTheta/dv``, ``dTheta/dt`` and the distance to
  the mask edge per (time, point) out.
* :func:`exact_global_interpolant` (:mod:`.reference`): the dense
  saddle-point solve over all masked pixels, the reference for tests (small
  cases only).

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

* *Interior* (every pixel within ``halo`` of the point's pixel is masked,
  :mod:`.stencil`): the local system is the same for every such pixel (the
  grid is shift invariant), so it is solved once (per ``c*R0`` and ``halo``,
  cached) for the cardinal weights ``w(delta)`` of the disc of 441 pixels as
  functions of the subpixel offset ``delta`` in [-1/2, 1/2]^2. ``w`` is
  analytic in ``delta``; it is stored as tensor Chebyshev series of degree 5
  on 4 x 4 sub-cells of the pixel (36 coefficient stencils per sub-cell; the
  series reproduce the weights to 3e-7 (value) and 7e-5 (d/du, d/dv) in l1
  norm, and reproduce linear fields exactly). Evaluating a field costs one
  gather of the 25 x 25 pixels around the point and one (625 x 36) matrix
  product per point, in float32 relative to the central pixel (rounding
  ~1e-6 K), in BLAS; value, ``d/du`` and ``d/dv`` follow from the same 36
  coefficients.
* *Near the mask edge* (:mod:`.tiles`): overlapping tiles, a core of ``tile``
  x ``tile`` pixels plus every masked pixel within ``halo`` of the core
  (its *window*, ~840 px, ~570 masked on a moving tube's edge). The window
  is the same for every tile, so each tile's saddle system (IMQ is positive
  definite; the monomials enter through a 3 x 3 Schur complement) is a
  principal submatrix of one kernel matrix: its Cholesky factor is a leading
  block of a factor of the whole window in a pixel order that sorts the
  window along the outline's normal (one of 128 directions; 16 factorisations
  serve all, by the window's symmetries), extended by the few pixels past
  that block (a Schur complement of their rows of the factor). Nothing is
  factorised per mask or pattern, and the triangular solves of the tiles of
  many times run as one matrix product per order: a tile costs the same
  whether the outline stands still or moves. Points are evaluated directly
  from the tile's RBF coefficients. The interpolant is that of each tile's
  own pixels (to round-off, ~1e-12 of the values).

*Accuracy* against :func:`exact_global_interpolant` (tests, benchmark), fields
of tens of K with 0.05 K noise: ~3e-5 K and ~6e-5 K/px from ``halo`` px off the
edge on; ~1e-3 K at 5-12 px, ~1e-2 K at 2-5 px, ~3e-2 K at 0.5-2 px and up to
~0.2 K in the outer half pixel (extrapolation). The near-edge differences do
not shrink with a larger halo (24 px: -15 %): there the global interpolant
depends on distant data through the RBF boundary error of a flat kernel with
linear monomials, and against the analytic truth both are off by similar
amounts (on the test fields the local one was 8 x better on one and 1.5 x
worse on another). Every point carries its distance to the mask edge.

*Alternatives weighed*: tiles everywhere with direct kernel evaluation cost
about 2.5 x the interior stencils; a global CG solve with an FFT (BTTB)
product needs ~100-1000 FFTs of a padded grid per field (condition 1e5-1e6)
and then still a 50k-centre sum at every point, whose 1/r tail defeats
truncation; per-point local solves cost a (441 + 3)^2 product per point. The
stencils plus edge tiles win by > 5 x. Edge tiles factorised per mask pattern
(cached by pattern, extending shared factors of the pixels neighbouring masks
have in common) cost more the faster the outline moves: a moving outline
makes most patterns new at every time. Measured run times and memory are in
``benchmarks/README.md`` (``benchmarks/bench_rbf.py``). Every stage limits
BLAS to the threads it was given (:mod:`irdic.threads`); the ~840 x 840
triangular products of the edge tiles gain little from more than one.
"""

from ..numerics.imq import imq, imq_dr
from .interpolant import METHODS, Evaluation, MaskedGridInterpolant, MaskedGridRBF
from .reference import exact_global_interpolant
from .series import SeriesEvaluation, evaluate_series

__all__ = [
    "METHODS",
    "imq",
    "imq_dr",
    "MaskedGridInterpolant",
    "MaskedGridRBF",
    "Evaluation",
    "SeriesEvaluation",
    "exact_global_interpolant",
    "evaluate_series",
]
