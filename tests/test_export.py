"""ParaView and CSV export (irdic.export), time and point selection (irdic.selection)."""

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pandas as pd
import pytest
import xarray as xr

from irdic.errors import ConfigError, DataError
from irdic.export import point_variables, write_csv, write_paraview, write_pvd
from irdic.selection import central_point, select_points, select_times

R = 60.0  # mm, cylinder radius of the fabricated patch


def contract_stores(n_s=9, n_h=7, times=(0.0, 0.5, 1.0, 1.5, 2.0), missing=((2, 19),), hidden=((1, 0), (3, 0))):
    """Fabricated ``points.zarr`` and ``fields.zarr`` with the contract layout.

    A cylinder patch (axis along y, radius R) of n_s x n_h points with IDs
    ``1000 + 10 * i + j`` (i along the arc s, j along the height h; 100 * i
    from 10 heights on, ...), seen by an
    affine "camera" ``u = 500 + 10 x``, ``v = 400 - 10 y``. Temperature
    ``20 + 0.5 h + 2 t`` °C, so the in-plane gradient is 0.5 K/mm along y and
    the rate 2 K/s. ``missing`` (time, point index) pairs have no DIC
    coordinates; ``hidden`` ones no temperature (status 3).
    """
    s = np.linspace(-20.0, 20.0, n_s)
    h = np.linspace(-15.0, 15.0, n_h)
    S, H = np.meshgrid(s, h, indexing="ij")
    S, H = S.ravel(), H.ravel()
    mult = 10 ** len(str(n_h - 1))
    ids = (1000 + mult * np.repeat(np.arange(n_s), n_h) + np.tile(np.arange(n_h), n_s)).astype(np.int64)
    t = np.asarray(times, dtype=float)
    T, N = t.size, S.size
    x0 = np.column_stack([R * np.sin(S / R), H, R * np.cos(S / R) - R])
    stretch = 1.0 + 0.01 * t  # uniform stretch along the height
    x = np.repeat(x0[None], T, axis=0)
    x[..., 1] *= stretch[:, None]
    theta = (20.0 + 0.5 * x[..., 1] + 2.0 * t[:, None]).astype(np.float32)
    pix = np.stack([500.0 + 10.0 * x[..., 0], 400.0 - 10.0 * x[..., 1]], axis=-1)
    status = np.zeros((T, N), dtype=np.int8)
    for ti, pi in missing:
        x[ti, pi] = np.nan
        pix[ti, pi] = np.nan
        theta[ti, pi] = np.nan
        status[ti, pi] = 2
    for ti, pi in hidden:
        theta[ti, pi] = np.nan
        status[ti, pi] = 3
    visible = np.isfinite(theta)
    g_pix = np.zeros((T, N, 2))
    g_pix[..., 1] = -0.05  # K/px: 0.5 K/mm along y, v = -10 y
    g_pix[~visible] = np.nan
    rate = np.where(visible, 2.0, np.nan)
    coords = {"time": ("time", t, {"units": "s"}), "point": ids,
              "component": np.array(["x", "y", "z"], dtype=object), "axis": np.array(["u", "v"], dtype=object)}
    points = xr.Dataset(
        {
            "temperature": (("time", "point"), theta, {"units": "degC"}),
            "pixel": (("time", "point", "axis"), pix, {"units": "px"}),
            "temperature_pixel_gradient": (("time", "point", "axis"), g_pix, {"units": "K/px"}),
            "temperature_local_rate": (("time", "point"), rate, {"units": "K/s"}),
            "visible": (("time", "point"), visible),
            "edge_distance": (("time", "point"), np.where(visible, 5.0, np.nan), {"units": "px"}),
            "status": (("time", "point"), status, {"flag_meanings": "interpolated extrapolated_from_edge"}),
            "x": (("time", "point", "component"), x, {"units": "mm"}),
            "mask_pixels": (("time",), np.full(T, 1234, dtype=np.int64)),
        },
        coords=coords,
        attrs={"experiment": "fab"},
    )
    grad = np.zeros((T, N, 3))
    grad[..., 1] = 0.5
    grad[~visible] = np.nan
    e_max = 0.5 * (stretch**2 - 1.0)
    strain = np.zeros((T, N, 2, 2))
    strain[..., 1, 1] = e_max[:, None]
    direction = np.zeros((T, N, 2, 3))
    direction[..., 0, 1] = 1.0  # max: along the height
    direction[..., 1, 0] = np.cos(S / R)  # min: along the arc
    direction[..., 1, 2] = -np.sin(S / R)
    fields = xr.Dataset(
        {
            "temperature_gradient": (("time", "point", "component"), grad, {"units": "K/mm"}),
            "temperature_rate": (("time", "point"), rate, {"units": "K/s"}),
            "temperature_rate_local": (("time", "point"), rate, {"units": "K/s"}),
            "temperature_rate_convective": (("time", "point"), np.where(visible, 0.0, np.nan), {"units": "K/s"}),
            "normal": (("time", "point", "component"),
                       np.broadcast_to(np.column_stack([np.sin(S / R), 0 * S, np.cos(S / R)]), (T, N, 3)).copy(),
                       {"units": "1"}),
            "strain": (("time", "point", "i", "j"), strain, {"units": "1"}),
            "max_principal_strain": (("time", "point"), np.broadcast_to(e_max[:, None], (T, N)).copy(), {"units": "1"}),
            "min_principal_strain": (("time", "point"), np.zeros((T, N)), {"units": "1"}),
            "principal_direction": (("time", "point", "principal", "component"), direction, {"units": "1"}),
            "equivalent_strain": (("time", "point"), np.broadcast_to(e_max[:, None], (T, N)).copy(), {"units": "1"}),
            "surface_parameter": (("point", "param"), np.column_stack([S, H]), {"units": "mm"}),
            "x": (("time", "point", "component"), x, {"units": "mm"}),
            "temperature": (("time", "point"), theta.astype(float), {"units": "degC"}),
            "filled": (("time", "point"), ~np.isfinite(x).all(axis=2)),
        },
        coords={**coords, "i": np.array(["1", "2"], dtype=object), "j": np.array(["1", "2"], dtype=object),
                "principal": np.array(["max", "min"], dtype=object), "param": np.array(["psi1", "psi2"], dtype=object)},
    )
    return points, fields


