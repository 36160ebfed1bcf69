import numpy as np
import pytest
import xarray as xr
import zarr

from irdic.errors import DataError
from irdic.outputs import OUTPUT_MARK, atomic_directory
from irdic.store import COMPLETE_ATTR, FrameStore, open_store, write_dataset


def _ds():
    return xr.Dataset(
        {"a": (("time", "point"), np.arange(6.0).reshape(2, 3), {"units": "K"})},
        coords={"time": [0.0, 0.5], "point": [10, 11, 12]},
    )


def test_write_dataset_roundtrip_with_provenance(tmp_path):
    out = write_dataset(_ds(), tmp_path / "s.zarr", stage="test", params={"c": np.float64(2.0)}, inputs=["f.txt"])
    ds = open_store(out)
    np.testing.assert_array_equal(ds["a"].values, _ds()["a"].values)
    assert ds["a"].attrs["units"] == "K"
    assert ds.attrs["irdic_stage"] == "test"
    assert ds.attrs["irdic_parameters"] == '{"c": 2.0}'
    assert ds.attrs[COMPLETE_ATTR] is True
    # no temporary sibling and no lock file left behind
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.zarr"]


def test_write_dataset_replaces_existing(tmp_path):
    write_dataset(_ds(), tmp_path / "s.zarr", stage="one")
    write_dataset(_ds() * 2, tmp_path / "s.zarr", stage="two")
    ds = open_store(tmp_path / "s.zarr")
    assert ds.attrs["irdic_stage"] == "two"
    assert float(ds["a"][1, 2]) == 10.0


def test_open_store_rejects_incomplete(tmp_path):
    # a store written by something else (or interrupted before the mark) is refused
    _ds().to_zarr(tmp_path / "half.zarr", zarr_format=3, consolidated=False)
    with pytest.raises(DataError, match="incomplete"):
        open_store(tmp_path / "half.zarr")
    with pytest.raises(DataError, match="not found"):
        open_store(tmp_path / "missing.zarr")


def test_framestore_streams_and_moves_into_place(tmp_path):
    v, u = np.arange(3) + 100, np.arange(4) + 7
    with FrameStore(tmp_path / "ir.zarr", "temperature", 2, ("v", "u"), {"v": v, "u": u},
                    var_attrs={"units": "degC"}, attrs={"x": 1},
                    extra_time_vars={"frame_index": ("int64", {})}) as fs:
        assert not (tmp_path / "ir.zarr").exists()  # nothing visible while writing
        fs.write(0, 0.0, np.zeros((3, 4)), frame_index=5)
        fs.write(1, 0.0, np.ones((3, 4)), frame_index=7)
        fs.set_times([1.0, 1.5])
    ds = open_store(tmp_path / "ir.zarr")
    assert ds["temperature"].dims == ("time", "v", "u")
    np.testing.assert_array_equal(ds["time"], [1.0, 1.5])
    np.testing.assert_array_equal(ds["u"], u)
    np.testing.assert_array_equal(ds["frame_index"], [5, 7])
    assert ds["temperature"].encoding["chunks"] == (1, 3, 4)


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int16])
def test_framestore_frames_round_trip_bit_exactly(tmp_path, dtype):
    # frames are encoded by FrameStore itself (blosc LZ4, bit shuffle): plain zarr and xarray must read
    # back exactly the values written, special floats included, in every frame slot, written out of order
    rng = np.random.default_rng(3)
    frames = (rng.normal(30.0, 5.0, (4, 5, 7)) * 100).round() / 100
    if np.dtype(dtype).kind == "f":
        frames[1, 0, :4] = [np.nan, np.inf, -np.inf, -0.0]
        frames[2] = rng.normal(0.0, 1e30, (5, 7))  # incompressible mantissas
    frames = frames.astype(dtype)
    with FrameStore(tmp_path / "ir.zarr", "temperature", 4, ("v", "u"), {"v": np.arange(5), "u": np.arange(7)},
                    dtype=dtype) as fs:
        for i in (2, 0, 3, 1):
            fs.write(i, float(i), frames[i])
    plain = xr.open_zarr(tmp_path / "ir.zarr")["temperature"].values
    assert plain.dtype == dtype
    assert plain.tobytes() == frames.tobytes()
    assert zarr.open_array(tmp_path / "ir.zarr" / "temperature")[:].tobytes() == frames.tobytes()
    assert open_store(tmp_path / "ir.zarr")["temperature"].values.tobytes() == frames.tobytes()
    with pytest.raises(DataError, match="frame index 4 outside 0..3"):
        with FrameStore(tmp_path / "x.zarr", "t", 4, ("v", "u"), {"v": np.arange(5), "u": np.arange(7)}) as fs:
            fs.write(4, 0.0, frames[0])


