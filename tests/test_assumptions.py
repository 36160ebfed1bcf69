"""Assumptions about a lab's records, each checked where it first shows, with the message a user sees."""

import errno
import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from irdic.camera import CameraModel
from irdic.cli import main
from irdic.errors import DataError, IrdicError
from irdic.store import FrameStore, open_store, write_dataset


def _ir(path, n=4):
    v, u = np.arange(3) + 100, np.arange(4) + 7
    with FrameStore(path, "temperature", n, ("v", "u"), {"v": v, "u": u}, attrs={"irdic_stage": "ingest-ir"}) as fs:
        for k in range(n):
            fs.write(k, float(k), np.full((3, 4), 20.0 + k))
    return path


def _dic(path, n_t=3, n_p=5):
    x = np.random.default_rng(0).normal(size=(n_t, n_p, 3))
    ds = xr.Dataset({"x": (("time", "point", "component"), x, {"units": "mm"})},
                    coords={"time": np.arange(n_t, dtype=float), "point": np.arange(n_p) + 1,
                            "component": ["x", "y", "z"]})
    return write_dataset(ds, path, stage="ingest-dic")


def _camera(angle=0.0):
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    K = np.array([[1000.0, 0, 512], [0, 1000.0, 384], [0, 0, 1]])
    return CameraModel(K=K, R=R, C=np.array([0.0, 0.0, -500.0]))


def _calibration(path, angle=0.0):
    cal = _camera(angle).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    return write_dataset(cal, path, stage="calibrate")


def _points(path, dic_path, angle=0.0):
    dic = open_store(dic_path)
    ds = dic[["x"]].load()
    ds.attrs = {"calibration_projection_matrix": np.asarray(_camera(angle).M).ravel().tolist()}
    return write_dataset(ds, path, stage="couple")


# --- identity: kinds and belonging together ------------------------------------


def test_couple_with_swapped_stores_names_them(tmp_path, capsys):
    ir, dic, cal = _ir(tmp_path / "ir.zarr"), _dic(tmp_path / "dic.zarr"), _calibration(tmp_path / "cal.zarr")
    code = main(["couple", "--dic", str(ir), "--ir", str(dic), "--calibration", str(cal),
                 "--out", str(tmp_path / "points.zarr")])
    err = capsys.readouterr().err
    assert code == 2
    assert f"irdic: error: {ir}: holds IR frames (ir.zarr), written by stage ingest-ir; expected DIC points " \
           "(dic.zarr), written by stage ingest-dic (are two paths swapped?)" in err
    assert "internal error" not in err


def test_fields_with_another_setups_calibration_is_refused(tmp_path, capsys):
    dic = _dic(tmp_path / "dic.zarr")
    pts = _points(tmp_path / "points.zarr", dic)
    other = _calibration(tmp_path / "other" / "cal.zarr", angle=0.3)
    code = main(["fields", "--points", str(pts), "--calibration", str(other), "--out", str(tmp_path / "f.zarr")])
    err = capsys.readouterr().err
    assert code == 2
    assert re.search(rf"{re.escape(str(other))}: is not the calibration {re.escape(str(pts))} was coupled with "
                     r"\(the projection matrices differ by 0\.\d+, relative\)", err), err


def test_same_calibration_written_twice_is_accepted():
    from irdic.identity import same_calibration

    M = np.asarray(_camera(0.1).M)
    ds = xr.Dataset(attrs={"calibration_projection_matrix": (-3.0 * M).ravel().tolist()})  # scale and sign free
    same_calibration(ds, "points.zarr", M, "cal.zarr")


def test_fields_with_another_experiments_dic_is_refused(tmp_path):
    from irdic.identity import fields_inputs

    pts = _points(tmp_path / "points.zarr", _dic(tmp_path / "dic.zarr"))
    cal = _calibration(tmp_path / "cal.zarr")
    other = _dic(tmp_path / "b" / "dic.zarr", n_p=6)
    with pytest.raises(DataError, match=rf"{re.escape(str(other))}: has 6 points, .*points\.zarr has 5; the two "
                                        "stores are not of the same experiment"):
        fields_inputs(pts, cal, other)
    shifted = open_store(_dic(tmp_path / "c" / "dic.zarr")).load()
    shifted["time"] = shifted["time"] + 0.5
    shifted = write_dataset(shifted, tmp_path / "c2" / "dic.zarr", stage="ingest-dic")
    with pytest.raises(DataError, match=r"dic\.zarr: time 0 is 0\.5 s, in .*points\.zarr it is 0\.0 s; the two"):
        fields_inputs(pts, cal, shifted)
    fields_inputs(pts, cal, tmp_path / "dic.zarr")  # its own dic.zarr passes


