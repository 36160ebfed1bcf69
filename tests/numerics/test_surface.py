"""Continuous surface x(Psi, t): parameters, interpolation, fill, smoothing, geometry, edges."""

import logging
import warnings

import numpy as np
import pytest
from scipy.interpolate import RBFInterpolator

from irdic.errors import ConfigError, DataError, GeometryError, IrdicWarning
from irdic.strain import strain
from irdic.numerics.temporal import TemporalInterpolant
from irdic.surface import (
    SpatialInterpolant,
    edge_distance,
    fit_stages,
    fit_surface,
    gcv_spatial,
    smooth_series,
    surface_geometry,
    surface_parameters,
)

# ----------------------------------------------------------------------------------
# analytic scenes
# ----------------------------------------------------------------------------------


def half_shell(spacing=1.0, R=65.0, half_angle=36.87, H=50.0):
    """Cylinder patch (half-shell), axis along y, seen from +z; material grid (S = arc, h)."""
    smax = R * np.radians(half_angle)
    n_s = int(round(2 * smax / spacing)) + 1
    S, h = np.meshgrid(np.linspace(-smax, smax, n_s), np.arange(0, H + 1e-9, spacing))
    S, h = S.ravel(), h.ravel()
    x = np.c_[R * np.sin(S / R), h, R * np.cos(S / R) - R]
    return S, h, x


class Tube:
    """Tube R = 15 mm under proportional tension-torsion over a 40 mm gauge (isochoric radius)."""

    R, L = 15.0, 40.0

    def __init__(self, half_angle=60.0, spacing=1.0):
        smax = np.floor(self.R * np.radians(half_angle) / spacing) * spacing
        S, Z = np.meshgrid(np.arange(-smax, smax + 1e-9, spacing), np.arange(-20, 20 + 1e-9, spacing))
        self.S, self.Z = S.ravel(), Z.ravel()
        self.edge = np.minimum(smax - np.abs(self.S), 20 - np.abs(self.Z))

    @staticmethod
    def load(t):
        s = np.sin(np.pi * t / 20) ** 2  # smooth proportional ramp on [0, 10] s
        return 1 + 0.04 * s, 0.3 * s  # axial stretch, twist angle (rad)

    def x(self, t):
        lam, phi = self.load(t)
        r = self.R / np.sqrt(lam)
        a = self.S / self.R + phi * self.Z / self.L
        return np.c_[r * np.sin(a), lam * self.Z, r * np.cos(a)]

    def tangents(self, t):
        lam, phi = self.load(t)
        r = self.R / np.sqrt(lam)
        a = self.S / self.R + phi * self.Z / self.L
        e_t = np.c_[np.cos(a), 0 * a, -np.sin(a)]
        e_z = np.c_[0 * a, 1 + 0 * a, 0 * a]
        return np.stack([(r / self.R) * e_t, (r * phi / self.L) * e_t + lam * e_z], 1)

    def normal(self, t):
        lam, phi = self.load(t)
        a = self.S / self.R + phi * self.Z / self.L
        return np.c_[np.sin(a), 0 * a, np.cos(a)]

    def velocity(self, t, dt=1e-6):
        return (self.x(t + dt) - self.x(t - dt)) / (2 * dt)

    def principal_strains(self, t):
        lam, phi = self.load(t)
        r = self.R / np.sqrt(lam)
        g = r * phi / self.L
        C = np.array([[(r / self.R) ** 2, (r / self.R) * g], [(r / self.R) * g, lam**2 + g * g]])
        w = np.linalg.eigvalsh(0.5 * (C - np.eye(2)))
        return w[1], w[0]


def tube_stages(tube, times, missing_per_stage=20, seed=0):
    X = np.stack([tube.x(t) for t in times])
    rng = np.random.default_rng(seed)
    for k in range(1, len(times), 2):
        X[k, rng.choice(X.shape[1], missing_per_stage, replace=False)] = np.nan
    return X


# ----------------------------------------------------------------------------------
# surface parameters
# ----------------------------------------------------------------------------------


def test_plane_parameters_are_an_isometry_of_a_tilted_plane():
    rng = np.random.default_rng(3)
    q = rng.uniform(-20, 20, (300, 2))
    n = np.array([0.2, -0.3, 1.0])
    n /= np.linalg.norm(n)
    e1 = np.cross([0, 1.0, 0], n)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    x = 5.0 + q[:, :1] * e1 + q[:, 1:] * e2
    psi, info = surface_parameters(x)
    assert info["method"] == "plane" and info["rms"] < 1e-12
    d_psi = np.linalg.norm(psi[:, None] - psi[None], axis=2)
    d_x = np.linalg.norm(x[:, None] - x[None], axis=2)
    np.testing.assert_allclose(d_psi, d_x, atol=1e-10)
    # normal towards +z (the DIC cameras), Psi1 along the projected DIC x axis
    np.testing.assert_allclose(info["axes"][2], n, atol=1e-12)
    e1_true = np.r_[1.0, 0, 0] - n[0] * n
    np.testing.assert_allclose(info["axes"][0], e1_true / np.linalg.norm(e1_true), atol=1e-12)


def test_half_shell_takes_the_paper_plane():
    S, h, x = half_shell()
    psi, info = surface_parameters(x)
    assert info["method"] == "plane"
    assert 33 < info["normal_angle_p99_deg"] < 37.5  # the shell spans +-36.87 deg
    # Psi1 = R sin(S / R) (projection onto the chord plane), Psi2 = height (up to a shift)
    chord = 65 * np.sin(S / 65)
    np.testing.assert_allclose(psi[:, 0] - psi[:, 0].mean(), chord - chord.mean(), atol=1e-9)
    np.testing.assert_allclose(psi[:, 1] - psi[:, 1].mean(), h - h.mean(), atol=1e-9)


def test_wide_tube_patch_is_unwrapped_on_a_cylinder():
    tube = Tube(half_angle=85.0)
    x = tube.x(0.0)
    psi, info = surface_parameters(x)
    assert info["method"] == "cylinder"
    assert info["candidates"]["plane"]["normal_angle_p99_deg"] > 70
    assert info["radius"] == pytest.approx(15.0, abs=1e-9)
    assert abs(info["axis_direction"] @ [0, 1, 0]) == pytest.approx(1, abs=1e-12)
    # Psi = (arc length, axial): an isometry of the unwrapped cylinder (up to a shift)
    np.testing.assert_allclose(psi[:, 0] - psi[:, 0].mean(), tube.S - tube.S.mean(), atol=1e-8)
    np.testing.assert_allclose(psi[:, 1] - psi[:, 1].mean(), tube.Z - tube.Z.mean(), atol=1e-8)
    # a1 x a2 points outward (away from the axis)
    sf_dir = np.cross(np.r_[1.0, 0, 0], [0, 1.0, 0])  # e_theta x e_z at theta = 0 is +z = outward there
    assert sf_dir[2] == 1
    # an explicit plane folds here
    with pytest.raises(GeometryError, match="plane: local normals up to 8[0-9].[0-9] deg"):
        surface_parameters(x, "plane")


def test_every_parametrisation_folds_on_a_sphere_cap():
    pol, az = np.meshgrid(np.radians(np.linspace(0, 110, 40)), np.radians(np.linspace(0, 360, 90, endpoint=False)))
    x = 20 * np.c_[np.sin(pol.ravel()) * np.cos(az.ravel()), np.sin(pol.ravel()) * np.sin(az.ravel()),
                   np.cos(pol.ravel())]
    with pytest.raises(GeometryError, match="every parametrisation folds the surface: plane: .*; cylinder: "):
        surface_parameters(x)


