import numpy as np
import pytest
import xarray as xr
import zarr

from irdic.errors import DataError
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
    # no temporary sibling left behind (the writers' lock file stays, empty)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".s.zarr.lock", "s.zarr"]


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


def test_framestore_interrupted_leaves_nothing(tmp_path):
    write_dataset(_ds(), tmp_path / "ir.zarr", stage="old")  # an older complete result
    with pytest.raises(RuntimeError):
        with FrameStore(tmp_path / "ir.zarr", "temperature", 3, ("v", "u"), {"v": np.arange(2), "u": np.arange(2)}) as fs:
            fs.write(0, 0.0, np.zeros((2, 2)))
            raise RuntimeError("killed")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".ir.zarr.lock", "ir.zarr"]
    assert open_store(tmp_path / "ir.zarr").attrs["irdic_stage"] == "old"


def test_framestore_checks(tmp_path):
    fs = FrameStore(tmp_path / "ir.zarr", "temperature", 2, ("v", "u"), {"v": np.arange(2), "u": np.arange(2)})
    with pytest.raises(DataError, match="shape"):
        fs.write(0, 0.0, np.zeros((3, 2)))
    fs.write(0, 0.0, np.zeros((2, 2)))
    with pytest.raises(DataError, match="never written"):
        fs.close()
    fs.abort()
    assert [p.name for p in tmp_path.iterdir()] == [".ir.zarr.lock"]


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
    assert sorted(p.name for p in tmp_path.iterdir()) == [".ir.zarr.lock", "ir.zarr"]