def test_framestore_interrupted_leaves_nothing(tmp_path):
    write_dataset(_ds(), tmp_path / "ir.zarr", stage="old")  # an older complete result
    with pytest.raises(RuntimeError):
        with FrameStore(tmp_path / "ir.zarr", "temperature", 3, ("v", "u"), {"v": np.arange(2), "u": np.arange(2)}) as fs:
            fs.write(0, 0.0, np.zeros((2, 2)))
            raise RuntimeError("killed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ir.zarr"]
    assert open_store(tmp_path / "ir.zarr").attrs["irdic_stage"] == "old"


def test_framestore_checks(tmp_path):
    fs = FrameStore(tmp_path / "ir.zarr", "temperature", 2, ("v", "u"), {"v": np.arange(2), "u": np.arange(2)})
    with pytest.raises(DataError, match="shape"):
        fs.write(0, 0.0, np.zeros((3, 2)))
    fs.write(0, 0.0, np.zeros((2, 2)))
    with pytest.raises(DataError, match="never written"):
        fs.close()
    fs.abort()
    assert [p.name for p in tmp_path.iterdir()] == []


def test_killed_stage_leaves_no_store_and_the_next_run_cleans_up(tmp_path):
    """A stage killed while writing (SIGKILL, no clean-up code runs) leaves no
    store under the final name; the next run removes the dead temporary."""
    import signal
    import subprocess
    import sys
    import textwrap
    import time

    script = textwrap.dedent(f"""
        import time, numpy as np
        from irdic.store import FrameStore
        with FrameStore({str(tmp_path / 'ir.zarr')!r}, "temperature", 1000, ("v", "u"),
                        {{"v": np.arange(64), "u": np.arange(64)}}) as fs:
            for i in range(1000):
                fs.write(i, float(i), np.full((64, 64), float(i)))
                if i == 5:
                    print("writing", flush=True)
                time.sleep(0.01)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "writing"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    time.sleep(0.1)
    names = [p.name for p in tmp_path.iterdir()]
    assert "ir.zarr" not in names  # nothing a later stage could take for a result
    assert any(n.startswith(".ir.zarr.tmp-") for n in names)  # the dead job's temporary
    with pytest.raises(DataError, match="not found"):
        open_store(tmp_path / "ir.zarr")
    write_dataset(_ds(), tmp_path / "ir.zarr", stage="rerun")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ir.zarr"]


# --------------------------------------------------------------------------- data safety

_BY_TIME = {"a": {"chunks": (1, 3)}}


def test_refuses_to_replace_what_irdic_did_not_write(tmp_path):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "thesis.tex").write_text("precious")
    with pytest.raises(DataError, match=r"victim: output path exists and is a folder that irdic did not write"):
        write_dataset(_ds(), victim, stage="x")
    assert (victim / "thesis.tex").read_text() == "precious"
    afile = tmp_path / "notes.txt"
    afile.write_text("precious")
    with pytest.raises(DataError, match="is a file that irdic did not write"):
        write_dataset(_ds(), afile, stage="x")
    assert afile.read_text() == "precious"
    # a foreign zarr store (no irdic provenance) is a user's data too
    _ds().to_zarr(tmp_path / "theirs.zarr", zarr_format=3, consolidated=False)
    with pytest.raises(DataError, match="irdic did not write"):
        write_dataset(_ds(), tmp_path / "theirs.zarr", stage="x")
    link = tmp_path / "link.zarr"
    link.symlink_to(victim)
    with pytest.raises(DataError, match="is a symbolic link"):
        write_dataset(_ds(), link, stage="x")
    assert (victim / "thesis.tex").read_text() == "precious"
    # nothing was written next to them either
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]


def test_empty_folder_and_irdic_output_folders_are_replaced(tmp_path):
    (tmp_path / "s.zarr").mkdir()
    write_dataset(_ds(), tmp_path / "s.zarr", stage="one")
    assert open_store(tmp_path / "s.zarr").attrs["irdic_stage"] == "one"
    with atomic_directory(tmp_path / "out") as tmp:
        tmp.mkdir()
        (tmp / "a.vtu").write_text("1")
    assert (tmp_path / "out" / OUTPUT_MARK).is_file()
    with atomic_directory(tmp_path / "out") as tmp:
        tmp.mkdir()
        (tmp / "b.vtu").write_text("2")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [OUTPUT_MARK, "b.vtu"]


def test_open_store_refuses_a_store_with_missing_chunks(tmp_path):
    write_dataset(_ds(), tmp_path / "s.zarr", stage="x", encoding=_BY_TIME)
    chunk = tmp_path / "s.zarr" / "a" / "c" / "1" / "0"
    assert chunk.is_file()
    chunk.unlink()
    with pytest.raises(DataError, match=r"s.zarr: variable 'a' has 1 of its 2 chunks"):
        open_store(tmp_path / "s.zarr")


def test_chunk_lost_after_open_raises_instead_of_nan(tmp_path):
    write_dataset(_ds(), tmp_path / "s.zarr", stage="x", encoding=_BY_TIME)
    ds = open_store(tmp_path / "s.zarr")
    (tmp_path / "s.zarr" / "a" / "c" / "1" / "0").unlink()
    with pytest.raises(DataError, match=r"variable 'a': chunk a/c/1/0 is missing"):
        ds["a"].values


def test_all_fill_value_chunks_are_not_missing(tmp_path):
    # zarr does not write chunks equal to the fill value: they must not read as damage
    ds = _ds()
    ds["a"][:] = np.nan
    write_dataset(ds, tmp_path / "s.zarr", stage="x", encoding=_BY_TIME)
    assert np.isnan(open_store(tmp_path / "s.zarr")["a"].values).all()


def test_store_replaced_while_read_lazily_raises(tmp_path):
    write_dataset(_ds(), tmp_path / "s.zarr", stage="one")
    ds = open_store(tmp_path / "s.zarr")
    write_dataset(_ds() * 2, tmp_path / "s.zarr", stage="two")
    with pytest.raises(DataError, match="replaced or removed while it was being read"):
        ds["a"].values  # the old metadata with the new chunks would be a silent mix


_RACE_WRITER = """
import sys, numpy as np, xarray as xr
from irdic.store import write_dataset
path, n = sys.argv[1], int(sys.argv[2])
for k in range(1, n + 1):
    ds = xr.Dataset({"a": (("time", "point"), np.full((20, 50), float(k)))},
                    coords={"time": np.arange(20.0), "point": np.arange(50)})
    write_dataset(ds, path, stage="race", params={"k": k}, encoding={"a": {"chunks": (1, 50)}})
"""


def test_reader_never_sees_a_half_replaced_store(tmp_path):
    """A reader looping over open_store while another process rewrites the
    store gets complete data with the values of one write, or a DataError;
    never NaN (missing chunks), never a raw KeyError, never a mix."""
    import json
    import subprocess
    import sys

    path = tmp_path / "s.zarr"
    subprocess.run([sys.executable, "-c", _RACE_WRITER, str(path), "1"], check=True)
    writer = subprocess.Popen([sys.executable, "-c", _RACE_WRITER, str(path), "25"])
    good = errors = 0
    try:
        while writer.poll() is None:
            try:
                ds = open_store(path)
                k = json.loads(ds.attrs["irdic_parameters"])["k"]
                a = ds["a"].values
            except DataError:
                errors += 1
                continue
            assert a.shape == (20, 50)
            assert np.all(a == float(k)), f"write {k} read back as {np.unique(a)}"
            good += 1
    finally:
        writer.wait(timeout=120)
    assert writer.returncode == 0
    assert good > 0
    ds = open_store(path)
    assert np.all(ds["a"].values == 25.0)
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name or ".old-" in p.name]


def test_two_writers_take_turns(tmp_path):
    import subprocess
    import sys

    path = tmp_path / "s.zarr"
    procs = [subprocess.Popen([sys.executable, "-c", _RACE_WRITER, str(path), "8"], stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=180)
        assert p.returncode == 0, err
    assert np.all(open_store(path)["a"].values == 8.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.zarr"]


def test_second_writer_times_out_clearly(tmp_path):
    path = tmp_path / "s.zarr"
    with atomic_directory(path) as tmp:
        tmp.mkdir()
        with pytest.raises(DataError, match=r"s.zarr: another job has been writing this output for over 0.2 s "
                                            r"\(its temporary: \.s\.zarr\.tmp-"):
            with atomic_directory(path, lock_timeout=0.2):
                pass
    assert (path / OUTPUT_MARK).is_file()


def test_stale_temporaries_of_other_hosts_are_kept(tmp_path, monkeypatch):
    import os
    import time

    from irdic import outputs

    path = tmp_path / "s.zarr"
    other = tmp_path / ".s.zarr.tmp-999999-abcdef12-othernode-7"
    mine_dead = tmp_path / f".s.zarr.tmp-999999-abcdef12-{outputs._host()}"
    old_other = tmp_path / ".s.zarr.tmp-999999-abcdef13-othernode-8"
    for d in (other, mine_dead, old_other):
        d.mkdir()
    old = time.time() - outputs.STALE_AGE_S - 10
    os.utime(old_other, (old, old))
    monkeypatch.setattr(outputs, "_pid_alive", lambda pid: False)
    write_dataset(_ds(), path, stage="x")
    names = {p.name for p in tmp_path.iterdir()}
    assert other.name in names  # a live job on another node may own it: os.kill cannot tell
    assert mine_dead.name not in names and old_other.name not in names


def test_plain_xarray_opens_a_store_without_warnings(tmp_path):
    """Users read stores with plain ``xr.open_zarr``: no warning, even inside a Snakemake directory output."""
    import warnings

    ds = xr.Dataset({"a": (("time", "point"), np.arange(12.0).reshape(3, 4))},
                    coords={"time": [0.0, 1.0, 2.0], "point": [1, 2, 3, 4]})
    write_dataset(ds, tmp_path / "s.zarr", stage="test")
    (tmp_path / "s.zarr" / ".snakemake_timestamp").touch()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = xr.open_zarr(tmp_path / "s.zarr")
        xr.testing.assert_equal(got.a.load(), ds.a)
    assert open_store(tmp_path / "s.zarr").attrs["irdic_complete"]


def test_a_store_written_in_parts_equals_one_written_whole(tmp_path):
    """write_dataset(append=...) (the gather of time chunks, one part in memory at a time) gives the same store."""
    from irdic.chunks import gathered

    rng = np.random.default_rng(0)
    parts = []
    for i, n in enumerate((3, 4, 2)):  # later parts longer and shorter than the first (its zarr chunks)
        t = np.arange(n) + 10.0 * i
        parts.append(xr.Dataset({"v": (("time", "point"), rng.normal(size=(n, 5)), {"units": "K"}),
                                 "w": (("time", "point", "component"), rng.normal(size=(n, 5, 3))),
                                 "ref": (("point",), np.arange(5.0))},
                                coords={"time": t, "point": np.arange(5)}, attrs={"note": "first" if i == 0 else "x"}))
    whole = xr.concat([p[["v", "w"]] for p in parts], dim="time").assign(ref=parts[0]["ref"])
    write_dataset(whole.assign_attrs(parts[0].attrs), tmp_path / "whole.zarr", stage="test")
    first, rest = gathered(parts)
    write_dataset(first, tmp_path / "parts.zarr", stage="test", append=rest)
    a, b = open_store(tmp_path / "whole.zarr"), open_store(tmp_path / "parts.zarr")
    xr.testing.assert_identical(a.drop_attrs(), b.drop_attrs())
    assert b.attrs["note"] == "first" and b.attrs["irdic_stage"] == a.attrs["irdic_stage"]


_LOCK_WORKER = """
import os, sys, time
from pathlib import Path
from irdic import outputs
final, marker, n = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
for _ in range(n):
    with outputs._writer_lock(final, 60):
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)  # FileExistsError: two holders at once
        time.sleep(0.001)
        os.close(fd)
        os.unlink(marker)