def test_missing_reference_points_take_their_first_valid_stage():
    S, h, x = half_shell(spacing=2.0)
    X = np.stack([x, x + [0.01, 0.0, 0.0], x])
    X[0, 5] = np.nan  # missing in the reference, valid in stage 1
    X[:, 7] = np.nan  # never valid
    psi, info = surface_parameters(X)
    assert info["n_reference_from_later_stage"] == 1 and info["n_without_data"] == 1
    assert np.isnan(psi[7]).all() and np.isfinite(np.delete(psi, 7, 0)).all()
    # point 5 is projected from stage 1
    np.testing.assert_allclose(psi[5], (X[1, 5] - info["origin"]) @ info["axes"][:2].T, atol=1e-12)


def test_parameter_errors():
    with pytest.raises(ConfigError, match=r"x must have shape \(N, 3\) or \(stages, N, 3\), got \(10, 2\)"):
        surface_parameters(np.zeros((10, 2)))
    with pytest.raises(ConfigError, match="`method` must be one of 'auto', 'plane', 'cylinder'; got 'sphere'"):
        surface_parameters(np.zeros((10, 3)), "sphere")
    with pytest.raises(DataError, match="x: 4 point.* the surface needs at least 6"):
        surface_parameters(np.r_[np.random.rand(4, 3), np.full((3, 3), np.nan)])
    with pytest.raises(GeometryError, match="lie on a line"):
        surface_parameters(np.outer(np.arange(10.0), [1, 2, 3]))
    x = np.random.rand(10, 3)
    x[3, 1] = np.inf
    with pytest.raises(DataError, match="infinite coordinate at stage 0, point 3"):
        surface_parameters(x)


# ----------------------------------------------------------------------------------
# spatial interpolant
# ----------------------------------------------------------------------------------


def grid(spacing, half):
    g = np.arange(-half, half + 1e-9, spacing)
    P, Q = np.meshgrid(g, g)
    return np.c_[P.ravel(), Q.ravel()]


def curved(psi):
    """A smooth vector field like the coordinates of a curved surface."""
    R = 15.0
    return np.c_[R * np.sin(psi[:, 0] / R), psi[:, 1] * (1 + 0.01 * psi[:, 0]), R * np.cos(psi[:, 0] / R) * np.cos(
        psi[:, 1] / 40)]


@pytest.mark.parametrize("solver", ["global", "local"])
def test_linear_fields_are_reproduced_exactly(solver):
    rng = np.random.default_rng(0)
    psi = grid(1.0, 12) + rng.uniform(-0.2, 0.2, (625, 2))
    f = np.c_[1 + 2 * psi[:, 0] - 3 * psi[:, 1], 4 - psi[:, 1]]
    sp = SpatialInterpolant(psi, solver=solver)
    q = rng.uniform(-10, 10, (50, 2))
    v, d1, d2 = sp.evaluate(f, q)
    np.testing.assert_allclose(v, np.c_[1 + 2 * q[:, 0] - 3 * q[:, 1], 4 - q[:, 1]], atol=1e-9)
    np.testing.assert_allclose(d1, np.broadcast_to([2.0, 0.0], d1.shape), atol=1e-9)
    np.testing.assert_allclose(d2, np.broadcast_to([-3.0, -1.0], d2.shape), atol=1e-9)
    v, d1, d2 = sp.evaluate(f)
    np.testing.assert_array_equal(v, f)  # interpolation: the data at the points
    assert sp.info["solver"] == solver


