"""Footprint temperatures: local-linear box values of the IR pixels, against analytic truth."""

import numpy as np
import pytest

from irdic.noise import interpolation_noise_gains
from irdic.footprint.temperature import FootprintOperator, footprint_side


def _disc(H=40, W=50, r=15.0):
    v, u = np.mgrid[:H, :W].astype(float)
    return (u - 24.3) ** 2 + (v - 19.6) ** 2 <= r * r, u, v


def test_linear_field_is_reproduced_up_to_the_mask_edge():
    # a cut box's plain mean would sit off the pixel: a bias of the gradient (0.8 K/px) times the shift
    mask, u, v = _disc()
    frames = np.stack([20.0 + 0.8 * u - 0.3 * v, 25.0 - 0.1 * u + 0.6 * v])
    out = FootprintOperator(3).frames(frames, mask)
    np.testing.assert_allclose(out[:, mask], frames[:, mask], atol=1e-9)
    # outside the mask the frames are left as they are
    np.testing.assert_array_equal(out[:, ~mask], frames[:, ~mask])


def test_quadratic_field_offset_and_noise_reduction():
    mask, u, v = _disc(r=18.0)
    side = 3
    frames = (0.02 * u ** 2 + 0.01 * v ** 2)[None]
    out = FootprintOperator(side).frames(frames, mask)[0]
    inner = np.zeros_like(mask)
    inner[1:-1, 1:-1] = mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:] & mask[:-2, :-2] \
        & mask[2:, 2:] & mask[:-2, 2:] & mask[2:, :-2] & mask[1:-1, 1:-1]
    # the box mean of a quadratic: the field plus (side² - 1) / 24 ∇²Θ, ∇²Θ = 2 (0.02 + 0.01) K/px²
    np.testing.assert_allclose(out[inner] - frames[0][inner], (side ** 2 - 1) / 24 * 0.06, atol=1e-12)
    rng = np.random.default_rng(1)
    noise = rng.standard_normal((20,) + mask.shape)
    f = FootprintOperator(side).frames(noise, mask)
    # white noise through a full box of side² pixels: std 1/side (0.333)
    assert abs(f[:, inner].std() - 1 / side) < 0.02, f[:, inner].std()
    # the couple stage's gain of the interpolated footprint temperature (probe): about 1/side of the plain one's
    t = np.arange(8) * 0.25
    g1 = interpolation_noise_gains(t, c=0.95, R0=1.0).temperature
    g3 = interpolation_noise_gains(t, c=0.95, R0=1.0, footprint=3).temperature
    assert 0.25 < g3 / g1 < 0.45, (g1, g3)


def test_footprint_side_is_the_largest_odd_box_within_the_point_spacing():
    for spacing, side in ((3.1, 3), (2.0, 1), (2.9, 1), (5.5, 3), (13.0, 3)):
        g = np.stack(np.meshgrid(np.arange(10) * spacing, np.arange(10) * spacing), -1).reshape(1, -1, 2)
        # the two fields of irdic.footprint.visibility.Projection it reads
        fake = type("P", (), {"local": g, "in_frame": np.ones(g.shape[:2], bool)})()
        assert footprint_side(fake) == side, (spacing, footprint_side(fake))


def test_one_pass_equals_a_second_interpolation_of_the_footprint_frames():
    """The footprint temperature is an extra right-hand side of the same tile factorisations
    (evaluate_series' pixel_operator): equal to interpolating the box-fitted frames in a pass of their own."""
    from irdic.image_rbf import evaluate_series

    mask0, u, v = _disc(r=14.0)
    masks = np.stack([mask0, np.roll(mask0, 1, axis=1), np.roll(mask0, 2, axis=1)])  # a moving specimen
    union = masks.any(axis=0)
    rng = np.random.default_rng(3)
    t = np.arange(6) * 0.5
    frames = 20 + 0.3 * u + 0.01 * (v - 20) ** 2 + 0.5 * t[:, None, None] + rng.normal(0, 0.05, (6,) + u.shape)
    te = np.array([0.6, 1.2, 2.1])
    pts = np.stack([np.c_[24 + 8 * rng.uniform(-1, 1, 50), 19.6 + 8 * rng.uniform(-1, 1, 50)]] * 3)
    op = FootprintOperator(3)
    one = evaluate_series(frames, t, te, pts, masks, pixel_operator=op)
    boxed = op.frames(frames, union)  # the box fit over the union, as the pass applies it
    two = evaluate_series(boxed, t, te, pts, masks)
    plain = evaluate_series(frames, t, te, pts, masks)
    assert np.isfinite(one.theta_extra).sum() > 100
    np.testing.assert_allclose(one.theta_extra, two.theta, atol=1e-12, equal_nan=True)
    # the paper's values and derivatives are untouched by the extra right-hand side (to round-off: the
    # chunks run on worker threads, and a shared edge tile may be built by either of them)
    for a, b in zip(one[:5], plain[:5]):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10, equal_nan=True)
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    assert plain.theta_extra is None