@pytest.fixture(scope="module")
def stores():
    return contract_stores()


# --------------------------------------------------------------------------- selection


def test_select_times_default_is_one_third_and_two_thirds():
    t = np.arange(31.0)
    assert select_times(t).tolist() == [10, 20]
    assert select_times(t, []).tolist() == [10, 20]
    assert select_times(np.array([5.0])).tolist() == [0]


def test_select_times_snaps_to_nearest_and_drops_repeats():
    t = np.arange(0.0, 10.5, 0.5)
    assert select_times(t, [2.2, 2.3, 7.0, 0]).tolist() == [0, 4, 5, 14]  # 2.2 -> 2.0, 2.3 -> 2.5


@pytest.mark.parametrize("bad, match", [([40.0], r"report.times: 40 s outside the stored times 0 \.\. 30 s"),
                                         ([float("nan")], "finite numbers"), (["ten"], "'ten'"),
                                         ("10", "list of times"), ([True], "True")])
def test_select_times_rejects_bad_times(bad, match):
    with pytest.raises(ConfigError, match=match):
        select_times(np.arange(31.0), bad, name="report.times")


def test_central_point_is_the_middle_of_the_patch(stores):
    points, _ = stores
    # grid 9 x 7: the middle is i = 4, j = 3; the centroid of a cylinder patch lies behind it
    assert central_point(points) == 1043


def test_central_point_skips_points_that_are_often_hidden(stores):
    points, _ = stores
    p = points.copy(deep=True)
    k = int(np.flatnonzero(p["point"].values == 1043)[0])
    p["visible"][:3, k] = False  # hidden at 3 of 5 times
    assert central_point(p) in (1033, 1053, 1042, 1044)  # a neighbour at the same distance class


