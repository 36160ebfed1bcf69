"""The IR clock from the data (``time_offset: auto``) against synthetic experiments with known offsets.

The frames are rendered at the true times and stored ``offset`` seconds
early (:mod:`tests._clock_scenes`), so the offset to find is known exactly.
Tolerances are the goals: within 0.1 IR frame period on noise-free exports,
0.2 on realistic ones (0.05 K, 2 decimals, mixed edge pixels, DIC noise),
and the truth within 3 stated standard uncertainties.
"""

import re
import time
import warnings

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError, IrdicWarning
from irdic.timing.clock import estimate_from_stores, ir_clock
from irdic.timing.nodes import Mesh, Nodes
from irdic.coupling import couple

from ._clock_scenes import at_dic_times, clock_scene, family_scene

pytestmark = pytest.mark.slow


def _check(offset, *, realistic, tol_frames, **kw):
    dic, ir, cal, _ = clock_scene(offset, realistic=realistic, **kw)
    period = float(np.median(np.diff(ir["time"].values)))
    shifted, attrs = ir_clock(dic, ir, cal, "s07")
    est, std = attrs["ir_time_offset"], attrs["ir_time_offset_std"]
    assert attrs["ir_time_offset_source"] == "estimated"
    assert abs(est - offset) <= tol_frames * period, (est, offset, std)
    assert abs(est - offset) <= 3 * std, (est, offset, std)
    assert std <= 0.25 * period
    np.testing.assert_allclose(shifted["time"].values, ir["time"].values + est)
    return est, std, period


# IR at twice the DIC rate (tiny tube: 13 frames at 2 Hz, DIC 1 Hz): sub-frame and multi-frame, both signs
@pytest.mark.parametrize("frames", [0.37, -0.81, 2.3, -1.65])
def test_clean_ir_faster(frames):
    _check(frames * 0.5, realistic=False, tol_frames=0.1)


@pytest.mark.parametrize("frames,seed", [(0.63, 1), (-2.2, 2), (1.45, 3)])
def test_realistic_ir_faster(frames, seed):
    _check(frames * 0.5, realistic=True, tol_frames=0.2, seed=seed)


# IR at the DIC rate (demo tube, every second frame: 21 frames at 2 Hz, frames at the DIC times)
@pytest.mark.parametrize("frames,realistic", [(0.41, False), (-3.3, False), (2.6, True)])
def test_same_rate(frames, realistic):
    _check(frames * 0.5, realistic=realistic, tol_frames=0.2 if realistic else 0.1, scale="demo", same_rate=True)


# the default tube, whose pattern is weak (4 % around the tube, 4 K of heating): every specimen pixel counts
@pytest.mark.parametrize("frames,realistic,same_rate,seed", [(-0.3, True, False, 7), (4.0, True, False, 8),
                                                             (-1.7, False, False, 0), (1.7, True, True, 9)])
def test_weak_pattern(frames, realistic, same_rate, seed):
    _, std, period = _check(frames * 0.5 if same_rate else frames * 0.25, realistic=realistic,
                            tol_frames=0.2 if realistic else 0.1, scale="demo", same_rate=same_rate, tube={}, seed=seed)
    # the precision all the specimen's pixels allow (about 0.1 frame period at 0.05 K; sampling the points alone gave 0.15)
    assert std <= 0.12 * period


def _family(member, frames, *, realistic, seed=0):
    """(error, std) in IR frame periods of the estimate on a member of the scene family."""
    dic, ir, cal, _, offset, period = family_scene(member, frames, realistic=realistic, seed=seed)
    _, attrs = ir_clock(dic, ir, cal, "s07")
    return (attrs["ir_time_offset"] - offset) / period, attrs["ir_time_offset_std"] / period


# the default tube at tiny scale (12 frames at 2 Hz, DIC 1 Hz; the pattern 4 % around the tube, 4 K): the weakest
# record of the family that is estimated (Cramér-Rao bound 0.081 frame periods at 0.05 K)
@pytest.mark.parametrize("frames,seed", [(-2.6, 11), (-0.35, 12), (0.8, 13), (2.9, 14)])
def test_default_tube_tiny_realistic(frames, seed):
    error, std = _family("weak-tiny", frames, realistic=True, seed=seed)
    assert abs(error) <= 0.2 and abs(error) <= 3 * std, (error, std)
    assert std <= 0.12


@pytest.mark.parametrize("frames", [-1.65, 0.45])
def test_default_tube_tiny_clean(frames):
    error, std = _family("weak-tiny", frames, realistic=False)
    assert abs(error) <= 0.1 and abs(error) <= 3 * std, (error, std)