def test_global_interpolant_is_the_paper_one():
    # scipy's IMQ is 1 / sqrt(1 + (eps r)^2) = m(r) with eps = 1 / (c R0)
    rng = np.random.default_rng(1)
    psi = rng.uniform(0, 20, (400, 2))
    f = curved(psi)
    q = rng.uniform(2, 18, (30, 2))
    ref = RBFInterpolator(psi, f, kernel="inverse_multiquadric", epsilon=1 / 0.95, degree=1)
    v, d1, d2 = SpatialInterpolant(psi, c=0.95, solver="global").evaluate(f, q)
    np.testing.assert_allclose(v, ref(q), atol=1e-8)
    h = 1e-5
    np.testing.assert_allclose(d1, (ref(q + [h, 0]) - ref(q - [h, 0])) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(d2, (ref(q + [0, h]) - ref(q - [0, h])) / (2 * h), atol=1e-6)


def test_local_tiles_match_the_global_interpolant_inside():
    # 0.6 mm grid (the paper's half-shell spacing)
    psi = grid(0.6, 16)
    f = curved(psi)
    g = SpatialInterpolant(psi, solver="global").evaluate(f, value=False)
    loc = SpatialInterpolant(psi, solver="local").evaluate(f, value=False)
    edge = 16 - np.abs(psi).max(axis=1)
    exact = np.c_[np.cos(psi[:, 0] / 15), 0.01 * psi[:, 1], -np.sin(psi[:, 0] / 15) * np.cos(psi[:, 1] / 40)]
    # 8 mm or more inside the two agree to ~1e-5 (data of ~15 mm)
    deep = edge >= 8
    for a, b in zip(g[1:], loc[1:]):
        assert np.abs(a - b)[deep].max() < 3e-5
    assert np.abs(g[1] - exact)[deep].max() < 5e-5
    # nearer the edge they differ, but the tiles are not less accurate than the global solve
    # (the global interpolant's edge error reaches far in; the tiles cut its tail)
    for lo, hi in ((0.5, 1.5), (1.5, 3), (3, 5)):
        band = (edge >= lo) & (edge < hi)
        assert np.abs(loc[1] - exact)[band].max() <= np.abs(g[1] - exact)[band].max()


def test_dense_grid_tiles_hold_20_spacings_and_keep_the_accuracy():
    """On a grid much denser than the kernel (h = 0.2 mm, c R0 = 0.95 mm) the default halo is 20 spacings,
    not 9 c R0 (a tile then holds a bounded number of points: time linear in the points), and the tangents
    stay as accurate against the truth: 1e-6 of the data inside, better than the wide tiles near the edge."""
    psi = grid(0.2, 5)
    f = curved(psi)
    exact = np.c_[np.cos(psi[:, 0] / 15), 0.01 * psi[:, 1], -np.sin(psi[:, 0] / 15) * np.cos(psi[:, 1] / 40)]
    edge = 5 - np.abs(psi).max(axis=1)
    sp = SpatialInterpolant(psi, solver="local")
    assert sp.halo == pytest.approx(20 * 0.2)
    d = sp.evaluate(f, value=False)[1]
    wide = SpatialInterpolant(psi, solver="local", halo=9 * 0.95).evaluate(f, value=False)[1]
    assert np.abs(d - exact)[edge >= 3].max() < 1e-5
    for lo, hi in ((0, 0.5), (0.5, 1.5), (1.5, 3)):
        band = (edge >= lo) & (edge < hi)
        assert np.abs(d - exact)[band].max() <= np.abs(wide - exact)[band].max()
    # a coarse grid keeps the halo of nine kernel widths
    assert SpatialInterpolant(grid(0.6, 6), solver="local").halo == pytest.approx(9 * 0.95)


def test_fill_equals_the_interpolant_of_the_valid_points():
    rng = np.random.default_rng(2)
    psi = grid(0.6, 15) + rng.uniform(-0.06, 0.06, (2601, 2))
    X = np.stack([curved(psi), curved(psi) * 1.01])
    valid = np.ones((2, 2601), bool)
    miss = rng.choice(2601, 60, replace=False)
    valid[1, miss] = False
    X[1, miss] = np.nan
    sp = SpatialInterpolant(psi)
    filled, flag = sp.fill(X, valid)
    np.testing.assert_array_equal(flag, ~valid)
    np.testing.assert_array_equal(filled[0], X[0])
    keep = np.flatnonzero(valid[1])
    direct = SpatialInterpolant(psi[keep], solver="global").evaluate(X[1, keep], psi[miss])[0]
    deep = edge_distance(psi)[miss] >= 8
    assert deep.sum() >= 5
    # inside, the fill converges to the global interpolant of the valid points as the halo grows
    wide = SpatialInterpolant(psi, halo=16.0).fill(X, valid)[0]
    assert np.abs(wide[1, miss[deep]] - direct[deep]).max() < 1e-4
    assert np.abs(filled[1, miss[deep]] - direct[deep]).max() < 2e-3
    # and with the default halo it is closer to the truth than the global one (whose edge error is large)
    truth = curved(psi[miss]) * 1.01
    assert np.abs(filled[1, miss] - truth)[deep].max() <= np.abs(direct - truth)[deep].max()
    assert np.abs(filled[1, miss] - truth).max() < 0.2 * np.abs(direct - truth).max()


def test_fill_of_stages_sharing_a_pattern_equals_each_stage_alone():
    """Stages with the same missing points are solved together (noise probes): same values as one by one."""
    rng = np.random.default_rng(5)
    psi = grid(0.6, 12) + rng.uniform(-0.05, 0.05, (grid(0.6, 12).shape[0], 2))
    n = psi.shape[0]
    a, b = rng.choice(n, 40, replace=False), rng.choice(n, 25, replace=False)
    valid = np.ones((7, n), bool)
    for m, q in zip(range(7), (a, b, a, None, b, a, b)):
        if q is not None:
            valid[m, q] = False
    X = curved(psi)[None] + rng.normal(size=(7,) + curved(psi).shape)
    X[~valid] = np.nan
    sp = SpatialInterpolant(psi)
    together, flag = sp.fill(X, valid)
    np.testing.assert_array_equal(flag, ~valid)
    for m in range(7):
        alone = sp.fill(X[m:m + 1], valid[m:m + 1])[0][0]
        np.testing.assert_allclose(together[m], alone, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(together[valid], X[valid])
    assert np.isfinite(together).all()


def test_fill_factorisations_are_reused_only_with_their_rows_of_g():
    """A missing pattern's LU is kept for the next fill with the same points, and dropped when more rows of
    G are built (their tiles may differ): the result is the one of an instance that never kept it."""
    rng = np.random.default_rng(6)
    psi = grid(0.6, 9) + rng.uniform(-0.05, 0.05, (grid(0.6, 9).shape[0], 2))
    n = psi.shape[0]
    X = curved(psi)[None] + rng.normal(size=(1, n, 3))
    a, b = (np.ones((1, n), bool) for _ in range(2))
    a[0, rng.choice(n, 30, replace=False)] = False
    b[0, rng.choice(n, 200, replace=False)] = False
    sp = SpatialInterpolant(psi)
    first = sp.fill(np.where(a[..., None], X, np.nan), a)[0]
    assert len(sp._fill_lu[1]) == 1
    np.testing.assert_array_equal(sp.fill(np.where(a[..., None], X, np.nan), a)[0], first)
    sp.fill(np.where(b[..., None], X, np.nan), b)
    again = sp.fill(np.where(a[..., None], X, np.nan), a)[0]
    other = SpatialInterpolant(psi)
    other.fill(np.where(b[..., None], X, np.nan), b)
    np.testing.assert_allclose(again, other.fill(np.where(a[..., None], X, np.nan), a)[0], rtol=0, atol=1e-12)


def test_dropped_derivative_weights_are_rebuilt_with_the_same_numbers():
    """drop_derivative_weights frees the local tiles' weights of a cache's exact interpolants: the fill (rows of
    G) works on without them, and an evaluation that needs the derivatives builds them again on the same tiles:
    the same numbers up to the BLAS's rounding (bit for bit on some machines, 1e-14 apart on others)."""
    from irdic.surface import drop_derivative_weights, shared_interpolant

    rng = np.random.default_rng(8)
    psi = grid(0.6, 9) + rng.uniform(-0.05, 0.05, (grid(0.6, 9).shape[0], 2))
    n = psi.shape[0]
    X = curved(psi)[None] + rng.normal(size=(1, n, 3))
    valid = np.ones((1, n), bool)
    valid[0, rng.choice(n, 40, replace=False)] = False
    ops = {}
    sp = shared_interpolant(ops, psi, solver="local")
    sp.local_pass(np.flatnonzero(~valid[0]))
    filled = sp.fill(np.where(valid[..., None], X, np.nan), valid)[0]
    before = sp.evaluate(filled[0], value=False)
    assert sp._local is not None
    drop_derivative_weights(ops)
    assert sp._local is None
    np.testing.assert_array_equal(sp.fill(np.where(valid[..., None], X, np.nan), valid)[0], filled)
    after = sp.evaluate(filled[0], value=False)
    assert sp._local is not None
    for a, b in zip(before[1:], after[1:]):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12 * np.abs(a).max())


def test_regression_reduces_noise_in_derivatives():
    rng = np.random.default_rng(4)
    psi = grid(0.7, 14)
    f = curved(psi)
    noisy = f + rng.normal(0, 0.005, f.shape)  # DIC-like coordinate noise
    exact = np.c_[np.cos(psi[:, 0] / 15), 0.01 * psi[:, 1], -np.sin(psi[:, 0] / 15) * np.cos(psi[:, 1] / 40)]
    inner = np.abs(psi).max(axis=1) <= 10
    k, table = gcv_spatial(psi, noisy)
    assert k > 1 and len(table) >= 3
    d_int = SpatialInterpolant(psi).evaluate(noisy, value=False)[1]
    d_reg = SpatialInterpolant(psi, smoothing=k).evaluate(noisy, value=False)[1]
    e_int = np.sqrt(np.mean((d_int - exact)[inner] ** 2))
    e_reg = np.sqrt(np.mean((d_reg - exact)[inner] ** 2))
    assert e_int / e_reg > 3


def test_gcv_table_is_the_regressions_residual():
    """Each GCV entry is ``n RSS / m / (n - p)²`` of the regression's projection ``Q Qᵀ`` (the residual's sum of
    squares read off the triangular factor of the design with the samples beside it)."""
    from irdic.surface.regression import ls_design, median_spacing

    rng = np.random.default_rng(11)
    psi = grid(0.7, 14)
    psi = psi + rng.normal(0, 0.05, psi.shape)
    F = curved(psi) + rng.normal(0, 0.005, (psi.shape[0], 3))
    h, n = median_spacing(psi), psi.shape[0]
    _, table = gcv_spatial(psi, F)
    assert len(table) >= 3
    for k, pp, g in table:
        Qm = ls_design(psi, k, h, 0.95, 1.0)[3]
        rss = float(np.sum((F - Qm @ (Qm.T @ F)) ** 2))
        assert pp == Qm.shape[1]
        np.testing.assert_allclose(g, n * rss / 3 / (n - pp) ** 2, rtol=1e-10)


def test_spatial_interpolant_errors():
    psi = grid(1.0, 3)
    with pytest.raises(GeometryError, match=r"points 0 and 49 have the same surface parameters"):
        SpatialInterpolant(np.r_[psi, psi[:1]])
    with pytest.raises(DataError, match="5 point.*at least 6"):
        SpatialInterpolant(psi[:5])
    with pytest.raises(DataError, match="lie on one line"):
        SpatialInterpolant(np.c_[np.arange(10.0), 2 * np.arange(10.0)])
    with pytest.raises(ConfigError, match=r"psi must be finite .* row 2"):
        SpatialInterpolant(np.r_[psi[:2], [[np.nan, 0]], psi[3:]])
    with pytest.raises(ConfigError, match="`c` must be finite and > 0; got -1"):
        SpatialInterpolant(psi, c=-1)
    with pytest.raises(ConfigError, match="`solver` must be one of 'auto', 'global', 'local'; got 'dense'"):
        SpatialInterpolant(psi, solver="dense")
    with pytest.raises(ConfigError, match="smoothing is the centre spacing .* must be >= 1"):
        SpatialInterpolant(psi, smoothing=0.5)
    sp = SpatialInterpolant(psi)
    with pytest.raises(ConfigError, match="values must have N = 49 rows"):
        sp.evaluate(np.zeros(48))
    with pytest.raises(DataError, match="fill the missing points first"):
        sp.evaluate(np.r_[np.nan, np.zeros(48)])


# ----------------------------------------------------------------------------------
# time
# ----------------------------------------------------------------------------------


def test_temporal_interpolant_identity_and_linear_exactness():
    t = np.r_[0.0, 0.5, 1.0, 2.0, 2.5, 4.0]  # irregular (a dropped stage)
    ts = TemporalInterpolant(t)
    np.testing.assert_array_equal(ts.weights(), np.eye(6))
    f = 3 - 2 * t
    te = np.array([0.25, 1.7, 3.9])
    np.testing.assert_allclose(ts.weights(te) @ f, 3 - 2 * te, atol=1e-12)
    np.testing.assert_allclose(ts.weights(te, 1) @ f, -2, atol=1e-12)
    assert np.isnan(ts.weights([-0.1, 4.1])).all()
    with pytest.raises(DataError, match=r"times must be strictly increasing: times\[1\] = 1.0 s is followed by"):
        TemporalInterpolant([0.0, 1.0, 1.0])
    with pytest.raises(DataError, match=r"times: 1 time\(s\); .* needs at least 2"):
        TemporalInterpolant([0.0])


def test_smooth_series_fills_gaps_from_the_own_series():
    t = np.linspace(0, 10, 21)
    f = np.c_[np.sin(t / 3), t**2 / 50]
    g = f.copy()
    g[[4, 9], 0] = np.nan
    g[:, 1] = np.nan
    g[3, 1] = 1.0  # a single valid value: the series cannot be interpolated
    fit = smooth_series(g, t, smoothing=None)
    np.testing.assert_array_equal(np.delete(fit.value[:, 0], [4, 9]), np.delete(f[:, 0], [4, 9]))
    assert np.abs(fit.value[[4, 9], 0] - f[[4, 9], 0]).max() < 1e-2  # a 1 s gap in a 2 Hz series
    assert np.isnan(fit.value[:, 1]).all() and np.isnan(fit.rate[:, 1]).all()


# ----------------------------------------------------------------------------------
# the space-time surface
# ----------------------------------------------------------------------------------


def test_affine_motion_of_a_plane_is_exact_with_missing_points():
    rng = np.random.default_rng(5)
    q = grid(1.0, 10) + rng.uniform(-0.2, 0.2, (441, 2))
    X0 = np.c_[q, 0.3 * q[:, 0] - 0.1 * q[:, 1]]
    G = np.array([[0.01, 0.02, 0.0], [-0.005, 0.03, 0.01], [0.0, 0.01, -0.02]])
    u0 = np.array([0.5, -0.2, 0.1])
    times = np.array([0.0, 1.0, 2.5, 3.0, 4.0])
    X = np.stack([X0 @ (np.eye(3) + t * G).T + t * u0 for t in times])  # linear in time
    X[2, rng.choice(441, 15, replace=False)] = np.nan
    sf = fit_surface(X, times)
    Fs = np.stack([np.eye(3) + t * G for t in times])
    np.testing.assert_allclose(sf.tangents, np.einsum("tij,naj->tnai", Fs, sf.ref_tangents), atol=1e-8)
    np.testing.assert_allclose(sf.velocity, np.broadcast_to(X0 @ G.T + u0, sf.velocity.shape), atol=1e-8)
    assert sf.filled.sum() == 15 and sf.filled[2].sum() == 15
    np.testing.assert_allclose(sf.x[2][sf.filled[2]], (X0 @ (np.eye(3) + 2.5 * G).T + 2.5 * u0)[sf.filled[2]],
                               atol=1e-8)
    st = strain(sf.tangents, sf.ref_tangents)
    N = np.cross(sf.ref_tangents[0, 0], sf.ref_tangents[0, 1])
    N /= np.linalg.norm(N)
    P0 = np.eye(3) - np.outer(N, N)
    F = np.eye(3) + 4.0 * G
    np.testing.assert_allclose(st.E[-1], np.broadcast_to(0.5 * (P0 @ F.T @ F @ P0 - P0), st.E[-1].shape), atol=1e-8)
    # between stages: linear in time is reproduced
    sf2 = fit_surface(X, times, t_eval=[1.7])
    np.testing.assert_allclose(sf2.x[0], X0 @ (np.eye(3) + 1.7 * G).T + 1.7 * u0, atol=1e-8)


def test_half_shell_tangents_and_normals():
    S, h, x = half_shell()
    times = np.array([0.0, 1.0, 2.0])
    X = np.stack([x, x, x])  # static (the heating experiment)
    sf = fit_surface(X, times)
    geo = surface_geometry(sf.tangents)
    n_true = np.c_[np.sin(S / 65), 0 * S, np.cos(S / 65)]
    inner = sf.edge_distance >= 2
    err_n = np.linalg.norm(geo.normal[1] - n_true, axis=1)
    deep = sf.edge_distance >= 5
    assert np.sqrt(np.mean(err_n[inner] ** 2)) < 1e-3 and err_n[deep].max() < 2e-4
    # dual vectors are dual, the normal is orthogonal to both tangents
    np.testing.assert_allclose(np.einsum("nai,nbi->nab", geo.dual[1], sf.tangents[1]),
                               np.broadcast_to(np.eye(2), (S.size, 2, 2)), atol=1e-12)
    assert np.abs(np.einsum("nai,ni->na", sf.tangents[1], geo.normal[1])).max() < 1e-12
    np.testing.assert_allclose(sf.velocity, 0, atol=1e-12)
    # edge distance: the material grid's distance to the patch border (in the projected Psi)
    assert sf.edge_distance.max() == pytest.approx(25.0, abs=0.2)


@pytest.fixture(scope="module")
def tube_fit():
    tube = Tube(half_angle=60.0)
    times = np.linspace(0, 10, 21)
    X = tube_stages(tube, times)
    sf = fit_surface(X, times, parametrisation="cylinder")
    return tube, times, X, sf


def test_tube_strain_normals_and_velocity(tube_fit):
    tube, times, X, sf = tube_fit
    assert sf.info["parametrisation"]["method"] == "cylinder"
    inner = sf.edge_distance >= 2
    np.testing.assert_allclose(sf.edge_distance, tube.edge, atol=0.06)
    st = strain(sf.tangents, sf.ref_tangents)
    geo = surface_geometry(sf.tangents)
    e_err, n_err, v_err = [], [], []
    for k in range(1, len(times) - 1):
        e_max, e_min = tube.principal_strains(times[k])
        e_err.append(st.e_max[k][inner] - e_max)
        n_err.append(np.linalg.norm(geo.normal[k] - tube.normal(times[k]), axis=1)[inner])
        v_err.append(np.linalg.norm(sf.velocity[k] - tube.velocity(times[k]), axis=1)[inner])
    e_err, n_err, v_err = map(np.concatenate, (e_err, n_err, v_err))
    assert np.sqrt(np.mean(e_err**2)) <= 1e-3
    # normals carry the interpolant's edge error (2-3 mm in: ~1e-2) and the holes of missing points
    assert np.sqrt(np.mean(n_err**2)) <= 2e-2
    deep = sf.edge_distance >= 5
    n_deep = np.concatenate([np.linalg.norm(geo.normal[k] - tube.normal(times[k]), axis=1)[deep]
                             for k in range(1, len(times) - 1)])
    assert np.sqrt(np.mean(n_deep**2)) <= 5e-3
    # velocity: the paper's temporal interpolant (c = 1, R0 = 1 s) at 0.5 s stages, ~1 % of the peak
    v_scale = np.linalg.norm(tube.velocity(5.0), axis=1).max()
    assert np.sqrt(np.mean(v_err**2)) <= 2e-2 * v_scale
    # the largest principal strain at the load peak, 5 mm inside
    assert np.abs(st.e_max[10][deep] - tube.principal_strains(times[10])[0]).max() < 1e-3


def test_missing_points_do_not_poison_their_neighbours(tube_fit):
    tube, times, X, sf = tube_fit
    assert sf.filled.sum() == 200 and np.isfinite(sf.tangents[:, np.isfinite(sf.psi[:, 0])]).all()
    clean = fit_surface(np.stack([tube.x(t) for t in times]), times, sf.psi)
    inner = sf.edge_distance >= 2
    # the surfaces differ only by the interpolant's error at the missing points
    diff = np.abs(sf.tangents - clean.tangents)[:, inner]
    assert diff.max() < 0.05 and np.sqrt(np.mean(diff**2)) < 3e-3
    # and the strain is as accurate as without missing points
    e_miss = strain(sf.tangents, sf.ref_tangents).e_max
    e_clean = strain(clean.tangents, clean.ref_tangents).e_max
    truth = np.array([tube.principal_strains(t)[0] for t in times])[:, None]
    rms = [np.sqrt(np.mean((e - truth)[1:-1][:, inner] ** 2)) for e in (e_miss, e_clean)]
    assert rms[0] <= 1.3 * rms[1] + 5e-5
    # the filled positions lie within the interpolant's accuracy between points (c R0 ~ spacing)
    err = np.abs(sf.x[sf.filled] - np.stack([tube.x(t) for t in times])[sf.filled])
    assert np.median(err) < 0.02 and err.max() < 0.2
    # velocities come from the points' own series filled in time: no bumps there
    assert sf.info["filled_in_time"] == 200
    v_space = fit_surface(X, times, sf.psi, fill="space").velocity
    v_truth = np.stack([tube.velocity(t) for t in times])
    near = sf.filled.any(axis=0) & inner
    err_v = np.abs(sf.velocity - v_truth)[1:-1, near].max()
    assert err_v < 0.5 * np.abs(v_space - v_truth)[1:-1, near].max()


@pytest.mark.parametrize("smoothing", [None, 3.0, (4.0, 3.0)])
def test_fit_stages_is_fit_surface_at_its_stage_times(tube_fit, smoothing):
    """Interpolating in time, the surface at a stage's own time is that stage's spatial fit alone; stacked
    stages with their own shape stages are each fitted as alone."""
    _, times, X, _ = tube_fit
    rng = np.random.default_rng(4)
    Xn = X + rng.standard_normal(X.shape) * 0.003  # regression must see something to smooth
    ops = {}  # one fill operator for both (the fields stage shares it the same way)
    sf = fit_surface(Xn, times, parametrisation="cylinder", smoothing=smoothing, operators=ops)
    nodes = np.flatnonzero(np.isfinite(sf.x).all(axis=-1).any(axis=0))
    sub = np.array([0, 3, 8, 20])  # 3: a stage with missing points
    x_fit, tang = fit_stages(Xn[sub], sf.psi, nodes=nodes, smoothing=smoothing, operators=ops)
    scale = np.nanmax(np.abs(sf.tangents))
    np.testing.assert_allclose(x_fit, sf.x[sub], rtol=0, atol=1e-8 * np.nanmax(np.abs(sf.x)))
    np.testing.assert_allclose(tang, sf.tangents[sub], rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose(tang[0], sf.ref_tangents, rtol=0, atol=1e-8 * scale)
    # stacked with another record's stages and shape stage: each as alone
    Xm = X + rng.standard_normal(X.shape) * 0.003
    _, tang_m = fit_stages(Xm[sub], sf.psi, nodes=nodes, smoothing=smoothing, operators=ops)
    shapes = np.concatenate([np.broadcast_to(Xn[0], (4,) + Xn[0].shape), np.broadcast_to(Xm[0], (4,) + Xm[0].shape)])
    _, both = fit_stages(np.concatenate([Xn[sub], Xm[sub]]), sf.psi, nodes=nodes, smoothing=smoothing,
                         shape_stage=shapes, operators=ops)
    np.testing.assert_allclose(both[:4], tang, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(both[4:], tang_m, rtol=0, atol=1e-10 * scale)
    assert np.nanmax(np.abs(tang_m - tang)) > 1e3 * 1e-10 * scale  # the two records' tangents differ
    # the tangents alone (the noise probes' way): the same tangents, no positions
    none, alone = fit_stages(np.concatenate([Xn[sub], Xm[sub]]), sf.psi, nodes=nodes, smoothing=smoothing,
                             shape_stage=shapes, operators=ops, values=False)
    assert none is None
    np.testing.assert_allclose(alone, both, rtol=0, atol=1e-12 * scale)

def test_local_and_global_solvers_agree_on_strain(tube_fit):
    tube, times, X, sf = tube_fit
    other = "global" if sf.info["solver"] == "local" else "local"
    sf2 = fit_surface(X, times, sf.psi, solver=other)
    inner = sf.edge_distance >= 2
    e1 = strain(sf.tangents, sf.ref_tangents).e_max[1:-1][:, inner]
    e2 = strain(sf2.tangents, sf2.ref_tangents).e_max[1:-1][:, inner]
    assert np.sqrt(np.mean((e1 - e2) ** 2)) < 1e-3


def test_sparse_stage_is_left_out_with_a_warning():
    tube = Tube(half_angle=40.0, spacing=1.5)
    times = np.arange(6.0)
    X = np.stack([tube.x(t) for t in times])
    X[3, ::3] = np.nan
    X[3, 1::3] = np.nan  # only a third valid
    with pytest.warns(IrdicWarning, match=r"1 stage\(s\) with fewer than 50% valid points .*\[3\]"):
        sf = fit_surface(X, times)
    assert not sf.stage_used[3] and sf.stage_used[[0, 1, 2, 4, 5]].all()
    inner = sf.edge_distance >= 2
    # stage 3 comes from the temporal interpolant across a 2 s gap
    assert np.abs(sf.x[3] - tube.x(3.0))[inner].max() < 0.05


def test_fit_surface_errors():
    tube = Tube(half_angle=30.0, spacing=2.0)
    X = np.stack([tube.x(0.0), tube.x(1.0)])
    with pytest.raises(ConfigError, match="times has 3 entries but x has 2 stages"):
        fit_surface(X, [0.0, 1.0, 2.0])
    with pytest.raises(DataError, match=r"times must be strictly increasing: times\[0\] = 1.0 s"):
        fit_surface(X, [1.0, 0.5])
    with pytest.raises(DataError, match="1 stage.*at least 2"):
        fit_surface(X[:1], [0.0])
    with pytest.raises(ConfigError, match=r"x must have shape \(stages, points, 3\)"):
        fit_surface(X[0], [0.0])
    Y = X.copy()
    Y[0, : X.shape[1] // 2 + 1] = np.nan
    with pytest.raises(DataError, match="stage 0 \\(the reference\\) has only"):
        fit_surface(Y, [0.0, 1.0])
    with pytest.raises(ConfigError, match="smoothing_t must be None"):
        fit_surface(X, [0.0, 1.0], smoothing_t="lots")


def test_temporal_smoothing_of_noisy_positions_improves_velocity():
    tube = Tube(half_angle=30.0, spacing=1.0)
    times = np.linspace(0, 10, 41)
    rng = np.random.default_rng(7)
    X = np.stack([tube.x(t) for t in times]) + rng.normal(0, 0.005, (41, tube.S.size, 3))
    psi = surface_parameters(np.stack([tube.x(t) for t in times]))[0]
    truth = np.stack([tube.velocity(t) for t in times])
    inner_t = slice(4, -4)
    v_int = fit_surface(X, times, psi).velocity
    sf = fit_surface(X, times, psi, smoothing_t="gcv")
    e_int = np.sqrt(np.mean((v_int - truth)[inner_t] ** 2))
    e_gcv = np.sqrt(np.mean((sf.velocity - truth)[inner_t] ** 2))
    assert sf.info["smoothing_t"] > 1 and e_int / e_gcv > 3


# ----------------------------------------------------------------------------------
# geometry and edges
# ----------------------------------------------------------------------------------


def test_geometry_of_a_skew_parametrisation():
    a = np.array([[[2.0, 0, 0], [1.0, 1.0, 0]]])
    geo = surface_geometry(a)
    np.testing.assert_allclose(geo.metric[0], [[4, 2], [2, 2]])
    np.testing.assert_allclose(geo.dual[0], [[0.5, -0.5, 0], [0, 1, 0]])
    np.testing.assert_allclose(geo.normal[0], [0, 0, 1])
    assert geo.area_ratio[0] == pytest.approx(2.0)


def test_degenerate_tangents_are_nan_with_a_logged_reason(caplog):
    a = np.array([[[1.0, 0, 0], [0, 1.0, 0]], [[1.0, 0, 0], [2.0, 0, 0]], [[np.nan, 0, 0], [0, 1, 0]]])
    with caplog.at_level(logging.WARNING, logger="irdic.surface"):
        geo = surface_geometry(a)
    assert "1 of 2 tangent pairs are degenerate" in caplog.text
    assert np.isnan(geo.normal[1]).all() and np.isnan(geo.dual[1]).all() and geo.degenerate[1]
    assert np.isnan(geo.normal[2]).all() and not geo.degenerate[2]
    np.testing.assert_allclose(geo.normal[0], [0, 0, 1])
    with pytest.raises(GeometryError, match="all 1 tangent pairs are degenerate"):
        surface_geometry(a[1:2])


def test_edge_distance_of_a_square_with_a_hole():
    psi = grid(1.0, 10)  # square [-10, 10]^2
    hole = (np.abs(psi[:, 0] - 4) <= 2) & (np.abs(psi[:, 1]) <= 2)  # 5 x 5 points removed
    d = edge_distance(np.where(hole[:, None], np.nan, psi))
    assert np.isnan(d[hole]).all() and np.isfinite(d[~hole]).all()

    def at(p, q):
        return d[np.flatnonzero((psi[:, 0] == p) & (psi[:, 1] == q))[0]]

    # near the outer edge: the distance to the square
    near = ~hole & (np.abs(psi).max(axis=1) >= 9)
    np.testing.assert_allclose(d[near], 10 - np.abs(psi[near]).max(axis=1), atol=1e-9)
    assert at(0, 0) == pytest.approx(1.0)  # beside the hole's left side (the valid ring at x = 1)
    assert at(4, -5) == pytest.approx(2.0)  # below the hole's bottom side (y = -3)
    assert at(-3, 0) == pytest.approx(4.0)
    assert at(-5, -4) == pytest.approx(5.0)  # nearer to the outer edge than to the hole


# ----------------------------------------------------------------------------------
# the synthetic experiments (irdic.synthetic) and a real DIC sample
# ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["tube", "halfshell"])
def test_synthetic_experiment_truth(name):
    synthetic = pytest.importorskip("irdic.synthetic")
    from irdic.gradient import material_rate, surface_gradient

    ex = synthetic.experiment(name, "demo", dic_noise=0.0)
    tr = ex.truth()
    sf = fit_surface(ex.x_dic, ex.dic_times)
    inner = tr.patch_edge_distance.values >= 2
    mid = slice(1, -1)
    st = strain(sf.tangents, sf.ref_tangents)
    e = (st.e_max - tr.strain_max.values)[mid][:, inner]
    assert np.sqrt(np.mean(e**2)) < 1e-3
    # with the true pixel derivatives and camera, the gradient and rate follow the surface's accuracy
    J = ex.camera.jacobian(tr.x.values.reshape(-1, 3)).reshape(tr.x.shape[:2] + (2, 3))
    g = np.stack([tr.dT_du.values, tr.dT_dv.values], -1)
    ok = inner[None] & tr.visible.values
    ok[[0, -1]] = False
    grad = surface_gradient(g, J, sf.tangents)
    scale = np.linalg.norm(tr.temperature_gradient.values[ok], axis=-1).max()
    err = np.linalg.norm(grad - tr.temperature_gradient.values, axis=-1)[ok]
    assert np.sqrt(np.mean(err**2)) < 3e-3 * scale
    rate = material_rate(tr.dT_dt_pixel.values, g, J, sf.velocity).rate
    r_scale = np.abs(tr.temperature_rate.values[ok]).max()
    assert np.sqrt(np.mean((rate - tr.temperature_rate.values)[ok] ** 2)) < 5e-3 * r_scale


@pytest.mark.samples
def test_real_dice_stereo_sample(samples):
    from irdic.io import read_dic

    stages = [read_dic(samples / "dice" / f"DICe_solution_{i}.txt") for i in (0, 1)]
    X = np.stack([s["x"].values for s in stages])
    assert X.shape == (2, 1089, 3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sf = fit_surface(X, [0.0, 1.0])
    info = sf.info["parametrisation"]
    assert info["method"] == "plane"
    assert sf.info["spacing"] == pytest.approx(0.1405, abs=5e-4)  # 33 x 33 subsets, 25 px steps
    st = strain(sf.tangents[1], sf.ref_tangents)
    inner = sf.edge_distance >= 0.5
    assert inner.sum() == 625
    # this regression case deforms by ~0.5 % (neighbouring displacements differ by ~1e-3 mm)
    assert np.median(st.e_max[inner]) == pytest.approx(0.00713, abs=1e-4)
    assert np.median(st.e_min[inner]) == pytest.approx(0.00234, abs=1e-4)
    # cross-check with an independent estimate: the least-squares affine fit of the displacement
    axes, o = info["axes"], info["origin"]
    P = np.c_[(X[0] - o) @ axes[:2].T, np.ones(1089)]
    grad = np.linalg.lstsq(P, X[1] - X[0], rcond=None)[0][:2].T
    a = axes[:2].T + grad
    E_affine = 0.5 * (a.T @ a - np.eye(2))
    trace = np.mean(np.trace(st.E2[inner], axis1=-2, axis2=-1))
    assert trace == pytest.approx(np.trace(E_affine), rel=0.25)


def test_spatial_smoothing_of_noisy_positions_improves_strain():
    tube = Tube(half_angle=40.0, spacing=0.8)
    times = np.linspace(0, 10, 11)
    rng = np.random.default_rng(8)
    clean = np.stack([tube.x(t) for t in times])
    X = clean + rng.normal(0, 0.005, clean.shape)  # DIC-like coordinate noise
    psi = surface_parameters(clean, "cylinder")[0]
    truth = np.array([tube.principal_strains(t)[0] for t in times])[:, None]
    inner = tube.edge >= 3
    e_int = strain((sf := fit_surface(X, times, psi)).tangents, sf.ref_tangents).e_max
    sm = fit_surface(X, times, psi, smoothing="gcv")
    e_gcv = strain(sm.tangents, sm.ref_tangents).e_max
    rms_int = np.sqrt(np.mean((e_int - truth)[1:-1][:, inner] ** 2))
    rms_gcv = np.sqrt(np.mean((e_gcv - truth)[1:-1][:, inner] ** 2))
    assert sm.info["smoothing"] > 1 and sm.info["solver"] == "regression" and len(sm.info["gcv"]) >= 3
    assert rms_int > 3e-3  # 0.005 mm noise on a 0.8 mm grid: interpolated strains are noise
    assert rms_int / rms_gcv > 3
    # choosing alone (the fields stage's choice for the record) chooses what the fit chose
    chosen = fit_surface(X, times, psi, smoothing="gcv", smoothing_t="gcv", choose_only=True)
    both = fit_surface(X, times, psi, smoothing="gcv", smoothing_t="gcv").info
    assert {k: chosen[k] for k in ("smoothing", "smoothing_shape", "smoothing_t")} == \
        {k: both[k] for k in ("smoothing", "smoothing_shape", "smoothing_t")}
    assert both["smoothing_t"] > 1 and both["smoothing"] > 1


def test_duplicate_points_are_left_out_with_a_logged_reason(caplog):
    tube = Tube(half_angle=30.0, spacing=1.5)
    times = np.array([0.0, 1.0, 2.0])
    X = np.stack([tube.x(t) for t in times])
    X = np.concatenate([X, X[:, 7:8]], axis=1)  # point 7 exported twice
    with caplog.at_level(logging.WARNING, logger="irdic.surface"):
        sf = fit_surface(X, times)
    assert "1 point(s) have the same surface parameters" in caplog.text
    assert sf.info["duplicates"] == [X.shape[1] - 1]
    assert np.isnan(sf.tangents[:, -1]).all() and np.isfinite(sf.tangents[:, 7]).all()


def test_gradient_risk_of_points_denser_than_the_pixels_is_judged_one_per_pixel():
    """Points 0.15 mm apart carrying the noise of 0.35 mm pixels (each point its nearest pixel's): judged on
    all points, the white-noise estimate takes the pilot (the least smoothed regression follows the
    correlated noise); judged on one point per pixel (``separation``) it takes a spacing whose gradient error
    is near the best candidate's."""
    from irdic.surface.regression import gradient_risk_spatial

    rng = np.random.default_rng(3)
    psi = np.stack(np.meshgrid(np.arange(64.0), np.arange(64.0)), -1).reshape(-1, 2) * 0.15
    psi = psi + rng.uniform(-0.01, 0.01, psi.shape)
    f = 0.2 * (psi[:, 0] - 5) ** 2 / 5 + 0.3 * psi[:, 1] + np.sin(psi[:, 0] / 2)
    g = np.c_[0.4 * (psi[:, 0] - 5) / 5 + np.cos(psi[:, 0] / 2) / 2, np.full(len(psi), 0.3)]
    pixel = np.unique(np.floor(psi / 0.35).astype(int), axis=0, return_inverse=True)[1].ravel()
    F = f[:, None] + rng.normal(0, 0.05, (pixel.max() + 1, 8))[pixel]

    def error(k):
        _, d1, d2 = SpatialInterpolant(psi, smoothing=k).evaluate(F, value=False)
        return np.sqrt(np.mean((d1 - g[:, :1]) ** 2 + (d2 - g[:, 1:]) ** 2))

    k_white, _ = gradient_risk_spatial(psi, F)
    k, table = gradient_risk_spatial(psi, F, separation=0.35)
    assert k_white <= 3 and k > 8
    # the candidates are in units of the subset's spacing, returned in the whole cloud's
    assert table[0][0] == pytest.approx(2.0 * 0.35 / 0.15, rel=0.25)
    best = min(error(kk) for kk in (8, 12, 16, 20, 24))
    assert error(k) <= 1.5 * best < 0.2 * error(k_white)


def test_gradient_risk_estimates_the_gradient_error_and_beats_gcv():
    """The spacing of the temperature regression is chosen for its gradient. The Mallows-type
    estimate tracks the true mean squared gradient error at every spacing, and its choice has a smaller
    gradient error than GCV's (which judges values: a flat curve on smooth fields)."""
    from irdic.surface.regression import GRADIENT_CANDIDATES, gradient_risk_spatial

    rng = np.random.default_rng(1)
    psi = np.stack(np.meshgrid(np.arange(40.0), np.arange(40.0)), -1).reshape(-1, 2) * 0.5
    psi = psi + rng.uniform(-0.1, 0.1, psi.shape)
    f = 0.02 * (psi[:, 0] - 10) ** 2 + 0.3 * psi[:, 1] + np.sin(psi[:, 0] / 4)
    g = np.c_[0.04 * (psi[:, 0] - 10) + np.cos(psi[:, 0] / 4) / 4, np.full(len(psi), 0.3)]
    F = f[:, None] + rng.normal(0, 0.05, (len(psi), 8))  # 0.05 K on 8 "times"
    k, table = gradient_risk_spatial(psi, F)
    true = {}
    for kk, _, risk, _ in table:
        _, d1, d2 = SpatialInterpolant(psi, smoothing=kk).evaluate(F, value=False)
        true[kk] = np.mean((d1 - g[:, :1]) ** 2 + (d2 - g[:, 1:]) ** 2)
        # within 40 % of the true risk or 10 % of the least smoothed candidate's (the pilot's scatter)
        assert abs(risk - true[kk]) <= max(0.4 * true[kk], 0.1 * true[table[0][0]]), (kk, risk, true[kk])
    assert len(table) >= 8 and table[0][0] == GRADIENT_CANDIDATES[0]
    assert true[k] <= 1.2 * min(true.values()), (k, true)
    k_gcv, _ = gcv_spatial(psi, F)
    assert true[k] <= 0.7 * true[k_gcv], (k, k_gcv, true)


def test_the_laplacian_risk_takes_the_widest_spacing_within_one_standard_error():
    """The one-standard-error rule of the Laplacian's risk: where the wider candidates' estimated risks differ
    from the least by their noise alone (a noise-dominated Laplacian: the paper-scale moving tube's curve was
    flat from 12 to 32 spacings, 16 the least by 1 % of the pilot's scatter, and 16 had 4 times the error of
    32), the widest; where a wider spacing's risk stands out of that noise (a narrow feature's bias), not it."""
    from irdic.surface.regression import _widest_within_one_se

    rng = np.random.default_rng(7)
    pj = rng.uniform(0.0, 30.0, (6000, 2))  # mm
    ks = [4.0, 8.0, 12.0, 16.0, 24.0]
    h = 0.25

    def tile_noise(scale, side=8.0):  # noise correlated within tiles of the regression's reach
        cell = np.floor(pj / side).astype(int)
        ids = np.unique(cell[:, 0] * 100 + cell[:, 1], return_inverse=True)[1].ravel()
        return scale * (rng.standard_normal(ids.max() + 1)[ids] + rng.standard_normal(pj.shape[0]))

    base = tile_noise(1.0)
    flat = [base + 5.0, base] + [base + tile_noise(0.3) for _ in ks[2:]]
    table = [(k, 10, float(np.mean(t))) for k, t in zip(ks, flat)]
    assert _widest_within_one_se(table, flat, pj, h) == len(ks) - 1
    # the widest two carry a bias far outside the noise: the widest of the others is taken
    biased = flat[:3] + [flat[3] + 2.0, flat[4] + 4.0]
    table = [(k, 10, float(np.mean(t))) for k, t in zip(ks, biased)]
    assert _widest_within_one_se(table, biased, pj, h) == 2
    # too few tiles to judge a difference: no wider candidate is taken
    table = [(k, 10, float(np.mean(t))) for k, t in zip(ks, flat)]
    assert _widest_within_one_se(table, flat, pj, 100.0) == min(range(len(ks)), key=lambda i: table[i][2])


def test_surface_geometry_in_blocks_of_times_equals_one_block():
    from irdic.surface.geometry import _geometry
    from irdic.threads import stage_threads

    rng = np.random.default_rng(4)
    a = rng.normal(size=(5, 30, 2, 3))
    a[1, 3, 1] = 2 * a[1, 3, 0]  # degenerate
    with stage_threads(2):
        g = surface_geometry(a)
    metric, inv, dual, normal, area, _, degenerate = _geometry(a, 1e-6)
    for x, y in ((g.metric, metric), (g.inverse_metric, inv), (g.dual, dual), (g.normal, normal),
                 (g.area_ratio, area), (g.degenerate, degenerate)):
        assert np.array_equal(x, y, equal_nan=True)
    assert g.degenerate[1, 3] and np.isnan(g.normal[1, 3]).all()


def test_the_regressions_factor_is_built_once_when_two_threads_ask_at_once(monkeypatch):
    import threading
    import time

    import irdic.surface.interpolation as interpolation

    rng = np.random.default_rng(3)
    psi = rng.uniform(0.0, 10.0, (300, 2))
    sp = interpolation.SpatialInterpolant(psi, smoothing=3.0)
    built = []
    design = interpolation.ls_design

    def slow_design(*args):
        built.append(1)
        time.sleep(0.2)  # both threads inside the lazy build at once, were it not guarded
        return design(*args)

    monkeypatch.setattr(interpolation, "ls_design", slow_design)
    F = rng.normal(size=(300, 2))
    out = [None, None]

    def evaluate(i):
        out[i] = sp.evaluate(F)

    threads = [threading.Thread(target=evaluate, args=(i,)) for i in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len(built) == 1 and out[0] is not None and out[1] is not None
    for a, b in zip(out[0], out[1]):
        np.testing.assert_array_equal(a, b)


def test_gradient_risk_measures_noise_correlated_in_space_from_runs_in_time():
    """Noise shared by neighbouring points (pixels, the DIC surface) is not white in space: the white model's
    noise of a wide candidate is several times too low and its risk chooses a spacing of 20 times the best one's
    error. Runs of five consecutive times (the noise white in time) measure each candidate's noise within 25 %,
    and the risk then chooses near the best."""
    from irdic.surface.regression import gradient_risk_spatial

    rng = np.random.default_rng(1)
    psi = np.stack(np.meshgrid(np.arange(40.0), np.arange(40.0)), -1).reshape(-1, 2) * 0.5
    psi = psi + rng.uniform(-0.1, 0.1, psi.shape)
    f = 0.02 * (psi[:, 0] - 10) ** 2 + 0.3 * psi[:, 1] + np.sin(psi[:, 0] / 4)
    g = np.c_[0.04 * (psi[:, 0] - 10) + np.cos(psi[:, 0] / 4) / 4, np.full(len(psi), 0.3)]
    cell = np.unique(np.floor(psi / 1.5).astype(int), axis=0, return_inverse=True)[1].ravel()

    def noise(n):  # 0.05 K white plus 0.05 K shared by the points of a 1.5 mm cell, white in time
        return rng.normal(0, 0.05, (len(psi), n)) + rng.normal(0, 0.05, (cell.max() + 1, n))[cell]

    F = f[:, None] + noise(8)
    k_white, white = gradient_risk_spatial(psi, F)
    k, table = gradient_risk_spatial(psi, F, quintets=f[:, None, None] + noise(40).reshape(len(psi), 8, 5))
    probe = noise(200)
    bias, var = {}, {}
    for (kk, _, _, measured), (_, _, _, modelled) in zip(table, white):
        interp = SpatialInterpolant(psi, smoothing=kk)
        _, d1, d2 = interp.evaluate(probe, value=False)
        var[kk] = np.mean(d1 ** 2 + d2 ** 2)
        _, b1, b2 = interp.evaluate(f[:, None], value=False)
        bias[kk] = np.mean((b1 - g[:, :1]) ** 2 + (b2 - g[:, 1:]) ** 2)
        assert measured == pytest.approx(var[kk], rel=0.25), kk
        if kk >= 4:
            assert modelled < 0.3 * var[kk], kk
    risk = {kk: bias[kk] + var[kk] for kk in var}
    assert risk[k] <= 1.2 * min(risk.values()) and risk[k_white] > 20 * risk[k]


def test_gradient_risk_designs_kept_for_other_samples_give_the_same_table():
    """The candidates' designs kept from one call (``designs``) serve a later call on the same points with other
    samples: its table equals a fresh call's exactly; other points clear them first."""
    from irdic.surface.regression import gradient_risk_spatial

    rng = np.random.default_rng(4)
    psi = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0)), -1).reshape(-1, 2) * 0.5
    psi = psi + rng.uniform(-0.1, 0.1, psi.shape)
    f = 0.3 * np.sin(psi[:, 0] / 2) + 0.1 * psi[:, 1]
    designs = {}
    first = gradient_risk_spatial(psi, f[:, None] + rng.normal(0, 0.05, (len(psi), 4)), designs=designs)
    kept = {k for k in designs if k != "set"}
    assert len(kept) >= len(first[1])  # every candidate tried kept (those that do not fit as such)
    F2 = f[:, None] + rng.normal(0, 0.02, (len(psi), 4))
    assert gradient_risk_spatial(psi, F2, designs=designs) == gradient_risk_spatial(psi, F2)
    other = psi[:600]
    assert gradient_risk_spatial(other, F2[:600], designs=designs) == gradient_risk_spatial(other, F2[:600])
    assert len(designs["set"][0]) <= 600  # the first set's designs cleared