def test_noise_factor_of_a_box_cut_by_a_straight_edge():
    """On the mask the factor is side x the norm of the box fit's row at the nearest pixel: 1 for a whole
    box; at a straight edge the 3 x 3 box keeps 2 columns, the plane through them at the centre column has
    w0 = e0' A^-1 e0 = 3 / 9 (A = [[6, 3, 0], [3, 3, 0], [0, 0, 4]]): factor 3 sqrt(1/3) = sqrt(3)."""
    from irdic.image_rbf import SeriesEvaluation

    mask = np.zeros((20, 20), bool)
    mask[2:18, 5:18] = True
    op = FootprintOperator(3)
    vv, uu = np.nonzero(mask)
    op(mask, np.c_[uu, vv])
    local = np.array([[[10.2, 9.9], [5.1, 10.0]]])  # inside; on the mask's first column
    res = SeriesEvaluation(*(np.zeros((1, 2)),) * 5, np.ones(1, bool))
    f = op.noise_factor(local, res, 2, np.array([], np.int64), np.zeros((9, 1, 0, 2)))
    np.testing.assert_allclose(f, [[1.0, np.sqrt(3.0)]], rtol=1e-12)


def _footprint_errors(scale, n):
    """The tube's footprint temperatures minus the truth over ``n`` IR noise realisations (0.05 K) through the
    couple stage: (n, T, N) K, and the last realisation's points."""
    from irdic.coupling import couple

    from .._synthetic_stores import synthetic_inputs

    errs, pts = [], None
    for seed in range(n):
        dic, ir, cal, truth = synthetic_inputs("tube", scale, ir_noise=0.05, seed=seed)
        pts = couple(dic, ir, cal)
        errs.append(pts.temperature_footprint.values - truth.sel(point=pts.point).temperature.values)
    return np.array(errs), pts


def test_noise_factor_matches_monte_carlo_on_the_couple_stage():
    """Per point, the footprint temperature's scatter over IR noise realisations is the probe gain times the
    noise factor (whole boxes, cut boxes and points extrapolated from the edge), within the Monte Carlo
    spread (8 realisations: about 25 % per point, a few % over a group)."""
    e, pts = _footprint_errors("tiny", 8)
    e = (e - e.mean(axis=0)) * np.sqrt(len(e) / (len(e) - 1))  # the noise: the box's offset is not
    pred = 0.05 * pts.attrs["ir_noise_gain_temperature_footprint"] * pts.temperature_footprint_noise_factor.values
    status = pts.status.values
    for group in (status == 0, status == 1):
        ok = group & np.isfinite(e).all(axis=0)
        assert ok.sum() > 50
        ratio = np.sqrt(np.mean(e[:, ok] ** 2)) / np.sqrt(np.mean(pred[ok] ** 2))
        assert 0.85 < ratio < 1.15, (ratio, ok.sum())


