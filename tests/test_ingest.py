"""Ingest stage: raw series -> ir.zarr / dic.zarr, times, missing data and bad input."""

import datetime as dt

import numpy as np
import pytest

from irdic.errors import DataError, FormatError, IrdicError
from irdic.ingest import frame_times, ingest_dic, ingest_ir, list_inputs
from irdic.io.irbis import write_irbis
from irdic.io.nodemap import write_nodemap
from irdic.store import open_store

T0 = dt.datetime(2025, 3, 14, 9, 26, 53)


def _frame(k, shape=(6, 8)):
    v, u = np.mgrid[: shape[0], : shape[1]]
    return (20.0 + 0.1 * u + 0.05 * v + 0.5 * k).astype(np.float64)


def _write_ir_series(folder, frame_numbers, *, start_pos=(300, 200), ms0=1234.5, rate=4.0, **kw):
    folder.mkdir(parents=True, exist_ok=True)
    for k in frame_numbers:
        write_irbis(folder / f"spec_{k:05d}.txt", _frame(k), ms=ms0 + 1000.0 * k / rate, frame_index=k,
                    rec_datetime=T0, start_pos=start_pos, sensor_size=(1024, 768), decimals=3, **kw)
    return folder


def test_ingest_ir_series_with_dropped_frame_and_crop(tmp_path):
    src = _write_ir_series(tmp_path / "ir", [10, 11, 12, 14, 15], sep=";", decimal=",", trailing_sep=True)
    out = ingest_ir(src, tmp_path / "ir.zarr")
    ds = open_store(out)
    assert ds["temperature"].dims == ("time", "v", "u")
    assert ds["temperature"].dtype == np.float32
    assert ds["temperature"].attrs["units"] == "degC"
    # time from the files' ms, origin at the first frame; the dropped frame 13 leaves a gap
    np.testing.assert_allclose(ds["time"], [0.0, 0.25, 0.5, 1.0, 1.25], atol=1e-9)
    np.testing.assert_array_equal(ds["frame_index"], [10, 11, 12, 14, 15])
    # full-sensor pixel coordinates of the crop window
    np.testing.assert_array_equal(ds["u"], np.arange(300, 308))
    np.testing.assert_array_equal(ds["v"], np.arange(200, 206))
    for i, k in enumerate([10, 11, 12, 14, 15]):
        np.testing.assert_allclose(ds["temperature"][i].values, _frame(k), atol=5e-4)
    assert ds["temperature"].encoding["chunks"] == (1, 6, 8)
    assert ds.attrs["irdic_stage"] == "ingest-ir"


def test_ingest_ir_time_offset_and_frame_rate(tmp_path):
    src = _write_ir_series(tmp_path / "ir", [0, 1, 2])
    ds = open_store(ingest_ir(src, tmp_path / "a.zarr", time_offset=0.5))
    np.testing.assert_allclose(ds["time"], [0.5, 0.75, 1.0])
    ds = open_store(ingest_ir(src, tmp_path / "b.zarr", time_source="frame_rate", frame_rate=2.0))
    np.testing.assert_allclose(ds["time"], [0.0, 0.5, 1.0])
    ds = open_store(ingest_ir(src, tmp_path / "c.zarr", time_origin="file"))
    np.testing.assert_allclose(ds["time"], [1.2345, 1.4845, 1.7345])


def test_ingest_ir_rejects_frames_of_other_size(tmp_path):
    src = _write_ir_series(tmp_path / "ir", [0, 1])
    write_irbis(src / "spec_00002.txt", np.zeros((5, 8)) + 20, ms=2000.0, frame_index=2, start_pos=(300, 200))
    with pytest.raises(DataError, match=r"spec_00002\.txt.*same size"):
        ingest_ir(src, tmp_path / "ir.zarr")
    assert not (tmp_path / "ir.zarr").exists()
    # no half-written store (the writers' lock file may stay)
    assert [p.name for p in tmp_path.iterdir() if p.name != ".ir.zarr.lock"] == ["ir"]