def test_default_tube_tiny_monte_carlo():
    """Eight noise seeds of the weak tiny record: the truth within 3 std each time, the std honest on average
    (it is mostly the exact variance of an estimator linear in the pixel noise)."""
    z = [np.divide(*_family("weak-tiny", (-2.1, -0.6, 0.4, 1.9)[i % 4], realistic=True, seed=20 + i))
         for i in range(8)]
    assert np.all(np.abs(z) <= 3), z
    assert 0.5 <= np.sqrt(np.mean(np.square(z))) <= 1.6, z


def test_the_estimate_does_not_depend_on_where_the_search_starts():
    """The refinement is the root of a score whose weights are fitted once: searches centred half a grid step
    apart (other candidates, another start) end on the same offset."""
    dic, ir, cal, _, offset, period = family_scene("weak-tiny", 0.7, realistic=True, seed=3)
    a = estimate_from_stores(dic, ir, cal, "s07")
    b = estimate_from_stores(dic, ir, cal, "s07", centre=0.3 * period)
    assert abs(a.offset - b.offset) <= 0.01 * period, (a.offset, b.offset)
    assert abs(a.offset - offset) <= 3 * a.std


def test_constant_rate_loading_at_a_coarse_dic_rate_refused():
    """A ramp at constant rate shows the offset only at its kinks, which fall between the 1 Hz DIC stages:
    a clear refusal (the bound is 0.15 frame periods), not a number."""
    dic, ir, cal, _, _, _ = family_scene("ramp-tiny", 0.6, realistic=True, seed=1)
    with pytest.raises(DataError, match=r"experiments\.s07\.ir\.time_offset: auto cannot estimate") as err:
        ir_clock(dic, ir, cal, "s07")
    assert "constant rate" in str(err.value) and re.search(r"fixes the offset only to \+- [0-9.]+ s", str(err.value))


def test_too_little_motion_for_the_noise_refused():
    """Half the stretch, 10 deg of twist over 9 s and 2 K: 7 px of motion fix the offset to about a third of a
    frame period at 0.05 K (bound 0.35): refused, naming the motion and the precision it allows."""
    dic, ir, cal, _, _, _ = family_scene("slow-small", -1.2, realistic=True, seed=2)
    with pytest.raises(DataError, match=r"experiments\.s07\.ir\.time_offset: auto cannot estimate") as err:
        ir_clock(dic, ir, cal, "s07")
    msg = str(err.value)
    assert re.search(r"move at most [0-9.]+ px in the IR image", msg) and "IR frames" in msg, msg


def test_two_pattern_components_estimated():
    """A second pattern with its own history (not a pattern that only scales): the one-component model leaves
    structure, the two-component one fits it; noise-free, the estimate is within 0.1 frame and 3 std."""
    dic, ir, cal, _, offset, period = family_scene("second-pattern", 1.3, realistic=False)
    est = estimate_from_stores(dic, ir, cal, "s07")
    assert est.rank >= 2
    assert abs(est.offset - offset) <= min(0.1 * period, 3 * est.std), (est.offset - offset, est.std)


def test_the_estimate_does_not_depend_on_the_threads():
    """The models of two and three components fitted one after the other (one thread), at once (two), and beside a
    pool's busy items (the couple stage's masks: the second model runs after the first on the same thread) give
    the same estimate, to the last bit; so do the nodes' own spline and the points' combined at every time."""
    from irdic.numerics.threads import map_beside
    from irdic.threads import stage_threads

    dic, ir, cal, _, offset, period = family_scene("second-pattern", 1.3, realistic=False)
    runs = []
    for threads in (1, 2):
        with stage_threads(threads):
            runs.append(estimate_from_stores(dic, ir, cal, "s07"))
    with stage_threads(2):
        runs.append(map_beside(lambda: estimate_from_stores(dic, ir, cal, "s07"), lambda _: time.sleep(3), [0])[0])
    assert runs[0].rank >= 2
    for est in runs[1:]:
        assert (est.offset, est.std, est.rank) == (runs[0].offset, runs[0].std, runs[0].rank)
    # the nodes moved by their own spline (from the second evaluation on) and by the points' spline combined
    mesh = Mesh(np.cumsum(np.random.default_rng(2).normal(0, 0.3, (6, 40, 2)), axis=0) + np.mgrid[0:40:5, 0:50:10]
                .reshape(2, -1).T[None], np.arange(6.0))
    nodes = Nodes(mesh, 1.5, 1.0)
    t = np.linspace(-0.2, 5.2, 23)
    first, second = nodes.at(t), nodes.at(t)
    assert nodes._own is not None
    np.testing.assert_allclose(second, first, rtol=0, atol=1e-10)


