"""The tiny demo's results stay what they were (refactoring guard).

``tests/data/golden_tiny.npz`` holds every numeric variable of the stores the
pipeline writes for the tiny demo (with its default noise, and once more with
all three regression options on). A change that is meant to keep behaviour
(a refactoring, a speed-up) must reproduce them to 1e-9 relative.

A change that is *meant* to change results regenerates the file, and says so
in its commit message::

    python -m tests.test_golden --write
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

GOLDEN = Path(__file__).resolve().parent / "data" / "golden_tiny.npz"
RTOL = 1e-9
#: OpenBLAS kernels the golden file was written with (tests/conftest.py picks them where the CPU has them)
KERNEL = "Haswell"
#: other kernels round differently in the last bits, which the RBF systems amplify (7e-6 seen, AVX-512 against
#: AVX2): on such a machine the file still guards against changes of results, at this tolerance
RTOL_OTHER_KERNEL = 1e-4
#: the uncertainties (``*_std``) come from noise probes whose bias estimates subtract nearly equal mean squares
#: (``d² − v``) before a square root: the same kernels on another CPU (AMD EPYC, AVX2, against the file's
#: machine) moved them by up to 1e-8 of their scale while every value stayed within 1e-9; a change of the
#: uncertainty model moves them by far more than this
RTOL_STD = 1e-7


def blas_kernels() -> set[str]:
    """The OpenBLAS kernel names numpy and scipy run with here (threadpoolctl's ``architecture``)."""
    from threadpoolctl import threadpool_info

    return {i.get("architecture", "?") for i in threadpool_info() if i.get("internal_api") == "openblas"}

pytestmark = pytest.mark.slow

_STORES = {
    "calibration": ("setups", "lab", "calibration.zarr"),
    "points": ("{e}", "points.zarr"),
    "fields": ("{e}", "fields.zarr"),
}


def _config(smoothing: bool) -> dict:
    from irdic.config import validate_config

    cfg = {
        "demo": {"enabled": False},
        "setups": {"lab": {"markers": {"path": "demo/setup/markers.txt"},
                           "target_image": {"path": "demo/setup/target.txt"}}},
        "experiments": {e: {"setup": "lab", "dic": {"path": f"demo/{e}/dic"}, "ir": {"path": f"demo/{e}/ir"}}
                        for e in ("halfshell", "tube")},
    }
    if smoothing:
        cfg["fields"] = {"temperature_smoothing": "gcv", "temperature_smoothing_space": "gcv",
                         "surface_smoothing": "gcv"}
    return validate_config(cfg)


def golden_arrays(workdir: Path) -> dict[str, np.ndarray]:
    """Run the tiny demo through :func:`irdic.pipeline.run` and collect its numbers."""
    import os

    from irdic.pipeline import run
    from irdic.synthetic.demo_folder import make_demo
    from irdic.store import open_store

    workdir = Path(workdir)
    make_demo(workdir / "demo", scale="tiny")
    out: dict[str, np.ndarray] = {}
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        for label, smoothing in (("default", False), ("gcv", True)):
            cfg = _config(smoothing)
            cfg["results"] = f"results-{label}"
            # one thread: multi-threaded BLAS rounds differently from run to run of a test session
            run(cfg, stages=("ingest", "calibrate", "couple", "fields"), threads=1)
            res = Path(cfg["results"])
            for e in ("halfshell", "tube"):
                for store in ("points", "fields") + (("calibration",) if e == "halfshell" else ()):
                    parts = [p.format(e=e) for p in _STORES[store]]
                    ds = open_store(res.joinpath(*parts))
                    for name, var in {**ds.data_vars, **ds.coords}.items():
                        if var.dtype.kind in "fiub":
                            out[f"{label}/{e if store != 'calibration' else 'lab'}/{store}/{name}"] = var.values
    finally:
        os.chdir(cwd)
    return out


@pytest.fixture(scope="module")
def current(tmp_path_factory):
    return golden_arrays(tmp_path_factory.mktemp("golden"))


def test_demo_results_unchanged(current):
    if not GOLDEN.exists():
        pytest.fail(f"{GOLDEN} is missing; create it with `python -m tests.test_golden --write`")
    with np.load(GOLDEN) as ref:
        expected = {k: ref[k] for k in ref.files}
    assert sorted(current) == sorted(expected), "the stores hold other variables than the golden file"
    # the kernels the file was written with give the same numbers to 1e-9 on any machine
    base = RTOL if blas_kernels() == {KERNEL} else RTOL_OTHER_KERNEL
    for key, want in expected.items():
        got = current[key]
        assert got.shape == want.shape, key
        if want.dtype.kind == "f":
            scale = np.nanmax(np.abs(want)) if np.isfinite(want).any() else 0.0
            np.testing.assert_array_equal(np.isnan(got), np.isnan(want), err_msg=key)
            # float32 stores round the float64 computation once more: a last-bit difference of the CPU's
            # BLAS kernels (AVX2 against AVX-512) moves a value by one float32 step, not by 1e-9
            rtol = max(base, float(np.finfo(want.dtype).eps), RTOL_STD if key.endswith("_std") else 0.0)
            np.testing.assert_allclose(got, want, rtol=rtol, atol=rtol * scale, equal_nan=True, err_msg=key)
        else:
            np.testing.assert_array_equal(got, want, err_msg=key)


if __name__ == "__main__":
    import os
    import tempfile

    if "--write" not in sys.argv:
        sys.exit("usage: python -m tests.test_golden --write")
    # BLAS must be single-threaded from start-up, as tests/conftest.py makes it
    # for the test run: a thread limit set later (threadpoolctl) picks other
    # kernels whose rounding differs by ~1e-8; and the kernels the test compares with (KERNEL).
    if (os.environ.get("OPENBLAS_NUM_THREADS") != "1" or os.environ.get("OMP_NUM_THREADS") != "1"
            or os.environ.get("OPENBLAS_CORETYPE") != KERNEL):
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_CORETYPE=KERNEL)
        os.execve(sys.executable, [sys.executable, "-m", "tests.test_golden", *sys.argv[1:]], env)
    with tempfile.TemporaryDirectory() as tmp:
        arrays = golden_arrays(Path(tmp))
    GOLDEN.parent.mkdir(exist_ok=True)
    np.savez_compressed(GOLDEN, **arrays)
    print(f"wrote {GOLDEN}: {len(arrays)} arrays, {GOLDEN.stat().st_size / 1e6:.2f} MB")
