"""The scene family: recipes drawn from a seed, and each scene's truth consistent with itself and its frames.

Every check compares independent evaluations of the same truth: finite
differences of the closed forms, the divergence form of the Laplacian, the
eigenvalues of the mixed strain tensor, rays cast back at the points.
"""

import math

import numpy as np
import pytest

from irdic.errors import ConfigError
from irdic.synthetic import family, point_truth
from irdic.synthetic.patterns import MovingBand
from irdic.synthetic.specimens import LABEL_SURFACE


@pytest.fixture(scope="module", params=[0, 1, 2, 3, 5, 7])
def scene(request):
    return family.draw(request.param, "tiny")


def test_recipes_are_reproducible_and_cover_the_kinds():
    assert family.recipe(11) == family.recipe(11)
    assert family.recipe(11) != family.recipe(12)
    recipes = [family.recipe(s) for s in range(60)]
    for what, kinds in family.KINDS.items():
        assert {r[what]["kind"] for r in recipes} == set(kinds), what
    for r in recipes:
        g = r["geometry"]
        assert g["kind"] != "cylinder" or 10 <= g["R"] <= 60
        assert g["kind"] != "sphere" or 30 <= g["Rs"] <= 100
        assert 0.3 <= r["spacing"] <= 1.0
        assert 0.02 <= r["noise"]["ir"] <= 0.1 and r["noise"]["decimals"] in (2, 3)
        assert 0.001 <= r["noise"]["dic"] <= 0.005 and 0 <= r["noise"]["missing"] <= 0.02
        assert r["motion"]["twist"] <= 0.5 and (r["motion"]["kind"] == "twist") == (r["motion"]["twist"] > 0)
        p = r["pattern"]
        assert p["kind"] != "band" or (1.5 <= p["width"] <= 4.0 and 0.5 <= p["speed"] <= 2.0)
        assert 300 <= r["camera"]["distance"] <= 600