@pytest.mark.parametrize("realistic", [False, True])
def test_pattern_changing_its_shape_refused(realistic):
    """Heat flowing in from a grip changes the pattern's shape on the material as it moves: models of two and
    three components disagree, so the data do not tell the motion from the pattern's change: refused (the
    one-component estimate was 8 frames off with a std of 0.4)."""
    dic, ir, cal, _, _, _ = family_scene("grip-front", -0.6, realistic=realistic, seed=3)
    with pytest.raises(DataError, match=r"experiments\.s07\.ir\.time_offset: auto cannot estimate"):
        ir_clock(dic, ir, cal, "s07")


def test_model_order_where_the_one_component_model_failed():
    """Only the two-component model fitted (the one-component one failed, e.g. most DIC times outside the IR
    record): no rank is assumed to exist, the estimate is refused as a model that cannot be checked."""
    from irdic.timing.offset import _model_order
    from irdic.timing.score import Uncertainty

    quiet = Uncertainty(noise=0.01, robust=0.01, interpolation=0.0)
    assert _model_order({1: (0.1, None, quiet, None, None)}, 0.5) == (1, 0.0)
    assert _model_order({2: (0.1, None, quiet, None, None)}, 0.5) == (2, np.inf)
    rank, shift = _model_order({2: (0.1, None, quiet, None, None), 3: (0.13, None, quiet, None, None)}, 0.5)
    assert rank == 2 and shift == pytest.approx(0.03)


def test_nodes_follow_an_affine_motion_exactly():
    """Nodes carried by the triangulation: positions and reference velocities ``F^-1 w`` exact for an affine
    motion of the points (whatever the triangles), and the gradient of a linear field exact to the outline."""
    rng = np.random.default_rng(0)
    m = np.stack(np.meshgrid(np.arange(20.0), np.arange(15.0)), axis=-1).reshape(-1, 2) * 3.0
    m += rng.uniform(-0.8, 0.8, m.shape)  # a DIC grid, irregular triangles
    t = np.linspace(0.0, 5.0, 11)

    def A(s):
        return np.array([[1 + 0.02 * s, 0.05 * s], [-0.03 * s, 1 - 0.01 * s]])

    dA, b = np.array([[0.02, 0.05], [-0.03, -0.01]]), (lambda s: np.array([2 * s, s * s]))
    nodes = Nodes(Mesh(np.stack([m @ A(s).T + b(s) for s in t]), t), 1.0, 2.0)
    times = np.array([0.2, 1.3, 3.7, 4.9])
    q, r = nodes.at(times), nodes.reference_velocity(times, deformations=3)
    for i, s in enumerate(times):
        np.testing.assert_allclose(q[i], nodes.reference @ A(s).T + b(s), atol=1e-9)
        w = nodes.reference @ dA.T + np.array([2.0, 2 * s])
        # F^-1 linear in time between the deformations' times: exact at them, close between
        expected = np.linalg.solve(A(s), w.T).T
        np.testing.assert_allclose(r[i], expected, atol=1e-9 if s in (0.2, 4.9) else 0.01 * np.abs(expected).max())
    g = nodes.gradient(0.3 * nodes.reference[:, 0] - 0.7 * nodes.reference[:, 1], 4.0)
    np.testing.assert_allclose(g, np.broadcast_to([0.3, -0.7], g.shape), atol=1e-9)


@pytest.mark.parametrize("shape", [(40, 300), (300, 40), (25, 25)])
def test_leading_components_as_the_svd(shape):
    """The pattern model's components (:func:`irdic.timing.samples.leading`) are the leading singular triplets,
    to 1e-9 also where the third stands barely above the noise (1.1-1.2 x its next singular value, where a
    subspace iteration converges slowly), frames fewer or more than nodes."""
    from irdic.timing.samples import leading

    n, m = shape
    rng = np.random.default_rng(3)
    X = (rng.normal(size=(n, 3)) * [30.0, 3.0, 0.015]) @ rng.normal(size=(3, m)) + 0.1 * rng.normal(size=(n, m))
    X -= X.mean(axis=1, keepdims=True)
    u, s, vt = np.linalg.svd(X, full_matrices=False)
    for rank in (1, 2, 3):
        s2, U, V = leading(X, rank)
        np.testing.assert_allclose(s2, s[:rank] ** 2, rtol=1e-9 if rank > 1 else 1e-6)
        tol = 1e-9 if rank > 1 else 1e-6
        np.testing.assert_allclose(np.abs(np.sum(U * u[:, :rank], axis=0)), 1.0, atol=tol)
        np.testing.assert_allclose(np.abs(np.sum(V * vt[:rank].T, axis=0)), 1.0, atol=tol)
        np.testing.assert_allclose(X @ V, U * np.sqrt(s2), atol=1e-9 * s[0])
        np.testing.assert_allclose(U.T @ U, np.eye(rank), atol=1e-12)