"""


def test_lock_files_are_removed_and_writers_still_exclude_each_other(tmp_path):
    """Each holder removes the lock file on release; three processes taking it 150 times each never overlap
    (a waiter that got the lock of a removed file tries again on the file now at the path)."""
    import subprocess
    import sys

    final = tmp_path / "s.zarr"
    procs = [subprocess.Popen([sys.executable, "-c", _LOCK_WORKER, str(final), str(tmp_path / "holder"), "150"],
                              stderr=subprocess.PIPE, text=True) for _ in range(3)]
    for p in procs:
        _, err = p.communicate(timeout=180)
        assert p.returncode == 0, err
    assert list(tmp_path.iterdir()) == []


def test_a_waiter_that_locked_a_removed_lock_file_does_not_count_as_holder(tmp_path, monkeypatch):
    """The race of removing lock files: B opens the lock file, its holder removes it and C creates and
    locks a new one; B's lock on the removed file must not let B in beside C."""
    import fcntl
    import os

    from irdic import outputs

    path = tmp_path / ".s.zarr.lock"
    real_flock = fcntl.flock
    other = {}

    def flock_after_the_holder_left(fd, op):
        if not other:  # between B's open and B's flock: the holder removes the file, C takes a new one
            os.unlink(path)
            other["fd"] = None
            other["fd"] = outputs._try_lock(path)
            assert other["fd"] is not None
        return real_flock(fd, op)

    monkeypatch.setattr(outputs.fcntl, "flock", flock_after_the_holder_left)
    path.touch()
    assert outputs._try_lock(path) is None  # C holds the file now at the path: B must wait
    monkeypatch.setattr(outputs.fcntl, "flock", real_flock)
    outputs._unlock(path, other["fd"])
    fd = outputs._try_lock(path)
    assert fd is not None
    outputs._unlock(path, fd)
    assert not path.exists()