def test_select_points_validates_ids(stores):
    points, _ = stores
    assert select_points(points, [1012, 1000, 1012]).tolist() == [1012, 1000]
    assert select_points(points, None).tolist() == [1043]
    assert select_points(points, "all").size == 63
    with pytest.raises(ConfigError, match=r"report.points: point IDs 7, 99999 not in the store \(63 points, IDs 1000 \.\. 1086\)"):
        select_points(points, [1000, 7, 99999], name="report.points")
    with pytest.raises(ConfigError, match=r"integer point IDs; got 1.5, '3'"):
        select_points(points, [1.5, "3"])
    with pytest.raises(ConfigError, match="'some'"):
        select_points(points, "some")


# --------------------------------------------------------------------------- ParaView


def _pvd(path):
    root = ET.parse(path).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    return [(float(d.get("timestep")), d.get("file")) for d in root.find("Collection")]


def test_paraview_arrays_round_trip_exactly(stores, tmp_path):
    points, fields = stores
    pvd = write_paraview(points, tmp_path / "pv", fields=fields, dtype="float64")
    entries = _pvd(pvd)
    t = points["time"].values
    assert [e[0] for e in entries] == t.tolist()
    assert [e[1] for e in entries] == [f"points_{i:04d}.vtu" for i in range(t.size)]
    ids = points["point"].values
    for i, (_, fname) in enumerate(entries):
        m = meshio.read(pvd.parent / fname)
        x = points["x"].values[i]
        keep = np.isfinite(x).all(axis=1)
        assert len(m.cells) == 1 and m.cells[0].type == "vertex"
        np.testing.assert_array_equal(m.cells[0].data.ravel(), np.arange(keep.sum()))
        np.testing.assert_array_equal(m.points, x[keep])
        pd_ = m.point_data
        np.testing.assert_array_equal(pd_["point_id"], ids[keep])
        np.testing.assert_array_equal(pd_["temperature"], points["temperature"].values[i][keep])
        assert pd_["temperature"].dtype == np.float32  # stored float32 stays float32
        np.testing.assert_array_equal(pd_["pixel"], points["pixel"].values[i][keep])
        np.testing.assert_array_equal(pd_["visible"], points["visible"].values[i][keep].astype(np.uint8))
        np.testing.assert_array_equal(pd_["status"], points["status"].values[i][keep])
        np.testing.assert_array_equal(pd_["temperature_gradient"], fields["temperature_gradient"].values[i][keep])
        np.testing.assert_array_equal(pd_["strain"], fields["strain"].values[i][keep].reshape(-1, 4))
        np.testing.assert_array_equal(pd_["principal_direction_max"], fields["principal_direction"].values[i, :, 0][keep])
        np.testing.assert_array_equal(pd_["principal_direction_min"], fields["principal_direction"].values[i, :, 1][keep])
        np.testing.assert_array_equal(pd_["surface_parameter"], fields["surface_parameter"].values[keep])
        # fields' copies of x and temperature are not written twice; per-time scalars are not point data
        assert "fields_temperature" not in pd_ and "fields_x" not in pd_ and "mask_pixels" not in pd_
    assert meshio.read(pvd.parent / "points_0002.vtu").points.shape[0] == 62  # one point missing at t = 1 s


def test_paraview_float32_and_selected_times(stores, tmp_path):
    points, fields = stores
    pvd = write_paraview(points, tmp_path / "pv", fields=fields, times=[0.4, 2.0], name="fab")
    entries = _pvd(pvd)
    assert entries == [(0.5, "fab_0001.vtu"), (2.0, "fab_0004.vtu")]
    assert sorted(p.name for p in pvd.parent.iterdir()) == [".irdic-output", "fab.pvd", "fab_0001.vtu", "fab_0004.vtu"]
    m = meshio.read(pvd.parent / "fab_0004.vtu")
    assert m.point_data["temperature_rate"].dtype == np.float32
    np.testing.assert_array_equal(m.point_data["temperature_rate"],
                                  fields["temperature_rate"].values[4].astype(np.float32))
    assert m.points.dtype == np.float64