def test_samples_and_criterion_independent_of_their_blocks(monkeypatch):
    """The frames are sampled, and the criterion summed, in blocks of
    :data:`~irdic.timing.samples.BLOCK_SAMPLES` samples: blocks of a few frames (ends not aligned with the
    frames) give the samples bit for bit, the criterion to rounding, and the samples equal a bilinear
    interpolation of the smoothed frames at the nodes' positions."""
    import irdic.timing.samples as S
    from irdic.timing.offset import crop_box
    from irdic.footprint.visibility import project_points
    from irdic.camera import load_camera

    dic, ir, cal, _ = clock_scene(0.3, realistic=True, seed=1)
    u, v = ir["u"].values, ir["v"].values
    local = project_points(load_camera(cal), dic, u, v).local
    rows, cols = crop_box(local, (v.size, u.size))
    frames = ir["temperature"].isel(v=rows, u=cols).values
    pos = S.prepared(local - [cols.start, rows.start], dic["time"].values)
    nodes = Nodes(Mesh(pos, dic["time"].values), 1.5, 3.0)
    sampler = S.Sampler(frames, ir["time"].values, nodes, 0.5)
    idx = sampler.inside(0.0, 0.0)
    whole = sampler(0.0, idx), S.Criterion(sampler, idx)(0.0)
    monkeypatch.setattr(S, "BLOCK_SAMPLES", 3 * nodes.M + 7)
    blocked = S.Sampler(frames, ir["time"].values, nodes, 0.5)
    assert len(S._blocks(idx.size, nodes.M)) > 2
    np.testing.assert_array_equal(blocked(0.0, idx), whole[0])
    assert S.Criterion(blocked, idx)(0.0) == pytest.approx(whole[1], rel=1e-12)
    # against scipy's bilinear interpolation of the smoothed frames at the nodes' positions
    from scipy.ndimage import map_coordinates

    q = nodes.at(sampler.t_ir[idx])
    ref = np.stack([map_coordinates(sampler.frames[k].astype(float), [q[i, :, 1], q[i, :, 0]], order=1)
                    for i, k in enumerate(idx)])
    # float32 positions (1e-5 px at 500 px) on gradients of ~0.1 K/px: 1e-6 K
    np.testing.assert_allclose(whole[0], ref, atol=1e-5)


def test_points_denser_than_the_pixels_are_thinned(monkeypatch, caplog):
    """The paper-scale tube's DIC points lie 0.95 px apart in the IR image: the clock carries its nodes on a
    subset at least :data:`~irdic.timing.nodes.POINT_SPACING_PX` apart (its cost in proportion to the points)
    and estimates as from every point, well inside the stated uncertainty; the subset covers the cloud (as many
    nodes)."""
    import irdic.timing.nodes as N

    offset = -0.65
    dic, ir, cal, _ = clock_scene(offset, realistic=True, seed=2, scale="paper")
    period = float(np.median(np.diff(ir["time"].values)))
    with caplog.at_level("INFO", logger="irdic.timing.nodes"):
        thin = estimate_from_stores(dic, ir, cal, "k")
    kept = re.search(r"IR clock: (\d+) of the (\d+) DIC points", caplog.text)
    assert kept and int(kept[1]) < 0.5 * int(kept[2]), caplog.text
    monkeypatch.setattr(N, "POINT_SPACING_PX", 0.0)
    every = estimate_from_stores(dic, ir, cal, "k")
    assert abs(thin.offset - every.offset) <= 0.2 * every.std
    assert thin.std == pytest.approx(every.std, rel=0.05)
    assert abs(thin.points - every.points) <= 0.01 * every.points
    assert abs(thin.offset - offset) <= min(0.2 * period, 3 * thin.std)


def test_thinning_keeps_points_apart_and_covers_the_cloud():
    """Kept points more than the spacing apart in the reference image, every point left out within it of a kept
    one, each kept point's whole track; a sparser cloud as given."""
    from scipy.spatial import cKDTree

    from irdic.timing.nodes import POINT_SPACING_PX, thinned

    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.arange(60.0), np.arange(40.0)), axis=-1).reshape(-1, 2) * 0.6
    g += rng.normal(0.0, 0.05, g.shape)
    pos = g[None] * (1.0 + 0.01 * np.arange(6.0))[:, None, None] + rng.normal(0.0, 0.01, (6,) + g.shape)
    out = thinned(pos)
    ref = out[0]
    assert 0.1 * g.shape[0] < ref.shape[0] < 0.3 * g.shape[0]
    assert cKDTree(ref).query(ref, k=2)[0][:, 1].min() > POINT_SPACING_PX
    assert cKDTree(ref).query(pos[0])[0].max() <= POINT_SPACING_PX
    rows = cKDTree(pos[0]).query(ref)[1]
    np.testing.assert_array_equal(out, pos[:, rows])
    sparse = pos * 3.0
    assert thinned(sparse) is sparse