def test_pixel_pitch_is_the_size_of_a_pixel_on_the_surface():
    """The fields stage judges its regression's spacing on about one point per pixel when the points are denser
    (:func:`irdic.surface.regression.gradient_risk_spatial`, ``separation``): the pixel's size in mm, from the
    projected positions of neighbouring points; None without them."""
    import xarray as xr

    from irdic.footprint.fields import pixel_pitch

    rng = np.random.default_rng(4)
    psi = np.stack(np.meshgrid(np.arange(30.0), np.arange(20.0)), -1).reshape(-1, 2) * 0.2
    psi += rng.uniform(-0.02, 0.02, psi.shape)
    # 0.25 mm per pixel, rotated, moving by a few px over the record, some points not projected
    rot = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    pix = np.stack([psi @ rot.T / 0.25 + [100 + 3 * k, 50] for k in range(7)])
    pix[2, :40] = np.nan
    points = xr.Dataset({"pixel": (("time", "point", "axis"), pix)})
    assert pixel_pitch(points, psi) == pytest.approx(0.25, rel=1e-6)
    assert pixel_pitch(points.drop_vars("pixel"), psi) is None
    assert pixel_pitch(points.isel(point=slice(0, 5)), psi[:5]) is None


def test_probes_carry_the_correlated_noise_of_points_extrapolated_from_the_edge():
    """The noise probes of the fields stage (:func:`footprint_probes`) against Monte Carlo on the couple stage
    (demo tube, 3 px between points): a point extrapolated from the mask edge takes its value from the pixels
    just inside the edge, and its noise is as correlated with the nearest point inside in the probes as over
    6 noise realisations (within the spread of that estimate); drawn independently, as before, the probes put
    that correlation near 0."""
    from scipy.spatial import cKDTree

    from irdic.footprint.fields import footprint_noise, footprint_probes, footprint_temperatures

    e, pts = _footprint_errors("demo", 6)
    e = e - e.mean(axis=0)  # the noise: the box's offset is not
    ext = pts.status.values == 1
    pixel = pts.pixel.transpose("time", "point", "axis").values
    pairs = []  # (time, extrapolated point, the nearest point inside within 4 px)
    for k in range(ext.shape[0]):
        have = np.isfinite(pixel[k]).all(axis=1)
        i, o = np.flatnonzero(ext[k] & have), np.flatnonzero(~ext[k] & have)
        if i.size and o.size:
            d, j = cKDTree(pixel[k][o]).query(pixel[k][i])
            pairs += [(k, a, b) for a, b in zip(i[d < 4.0], o[j[d < 4.0]])]
    k, a, b = np.array(pairs).T
    assert k.size > 200

    def corr(noise):
        x, y = noise[:, k, a], noise[:, k, b]
        ok = np.isfinite(x) & np.isfinite(y)
        return float(np.sum((x * y)[ok]) / np.sqrt(np.sum((x * x)[ok]) * np.sum((y * y)[ok])))

    real = corr(e)
    probes = corr(footprint_probes(footprint_temperatures(pts), None, 0.05)[0](np.random.default_rng(1), 32))
    factor = np.nan_to_num(pts.temperature_footprint_noise_factor.values, nan=1.0)
    independent = corr(footprint_noise(np.random.default_rng(1), pixel, pts.attrs["footprint_px"], (32,)) * factor)
    assert abs(probes - real) < 0.15, (real, probes)
    assert real - independent > 0.3, (real, independent)


def test_probes_without_footprint_share_the_nearest_pixels_noise():
    """Points denser than the pixels (no footprint, side 1): the probes of points with the same nearest pixel
    are the same noise, the others independent (white probes put the regressed gradient's noise of the demo
    tube forced to side 1 at 1 / 1.9 of the data's); a chunk's window carries the positions for them."""
    import xarray as xr

    from irdic.footprint.fields import footprint_probes, window_extras

    pix = np.array([[[10.2, 5.1], [9.8, 4.9], [13.0, 5.0], [20.0, 9.0]]] * 3)
    pts = xr.Dataset({"pixel": (("time", "point", "axis"), pix),
                      "status": (("time", "point"), np.zeros((3, 4), np.int8)),
                      "edge_distance": (("time", "point"), np.full((3, 4), 5.0))})
    draw, s_paper = footprint_probes(pts, None, 0.05)
    assert s_paper is None
    z = draw(np.random.default_rng(0), 2000)
    assert z.shape == (2000, 3, 4)
    np.testing.assert_array_equal(z[:, :, 0], z[:, :, 1])
    c = np.corrcoef(z[:, 0].T)
    assert abs(c[0, 2]) < 0.1 and abs(c[2, 3]) < 0.1 and abs(np.std(z) - 1) < 0.05
    w = window_extras(pts, slice(1, 3))
    assert w["pixel"].shape == (2, 4, 2) and np.isnan(w["extrapolated"]).all()


