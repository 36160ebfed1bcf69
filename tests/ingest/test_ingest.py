"""Ingest stage: raw series -> ir.zarr / dic.zarr, times, missing data and bad input."""

import datetime as dt

import numpy as np
import pytest

from irdic.errors import DataError, FormatError, IrdicError, IrdicWarning
from irdic.ingest.dic import ingest_dic
from irdic.ingest.ir import ingest_ir
from irdic.ingest.inputs import frame_times, list_inputs
from irdic.synthetic.writers import write_irbis, write_nodemap
from irdic.store import open_store
from irdic.synthetic.writers import write_irbis, write_nodemap

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
    assert [p.name for p in tmp_path.iterdir()] == ["ir"]


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
    # the reader first warns that the file ends mid-row, then refuses it
    with pytest.warns(IrdicWarning, match=r"spec_00001\.txt: the last data row has no line end"), \
            pytest.raises(FormatError, match=r"spec_00001\.txt"):
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


def test_mixed_dic_formats_are_refused_naming_both(tmp_path):
    from irdic.synthetic.writers import write_dice

    _write_dic_series(tmp_path / "dic")
    write_dice(tmp_path / "dic" / "DICe_solution_0.txt", np.arange(3), np.ones((3, 3)), np.zeros((3, 3)))
    with pytest.raises(DataError, match=r"mixes export formats: 3 nodemap files \(e\.g\. spec_0_0\.txt\) and "
                                        r"1 dice file \(e\.g\. DICe_solution_0\.txt\)") as exc:
        ingest_dic(tmp_path / "dic", tmp_path / "dic.zarr", time_source="file", frame_rate=2.0)
    assert "frame_rate" not in str(exc.value)
    assert not (tmp_path / "dic.zarr").exists()


def test_some_stages_without_time_stamp_do_not_suggest_frame_rate():
    with pytest.raises(DataError, match=r"b: no time stamp in the file, but a has one") as exc:
        frame_times([1.0, None, 3.0], None, labels=["a", "b", "c"], frame_rate=2.0)
    assert "frame_rate" not in str(exc.value)


def _npy_stack(path, frames):
    np.save(path, np.asarray(frames, dtype=np.float32))
    return path


def test_all_nan_stack_is_refused_at_ingest(tmp_path):
    # used to ingest with an INFO line and fail only at couple
    src = tmp_path / "ir"
    src.mkdir()
    _npy_stack(src / "stack.npy", np.full((3, 4, 5), np.nan))
    with pytest.raises(DataError, match=r"stack\.npy\[0\]: every pixel is NaN \(no temperature at all\); "
                                        r"irdic accepts at most 50 % NaN per frame"):
        ingest_ir(src, tmp_path / "ir.zarr", frame_rate=10.0)
    assert not (tmp_path / "ir.zarr").exists()


def test_mostly_nan_frame_names_its_valid_sensor_window(tmp_path):
    src = tmp_path / "ir"
    src.mkdir()
    frames = np.full((2, 6, 8), 21.0)
    frames[1, :, :] = np.nan
    frames[1, 2:4, 5:7] = 22.0  # 4 of 48 pixels valid
    _npy_stack(src / "stack.npy", frames)
    with pytest.raises(DataError, match=r"stack\.npy\[1\]: 91\.7 % of the pixels are NaN; the valid ones lie in "
                                        r"u 5\.\.6, v 2\.\.3 \(full-sensor px\)"):
        ingest_ir(src, tmp_path / "ir.zarr", frame_rate=10.0)


def test_nan_check_names_full_sensor_pixels_of_a_cropped_frame():
    from irdic.ingest.ir import check_nan_fraction
    from irdic.io.stack import temperature_dataarray

    x = np.full((6, 8), np.nan)
    x[0, 0] = 20.0
    da = temperature_dataarray(x, u0=300, v0=200)  # a crop export's sensor position
    with pytest.raises(DataError, match=r"f\.txt: 97\.9 % of the pixels are NaN; the valid ones lie in "
                                        r"u 300\.\.300, v 200\.\.200 \(full-sensor px\)"):
        check_nan_fraction("f.txt", da.values, da["u"].values, da["v"].values)


