"""The DIC points in the IR image: projection of every time, positions filled in time."""

import numpy as np
import pytest
import xarray as xr

from irdic.camera import CameraModel
from irdic.errors import DataError
from irdic.footprint import visibility
from irdic.footprint.visibility import fill_in_time, project_points


def _filled_point_by_point(a):
    """The definition, one point and time at a time: the nearest earlier valid time, else the nearest later."""
    out = a.copy()
    n_t, M, _ = a.shape
    ok = np.isfinite(a).all(axis=2)
    for j in range(M):
        good = np.flatnonzero(ok[:, j])
        for k in np.flatnonzero(~ok[:, j]):
            if good.size:
                before = good[good < k]
                out[k, j] = a[before[-1] if before.size else good[good > k][0], j]
    return out


@pytest.mark.parametrize("missing", [0.0, 0.05, 0.6, 1.0])
def test_fill_in_time_takes_the_nearest_earlier_else_later_valid_time(missing):
    rng = np.random.default_rng(3)
    a = rng.normal(size=(23, 40, 3))
    a[rng.random((23, 40)) < missing] = np.nan
    a[:, 0] = np.nan  # never seen: stays NaN
    a[:5, 1], a[-4:, 2] = np.nan, np.nan  # lost at the start, at the end
    out = fill_in_time(a)
    np.testing.assert_array_equal(out, _filled_point_by_point(a))
    assert out is not a and np.isnan(out[:, 0]).all()
    assert np.isfinite(out[:, 1:]).all() or missing == 1.0


def _dic(x):
    n_t, M, _ = x.shape
    return xr.Dataset({"x": (("time", "point", "component"), x)},
                      coords={"time": np.arange(n_t, dtype=float), "component": ["x", "y", "z"]})


def test_projection_in_blocks_of_times_equals_one_block(monkeypatch):
    """Projected a few times at a time (the record's temporaries at once cost more than the arithmetic): the
    same pixels, flags and positions as all times at once, points behind the camera and missing ones
    included."""
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    camera = CameraModel(K=K, R=np.eye(3), C=np.array([0.0, 0.0, -200.0]))
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(-40, 40, (7, 50, 2)), rng.uniform(-5, 5, (7, 50, 1))], axis=2)
    x[rng.random((7, 50)) < 0.1] = np.nan
    x[2, :3, 2] = -300.0  # behind the camera at one time
    u, v = np.arange(640.0), np.arange(480.0)
    whole = project_points(camera, _dic(x), u, v)
    monkeypatch.setattr(visibility, "PROJECT_BLOCK", 120)  # two times per block, the last block short
    blocks = project_points(camera, _dic(x), u, v)
    for name in ("x", "flat_x", "valid", "front", "pix", "in_frame", "local"):
        a, b = np.asarray(getattr(blocks, name)), np.asarray(getattr(whole, name))
        if a.dtype.kind == "f":  # the BLAS may round a block's products differently from the whole's (1e-16)
            np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=name)
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.nanmax(np.abs(b)), err_msg=name)
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)
    assert not whole.front.reshape(7, 50)[2, :3].any() and np.isnan(whole.pix[2, :3]).all()
    ok = whole.front.reshape(7, 50)
    np.testing.assert_allclose(whole.pix[ok], camera.project(x[ok]), rtol=0, atol=1e-9)
    with pytest.raises(DataError, match="no valid DIC point"):
        project_points(camera, _dic(np.full((2, 3, 3), np.nan)), u, v)


def test_masks_are_planned_before_they_are_built():
    """``planned`` hears how many masks will be built before the first is (the couple stage's progress model):
    one per run of times whose points move less than MASK_REUSE_PX, here two of five times."""
    from irdic.footprint.visibility import MASK_REUSE_PX, masks_and_facing

    gx, gy = np.meshgrid(np.arange(20.0), np.arange(20.0))
    plane = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    x = np.repeat(plane[None], 5, axis=0)
    pix = 40.0 + 5.0 * x[..., :2]
    pix[3:] += 2.0 * MASK_REUSE_PX  # the outline moves once, before the fourth time
    heard = []
    masks, facing = masks_and_facing(x, pix, np.array([10.0, 10.0, -200.0]), np.arange(200), np.arange(200),
                                     erosion=0.0, edge_factor=3.0, max_angle=80.0, planned=heard.append)
    assert heard == [2]
    assert facing.all() and masks[:, 100, 100].all() and not masks[:, 10, 10].any()
    _, _ = masks_and_facing(x, pix, np.array([10.0, 10.0, -200.0]), np.arange(200), np.arange(200), erosion=0.0,
                            edge_factor=3.0, max_angle=80.0, only=slice(3, 5), planned=heard.append)
    assert heard == [2, 1]  # a chunk of the last two times builds the one mask it uses
