"""Continuous surface ``x(Psi, t)`` from DIC stages: parameters, interpolation, tangents.

The paper's surface (eq:x_RBFInterp) is a tensor product. In the surface
parameters ``Psi`` an inverse multiquadric ``m(r) = c / sqrt(c^2 + r^2)``,
``r = |Psi - Psi_k| / R0`` (R0 = 1 mm), on every DIC point plus the monomials
{1, Psi1, Psi2}; in time the same kernel on every stage time (R0 = 1 s) plus
{1, t}. The ``Psi_k`` are fixed (Lagrangian): one spatial and one temporal
operator serve all stages and all three components. With the data ``X``
(points x stages) the surface at the points and evaluation times is
``S X W^T``, its time derivative ``S X W'^T`` and its tangents
``D_alpha X W^T``, where ``W``, ``W'`` are the temporal weights (value, d/dt)
and ``S``, ``D_alpha`` the spatial ones (value, d/dPsi^alpha).

Public API
----------
* :func:`surface_parameters` (:mod:`.parametrisation`): ``Psi`` from the
  reference points (best-fit plane or cylinder unwrapping, ``"auto"`` picks
  the one that does not fold).
* :class:`SpatialInterpolant` (:mod:`.interpolation`): the spatial operator
  (global dense, local tiles or regression with fewer centres), missing-point
  fill, values and ``d/dPsi^alpha`` at the points or anywhere.
* The temporal operator (interpolation or regression) is
  :class:`irdic.numerics.temporal.TemporalInterpolant`; :func:`smooth_series`
  applies it to any per-point time series (point temperatures: their
  derivative at fixed ``Psi`` is the material rate).
* :func:`gcv_spatial` (:mod:`.regression`),
  :func:`irdic.numerics.temporal_choice.gcv_temporal`: choice of the smoothing by
  generalised cross-validation.
* :func:`fit_surface` (:mod:`.fit`): the whole stage: ``x``, tangents
  ``a_alpha``, ``dx/dt``, reference tangents ``A_alpha``, fill flags and edge
  distance.
* :func:`surface_geometry` (:mod:`.geometry`): metric, dual vectors, unit normal.
* :func:`edge_distance` (:mod:`.geometry`): distance (mm, in ``Psi``) of points
  to the edge of the cloud.

Units: mm, s. Arrays of points are ``(N, 2)`` (``Psi``) or ``(N, 3)`` (``x``);
stage data ``(M, N, 3)`` (stage, point, component).

Notes
-----
**Spatial solver** (``solver=``). ``"global"``: the paper's interpolant, one
dense Cholesky factorisation of the N x N kernel matrix (plus a 3 x 3 Schur
complement for the monomials), coefficients for all columns, derivatives from
the kernel rows in blocks. ``"local"``: overlapping tiles, a square core of
points plus every point within ``halo`` of the core; one Cholesky per tile
gives the derivative weights of the core points, applied to all columns by
one matrix product per tile (single-threaded BLAS on a thread pool: the
tiles are many small factorisations). The global interpolant's weights decay
exponentially (about one decade per 1.4 c R0) down to an algebraic tail of
relative size ``~exp(-2 pi c R0 / h)`` (h = point spacing), and for points
near the cloud's edge they keep a tail of ~1e-3 all along the edge. So the
tiles (default ``halo = 9 c R0``, at least ``6 h``) reproduce the global tangents to
~1e-5 of the data's deviation from a plane 8 mm or more inside (h = 0.6 mm),
but nearer the edge they differ from them by about as much as the global
interpolant differs from the truth, and are the more accurate of the two:
on a curved test field (R = 15 mm, h = 0.6 mm) the largest tangent error was
1.4e-2 (tiles) against 7.0e-2 (global) 1.5-3 mm from the edge, 1.3e-3
against 5.3e-3 at 3-5 mm, 4.7e-6 against 1.1e-5 beyond 8 mm; with h = 1 mm
and c = 0.95 both are limited by the tail (~3e-4 in the interior).
On grids much denser than the kernel the halo is at most 20 point spacings
(``default_halo``), so that a tile holds a bounded number of points and the
pass costs time linear in the points at a fixed specimen (with 9 c R0 a
tile's points grow as 1/h^2 and its factorisation as 1/h^6). A denser grid
resolves the field better, and the shorter halo cuts more of the global
interpolant's edge error: on the curved test field (data of ~15 mm) the
largest tangent error with 20 spacings against 9 c R0 was, at h = 0.2 mm,
2.0e-4 / 6.4e-4 at 0.5-1.5 mm from the edge, 5.0e-6 / 9.3e-6 at 3-5 mm and
1.8e-6 / 4.0e-7 beyond 5 mm; at h = 0.14 mm 8.5e-6 / 3.8e-5, 3.3e-7 /
3.2e-7 and 3.3e-7 / 1.4e-8.
``"auto"`` estimates the cost of both for the data at hand (flop counts, a
matrix-product flop weighted about half a factorisation flop) and takes the
tiles when they are at least twice as cheap (10,000 points on a 0.6 mm grid
of the half-shell: tiles; 10,000 points on a narrow 25 x 40 mm tube patch,
where every tile would span the patch: global). ``info["solver"]`` says which.

**Missing points.** DIC points missing in some stages (NaN) are filled before
the tensor product is built, and flagged (``filled``): per stage, from that
stage's valid points. With ``G`` the map from data to RBF coefficients, the
values ``f_Q`` at the missing points ``Q`` with ``G_QQ f_Q = -G_QV f_V`` give
coefficients ``alpha_Q = 0``, so the all-points interpolant equals the
valid-points interpolant: the stage's surface stays smooth through the gap and
the neighbours' tangents hardly notice it. The rows of ``G`` come from local
tiles (they decay like the cardinal functions), so a stage's fill is one small
``|Q| x |Q|`` solve; 8 mm or more inside the cloud the fill matches the global
valid-points interpolant to ~1e-4 of the data's variation (h = 0.6 mm), and
near the edge it is closer to the truth than that interpolant (as above).
The velocities ``dx/dt`` use a second fill (``fill="both"``, the default):
short gaps (at most ``max_gap`` stages, valid stages on both sides) filled
from the point's own time series (temporal interpolant over the nearest 8
valid stages on each side), so that a filled value does not put a bump into
its point's series: each derivative sees the fill that is smooth along its
direction. Measured on the tube test (1 mm grid, 0.5 s stages, 1.5 % missing
in every other stage): filled in space only, the velocity error reached
0.09 mm/s next to filled values (a filled value errs by the interpolant's
0.02-0.1 mm between points, a bump in its series); filled in time only, the
strain error RMS of the synthetic tube rose from 5e-4 to 1.4e-3 (bumps in the
stage surfaces). Points
missing in the reference stage take their parameters ``Psi`` from their first
valid stage (a small approximation: the point has moved by then). Stages with
fewer than ``min_stage_fraction`` valid points are left out of the temporal fit.

**Smoothing** (beyond the paper; its outlook for noisy data). Regression with
fewer centres: centres on a subset of the points (time: of the stage times)
spaced ``k`` times the median spacing, a kernel six centre spacings wide
(``c R0_eff = 6 H``: flat kernels approximate smooth fields well with few
centres), least squares over all data (QR; missing points are filled first as
above). The hat matrix has trace ``p`` = number of parameters, so generalised
cross-validation, ``GCV(k) = n RSS / (n - p)^2`` pooled over all series, is
exact and cheap; ``smoothing="gcv"`` picks ``k`` by it. For the surface
GCV judges the displacements from the first stage (the strain depends on
the tangents through ``a_ab - A_ab``, i.e. on the displacement), over the
points measured in every pooled stage, among spacings up to 16 points
(:func:`irdic.surface.fit.gcv_displacement`): GCV on the positions stopped
where the geometric residual of the curved specimen equalled the noise
(tube, 0.003 mm noise on a 0.8 mm grid: strain error 1.5e-3 at 2.5 spacings
against 4e-4 at the 5 GCV now takes; a static half-shell: 3.6e-4 against
4.4e-5 at 16). Regression in time (``smoothing_t``) did not help the
strain there (4.5e-4 with GCV in time: the error left is the spatial
bias). Measured: the rate of
a 2 Hz, 250 s heating curve with 0.05 K noise errs by 0.14 K/s (RMS)
interpolated and 1.1e-3 K/s smoothed (GCV: centres every 48 stages); the
largest principal strain of a tube with 0.005 mm coordinate noise on a 0.8 mm
grid by 1.1e-2 interpolated and 7.9e-4 smoothed (centres every 5 points). A
ridge ``(A + lam I)`` was measured and rejected: the IMQ spectrum grows only
logarithmically at low frequencies, so any ``lam`` that damps the noise also
shrinks the signal (GCV then chose ``lam`` too small: rate error reduced only
1.3x on the heating curve).
"""

from ..numerics.series import SeriesFit, smooth_series
from .fit import SurfaceFields, fit_stages, fit_surface
from .geometry import Geometry, edge_distance, surface_geometry
from .interpolation import SpatialInterpolant, drop_derivative_weights, shared_interpolant
from .parametrisation import surface_parameters
from .regression import gcv_spatial

__all__ = [
    "surface_parameters",
    "SpatialInterpolant",
    "shared_interpolant",
    "drop_derivative_weights",
    "SeriesFit",
    "smooth_series",
    "gcv_spatial",
    "SurfaceFields",
    "fit_surface",
    "fit_stages",
    "Geometry",
    "surface_geometry",
    "edge_distance",
]
