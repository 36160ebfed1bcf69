import numpy as np
import pytest

from irdic.errors import ConfigError, GeometryError
from irdic.footprint.mask import edge_distance, facing_camera, point_normals, specimen_mask


def _grid(n=30, spacing=1.0):
    a = np.arange(n) * spacing
    uu, vv = np.meshgrid(a, a)
    return np.column_stack([uu.ravel(), vv.ravel()])


def test_point_normals_on_cylinder_are_radial():
    th, z = np.meshgrid(np.linspace(-0.6, 0.6, 40), np.linspace(0, 20, 20))
    r = 30.0
    x = np.column_stack([r * np.sin(th.ravel()), z.ravel(), r * np.cos(th.ravel())])
    x[7] = np.nan
    n = point_normals(x, towards=np.array([0.0, 10.0, 500.0]))
    radial = np.column_stack([np.sin(th.ravel()), np.zeros(th.size), np.cos(th.ravel())])
    ok = np.isfinite(n[:, 0])
    assert not ok[7] and ok.sum() == x.shape[0] - 1
    assert np.min(np.einsum("ij,ij->i", n[ok], radial[ok])) > 0.999


def test_facing_camera_rejects_grazing_and_back():
    x = np.zeros((3, 3))
    n = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 0, -1.0]])
    vis = facing_camera(x, n, np.array([0, 0, 100.0]))
    np.testing.assert_array_equal(vis, [True, False, False])


def test_specimen_mask_square_with_erosion():
    # points covering [10, 40] x [20, 50] px with 0.8 px spacing
    p = _grid(38, 0.8) + [10.0, 20.0]
    u, v = np.arange(0, 64), np.arange(0, 72)
    m0 = specimen_mask(p, u, v, erosion_px=0.0)
    uu, vv = np.meshgrid(u, v)
    expected = (uu >= 10) & (uu <= 10 + 37 * 0.8) & (vv >= 20) & (vv <= 20 + 37 * 0.8)
    assert (m0 == expected).mean() > 0.995
    m1 = specimen_mask(p, u, v, erosion_px=1.0)
    assert m1.sum() < m0.sum() and not (m1 & ~m0).any()
    # the eroded mask keeps pixels more than 1 px inside the covered square only
    assert not m1[20, 10] and m1[21 + 1, 12]


def test_specimen_mask_keeps_holes_open():
    p = _grid(40, 1.0)
    hole = np.linalg.norm(p - 20.0, axis=1) < 6.0
    m = specimen_mask(p[~hole], np.arange(40), np.arange(40), erosion_px=0.0)
    assert not m[20, 20] and m[5, 5]


def test_specimen_mask_checks():
    with pytest.raises(ConfigError, match="erosion_px"):
        specimen_mask(_grid(), np.arange(3), np.arange(3), erosion_px=-1)
    with pytest.raises(GeometryError, match="degenerate"):
        specimen_mask(np.column_stack([np.arange(10.0), np.arange(10.0)]), np.arange(10), np.arange(10))


def test_edge_distance_signed():
    mask = np.zeros((20, 30), bool)
    mask[5:15, 5:25] = True
    d = edge_distance(mask, np.array([[15.0, 10.0], [5.0, 10.0], [2.0, 10.0], [np.nan, 1.0]]), np.arange(30), np.arange(20))
    assert d[0] == pytest.approx(4.5)  # row 10: 5 px to row 15 (first outside), minus half a pixel
    assert d[1] == pytest.approx(0.5)
    assert d[2] < 0
    assert np.isnan(d[3])


@pytest.mark.parametrize("pts", [np.column_stack([np.arange(10.0), 2.0 * np.arange(10.0) + 1]),
                                 np.tile([[4.0, 5.0]], (6, 1))])
def test_collinear_points_say_so_without_a_qhull_dump(pts):
    with pytest.raises(GeometryError, match=r"the \d+ DIC points seen by the IR camera are degenerate: their "
                                            r"projections are collinear or coincide") as exc:
        specimen_mask(pts, np.arange(30), np.arange(30))
    msg = str(exc.value)
    assert "QH" not in msg and "qhull" not in msg.lower() and len(msg) < 400


def test_triangle_rasterisation_matches_point_location():
    """The per-triangle rasteriser marks exactly the pixel centres that Delaunay.find_simplex puts in a kept triangle."""
    from scipy.spatial import Delaunay

    from irdic.footprint.mask import _rasterise

    rng = np.random.default_rng(3)
    # a jittered, sheared grid with a hole, ~1 px spacing as on the IR sensor
    g = np.stack(np.meshgrid(np.arange(0, 60, 1.1), np.arange(0, 40, 0.9)), -1).reshape(-1, 2)
    g = g[np.hypot(g[:, 0] - 30, g[:, 1] - 20) > 6]
    p = g @ np.array([[1.0, 0.2], [0.0, 1.0]]) + rng.normal(0, 0.2, g.shape) + [5.3, 4.7]
    tri = Delaunay(p)
    corners = p[tri.simplices]
    keep = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1) <= 3.0
    u, v = np.arange(90), np.arange(60)
    uu, vv = np.meshgrid(u, v)
    s = tri.find_simplex(np.c_[uu.ravel(), vv.ravel()])
    ref = ((s >= 0) & keep[np.maximum(s, 0)]).reshape(uu.shape)
    got = _rasterise(corners[keep], u, v)
    assert ref.sum() > 1500
    assert np.array_equal(got, ref)


@pytest.mark.parametrize("radius", [0.5, 1.0, 1.5, 2.0, np.sqrt(2.0), 2.9])
def test_specimen_mask_erosion_is_the_euclidean_distance_rule(radius):
    """The erosion keeps exactly the pixels whose distance to the nearest unmasked pixel centre exceeds the
    radius (beyond the frame counts as masked), and the point spacing is the nearest-neighbour median,
    also with duplicate points and a cloud that leaves the frame (a frame without any unmasked pixel is
    not compared: the distance transform has nothing to measure to there)."""
    from scipy import ndimage
    from scipy.spatial import Delaunay, cKDTree

    from irdic.footprint.mask import _rasterise

    rng = np.random.default_rng(7)
    g = np.stack(np.meshgrid(np.arange(30), np.arange(22)), -1).reshape(-1, 2) * 2.2
    for p in (g + rng.normal(0, 0.05, g.shape) - [4.0, 3.0], np.r_[g, g[:5]] + [1.0, 1.0], rng.random((400, 2)) * 60):
        u, v = np.arange(70), np.arange(52)
        got = specimen_mask(p, u, v, erosion_px=radius)
        tri = Delaunay(p)
        spacing = np.median(cKDTree(p).query(p, k=2)[0][:, 1])
        c = p[tri.simplices]
        keep = np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).max(axis=1) <= 3.0 * spacing
        want = _rasterise(c[keep], u, v)
        want &= ndimage.distance_transform_edt(want) > radius
        assert want.any() and not want.all() and np.array_equal(got, want)