def test_paraview_replaces_its_own_folder_and_works_without_fields(stores, tmp_path):
    points, _ = stores
    out = tmp_path / "pv"
    pvd = write_paraview(points, out)
    assert [e[1] for e in _pvd(pvd)] == [f"points_{i:04d}.vtu" for i in range(5)]
    pvd = write_paraview(points, out, every=2)
    assert _pvd(pvd) == [(0.0, "points_0000.vtu"), (1.0, "points_0002.vtu"), (2.0, "points_0004.vtu")]
    assert not (out / "points_0001.vtu").exists()  # the older export was replaced as a whole
    m = meshio.read(pvd.parent / "points_0000.vtu")
    assert "temperature_local_rate" in m.point_data and "strain" not in m.point_data


def test_paraview_never_replaces_a_folder_irdic_did_not_write(stores, tmp_path):
    points, _ = stores
    out = tmp_path / "pv"
    out.mkdir()
    (out / "my_model.vtu").write_text("precious")
    with pytest.raises(DataError, match=r"pv: output path exists and is a folder that irdic did not write"):
        write_paraview(points, out)
    assert sorted(p.name for p in out.iterdir()) == ["my_model.vtu"]


def test_paraview_bad_arguments(stores, tmp_path):
    points, fields = stores
    with pytest.raises(ConfigError, match="plain file name stem"):
        write_paraview(points, tmp_path / "a", name="../x")
    with pytest.raises(ConfigError, match="dtype must be 'float32' or 'float64', got 'float16'"):
        write_paraview(points, tmp_path / "a", dtype="float16")
    with pytest.raises(ConfigError, match="every must be an integer >= 1, got 0"):
        write_paraview(points, tmp_path / "a", every=0)
    with pytest.raises(ConfigError, match="compression"):
        write_paraview(points, tmp_path / "a", compression="gzip")
    with pytest.raises(DataError, match="fields store has 4 times, points store 5"):
        write_paraview(points, tmp_path / "a", fields=fields.isel(time=slice(0, 4)))
    with pytest.raises(DataError, match="fields store has 62 points, points store 63"):
        write_paraview(points, tmp_path / "a", fields=fields.isel(point=slice(1, None)))
    with pytest.raises(DataError, match="lacks x"):
        write_paraview(points.drop_vars("x"), tmp_path / "a")
    assert not (tmp_path / "a").exists()


def test_fields_in_another_point_order_are_aligned(stores):
    points, fields = stores
    v = point_variables(points, fields.isel(point=slice(None, None, -1)))
    np.testing.assert_array_equal(v["surface_parameter"].values, fields["surface_parameter"].values)


def test_write_pvd_checks_lengths(tmp_path):
    with pytest.raises(ConfigError, match="2 files but 1 times"):
        write_pvd(tmp_path / "a.pvd", ["a.vtu", "b.vtu"], [0.0])


# --------------------------------------------------------------------------- CSV


def test_csv_round_trips_with_pandas(stores, tmp_path):
    points, fields = stores
    path = write_csv(points, tmp_path / "p.csv", fields=fields, point_ids=[1043, 1025])
    df = pd.read_csv(path)
    t = points["time"].values
    assert len(df) == 2 * t.size
    assert df.columns[:5].tolist() == ["time [s]", "point", "x [mm]", "y [mm]", "z [mm]"]
    for col in ("pixel_u [px]", "pixel_v [px]", "temperature [degC]", "temperature_gradient_y [K/mm]", "strain_22 [1]", "principal_direction_min_z [1]",
                "surface_parameter_psi2 [mm]", "visible", "status", "temperature_rate_convective [K/s]"):
        assert col in df.columns
    np.testing.assert_array_equal(df["time [s]"], np.repeat(t, 2))
    np.testing.assert_array_equal(df["point"], np.tile([1043, 1025], t.size))
    k = int(np.flatnonzero(points["point"].values == 1025)[0])
    rows = df[df["point"] == 1025]
    np.testing.assert_array_equal(rows[["x [mm]", "y [mm]", "z [mm]"]].values, points["x"].values[:, k])
    np.testing.assert_array_equal(rows["temperature [degC]"].values.astype(np.float32), points["temperature"].values[:, k])
    np.testing.assert_array_equal(rows["strain_22 [1]"].values, fields["strain"].values[:, k, 1, 1])
    np.testing.assert_array_equal(rows["status"].values, points["status"].values[:, k])
    assert rows["visible"].dtype == bool