def test_export_with_fields_of_other_points_is_refused(tmp_path, capsys):
    pts = _points(tmp_path / "points.zarr", _dic(tmp_path / "dic.zarr"))
    other = open_store(_dic(tmp_path / "b" / "dic.zarr", n_p=4)).load()
    fields = write_dataset(other, tmp_path / "b" / "fields.zarr", stage="fields")
    code = main(["export", "--points", str(pts), "--fields", str(fields), "--out", str(tmp_path / "exp")])
    assert code == 2
    assert f"{fields}: has 4 points, {pts} has 5" in capsys.readouterr().err


# --- corrupted data ---------------------------------------------------------------


def test_truncated_frame_chunk_names_store_variable_and_chunk(tmp_path, capsys):
    ir = _ir(tmp_path / "ir.zarr")
    chunk = ir / "temperature" / "c" / "2" / "0" / "0"
    chunk.write_bytes(chunk.read_bytes()[:-7])
    ds = open_store(ir)
    np.testing.assert_array_equal(ds["temperature"][1].values, 21.0)  # the whole chunks still read
    with pytest.raises(DataError, match=rf"{re.escape(str(ir))}: variable 'temperature': chunk temperature/c/2/0/0 "
                                        r"holds \d+ bytes, \d+ when the store was finished \(cut short"):
        ds["temperature"].values
    code = main(["info", str(ir)])
    assert code in (0, 2) and "internal error" not in capsys.readouterr().err


def test_chunk_damaged_in_place_names_store_variable_and_chunk(tmp_path):
    ir = _ir(tmp_path / "ir.zarr")
    chunk = ir / "temperature" / "c" / "1" / "0" / "0"
    raw = bytearray(chunk.read_bytes())
    raw[:16] = bytes(16)  # a block of zeros from a failing disk: same length, so the size check passes
    chunk.write_bytes(bytes(raw))
    with pytest.raises(DataError, match=rf"{re.escape(str(ir))}: variable 'temperature': chunk temperature/c/1/0/0 "
                                        r"cannot be decoded \(RuntimeError: .*\); the store is damaged"):
        open_store(ir)["temperature"].values