def test_some_nan_pixels_warn_with_their_fraction(tmp_path, caplog):
    src = tmp_path / "ir"
    src.mkdir()
    frames = np.full((2, 10, 10), 21.0)
    frames[1, 0, :5] = np.nan  # 5 of 200 values: 2.5 %
    _npy_stack(src / "stack.npy", frames)
    with caplog.at_level("WARNING", logger="irdic.ingest.ir"):
        ingest_ir(src, tmp_path / "ir.zarr", frame_rate=10.0)
    assert "IR: 2.50 % of all pixel values are NaN (no temperature), first in stack.npy[1] (5.00 % of that frame)" \
        in caplog.text
    ds = open_store(tmp_path / "ir.zarr")
    assert int(np.isnan(ds["temperature"].values).sum()) == 5


def test_duplicate_irb_time_stamps_are_refused_before_decoding(tmp_path, monkeypatch):
    import irdic.io.irb as irb
    from irdic.synthetic.writers import write_irb

    src = tmp_path / "ir"
    src.mkdir()
    write_irb(src / "seq.irb", 20 + np.zeros((3, 3, 4)), [0.0, 0.5, 0.5])

    def no_decoding(path):
        raise AssertionError("frames decoded before the time stamps were checked")

    monkeypatch.setattr(irb, "iter_irb_frames", no_decoding)
    with pytest.raises(DataError, match=r"IR frame times must increase: seq\.irb\[2\] \(t = 0\.5 s\) does not come "
                                        r"after seq\.irb\[1\] \(t = 0\.5 s\)"):
        ingest_ir(src, tmp_path / "ir.zarr")
    assert not (tmp_path / "ir.zarr").exists()


def test_irb_series_still_ingests(tmp_path):
    from irdic.synthetic.writers import write_irb

    src = tmp_path / "ir"
    src.mkdir()
    write_irb(src / "a.irb", 20 + np.arange(24.0).reshape(2, 3, 4), [0.0, 0.5])
    write_irb(src / "b.irb", 20 + np.arange(12.0).reshape(1, 3, 4), [1.0])
    ingest_ir(src, tmp_path / "ir.zarr")
    ds = open_store(tmp_path / "ir.zarr")
    np.testing.assert_allclose(ds["time"].values, [0.0, 0.5, 1.0])


def test_named_pipe_in_the_input_folder_is_refused(tmp_path):
    import os

    src = _write_ir_series(tmp_path / "ir", [0, 1])
    os.mkfifo(src / "spec_00002.txt")  # opening it would block for ever
    with pytest.raises(DataError, match=r"spec_00002\.txt: is a named pipe \(FIFO\), not a regular file"):
        list_inputs(src)
    with pytest.raises(DataError, match=r"spec_00002\.txt: is a named pipe"):
        ingest_ir(src, tmp_path / "ir.zarr")
    with pytest.raises(DataError, match=r"spec_00002\.txt: is a named pipe"):
        list_inputs(src / "spec_*.txt")
    with pytest.raises(DataError, match=r"spec_00002\.txt: is a named pipe"):
        list_inputs(src / "spec_00002.txt")
    (src / "sub").mkdir()  # sub-folders are still skipped
    os.remove(src / "spec_00002.txt")
    assert [p.name for p in list_inputs(src)] == ["spec_00000.txt", "spec_00001.txt"]


@pytest.mark.parametrize("threads", [2, 5])
def test_ir_files_read_in_parallel_equal_the_serial_result(tmp_path, threads):
    """A thread pool reading ahead writes the same store, frame for frame and in order, as one thread."""
    from irdic.threads import stage_threads

    src = tmp_path / "ir"
    src.mkdir()
    rng = np.random.default_rng(3)
    for k in range(23):  # not a multiple of the look-ahead (2 threads files)
        write_irbis(src / f"spec_{k:05d}.txt", 20 + rng.random((6, 9)), ms=100.0 * k, frame_index=k,
                    start_pos=(300, 200))
    with stage_threads(1):
        ingest_ir(src, tmp_path / "serial.zarr")
    with stage_threads(threads):
        ingest_ir(src, tmp_path / "parallel.zarr")
    a, b = open_store(tmp_path / "serial.zarr"), open_store(tmp_path / "parallel.zarr")
    for name in ("temperature", "time", "frame_index", "u", "v"):
        np.testing.assert_array_equal(a[name].values, b[name].values)
    np.testing.assert_array_equal(a["frame_index"].values, np.arange(23))