def test_gaps_interpolated_in_time_as_numpy_interp():
    """Each point's missing times linearly between the times seen either side, held beyond the first and last
    (as :func:`numpy.interp`), for every point at once; points seen at fewer than half the times left out."""
    from irdic.timing.samples import prepared

    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(0.0, 10.0, 30))
    pos = rng.normal(size=(30, 400, 2))
    pos[rng.random((30, 400)) < 0.2] = np.nan
    pos[:5, :40] = np.nan
    pos[-4:, 40:80] = np.nan
    pos[:20, 80:90] = np.nan  # seen at 10 of 30 times
    out = prepared(pos, t)
    seen = np.isfinite(pos).all(axis=2)
    kept = np.flatnonzero(seen.sum(axis=0) >= 15)
    assert out.shape == (30, kept.size, 2) and not np.isin(np.arange(80, 90), kept).any()
    for col, j in enumerate(kept):
        for c in (0, 1):
            np.testing.assert_allclose(out[:, col, c], np.interp(t, t[seen[:, j]], pos[seen[:, j], j, c]),
                                       rtol=0, atol=1e-12)


def _rms(points, ex):
    tr = ex.truth().sel(point=points.point)
    vis = points.visible.values & np.isfinite(tr.temperature.values)
    return float(np.sqrt(np.mean((points.temperature.values - tr.temperature.values)[vis] ** 2)))


def test_point_temperatures_as_with_the_true_offset():
    """An offset error ``e`` adds ``e`` times the temperature rate at the fixed pixel to every point temperature;
    with ``auto`` the point temperatures are as accurate as with the true offset up to that share, bounded by
    three stated standard uncertainties."""
    offset = 0.8  # 1.6 IR frames
    dic, ir, cal, ex = clock_scene(offset, realistic=True, seed=4)
    auto = couple(dic, ir, cal, method="bilinear")
    true_ir = ir.assign_coords(time=ir["time"].values + offset).assign_attrs(time_offset=offset)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IrdicWarning)
        known = couple(dic, true_ir, cal, method="bilinear")
        ignored = couple(dic, ir.assign_attrs(time_offset=0.0), cal, method="bilinear")
    e_auto, e_true, e_none = _rms(auto, ex), _rms(known, ex), _rms(ignored, ex)
    tr = ex.truth().sel(point=auto.point)
    rate = tr.dT_dt_pixel.values[auto.visible.values & np.isfinite(tr.dT_dt_pixel.values)]
    rms_rate = float(np.sqrt(np.mean(rate**2)))  # K/s
    error, std = auto.attrs["ir_time_offset"] - offset, auto.attrs["ir_time_offset_std"]
    extra = np.sqrt(max(e_auto**2 - e_true**2, 0.0))
    assert extra <= 3 * std * rms_rate, (e_auto, e_true, std, rms_rate)
    assert extra <= 2 * abs(error) * rms_rate + 0.1 * e_true, (extra, error, rms_rate)  # the share is the offset's
    assert e_none > 1.5 * e_true  # the offset matters on this scene: the checks above have power
    assert auto.attrs["ir_time_offset_source"] == "estimated"
    assert abs(error) <= 3 * std
    assert known.attrs["ir_time_offset"] == offset and known.attrs["ir_time_offset_std"] == 0.0


def test_static_specimen_refused():
    dic, ir, cal, _ = clock_scene(0.3, name="halfshell", realistic=True)
    with pytest.raises(DataError, match=r"experiments\.s07\.ir\.time_offset: auto cannot estimate") as err:
        ir_clock(dic, ir, cal, "s07")
    msg = str(err.value)
    assert re.search(r"move at most [0-9.e-]+ px in the IR image", msg) and "static specimen" in msg


@pytest.mark.parametrize("seed", [0, 1])
def test_offset_beyond_the_searched_range_refused(seed):
    """The weak tube's 12 frames with the clocks 4 frame periods apart (the search covers 3): a clear refusal,
    never a number whose uncertainty misses the truth (these seeds found a noise minimum 6 frames off)."""
    dic, ir, cal, _ = clock_scene(-2.0, realistic=True, seed=seed, tube={})
    with pytest.raises(DataError, match=r"experiments\.s07\.ir\.time_offset: auto"):
        ir_clock(dic, ir, cal, "s07")


def test_configured_offset_checked():
    offset = 0.6
    dic, ir, cal, _ = clock_scene(offset, realistic=True, seed=5)
    right = ir.assign_coords(time=ir["time"].values + offset).assign_attrs(time_offset=offset)
    with warnings.catch_warnings():
        warnings.simplefilter("error", IrdicWarning)
        _, attrs = ir_clock(dic, right, cal, "s07")
    assert attrs["ir_time_offset"] == offset and attrs["ir_time_offset_source"] == "configured"
    assert abs(attrs["ir_time_offset_estimate"] - offset) <= 3 * attrs["ir_time_offset_estimate_std"]
    wrong = ir.assign_coords(time=ir["time"].values + offset + 0.5).assign_attrs(time_offset=offset + 0.5)
    with pytest.warns(IrdicWarning, match=r"experiments\.s07\.ir\.time_offset: the data put the IR clock"):
        _, attrs = ir_clock(dic, wrong, cal, "s07")
    assert abs(attrs["ir_time_offset_estimate"] - offset) <= 3 * attrs["ir_time_offset_estimate_std"]