def test_disk_full_while_writing_names_the_output(tmp_path, monkeypatch):
    write_dataset(xr.Dataset({"a": ("t", [1.0])}), tmp_path / "s.zarr", stage="ingest-dic")

    def full(self, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(xr.Dataset, "to_zarr", full)
    with pytest.raises(IrdicError, match=rf"{re.escape(str(tmp_path / 's.zarr'))}: writing failed \(No space left "
                                          r"on device\); the previous s\.zarr is kept"):
        write_dataset(xr.Dataset({"a": ("t", [2.0])}), tmp_path / "s.zarr", stage="ingest-dic")
    assert float(open_store(tmp_path / "s.zarr")["a"][0]) == 1.0


def test_disk_full_while_streaming_frames_names_the_output(tmp_path, monkeypatch):
    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    out = tmp_path / "ir.zarr"
    with pytest.raises(IrdicError, match=rf"{re.escape(str(out))}: writing failed \(No space left on device\); "
                                          rf"nothing was written to {re.escape(str(out))}"):
        with FrameStore(out, "temperature", 2, ("v", "u"), {"v": np.arange(2), "u": np.arange(2)}) as fs:
            monkeypatch.setattr(Path, "write_bytes", full)
            fs.write(0, 0.0, np.zeros((2, 2)))
    monkeypatch.undo()
    assert not out.exists() and not list(tmp_path.glob(".ir.zarr.tmp*"))


def test_an_input_that_cannot_be_read_keeps_its_own_name(tmp_path):
    with pytest.raises(FileNotFoundError):
        with FrameStore(tmp_path / "ir.zarr", "temperature", 1, ("v",), {"v": np.arange(2)}):
            open(tmp_path / "no-such-export.csv")


# --- time -------------------------------------------------------------------------


def test_numbered_series_with_a_member_missing_keeps_the_others_times(caplog):
    from irdic.ingest.inputs import frame_times

    names = ["stage_0001.csv", "stage_0002.csv", "stage_0004.csv", "stage_0005.csv"]
    with caplog.at_level("WARNING"):
        t = frame_times([None] * 4, None, labels=names, frame_rate=2.0, time_source="frame_rate", what="DIC stage")
    np.testing.assert_allclose(t, [0.0, 0.5, 1.5, 2.0])
    assert "DIC stages: 1 numbers missing in the file names (first after stage_0002.csv)" in caplog.text
    # numbers that are not a count (time stamps in ms) and plain names keep the positions
    ms = ["f_1000.csv", "f_1040.csv", "f_1080.csv"]
    np.testing.assert_allclose(frame_times([None] * 3, None, labels=ms, frame_rate=2.0), [0.0, 0.5, 1.0])
    np.testing.assert_allclose(frame_times([None] * 3, None, labels=["a", "b", "c"], frame_rate=2.0), [0, 0.5, 1])


def test_ingest_of_a_numbered_npy_series_with_a_gap(tmp_path):
    from irdic.ingest.ir import ingest_ir

    src = tmp_path / "ir"
    src.mkdir()
    for k in (0, 1, 3):
        np.save(src / f"frame_{k:03d}.npy", np.full((4, 5), 20.0 + k))
    ds = open_store(ingest_ir(src, tmp_path / "ir.zarr", time_source="frame_rate", frame_rate=10.0))
    np.testing.assert_allclose(ds["time"], [0.0, 0.1, 0.3])


def test_dic_time_in_a_gap_of_the_ir_record_gets_no_temperature(caplog):
    from tests._synthetic_stores import synthetic_inputs
    from irdic.coupling import couple
    from irdic.vocabulary import Status

    dic, ir, cal, _ = synthetic_inputs("halfshell")
    kept = ~np.isin(ir["time"].values, [1.0, 1.5, 2.0, 2.5, 3.0])  # the IR camera stopped from 0.5 s to 3.5 s
    with caplog.at_level("WARNING"):
        pts = couple(dic, ir.isel(time=kept), cal, method="bilinear")
    status = pts["status"].values
    assert (status[2] > Status.EXTRAPOLATED_FROM_EDGE).all() and np.isnan(pts["temperature"].values[2]).all()
    assert (status[2] == Status.TIME_OUTSIDE_IR_SPAN).sum() > 0.5 * status.shape[1]
    assert (status[[0, 1, 3, 4]] != Status.TIME_OUTSIDE_IR_SPAN).all()
    assert np.isfinite(pts["temperature"].values[[1, 3]]).any()
    assert ("couple: 1 DIC time(s) lie in a gap of the IR record, farther than 1 s from every IR frame (first "
            "t = 2 s, 1.5 s from the nearest frame)") in caplog.text


def test_a_gap_is_judged_against_the_kernel_the_interpolant_uses():
    from irdic.coupling.compute import in_ir_gap

    p = {"c_time": 1.0, "R0_time": 1.0}
    # a 25 Hz camera that stopped from 1.0 to 1.6 s: the interpolant's kernel spans 6 frame steps (0.24 s),
    # not the configured 1 s, so a DIC time 0.3 s from every frame lies in a gap, one 0.1 s from a frame not
    t_ir = np.r_[np.arange(0, 1.0001, 0.04), np.arange(1.6, 3.0001, 0.04)]
    t_dic = np.array([0.5, 1.1, 1.3, 2.0])
    np.testing.assert_array_equal(in_ir_gap(t_dic, t_ir, t_ir, p), [False, False, True, False])
    # a 2 Hz camera keeps the configured kernel (2 frame steps): 0.9 s from every frame is covered, 1.25 s not
    slow = np.r_[0.0, 0.5, 1.0, 3.5, 4.0]
    np.testing.assert_array_equal(in_ir_gap(np.array([1.9, 2.25]), slow, slow, p), [False, True])


# --- structure: a file holding more than the reader takes ---------------------------


def test_irbis_file_with_two_frames_is_refused(tmp_path):
    from irdic.io import read_ir
    from irdic.errors import FormatError
    from irdic.synthetic.writers import write_irbis

    frame = np.full((6, 8), 20.0)
    write_irbis(tmp_path / "a.txt", frame, ms=0.0, frame_index=1)
    write_irbis(tmp_path / "b.txt", frame + 1, ms=40.0, frame_index=2)
    both = (tmp_path / "a.txt").read_bytes() + (tmp_path / "b.txt").read_bytes()
    (tmp_path / "ab.txt").write_bytes(both)
    line = both[:both.rfind(b"[Data]")].count(b"\n") + 1
    with pytest.raises(FormatError, match=rf"ab\.txt, line {line}: a second \[Data\] section follows the first "
                                          r"frame's matrix: the file holds more than one frame"):
        read_ir(tmp_path / "ab.txt")


def test_tiff_pages_written_one_by_one_are_read_whole(tmp_path):
    import tifffile
    from irdic.errors import FormatError
    from irdic.io import read_ir

    with tifffile.TiffWriter(tmp_path / "pages.tif") as w:
        for k in range(3):
            w.write(np.full((4, 5), 20.0 + k, np.float32))
    da = read_ir(tmp_path / "pages.tif", frame_rate=2.0)
    assert da.shape == (3, 4, 5)
    np.testing.assert_array_equal(da.values[:, 0, 0], [20.0, 21.0, 22.0])
    with tifffile.TiffWriter(tmp_path / "mixed.tif") as w:
        w.write(np.full((4, 5), 20.0, np.float32))
        w.write(np.full((8, 10), 20.0, np.float32))  # a thumbnail or another camera's frame
    with pytest.raises(FormatError, match=r"mixed\.tif: holds 2 image series of different shapes or types "
                                          r"\(\(4, 5\) float32, \(8, 10\) float32\)"):
        read_ir(tmp_path / "mixed.tif", frame_rate=2.0)


# --- units and plausibility ------------------------------------------------------------


def _nodemaps(folder, scale_of_stage=None):
    from irdic.synthetic.writers import write_nodemap

    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(1)
    ids = np.arange(40) + 1
    x0 = np.c_[rng.uniform(0, 40, 40), rng.uniform(0, 20, 40), np.zeros(40)]
    for s in range(4):
        f = 1e-3 if s == scale_of_stage else 1.0
        write_nodemap(folder / f"spec_0_{s}.txt", ids, x0 * f, 0.01 * s * x0 * f, stage_index=s, relative_time=s)
    return folder


def test_dic_stage_in_metres_among_stages_in_mm_is_refused(tmp_path):
    from irdic.ingest.dic import ingest_dic

    src = _nodemaps(tmp_path / "dic", scale_of_stage=2)
    with pytest.raises(DataError, match=r"spec_0_2\.txt: its point cloud is 0\.001\d* times the size of the other "
                                        r"stages' .*a stage in another length unit \(m or inch instead of mm\)"):
        ingest_dic(src, tmp_path / "dic.zarr")
    assert not (tmp_path / "dic.zarr").exists()
    ok = open_store(ingest_dic(_nodemaps(tmp_path / "ok"), tmp_path / "ok.zarr"))
    assert ok.sizes["time"] == 4


def test_dic_cloud_in_metres_is_refused_at_couple():
    from tests._synthetic_stores import synthetic_inputs
    from irdic.coupling import couple

    dic, ir, cal, _ = synthetic_inputs("halfshell")
    metres = dic.copy()
    metres["x"] = dic["x"] * 1e-3
    with pytest.raises(DataError, match=r"the DIC points span at most 0\.\d+ px of the IR image \(their cloud is "
                                        r"0\.0\d+ across in the DIC unit\); are the DIC coordinates in m instead of mm\?"):
        couple(metres, ir, cal, method="bilinear")


# --- folders ---------------------------------------------------------------------------------


def test_store_written_into_its_own_export_folder_is_refused(tmp_path, capsys):
    src = tmp_path / "ir"
    src.mkdir()
    np.save(src / "frame_000.npy", np.full((4, 5), 20.0))
    code = main(["ingest-ir", str(src), str(src / "ir.zarr"), "--frame-rate", "2"])
    assert code == 2
    assert (f"irdic: error: stage ingest_ir: input source {src} contains output store {src / 'ir.zarr'}; inputs and "
            "outputs must not overlap") in capsys.readouterr().err
    assert not (src / "ir.zarr").exists()


def test_output_that_would_replace_its_input_is_refused(tmp_path):
    from irdic.errors import ConfigError
    from irdic.stages import couple

    dic = _dic(tmp_path / "dic.zarr")
    with pytest.raises(ConfigError, match=r"stage couple: input dic .*dic\.zarr is output store .*dic\.zarr"):
        couple.run({"dic": dic, "ir": tmp_path / "ir.zarr", "calibration": tmp_path / "c.zarr"}, {"store": dic})
    assert open_store(dic).sizes["point"] == 5
