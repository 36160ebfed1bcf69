"""Which pipeline jobs are up to date: the key of a job and the fingerprints of its outputs."""

import os

import numpy as np
import xarray as xr

from irdic.runs import LEDGER_DIR, Ledger, fingerprint
from irdic.store import write_dataset


def _job(tmp_path, ledger, params, calls):
    src, out = tmp_path / "raw.txt", tmp_path / "results" / "out.txt"

    def fn():
        calls.append(1)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(src.read_text() + str(params))

    return ledger.run("stage/exp", "code1", params, [src], [out], fn)


def test_a_job_is_skipped_only_when_key_and_outputs_are_unchanged(tmp_path):
    (tmp_path / "raw.txt").write_text("a")
    calls = []
    ledger = Ledger(tmp_path / "results")
    assert _job(tmp_path, ledger, {"c": 1}, calls) and len(calls) == 1
    assert (tmp_path / "results" / LEDGER_DIR / "stage__exp.json").is_file()
    assert not _job(tmp_path, ledger, {"c": 1}, calls) and len(calls) == 1  # unchanged: skipped
    assert ledger.skipped == ["stage/exp"]
    assert _job(tmp_path, ledger, {"c": 2}, calls) and len(calls) == 2  # a parameter
    st = (tmp_path / "raw.txt").stat()
    os.utime(tmp_path / "raw.txt", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert _job(tmp_path, ledger, {"c": 2}, calls) and len(calls) == 3  # an edited input
    (tmp_path / "results" / "out.txt").write_text("someone else's")
    assert _job(tmp_path, ledger, {"c": 2}, calls) and len(calls) == 4  # the output rewritten by another tool
    (tmp_path / "results" / "out.txt").unlink()
    assert _job(tmp_path, ledger, {"c": 2}, calls) and len(calls) == 5  # the output removed
    assert _job(tmp_path, Ledger(tmp_path / "results", force=True), {"c": 2}, calls) and len(calls) == 6
    # new code
    key = Ledger.key("code1", {"c": 2}, [tmp_path / "raw.txt"])
    assert key != Ledger.key("code2", {"c": 2}, [tmp_path / "raw.txt"])


def test_fingerprints_of_stores_files_and_folders(tmp_path):
    ds = xr.Dataset({"a": ("x", np.arange(3.0), {"units": "K", "long_name": "a"})})
    write_dataset(ds, tmp_path / "s.zarr", stage="test")
    fp = fingerprint(tmp_path / "s.zarr")
    assert fp.startswith("zarr:") and fingerprint(tmp_path / "s.zarr") == fp
    assert fingerprint(tmp_path / "missing") is None
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "f.txt").write_text("x")
    assert set(fingerprint(tmp_path / "d")) == {"f.txt"}
    assert fingerprint(tmp_path / "d" / "f.txt")[0] == 1