def test_ingest_ir_rejects_non_increasing_times(tmp_path):
    src = _write_ir_series(tmp_path / "ir", [0, 1, 2])
    write_irbis(src / "spec_00001.txt", _frame(1), ms=1000.0, frame_index=1, start_pos=(300, 200))
    with pytest.raises(DataError, match=r"times must increase: spec_00001\.txt"):
        ingest_ir(src, tmp_path / "ir.zarr")
    assert not (tmp_path / "ir.zarr").exists()


def test_ingest_ir_unreadable_file_names_it(tmp_path):
    src = _write_ir_series(tmp_path / "ir", [0, 1, 2])
    text = (src / "spec_00001.txt").read_bytes()
    (src / "spec_00001.txt").write_bytes(text[: len(text) // 2])  # truncated
    with pytest.raises(FormatError, match=r"spec_00001\.txt"):
        ingest_ir(src, tmp_path / "ir.zarr")
    assert not (tmp_path / "ir.zarr").exists()


def test_empty_folder_and_missing_path(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="folder contains no"):
        ingest_ir(tmp_path / "empty", tmp_path / "ir.zarr")
    with pytest.raises(DataError, match="no such file or folder"):
        ingest_dic(tmp_path / "nope", tmp_path / "dic.zarr")
    with pytest.raises(DataError, match="matches no"):
        list_inputs(tmp_path / "*.txt")


def test_list_inputs_natural_order_skips_pictures(tmp_path):
    for name in ["f_10.txt", "f_2.txt", "f_1.txt", "preview.png", ".hidden"]:
        (tmp_path / name).write_text("x")
    assert [p.name for p in list_inputs(tmp_path)] == ["f_1.txt", "f_2.txt", "f_10.txt"]


def test_frame_times_without_stamps_needs_rate():
    with pytest.raises(DataError, match="set frame_rate"):
        frame_times([None, None], None, labels=["a", "b"])
    np.testing.assert_allclose(frame_times([None, None], [3, 5], frame_rate=2.0), [0.0, 1.0])


def _write_dic_series(folder, n_points=12, n_stages=3):
    folder.mkdir(parents=True, exist_ok=True)
    ids = np.arange(100, 100 + n_points)
    rng = np.random.default_rng(1)
    x0 = rng.uniform(-10, 10, (n_points, 3))
    truth = []
    for s in range(n_stages):
        disp = np.zeros((n_points, 3))
        disp[:, 1] = 0.1 * s * x0[:, 1]
        keep = np.ones(n_points, bool)
        if s == 1:
            keep[3] = False  # point 103 absent from stage 1
            disp[5] = np.nan  # point 105 failed in stage 1
        write_nodemap(folder / f"spec_0_{s}.txt", ids[keep], x0[keep], disp[keep], stage_index=s,
                      relative_time=0.5 * s + 2.0)
        cur = x0 + disp
        cur[~keep] = np.nan
        truth.append(cur)
    return ids, x0, np.array(truth)


def test_ingest_dic_missing_points_and_times(tmp_path):
    ids, x0, truth = _write_dic_series(tmp_path / "dic")
    ds = open_store(ingest_dic(tmp_path / "dic", tmp_path / "dic.zarr"))
    assert ds["x"].dims == ("time", "point", "component")
    np.testing.assert_array_equal(ds["point"], ids)
    assert list(ds["component"].values) == ["x", "y", "z"]
    np.testing.assert_allclose(ds["time"], [0.0, 0.5, 1.0])
    np.testing.assert_allclose(ds["x"].values, truth, atol=1e-4, equal_nan=True)
    assert np.isnan(ds["x"].sel(point=103)[1]).all() and np.isnan(ds["x"].sel(point=105)[1]).all()
    np.testing.assert_allclose(ds["x_ref"].values, x0, atol=1e-4)
    assert ds["x"].attrs["units"] == "mm"


def test_ingest_dic_bad_file_in_series(tmp_path):
    _write_dic_series(tmp_path / "dic")
    (tmp_path / "dic" / "spec_0_1.txt").write_text("this is not a nodemap\n", encoding="latin-1")
    with pytest.raises(IrdicError, match=r"spec_0_1\.txt"):
        ingest_dic(tmp_path / "dic", tmp_path / "dic.zarr")
    assert not (tmp_path / "dic.zarr").exists()
