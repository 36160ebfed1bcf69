"""Assumptions about a lab's records, each checked where it first shows, with the message a user sees."""

import errno
import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from irdic.camera import CameraModel
from irdic.cli import main
from irdic.errors import DataError, OutputError
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
    from irdic.stages.identity import same_calibration

    M = np.asarray(_camera(0.1).M)
    ds = xr.Dataset(attrs={"calibration_projection_matrix": (-3.0 * M).ravel().tolist()})  # scale and sign free
    same_calibration(ds, "points.zarr", M, "cal.zarr")


def test_fields_with_another_experiments_dic_is_refused(tmp_path):
    from irdic.stages.identity import fields_inputs

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


def test_disk_full_while_writing_names_the_output(tmp_path, monkeypatch):
    write_dataset(xr.Dataset({"a": ("t", [1.0])}), tmp_path / "s.zarr", stage="ingest-dic")

    def full(self, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(xr.Dataset, "to_zarr", full)
    with pytest.raises(OutputError, match=rf"{re.escape(str(tmp_path / 's.zarr'))}: writing failed \(No space left "
                                          r"on device\); the previous s\.zarr is kept"):
        write_dataset(xr.Dataset({"a": ("t", [2.0])}), tmp_path / "s.zarr", stage="ingest-dic")
    assert float(open_store(tmp_path / "s.zarr")["a"][0]) == 1.0


def test_disk_full_while_streaming_frames_names_the_output(tmp_path, monkeypatch):
    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    out = tmp_path / "ir.zarr"
    with pytest.raises(OutputError, match=rf"{re.escape(str(out))}: writing failed \(No space left on device\); "
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