def test_csv_missing_values_are_empty_and_times_selectable(stores, tmp_path):
    points, _ = stores
    idx = int(np.flatnonzero(points["point"].values == 1025)[0])
    assert idx == 19  # the point missing at t = 1 s in contract_stores()
    path = write_csv(points, tmp_path / "p.csv", point_ids=[1025], times=[1.0, 2.0],
                     variables=["temperature", "status"])
    text = path.read_text(encoding="utf-8").splitlines()
    assert text[0] == "time [s],point,x [mm],y [mm],z [mm],temperature [degC],status"
    assert text[1] == "1.0,1025,,,,,2"
    df = pd.read_csv(path)
    assert df["time [s]"].tolist() == [1.0, 2.0] and np.isnan(df.loc[0, "temperature [degC]"])


def test_csv_bad_arguments(stores, tmp_path):
    points, fields = stores
    with pytest.raises(ConfigError, match="point_ids: point ID 5 not in the store"):
        write_csv(points, tmp_path / "p.csv", point_ids=[5])
    with pytest.raises(ConfigError, match=r"variables: 'strain' not in the stores; available: .*temperature"):
        write_csv(points, tmp_path / "p.csv", variables=["strain"])
    with pytest.raises(ConfigError, match="list of names"):
        write_csv(points, tmp_path / "p.csv", fields=fields, variables="strain")
    with pytest.raises(ConfigError, match="times: 9 s outside"):
        write_csv(points, tmp_path / "p.csv", times=[9.0])
    assert not (tmp_path / "p.csv").exists()


def _fields_with_signals(fields):
    from irdic.io.signals import signal_coords

    t = fields["time"].values
    v = np.column_stack([1000.0 * t, 2.0 * t, t + 100.0])
    v[1, 0] = np.nan  # a DIC stage without the force
    return fields.assign({"signal_value": (("time", "signal"), v)}).assign_coords(
        signal_coords(["force", "machine_force", "time"], ["value_element", "machine", "value_element"],
                      ["N", "kN", ""]))


def test_csv_carries_the_signals_at_each_time(stores, tmp_path):
    import pandas as pd

    points, fields = stores
    f = _fields_with_signals(fields)
    p = write_csv(points, tmp_path / "s.csv", fields=f, point_ids=[1000, 1025])
    df = pd.read_csv(p)
    t = df["time [s]"].to_numpy()
    # the DIC signal named "time" must not pass for the time column
    assert list(df.columns[-3:]) == ["force [N]", "machine_force [kN]", "signal_time"]
    np.testing.assert_allclose(df["machine_force [kN]"], 2.0 * t)
    np.testing.assert_allclose(df["signal_time"], t + 100.0)
    gap = t == fields["time"].values[1]
    assert gap.sum() == 2 and df["force [N]"][gap].isna().all()
    np.testing.assert_allclose(df["force [N]"][~gap], 1000.0 * t[~gap])


def test_paraview_field_data_carries_the_signals(stores, tmp_path):
    import meshio

    points, fields = stores
    pvd = write_paraview(points, tmp_path / "pv", fields=_fields_with_signals(fields), dtype="float64")
    for k, t in enumerate(fields["time"].values):
        m = meshio.read(pvd.parent / f"points_{k:04d}.vtu")
        assert float(m.field_data["machine_force [kN]"][0]) == 2.0 * t
        if k == 1:
            assert np.isnan(m.field_data["force [N]"][0])
        else:
            assert float(m.field_data["force [N]"][0]) == 1000.0 * t