def test_configured_offset_on_a_static_specimen_is_not_checked():
    dic, ir, cal, _ = clock_scene(0.0, name="halfshell", realistic=True, mode=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", IrdicWarning)
        shifted, attrs = ir_clock(dic, ir, cal, "s07")
    assert attrs == {"ir_time_offset": 0.0, "ir_time_offset_std": 0.0, "ir_time_offset_source": "configured"}
    assert shifted is ir


def test_ingest_keeps_the_ir_clock_with_auto(tmp_path):
    from irdic.ingest.ir import ingest_ir
    from irdic.store import open_store
    from irdic.synthetic.writers import write_irbis

    for i in range(3):
        write_irbis(tmp_path / f"f{i}.txt", np.full((4, 5), 20.0 + i, np.float32), ms=1000 * (10 + i))
    auto = open_store(ingest_ir(tmp_path, tmp_path / "auto.zarr", time_offset="auto"))
    np.testing.assert_allclose(auto["time"].values, [0.0, 1.0, 2.0])
    assert auto.attrs["time_offset"] == "auto"
    fixed = open_store(ingest_ir(tmp_path, tmp_path / "fixed.zarr", time_offset=0.25))
    np.testing.assert_allclose(fixed["time"].values, [0.25, 1.25, 2.25])
    assert fixed.attrs["time_offset"] == 0.25
    with pytest.raises(ConfigError, match="ir.time_offset must be a finite number of seconds or 'auto'"):
        ingest_ir(tmp_path, tmp_path / "bad.zarr", time_offset="soon")


def test_config_and_cli_accept_auto():
    from irdic.cli import _parser
    from irdic.config import validate_config

    def config(value):
        return {"setups": {"lab": {"markers": {"path": "m"}, "target_image": {"path": "t"}}},
                "experiments": {"s07": {"setup": "lab", "dic": {"path": "d"},
                                        "ir": {"path": "i", "time_offset": value}}}}

    assert validate_config(config("auto"))["experiments"]["s07"]["ir"]["time_offset"] == "auto"
    assert validate_config(config(-0.4))["experiments"]["s07"]["ir"]["time_offset"] == -0.4
    with pytest.raises(ConfigError, match=r"experiments\.s07\.ir\.time_offset: 'soon' is not a number or 'auto'"):
        validate_config(config("soon"))
    args = _parser().parse_args(["ingest-ir", "src", "out.zarr", "--time-offset", "auto"])
    assert args.time_offset == "auto"
    assert _parser().parse_args(["ingest-ir", "src", "out.zarr", "--time-offset", "0.5"]).time_offset == 0.5


def test_info_and_report_show_the_clock(tmp_path):
    import xarray as xr

    from irdic.cli import describe_store
    from irdic.report import collect_figures, write_report
    from irdic.store import write_dataset
    from irdic.timing.summary import clock_summary

    attrs = {"ir_time_offset": 0.8115, "ir_time_offset_std": 0.021, "ir_time_offset_source": "estimated"}
    assert clock_summary(attrs) == "IR clock: time_offset 0.8115 s +- 0.021 s (estimated)"
    assert clock_summary({"ir_noise_k": 0.05}) is None
    write_dataset(xr.Dataset({"temperature": ("time", np.zeros(2))}, attrs=attrs), tmp_path / "s07/points.zarr",
                  stage="couple")
    assert "IR clock: time_offset 0.8115 s +- 0.021 s (estimated)" in describe_store(tmp_path / "s07/points.zarr")
    (tmp_path / "s07/figures").mkdir()
    from PIL import Image

    Image.new("RGB", (4, 4)).save(tmp_path / "s07/figures/history.png")
    page = write_report(collect_figures(tmp_path), tmp_path / "report.html", title="s07").read_text()
    assert "IR clock: time_offset 0.8115 s +- 0.021 s (estimated)" in page


def test_every_time_chunk_gets_the_same_offset():
    dic, ir, cal, _ = clock_scene(-0.7, realistic=True, seed=6)
    _, whole = ir_clock(dic, ir, cal, "s07")
    for i in range(2):
        part = couple(dic, ir, cal, chunk=(i, 2), method="bilinear")
        assert part.attrs["ir_time_offset"] == whole["ir_time_offset"]
        assert part.attrs["ir_time_offset_std"] == whole["ir_time_offset_std"]


def test_uncertainty_by_monte_carlo():
    """Six noise realisations: every truth within 3 std, and the std neither far too small nor far too large."""
    z = []
    for seed in range(10, 16):
        offset = (seed - 12.5) * 0.3  # -0.75 .. +0.75 s: -1.5 .. +1.5 IR frames
        dic, ir, cal, _ = clock_scene(offset, realistic=True, seed=seed)
        _, a = ir_clock(dic, ir, cal, "s07")
        z.append((a["ir_time_offset"] - offset) / a["ir_time_offset_std"])
    z = np.array(z)
    assert np.all(np.abs(z) <= 3), z
    assert 0.3 <= np.sqrt(np.mean(z**2)) <= 2.0, z


def _stretched_plate(growth, noise_seed):
    """Family member drawn-404 (a plate stretched by 3.7 %, heated from its lower edge by a 35 K profile, 17
    stages at 4 Hz, IR at 8 Hz, true offset 0) with the profile's decay length growing ``growth`` times over
    its course (2.17 as drawn), and ``ir`` set to ``auto``."""
    from irdic.synthetic import family

    r = family.recipe(404)
    if growth is not None:
        r["pattern"] = dict(r["pattern"], growth=growth)
    dic, ir, cal = family.build(r, noise_seed=noise_seed).inputs()
    return dic, ir.assign_attrs(time_offset="auto"), cal


@pytest.mark.parametrize("growth, noise_seed", [(None, 404), (None, 405), (1.3, 404), (1.3, 405)])
def test_a_widening_edge_profile_on_a_stretched_plate_is_refused_or_covered(growth, noise_seed):
    """The widening of the edge profile, ``d'(t) y T / d²``, has the form of the stretch's convective term
    ``ε̇ y ∂T/∂y = -ε̇ y T / d``: a shift in time trades one for the other, and the little of the motion's signal
    the pattern model leaves rests on the fitted pattern (before: +4.79 +- 0.083 frames on noise seed 404,
    -4.80 +- 0.069 with a 1.3 x widening, true 0). Refused, or the truth within 3 std."""
    dic, ir, cal = _stretched_plate(growth, noise_seed)
    try:
        _, attrs = ir_clock(dic, ir, cal, "s07")
    except DataError as exc:
        assert "experiments.s07.ir.time_offset" in str(exc)
        return
    assert abs(attrs["ir_time_offset"]) <= 3 * attrs["ir_time_offset_std"], attrs


def test_an_unstable_estimate_is_refused_with_the_reason(monkeypatch):
    """On the drawn plate with noise seed 404 the refinement lands 4.8 frames off with a stated 0.12 frame;
    repeated on the frames with their pixel noise drawn again it moves by about half a frame. With the bound on
    the stated uncertainty and the rival minima's margin relaxed (so that no other check decides), the redraw
    refuses it, saying why."""
    import irdic.timing.checks as checks

    monkeypatch.setattr(checks, "MAX_STD_FRAMES", 0.5)
    monkeypatch.setattr(checks, "RIVAL_SCATTERS", 0.0)
    dic, ir, cal = _stretched_plate(None, 404)
    with pytest.raises(DataError, match=r"experiments\.s07\.ir\.time_offset: auto cannot estimate") as err:
        ir_clock(dic, ir, cal, "s07")
    assert "drawn again" in str(err.value) and "widens while the specimen stretches" in str(err.value)


def test_a_misfit_every_frame_shares_widens_the_uncertainty():
    """With the widening at 1.3 x one pattern component fits each frame but for a misfit the whole frame shares,
    differently from frame to frame; summed per tile it cancels (before: -4.80 +- 0.069 frames, true 0).
    Summed per frame it is the largest part of the uncertainty (about one frame period): refused, saying why."""
    dic, ir, cal = _stretched_plate(1.3, 404)
    with pytest.raises(DataError, match=r"fixes the offset only to \+- [0-9.]+ s \(1\.[0-9]+ IR frames\)") as err:
        ir_clock(dic, ir, cal, "s07")
    assert "each frame misfits the pattern model as a whole" in str(err.value)


def test_the_same_plate_without_the_widening_is_estimated():
    """The control: the same plate and motion with a profile that only scales (no widening) is estimated,
    within 0.2 frame and 3 std of the truth (0) on two noise seeds."""
    for noise_seed in (404, 405):
        dic, ir, cal = _stretched_plate(1.0, noise_seed)
        _, attrs = ir_clock(dic, ir, cal, "s07")
        period = float(np.median(np.diff(ir["time"].values)))
        est, std = attrs["ir_time_offset"], attrs["ir_time_offset_std"]
        assert abs(est) <= min(0.2 * period, 3 * std), (est / period, std / period)


@pytest.mark.parametrize("name, realistic, offsets, same_rate", [
    ("cap-spot", True, (-3.4, 1.7), False),  # a sphere cap, stretched, a hot spot; IR 0.07 K, 2 decimals
    ("cap-spot", True, (-0.6,), True),  # the same with IR at the DIC rate
    ("plate-fine-twist", False, (-0.6, 2.6), False),  # a plate stretched and twisted, smooth heating; noise-free
])
def test_other_geometries_estimated(name, realistic, offsets, same_rate):
    """Members of the noisy fields' scene family that are not tubes (:mod:`irdic.synthetic.family`, their own
    noise, camera and rates; IR at twice the DIC rate, or at its rate), their IR clock put a known number of
    frame periods behind: within 0.2 (realistic) / 0.1 (noise-free) frame and 3 std of the truth, multi-frame
    and sub-frame, both signs (benchmarks/README.md: every member of the family)."""
    from irdic.synthetic import family

    scene = family.member(name)
    dic, ir, cal = scene.inputs(realistic=realistic)
    if same_rate:
        ir = ir.isel(time=at_dic_times(ir["time"].values, scene.dic_times))
        assert ir.sizes["time"] == scene.dic_times.size
    period = float(np.median(np.diff(ir["time"].values)))
    for k in offsets:
        early = ir.assign_coords(time=ir["time"].values - k * period).assign_attrs(time_offset="auto")
        _, attrs = ir_clock(dic, early, cal, "s07")
        err = attrs["ir_time_offset"] - k * period
        assert abs(err) <= (0.2 if realistic else 0.1) * period, (k, err / period)
        assert abs(err) <= 3 * attrs["ir_time_offset_std"], (k, err, attrs["ir_time_offset_std"])


def test_a_travelling_band_on_a_stretched_plate_is_refused():
    """A hot band travelling along a stretched plate (family member plate-band-2mm: 2 mm wide at 0.8 mm/s, the
    points moving 2.3 px) changes the pattern on the material as a motion would: refused, naming the key (the
    reason the message gives depends on the noise and the points kept: the models of two and three components
    disagree, the little motion fixes the offset to more than 0.12 frame, or the criterion falls to the end of
    the searched range), never an estimate."""
    from irdic.synthetic import family

    dic, ir, cal = family.member("plate-band-2mm").inputs()
    with pytest.raises(DataError, match=r"experiments\.s07\.ir\.time_offset: auto") as err:
        ir_clock(dic, ir.assign_attrs(time_offset="auto"), cal, "s07")
    assert any(why in str(err.value) for why in ("fixes the offset only to", "at the end of the searched range"))


@pytest.mark.parametrize("noise, frames, reason", [
    (0.07, 0.21, "each frame misfits the pattern model"),  # drawn-404: without the per-frame part it would stand
    (0.137, 0.178, "too little motion for the record's noise"),  # drawn-202: the noise alone is beyond the bound
])
def test_a_refusal_gives_the_reason_that_decides(noise, frames, reason):
    """The reason a refusal names is one that decides it: the per-frame misfit (a pattern changing its shape as the
    motion would) only where the estimate would stand without it; noise alone beyond the bound is too little
    information (family member drawn-202, a twisted cylinder heated smoothly, 0.073 K, was told of a widening
    edge profile)."""
    from irdic.timing.checks import check_identified
    from irdic.timing.score import Uncertainty

    period = 0.125
    parts = Uncertainty(noise * period, 0.9 * noise * period, 0.0, frames=frames * period)
    with pytest.raises(DataError, match=r"experiments\.s07\.ir\.time_offset: auto cannot estimate") as err:
        check_identified(parts, period, 24.1, "experiments.s07.ir.time_offset")
    assert reason in str(err.value)


@pytest.mark.parametrize("offset_frames, noise_seed", [(-3.4, 404), (-0.6, 405)])
def test_two_equally_good_offsets_refused(offset_frames, noise_seed):
    """drawn-404 (the plate whose edge profile widens while it stretches) with its IR clock 3.4 or 0.6 frames
    behind: two- and three-component models agreed on +7.5 frames (+- 0.07-0.09), while minima 6-12 frames
    from it fitted the frames within 0.5 % as well. Refused, naming both offsets, instead of a confident wrong
    number."""
    dic, ir, cal = _stretched_plate(None, noise_seed)
    period = float(np.median(np.diff(ir["time"].values)))
    early = ir.assign_coords(time=ir["time"].values - offset_frames * period)
    try:
        _, attrs = ir_clock(dic, early, cal, "s07")
    except DataError as exc:
        assert "experiments.s07.ir.time_offset" in str(exc)
        return
    assert abs(attrs["ir_time_offset"] - offset_frames * period) <= 3 * attrs["ir_time_offset_std"], attrs