@pytest.mark.parametrize("side", [1, 3])
def test_footprint_noise_with_a_shared_plan_draws_what_it_draws_without(side):
    """The probe groups share each time's pixels and extrapolation lines (``plan``): group after group, the
    same noise as each group built alone from the same generator, extrapolated points included."""
    from irdic.footprint.fields import footprint_noise

    rng = np.random.default_rng(0)
    u, v = np.meshgrid(np.arange(10) * 1.7, np.arange(8) * 1.3)
    pix = np.stack([u.ravel() + 20, v.ravel() + 30], axis=-1)
    pixel = np.stack([pix + rng.uniform(-0.4, 0.4, pix.shape) + k for k in range(3)])  # (3, 80, 2)
    pixel[1, 7] = np.nan  # a point without a position at one time
    ext = np.full(pixel.shape[:2], np.nan)
    edge = np.flatnonzero(pix[:, 0] == pix[:, 0].max())  # the last column: outside the mask by 0.3-0.9 px
    ext[:, edge] = rng.uniform(0.3, 0.9, (3, edge.size))
    plan = {}
    shared = [footprint_noise(np.random.default_rng(s), pixel, side, (4,), ext, plan) for s in (1, 2)]
    alone = [footprint_noise(np.random.default_rng(s), pixel, side, (4,), ext) for s in (1, 2)]
    assert sorted(plan) == [0, 1, 2]
    for a, b in zip(shared, alone):
        np.testing.assert_array_equal(a, b)
    assert np.all(shared[0][:, :, edge] != 0) and not np.array_equal(shared[0], shared[1])


def test_probes_without_footprint_carry_the_extrapolations_amplified_noise():
    """Points 3 px apart (no footprint): a value extrapolated from the mask edge is a parabola through the
    pixels inside, whose noise it amplifies (1.3 at 1 px, 2.6 at 3 px outside); its probes carry that
    amplification, within the Monte Carlo spread of the couple stage's (4 realisations of a twisted tube).
    Normalised to the inside points' noise, as before, they put the extrapolated values' std at half the
    real one, and the regressed gradient's noise at 1 / 1.4 of its own (a demo-scale member)."""
    from irdic.coupling import couple
    from irdic.footprint.fields import footprint_noise, footprint_probes
    from irdic.synthetic import family

    errs = []
    for seed in range(4):
        scene = family.build(family.recipe(202), "tiny", noise_seed=seed)
        pts = couple(*scene.inputs())
        errs.append(pts.temperature.values - scene.truth().sel(point=pts.point).temperature.values)
    assert pts.attrs["footprint_px"] == 1 and "temperature_paper" not in pts
    e = np.array(errs)
    e = (e - e.mean(axis=0)) * np.sqrt(len(e) / (len(e) - 1))
    status = pts.status.values
    inside, ext = (status == 0) & np.isfinite(e).all(axis=0), (status == 1) & np.isfinite(e).all(axis=0)
    assert inside.sum() > 1000 and ext.sum() > 300

    def amplification(noise):  # the extrapolated values' rms noise over the inside points'
        return float(np.sqrt(np.mean(noise[:, ext] ** 2) / np.mean(noise[:, inside] ** 2)))

    real = amplification(e)
    probes = amplification(np.array(footprint_probes(pts, None, 1.0)[0](np.random.default_rng(0), 16)))
    pixel = pts.pixel.transpose("time", "point", "axis").values
    ext_px = np.where(status == 1, -pts.edge_distance.values, np.nan)
    unit = amplification(footprint_noise(np.random.default_rng(0), pixel, 1, (16,), ext_px))
    assert real > 1.8, real
    assert 0.7 < probes / real < 1.1, (probes, real)
    assert unit / real < 0.6, (unit, real)