@pytest.mark.parametrize("name", sorted(family.FIXED))
def test_fixed_members_build_at_both_scales(name):
    tiny, demo = family.member(name, "tiny"), family.member(name, "demo")
    assert tiny.name == demo.name == name
    assert 150 <= tiny.s.size <= 500 and tiny.dic_times.size == 7
    assert 1200 <= demo.s.size <= 2600 and demo.dic_times.size == family.FIXED[name]["timing"]["stages"]
    # the median nearest-neighbour spacing of the reference points is the recipe's (a grid regular in world x, y)
    x0 = demo.specimen.position(demo.s, demo.h, 0.0)
    from scipy.spatial import cKDTree
    d = cKDTree(x0).query(x0, k=2)[0][:, 1]
    assert np.median(d) == pytest.approx(family.FIXED[name]["spacing"], rel=0.05)
    # the patch lies inside the specimen, seen by the camera inside the IR window at the first, middle and
    # last stage
    s0, s1, h0, h1 = demo.specimen.domain
    assert (demo.s > s0).all() and (demo.s < s1).all() and (demo.h > h0).all() and (demo.h < h1).all()
    t = demo.dic_times[[0, demo.dic_times.size // 2, -1]]
    tr = point_truth(demo.specimen, demo.camera, demo.s[::4], demo.h[::4], t, window=demo.window)
    assert tr.in_window.values.all() and tr.visible.values.mean() > 0.99
    # a twist's shear stays moderate
    assert np.nanmax(np.abs(tr.strain_max.values)) < 0.1


def test_the_truth_is_consistent(scene):
    sp, tr = scene.specimen, scene.truth()
    # the truth's identities: material rate = local + convective, gradient = P Jᵀ ∇_pix Θ
    rate = tr.dT_dt_pixel.values + np.einsum("tnp,tnp->tn", np.stack([tr.dT_du.values, tr.dT_dv.values], -1),
                                             tr.pixel_velocity.values)
    ok = np.isfinite(rate)
    assert ok.mean() > 0.95
    scale = np.abs(tr.temperature_rate.values[ok]).max() + 1e-3
    assert np.abs(rate - tr.temperature_rate.values)[ok].max() < 1e-4 * scale
    J = scene.camera.jacobian(tr.x.values)
    g3 = np.einsum("tnij,tni->tnj", J, np.stack([tr.dT_du.values, tr.dT_dv.values], -1))
    n = tr.normal.values
    g = g3 - np.einsum("tni,tni->tn", g3, n)[..., None] * n
    gs = np.nanmax(np.abs(tr.temperature_gradient.values))
    assert np.nanmax(np.abs(g - tr.temperature_gradient.values)) < 1e-4 * gs
    # closed-form derivatives against central differences
    s, h, t, d = scene.s[::5], scene.h[::5], 0.6 * scene.dic_times[-1], 1e-5
    a_s, a_h = sp.tangents(s, h, t)
    np.testing.assert_allclose((sp.position(s + d, h, t) - sp.position(s - d, h, t)) / (2 * d), a_s, atol=1e-7)
    np.testing.assert_allclose((sp.position(s, h + d, t) - sp.position(s, h - d, t)) / (2 * d), a_h, atol=1e-7)
    np.testing.assert_allclose((sp.position(s, h, t + d) - sp.position(s, h, t - d)) / (2 * d), sp.velocity(s, h, t),
                               atol=1e-6)
    T = sp.temperature
    Ts, Th, Tt = sp.temperature_derivatives(s, h, t)
    np.testing.assert_allclose((T(s + d, h, t) - T(s - d, h, t)) / (2 * d), Ts, atol=1e-6)
    np.testing.assert_allclose((T(s, h + d, t) - T(s, h - d, t)) / (2 * d), Th, atol=1e-6)
    np.testing.assert_allclose((T(s, h, t + d) - T(s, h, t - d)) / (2 * d), Tt, atol=1e-6)
    # the strain's principal values: eigenvalues of the mixed tensor G⁻¹ (g - G) / 2
    A = np.stack(sp.tangents(s, h, 0.0), -2)
    a = np.stack((a_s, a_h), -2)
    G, gm = (np.einsum("...ai,...bi->...ab", q, q) for q in (A, a))
    ev = np.sort(np.linalg.eigvals(np.linalg.solve(G, 0.5 * (gm - G))).real, axis=-1)
    e_max, e_min = sp.principal_strains(s, h, t)[:2]
    np.testing.assert_allclose(np.c_[e_min, e_max], ev, atol=1e-14)
    # the Laplace-Beltrami operator against its divergence form by central differences
    def flux(s, h):
        q = np.stack(sp.tangents(s, h, t), -2)
        m = np.einsum("...ai,...bi->...ab", q, q)
        sg = np.sqrt(np.linalg.det(m))
        Ts, Th, _ = sp.temperature_derivatives(s, h, t)
        return sg, sg[..., None] * np.einsum("...ab,...b->...a", np.linalg.inv(m), np.stack([Ts, Th], -1))
    d = 1e-4
    div = (flux(s + d, h)[1][..., 0] - flux(s - d, h)[1][..., 0] + flux(s, h + d)[1][..., 1]
           - flux(s, h - d)[1][..., 1]) / (2 * d)
    lap = div / flux(s, h)[0]
    np.testing.assert_allclose(sp.laplacian(s, h, t), lap, atol=1e-6 * (np.abs(lap).max() + 1e-3))


def test_rays_cast_at_the_points_hit_them(scene):
    sp, tr, cam = scene.specimen, scene.truth(), scene.camera
    k = scene.dic_times.size // 2
    x = tr.x.values[k]
    d = (x - cam.C) / np.linalg.norm(x - cam.C, axis=-1, keepdims=True)
    hit = sp.trace(cam.C, d, scene.dic_times[k])
    assert (hit.label == LABEL_SURFACE).all()
    np.testing.assert_allclose(hit.s, scene.s, atol=1e-8)
    np.testing.assert_allclose(hit.h, scene.h, atol=1e-8)
    np.testing.assert_allclose(hit.temperature, tr.temperature.values[k], atol=1e-9)
    np.testing.assert_allclose(hit.tau, np.linalg.norm(x - cam.C, axis=-1), rtol=1e-12)
    # beyond the specimen's edge the room
    s0, s1, h0, h1 = sp.domain
    out = sp.position(np.array([s1 + 0.3, s0 - 0.3]), np.array([0.0, 0.0]), scene.dic_times[k])
    d = (out - cam.C) / np.linalg.norm(out - cam.C, axis=-1, keepdims=True)
    hit = sp.trace(cam.C, d, scene.dic_times[k])
    assert (hit.label != LABEL_SURFACE).all() and (hit.temperature == sp.T_background).all()


def test_the_export_is_realistic(scene):
    ir = scene.ir()
    T = ir.temperature.values
    q = 10.0 ** -scene.decimals
    assert T.dtype == np.float32 and T.shape == (scene.ir_times.size,) + tuple(scene.window[:1:-1])
    assert np.abs(T / q - np.round(T / q)).max() < 0.01  # on the export's grid (float32 rounding aside)
    clean = scene.ir(realistic=False).temperature.values
    spec = scene.renderer.clean(scene.ir_times[3]).label == LABEL_SURFACE
    from scipy import ndimage
    inner = ndimage.binary_erosion(spec, iterations=2)
    noise = (T[3] - clean[3])[inner]
    assert np.std(noise) == pytest.approx(math.hypot(scene.ir_noise, q / math.sqrt(12)), rel=0.15)
    # the DIC data: noise and missing points as drawn, stage 0 complete
    x = scene.dic()["x"].values
    assert np.isfinite(x[0]).all()
    failed = ~np.isfinite(x[1:]).all(axis=-1)
    assert failed.mean() == pytest.approx(scene.missing, abs=0.006)
    err = x - scene.truth().x.values
    assert np.nanstd(err) == pytest.approx(scene.dic_noise, rel=0.2)


def test_band_speed_and_rate_follow_the_width():
    # the narrow band's DIC rate is raised so it moves at most 0.75 widths per stage, its speed kept within the patch
    r = family.recipe(3, pattern={"kind": "band", "amplitude": 3.0, "width": 1.5, "speed": 2.0, "angle": 0.0},
                      timing={"dic_rate": 1.0, "stages": 21, "dropped": False})
    sc = family.build(r, "tiny")
    band = sc.specimen.pattern
    assert isinstance(band, MovingBand)
    rate = sc.recipe["resolved"]["dic_rate"]
    assert band.speed / rate <= 0.75 * 1.5 + 1e-12
    s0, s1, h0, h1 = sc.patch
    assert band.speed * sc.dic_times[-1] <= 0.6 * (h1 - h0) + 1e-9
    with pytest.raises(ConfigError, match="name"):
        family.member("no-such-member")
    with pytest.raises(ConfigError, match="scale"):
        family.draw(1, "huge")
