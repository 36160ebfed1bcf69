"""The synthetic experiments are self-consistent and their exports read back.

Everything here is compared with independent evaluations of the same truth:
finite differences of the closed forms, eigen decompositions, the inverse
camera, the ray caster, the written-and-read files.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from irdic.errors import ConfigError, GeometryError
from irdic.synthetic import (
    HalfShell,
    OpenBook,
    TrueCamera,
    Tube,
    experiment,
    halfshell_experiment,
    lab_camera,
    make_demo,
    open_book_target,
    point_truth,
    tube_experiment,
)
from irdic.synthetic.render import FrameRenderer, field
from irdic.synthetic.specimens import LABEL_PLATE, LABEL_SURFACE, smoothstep

RNG = np.random.default_rng(12345)


# --------------------------------------------------------------------------- camera
@pytest.fixture(scope="module")
def distorted():
    return lab_camera(k1=-0.3, k2=0.08)


def test_lab_camera_is_the_papers_camera():
    cam = lab_camera()
    assert cam.f == pytest.approx(1754.386, abs=1e-3)
    assert (cam.cx, cam.cy, cam.width, cam.height) == (511.5, 383.5, 1024, 768)
    # 450 mm from the look-at point, 17.5 deg to +x, 10 deg up
    d = cam.C - np.array([0.0, 0.0, -5.0])
    assert np.linalg.norm(d) == pytest.approx(450.0)
    assert math.degrees(math.atan2(d[0], d[2])) == pytest.approx(17.5)
    # the look-at point is on the optical axis
    np.testing.assert_allclose(cam.project([0.0, 0.0, -5.0]), [511.5, 383.5], atol=1e-9)
    # the half-shell's observed surface covers roughly 300 x 200 px (the paper's scale)
    hs = HalfShell()
    s, h = np.meshgrid(np.linspace(-hs.s_e, hs.s_e, 50), np.linspace(0, hs.H, 30))
    uv = cam.project(hs.position(s.ravel(), h.ravel()))
    span = uv.max(axis=0) - uv.min(axis=0)
    assert 270 < span[0] < 330 and 170 < span[1] < 230


def test_image_axes_follow_the_convention():
    cam = TrueCamera.looking_at([0, 0, 500.0], [0, 0, 0.0])  # looking along -z, y up
    uv0 = cam.project([0, 0, 0.0])
    assert cam.project([10.0, 0, 0])[0] > uv0[0] + 30  # +x appears to the right (+u)
    assert cam.project([0, 10.0, 0])[1] < uv0[1] - 30  # +y appears up (-v)
    assert np.isnan(cam.project([0, 0, 600.0])).all()  # behind the camera


@pytest.mark.parametrize("k", [(0.0, 0.0), (-0.3, 0.08), (0.2, 0.0)])
def test_ray_and_projection_are_inverse(k):
    cam = lab_camera(k1=k[0], k2=k[1])
    u = RNG.uniform(-0.5, 1023.5, 200)
    v = RNG.uniform(-0.5, 767.5, 200)
    o, d = cam.ray(u, v)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-14)
    X = o + RNG.uniform(100, 900, 200)[:, None] * d
    uv, depth = cam.project(X, return_depth=True)
    assert (depth > 0).all()
    np.testing.assert_allclose(uv, np.column_stack([u, v]), atol=1e-7)


def test_projection_matrix_normalised_and_consistent():
    cam = lab_camera()
    M = cam.matrix()
    assert np.linalg.norm(M[2, :3]) == pytest.approx(1.0, abs=1e-14)
    X = RNG.uniform(-40, 40, (50, 3))
    h = np.c_[X, np.ones(50)] @ M.T
    _, depth = cam.project(X, return_depth=True)
    np.testing.assert_allclose(h[:, 2], depth, rtol=1e-12)
    np.testing.assert_allclose(h[:, :2] / h[:, 2:], cam.project(X), atol=1e-9)
    K, R = cam.K, cam.R
    np.testing.assert_allclose(M, K @ np.c_[R, -R @ cam.C], rtol=1e-12, atol=1e-9)


def test_jacobian_matches_finite_differences(distorted):
    X = RNG.uniform(-40, 40, (20, 3))
    J = distorted.jacobian(X)
    eps = 1e-4
    for k in range(3):
        e = np.zeros(3)
        e[k] = eps
        fd = (distorted.project(X + e) - distorted.project(X - e)) / (2 * eps)
        np.testing.assert_allclose(J[:, :, k], fd, atol=1e-6)


def test_camera_rejects_bad_input():
    with pytest.raises(ConfigError, match="`R` must be a proper rotation"):
        TrueCamera(f=1000, cx=0, cy=0, R=np.diag([1.0, 1.0, -1.0]), C=np.zeros(3))
    with pytest.raises(ConfigError, match="`f` must be finite and > 0"):
        TrueCamera(f=-1, cx=0, cy=0, R=np.eye(3), C=np.zeros(3))
    with pytest.raises(ConfigError, match="parallel to the viewing direction"):
        TrueCamera.looking_at([0, 100.0, 0], [0, 0, 0.0])
    with pytest.raises(ConfigError, match="last axis of `X`"):
        lab_camera().project(np.zeros((4, 2)))
    # strong pincushion folds the image: undistortion must refuse, not return garbage
    with pytest.raises(GeometryError, match="fold"):
        lab_camera(k1=-2.0).ray(0.0, 0.0)


# --------------------------------------------------------------------------- target
@pytest.fixture(scope="module")
def target_clean():
    return open_book_target(lab_camera(), noise=0.0)


def _conic_centres(book, cam):
    """Centres of the imaged marker ellipses from the homography (pinhole only)."""
    out = []
    e1, e2 = book.marker_axes()
    for c, a, b in zip(book.centres(), e1, e2):
        H = cam.K @ cam.R @ np.column_stack([a, b, c - cam.C])
        Hi = np.linalg.inv(H)
        Cn = Hi.T @ np.diag([1.0, 1.0, -book.radius**2]) @ Hi
        out.append(np.linalg.solve(Cn[:2, :2], -Cn[:2, 2]))
    return np.array(out)


def _weighted_centroids(img, centres, level):
    """Contrast-weighted centroids of the marker blobs of a noise-free image."""
    from scipy import ndimage

    blobs, _ = ndimage.label(np.abs(img - level) > 1e-6)
    out = []
    for u, v in centres:
        k = blobs[int(round(v)), int(round(u))]
        vv, uu = np.nonzero(blobs == k)
        w = np.abs(img[vv, uu] - level)
        out.append([(w * uu).sum() / w.sum(), (w * vv).sum() / w.sum()])
    return np.array(out)


def test_open_book_markers(target_clean):
    m = target_clean.markers
    ids = m.marker.values
    assert m.x.dims == ("marker", "component") and m.x.shape == (84, 3)
    assert list(m.component.values) == ["x", "y", "z"]
    assert np.unique(ids).size == 84 and (np.diff(ids) > 0).all()  # listed by ID ...
    assert not (np.diff(target_clean.book.ids) > 0).all()  # ... which do not follow the grid
    X = m.x.values
    # 6 x 7 on each wing: nearest neighbour at the 8 mm pitch; the two wings are not coplanar
    dist = np.linalg.norm(X[:, None] - X[None], axis=-1) + np.eye(84) * 1e9
    np.testing.assert_allclose(dist.min(axis=1), 8.0, atol=1e-9)
    assert np.linalg.svd(X - X.mean(0), compute_uv=False)[-1] > 10.0
    assert target_clean.truth.marker_visible.values.all()
    r = target_clean.truth.marker_radius_px.values
    assert 4.0 < r.min() and r.max() < 7.0  # 1.6 mm at ~450 mm


def test_open_book_image_levels(target_clean):
    img = target_clean.image
    assert img.dims == ("v", "u") and img.shape == (768, 1024) and img.dtype == np.float32
    assert img.attrs["units"] == "°C"
    cen = target_clean.truth.marker_centroid.values
    vals = img.values[np.rint(cen[:, 1]).astype(int), np.rint(cen[:, 0]).astype(int)]
    np.testing.assert_allclose(vals, 21.5, atol=1e-5)  # dark markers
    assert img.values[0, 0] == pytest.approx(20.0)  # room
    c = target_clean.book.hinge_point + 60.0 * target_clean.book.w[0] + np.array([0, 26.0, 0])
    u, v = np.rint(lab_camera().project(c)).astype(int)
    assert img.values[v, u] == pytest.approx(24.0)  # wing body between markers and edge


def test_open_book_perspective_centres_exact(target_clean):
    tr = target_clean.truth
    cen = tr.marker_centroid.values
    # the polygon centroid of the imaged circle is the conic (ellipse) centre
    conic = _conic_centres(target_clean.book, lab_camera())[np.argsort(target_clean.book.ids)]
    np.testing.assert_allclose(cen, conic, atol=1e-4)
    bias = np.hypot(*(cen - tr.marker_pixel.values).T)
    assert 0.003 < bias.max() < 0.1  # real, small perspective bias
    # the rendered image puts each marker exactly there (area sampling, 8 x 8 rays)
    wc = _weighted_centroids(target_clean.image.values.astype(float), cen, 24.0)
    err = np.hypot(*(wc - cen).T)
    assert err.max() < 0.02 and err.max() < bias.max()


def test_open_book_with_distortion_and_noise(distorted):
    tg = open_book_target(distorted, noise=0.04, polarity="bright", seed=3)
    tr = tg.truth
    assert float(tr.k1) == -0.3 and tr.attrs["marker_temperature"] == pytest.approx(26.5)
    assert tr.marker_visible.values.all()
    bg = tg.image.values[:100, :100]
    assert bg.std() == pytest.approx(0.04, rel=0.05) and bg.mean() == pytest.approx(20.0, abs=0.002)
    clean = open_book_target(distorted, noise=0.0, polarity="bright")
    wc = _weighted_centroids(clean.image.values.astype(float), tr.marker_centroid.values, 24.0)
    assert np.hypot(*(wc - tr.marker_centroid.values).T).max() < 0.02


def test_open_book_other_pose_pinhole():
    cam = lab_camera(azimuth_deg=-25.0, elevation_deg=-8.0, distance=380.0, roll_deg=-3.0)
    tg = open_book_target(cam, noise=0.0)
    tr = tg.truth
    assert tr.marker_visible.values.all()
    conic = _conic_centres(tg.book, cam)[np.argsort(tg.book.ids)]
    np.testing.assert_allclose(tr.marker_centroid.values, conic, atol=1e-4)
    wc = _weighted_centroids(tg.image.values.astype(float), tr.marker_centroid.values, 24.0)
    assert np.hypot(*(wc - tr.marker_centroid.values).T).max() < 0.03  # 8 x 8 rays on 3 px markers


def test_open_book_rejects_bad_input():
    with pytest.raises(ConfigError, match="`polarity` must be one of"):
        open_book_target(lab_camera(), polarity="grey")
    with pytest.raises(ConfigError, match="`opening_deg` must lie in"):
        OpenBook(opening_deg=180.0)
    with pytest.raises(ConfigError, match="`camera` must be a TrueCamera"):
        open_book_target("camera")


# --------------------------------------------------------------------------- specimens
SPECIMENS = [HalfShell(), Tube()]
TIMES = [0.0, 1.3, 3.0, 5.5, 7.2, 9.7]


def _material_sample(spec, n=40):
    if isinstance(spec, HalfShell):
        return RNG.uniform(-38, 38, n), RNG.uniform(3, 47, n)
    return RNG.uniform(-14, 14, n), RNG.uniform(-20, 20, n)


@pytest.mark.parametrize("spec", SPECIMENS, ids=lambda s: s.name)
@pytest.mark.parametrize("t", TIMES)
def test_kinematics_and_temperature_match_finite_differences(spec, t):
    s, h = _material_sample(spec)
    e = 1e-5
    a_s, a_h = spec.tangents(s, h, t)
    np.testing.assert_allclose(a_s, (spec.position(s + e, h, t) - spec.position(s - e, h, t)) / (2 * e), atol=1e-8)
    np.testing.assert_allclose(a_h, (spec.position(s, h + e, t) - spec.position(s, h - e, t)) / (2 * e), atol=1e-8)
    np.testing.assert_allclose(spec.velocity(s, h, t),
                               (spec.position(s, h, t + e) - spec.position(s, h, t - e)) / (2 * e), atol=1e-8)
    Ts, Th, Tt = spec.temperature_derivatives(s, h, t)
    T = spec.temperature
    np.testing.assert_allclose(Ts, (T(s + e, h, t) - T(s - e, h, t)) / (2 * e), atol=1e-8)
    np.testing.assert_allclose(Th, (T(s, h + e, t) - T(s, h - e, t)) / (2 * e), atol=1e-8)
    np.testing.assert_allclose(Tt, (T(s, h, t + e) - T(s, h, t - e)) / (2 * e), atol=1e-8)
    assert np.abs(Ts).max() + np.abs(Th).max() > 1e-3 or t == 0.0 and isinstance(spec, Tube)


@pytest.mark.parametrize("spec", SPECIMENS, ids=lambda s: s.name)
def test_gradient_is_the_in_plane_derivative_along_the_current_surface(spec):
    s, h = _material_sample(spec)
    t = 4.0
    g = spec.temperature_gradient(s, h, t)
    n = spec.normal(s, h, t)
    np.testing.assert_allclose(np.einsum("ij,ij->i", g, n), 0.0, atol=1e-12)
    e = 1e-5
    for al, be in ((1.0, 0.0), (0.0, 1.0), (0.6, -0.8)):
        dx = spec.position(s + e * al, h + e * be, t) - spec.position(s - e * al, h - e * be, t)
        dT = spec.temperature(s + e * al, h + e * be, t) - spec.temperature(s - e * al, h - e * be, t)
        np.testing.assert_allclose(np.einsum("ij,ij->i", g, dx), dT, atol=1e-11)


@pytest.mark.parametrize("t", [2.0, 5.5, 9.0])
def test_tube_strain_and_principal_values(t):
    spec = Tube()
    s, h = _material_sample(spec)
    E = spec.green_lagrange(s, h, t)
    e = 1e-5
    a_s = (spec.position(s + e, h, t) - spec.position(s - e, h, t)) / (2 * e)
    a_h = (spec.position(s, h + e, t) - spec.position(s, h - e, t)) / (2 * e)
    Efd = 0.5 * np.array([[np.einsum("ij,ij->i", a, b) for b in (a_s, a_h)] for a in (a_s, a_h)])
    Efd = np.moveaxis(Efd, -1, 0) - 0.5 * np.eye(2)
    np.testing.assert_allclose(E, Efd, atol=1e-9)
    e_max, e_min, n_max, n_min = spec.principal_strains(s, h, t)
    w, V = np.linalg.eigh(E)
    np.testing.assert_allclose(e_max, w[:, 1], atol=1e-14)
    np.testing.assert_allclose(e_min, w[:, 0], atol=1e-14)
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", n_max, V[:, :, 1])), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", n_min, V[:, :, 0])), 1.0, atol=1e-12)
    assert (n_max[:, 1] > 0).all()
    # tension-torsion: stretched along a helix, shortened across it
    assert e_max.min() > 0.005 and e_min.max() < -0.005
    if t == 5.5:  # fully loaded: u = 2 mm, phi = 25 deg over L = 60 mm, R = 15 mm, isochoric
        lam, phi = 1 + 2 / 60, math.radians(25)
        r2 = 15**2 / lam
        E_hand = 0.5 * np.array([[1 / lam - 1, r2 * phi / (15 * 60)], [r2 * phi / (15 * 60), lam**2 + r2 * phi**2 / 60**2 - 1]])
        np.testing.assert_allclose(E, np.broadcast_to(E_hand, E.shape), atol=1e-14)


def test_tube_loading_history():
    tb = Tube()
    u, du = tb.axial_displacement(np.array([0.0, 0.5, 5.5, 6.0, 10.0]))
    np.testing.assert_allclose(u, [0, 0, 2.0, 2.0, 1.8], atol=1e-15)
    np.testing.assert_allclose(du[[0, 1, 2, 4]], 0.0, atol=1e-15)
    phi, _ = tb.twist(np.array([5.5, 10.0]))
    np.testing.assert_allclose(np.degrees(phi), [25.0, 23.0])
    # C2 smooth steps: second derivative vanishes at both ends
    np.testing.assert_allclose(smoothstep(np.array([0.5, 5.5]), 0.5, 5.5)[2], 0.0, atol=1e-15)
    # isochoric: r^2 lam_z = R^2
    t = np.linspace(0, 10, 41)
    np.testing.assert_allclose(tb.radius(t) ** 2 * tb.stretch(t)[0], tb.R**2, rtol=1e-14)
    # heating obeys d(dT)/dt = Q ds/dt - dT / tau_c; ~1 K/s during loading, relaxing after
    dT, rate = tb.heating(t)
    e = 1e-5
    np.testing.assert_allclose(rate, (tb.heating(t + e)[0] - tb.heating(t - e)[0]) / (2 * e), atol=1e-8)
    assert 1.0 < rate.max() < 1.6 and 2.5 < dT.max() < 3.2
    assert dT[-1] < 0.8 * dT.max() and rate[-1] < 0


def test_halfshell_is_static_and_heated_from_below():
    hs = HalfShell()
    s, h = _material_sample(hs)
    np.testing.assert_array_equal(hs.velocity(s, h, 7.0), 0.0)
    np.testing.assert_array_equal(hs.green_lagrange(s, h, 7.0), 0.0)
    assert np.isnan(hs.principal_strains(s, h, 7.0)[2]).all()  # undefined directions
    x = hs.position(s, h, 0.0)
    np.testing.assert_allclose(np.hypot(x[:, 0], x[:, 2] + 65.0), 65.0)
    assert hs.position(0.0, 0.0, 0.0)[2] == 0.0
    # width 78 mm and depth 13 mm of the observed outer surface
    edge = hs.position(np.array([-hs.s_e, hs.s_e]), 0.0, 0.0)
    assert edge[1, 0] - edge[0, 0] == pytest.approx(78.0) and edge[0, 2] == pytest.approx(-13.0)
    t = np.array([0.0, 10.0, 30.0])
    bottom = hs.temperature(0.0, 0.0, t)
    assert (hs.plate_temperature(t) - bottom > 2.0).all()  # the discontinuity at the lower edge
    assert np.all(np.diff(bottom) > 5) and hs.temperature(0.0, 49.0, 30.0) < hs.T0 + 1.0
    np.testing.assert_allclose(hs.edge_distance([0.0, 40.0, 0.0], [25.0, 25.0, 2.0]), [25.0, hs.s_e - 40, 2.0])


# --------------------------------------------------------------------------- rendering and truth
@pytest.fixture(scope="module", params=["halfshell", "tube"])
def tiny(request):
    return experiment(request.param, "tiny")


def test_frame_at_a_pixel_centre_equals_the_point_temperature(tiny):
    r = FrameRenderer(tiny.specimen, tiny.camera, tiny.window)
    t = float(tiny.ir_times[-2])
    clean = r(t, noise=0.0)
    hit = r.clean(t)
    vv, uu = np.nonzero(hit.label == LABEL_SURFACE)
    pick = RNG.choice(vv.size, 50, replace=False)
    s, h = hit.s[vv[pick], uu[pick]], hit.h[vv[pick], uu[pick]]
    x = tiny.specimen.position(s, h, t)
    uv = tiny.camera.project(x)
    np.testing.assert_allclose(uv, np.column_stack([r.u[uu[pick]], r.v[vv[pick]]]), atol=1e-8)
    expected = tiny.specimen.temperature(s, h, t)
    np.testing.assert_allclose(clean.values[vv[pick], uu[pick]], expected, rtol=1e-6)
    assert clean.u[0] == tiny.window[0] and clean.v[0] == tiny.window[1]
    noisy = tiny.ir_frame(len(tiny.ir_times) - 2)
    diff = noisy.values.astype(float) - clean.values
    assert diff.std() == pytest.approx(0.05, rel=0.05)
    np.testing.assert_array_equal(noisy.values, tiny.ir_frame(len(tiny.ir_times) - 2).values)  # reproducible


def test_truth_pixel_identities(tiny):
    tr = tiny.truth()
    assert tr.visible.values.all() and tr.in_window.values.all()
    grad_pix = np.stack([tr.dT_du.values, tr.dT_dv.values], axis=-1)
    # material rate = local rate at the pixel + convective part
    conv = np.einsum("tpi,tpi->tp", grad_pix, tr.pixel_velocity.values)
    np.testing.assert_allclose(tr.temperature_rate.values, tr.dT_dt_pixel.values + conv, atol=1e-6)
    # in-plane gradient = tangent projection of J^T grad_pix (METHOD section 3)
    J = tiny.camera.jacobian(tr.x.values)
    g = np.einsum("tpij,tpi->tpj", J, grad_pix)
    n = tr.normal.values
    g -= np.einsum("tpj,tpj->tp", g, n)[..., None] * n
    np.testing.assert_allclose(g, tr.temperature_gradient.values, atol=1e-6)
    assert np.abs(tr.temperature_gradient.values).max() > 0.05
    # pixel velocity vs the projected trajectory
    t = tr.time.values
    e = 1e-5
    sp, cam = tiny.specimen, tiny.camera
    s, h = tr.s.values, tr.h.values
    fd = (cam.project(sp.position(s, h, t[:, None] + e)) - cam.project(sp.position(s, h, t[:, None] - e))) / (2 * e)
    np.testing.assert_allclose(tr.pixel_velocity.values, fd, atol=1e-5)
    np.testing.assert_allclose(tr.pixel.values, cam.project(tr.x.values), atol=1e-12)


def test_truth_directions_and_units():
    ex = tube_experiment("tiny")
    tr = ex.truth()
    for name, var in tr.data_vars.items():
        if var.dtype.kind == "f":
            assert "units" in var.attrs and "long_name" in var.attrs, name
    k = 4  # t = 4 s: loaded
    F_N = tr.direction_max_cur.values[k]
    N = tr.direction_max.values[k]
    np.testing.assert_allclose(np.linalg.norm(N, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("pi,pi->p", N, tr.normal.values[0]), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("pi,pi->p", F_N, tr.normal.values[k]), 0.0, atol=1e-12)
    # stretch along the principal direction: |F N|^2 = 1 + 2 e_max
    s, h = tr.s.values, tr.h.values
    a_s, a_h = ex.specimen.tangents(s, h, tr.time.values[k])
    E_s, E_h = ex.specimen.reference_basis(s, h)
    c = np.stack([np.einsum("pi,pi->p", N, E_s), np.einsum("pi,pi->p", N, E_h)], -1)
    FN = c[:, :1] * a_s + c[:, 1:] * a_h
    np.testing.assert_allclose(np.einsum("pi,pi->p", FN, FN), 1 + 2 * tr.strain_max.values[k], rtol=1e-12)
    assert np.isnan(tr.direction_max.values[0]).all()  # undeformed: undefined
    assert tr.edge_distance.values.min() == pytest.approx(10.0)  # |Z| <= 20, clamps at +-30
    assert tr.patch_edge_distance.values.min() == pytest.approx(0.0, abs=1e-12)


def test_other_camera_gets_a_fitted_window():
    cam = lab_camera(azimuth_deg=8.0, elevation_deg=5.0, distance=520.0, k1=-0.3, k2=0.08)
    ex = tube_experiment("tiny", camera=cam)
    assert ex.window != tube_experiment("tiny").window
    tr = ex.truth()
    assert tr.visible.values.all() and tr.in_window.values.all()
    k = len(ex.ir_times) // 2
    hit = ex.renderer.clean(ex.ir_times[k])
    vv, uu = np.nonzero(hit.label == LABEL_SURFACE)
    s, h = hit.s[vv[:20], uu[:20]], hit.h[vv[:20], uu[:20]]
    np.testing.assert_allclose(cam.project(ex.specimen.position(s, h, ex.ir_times[k])),
                               np.column_stack([ex.renderer.u[uu[:20]], ex.renderer.v[vv[:20]]]), atol=1e-8)


def test_visibility_sees_front_not_back():
    tb, cam = Tube(), lab_camera()
    s = np.array([0.0, tb.R * np.pi, tb.R * np.pi / 2, -tb.R * 1.7])
    tr = point_truth(tb, cam, s, np.zeros(4), [3.0])
    # front, back, side facing the camera (+x), side turned away beyond the silhouette
    np.testing.assert_array_equal(tr.visible.values[0], [True, False, True, False])
    assert np.isnan(tr.dT_du.values[0, 1])
    hit = field(HalfShell(), cam, 511.5, 530.0, 10.0)  # looking down at the plate in front
    assert hit.label == LABEL_PLATE and hit.temperature == pytest.approx(HalfShell().plate_temperature(10.0))


def test_experiment_plan_and_defects():
    hs = halfshell_experiment("demo")
    tb = tube_experiment("demo")
    for ex, ir_dt, dic_dt in ((hs, 0.5, 1.0), (tb, 0.25, 0.5)):
        assert ex.dic_times[0] == 0.0 == ex.ir_times[0]
        assert ex.dic_times[-1] <= ex.ir_times[-1]
        assert np.diff(ex.dic_times) == pytest.approx(dic_dt) and 1500 <= ex.ids.size <= 2500
        assert np.unique(ex.ids).size == ex.ids.size
        assert np.min(np.diff(ex.ir_times)) == pytest.approx(ir_dt)
        nan = np.isnan(ex.x_dic[..., 0]) & ex.present
        assert not nan[0].any() and ex.present[0].all()
        frac = nan[1:].mean(axis=1)
        assert frac.max() == pytest.approx(0.01, abs=0.002) and (frac == 0).any()
        assert 2 <= (~ex.present).any(axis=0).sum() <= 5
        good = ~np.isnan(ex.x_dic[..., 0])
        err = (ex.x_dic - ex.specimen.position(ex.s, ex.h, ex.dic_times[:, None]))[good]
        assert err.std() == pytest.approx(0.005, rel=0.05)
    assert hs.ir_times.size == 61 and tb.ir_times.size == 40
    assert 17 not in tb.ir_frame_numbers and tb.ir_frame_numbers[-1] == 40
    paper = experiment("halfshell", "paper")
    assert 9000 < paper.ids.size < 11000 and paper.ir_times.size == 501
    with pytest.raises(ConfigError, match="`scale` must be one of"):
        experiment("tube", "huge")
    with pytest.raises(ConfigError, match="`ir_noise` must be finite and >= 0"):
        experiment("tube", "tiny", ir_noise=-1.0)


# --------------------------------------------------------------------------- demo files
@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    paths = make_demo(out, scale="tiny")
    return out, paths


def test_demo_layout(demo):
    out, paths = demo
    for name in ("markers.txt", "target.txt", "seeds.yaml", "truth.zarr"):
        assert (out / "setup" / name).exists()
    hs = sorted((out / "halfshell" / "ir").glob("*.txt"))
    tb = sorted((out / "tube" / "ir").glob("*.txt"))
    assert [p.name for p in hs] == [f"halfshell_{n:05d}.txt" for n in range(9)]
    assert len(tb) == 12 and not (out / "tube" / "ir" / "tube_00005.txt").exists()
    assert sorted(p.name for p in (out / "tube" / "dic").glob("*.txt")) == sorted(f"tube_0_{k}.txt" for k in range(7))
    assert paths["tube"]["truth"] == out / "tube" / "truth.zarr"


def test_demo_setup_reads_back(demo):
    from irdic.io import read_ir, read_markers
    from irdic.store import open_store

    out, _ = demo
    from irdic.synthetic.demo import demo_book

    tg = open_book_target(lab_camera(), noise=0.04, seed=0, book=demo_book())
    m = read_markers(out / "setup" / "markers.txt")
    assert m.sizes["marker"] == 83  # one corner of the demo target is left unpainted
    assert sorted(m.marker.values) == sorted(tg.markers.marker.values)
    np.testing.assert_allclose(m.x.sel(marker=tg.markers.marker).values, tg.markers.x.values, atol=5e-7)
    img = read_ir(out / "setup" / "target.txt")
    assert img.shape == (768, 1024)
    np.testing.assert_allclose(img.values, tg.image.values, atol=5e-4 + 1e-5)
    truth = open_store(out / "setup" / "truth.zarr")
    np.testing.assert_allclose(truth.projection_matrix.values, lab_camera().matrix(), rtol=1e-15)
    np.testing.assert_allclose(truth.marker_centroid.values, tg.truth.marker_centroid.values, rtol=1e-15)
    seeds = yaml.safe_load((out / "setup" / "seeds.yaml").read_text())["seeds"]
    assert len(seeds) == 8
    for marker_id, uv in seeds.items():
        true = truth.marker_centroid.sel(marker=marker_id).values
        assert np.abs(np.array(uv) - true).max() <= 2.06


@pytest.mark.parametrize("name", ["halfshell", "tube"])
def test_demo_ir_reads_back(demo, name):
    from irdic.io import read_ir

    out, _ = demo
    ex = experiment(name, "tiny")
    for i in (0, len(ex.ir_times) - 1):
        n = int(ex.ir_frame_numbers[i])
        f = read_ir(out / name / "ir" / f"{name}_{n:05d}.txt")
        ref = ex.ir_frame(i)
        np.testing.assert_allclose(f.values, ref.values, atol=5e-4 + 1e-5)
        np.testing.assert_array_equal(f.u.values, ref.u.values)
        np.testing.assert_array_equal(f.v.values, ref.v.values)
        assert float(f.time) == pytest.approx(ex.ir_times[i] + 1.2345, abs=1e-9)
        assert f.attrs["frame_index"] == n + 1 and f.attrs["start_pos"] == list(ex.window[:2])


@pytest.mark.parametrize("name", ["halfshell", "tube"])
def test_demo_dic_reads_back(demo, name):
    from irdic.io import read_dic
    from irdic.store import open_store

    out, _ = demo
    ex = experiment(name, "tiny")
    truth = open_store(out / name / "truth.zarr")
    np.testing.assert_allclose(truth.temperature.values, ex.truth().temperature.values, rtol=1e-15)
    assert truth.temperature.attrs["units"] == "°C" and truth.temperature_gradient.attrs["units"] == "K/mm"
    n_nan = n_absent = 0
    for k, t in enumerate(ex.dic_times):
        d = read_dic(out / name / "dic" / f"{name}_0_{k}.txt")
        assert float(d.time) == pytest.approx(t)
        keep = ex.present[k]
        np.testing.assert_array_equal(d.point.values, ex.ids[keep])
        np.testing.assert_allclose(d.x.values, ex.x_dic[k][keep], atol=1.01e-4)  # 2 x 4 decimals
        np.testing.assert_array_equal(np.isnan(d.x.values[:, 0]), np.isnan(ex.x_dic[k][keep][:, 0]))
        n_nan += np.isnan(d.x.values[:, 0]).sum()
        n_absent += (~keep).sum()
    assert n_nan > 0 and n_absent > 0


def test_make_demo_rejects_bad_arguments(tmp_path):
    with pytest.raises(ConfigError, match="`scale` must be one of"):
        make_demo(tmp_path, scale="huge")
    with pytest.raises(ConfigError, match="`experiments` must be one of"):
        make_demo(tmp_path, experiments=("plate",))
    assert not any(tmp_path.iterdir())


@pytest.mark.samples
def test_demo_ir_export_looks_like_a_real_one(demo, samples):
    from irdic.io import read_ir

    out, _ = demo
    real = read_ir(samples / "irbis-text" / "GW_1_Z2_860.txt")
    assert real.attrs["frame_index"] == 860 and float(real.time) == pytest.approx(34.35975)
    ours = read_ir(out / "tube" / "ir" / "tube_00004.txt")
    # every header item of the camera's own export is there (CalibRange is the camera's, not ours)
    assert set(real.attrs) - {"calib_range"} <= set(ours.attrs)
    # RecTime is the frame's wall-clock second: recording start + ms, truncated
    assert ours.attrs["rec_datetime"] == "2024-05-14T14:02:13"  # 14:02:10 + 1.2345 s + 4 x 0.5 s
    assert float(ours.time) == pytest.approx(3.2345)  # ms since the recording started, / 1000
