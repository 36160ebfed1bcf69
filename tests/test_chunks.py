"""Time-chunked couple and fields: windows from the kernel's reach, scatter/gather, equality with whole records."""

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from irdic.chunks import chunk_slice, gathered, n_chunks, window
from irdic.errors import ConfigError, DataError
from irdic.numerics.temporal import FLAT_KERNEL_SPACINGS, TemporalInterpolant, temporal_reach

ROOT = Path(__file__).resolve().parents[1]


def test_chunks_partition_the_times():
    assert n_chunks(300, 100) == 3 and n_chunks(301, 100) == 4 and n_chunks(300, 0) == 1 and n_chunks(5, 10) == 1
    sl = [chunk_slice(301, i, 4) for i in range(4)]
    assert sl[0].start == 0 and sl[-1].stop == 301
    assert all(a.stop == b.start for a, b in zip(sl, sl[1:]))
    assert max(s.stop - s.start for s in sl) - min(s.stop - s.start for s in sl) <= 1
    with pytest.raises(DataError, match="3 DIC time.*4 chunks.*chunk_frames"):
        chunk_slice(3, 0, 4)
    with pytest.raises(ConfigError, match="chunk_frames must be an integer >= 0"):
        n_chunks(10, -1)


@pytest.mark.parametrize("h", [0.5, 0.25, 0.2])
def test_window_of_the_reach_reproduces_the_whole_series(h):
    """Values and rates from a window of reach samples each side equal the whole-series interpolant (1e-4)."""
    t = np.arange(400) * h
    n = temporal_reach(t, c=1.0, R0=1.0)
    assert n < 60  # the reach is short: a chunk reads a bounded window
    rng = np.random.default_rng(1)
    # ~10 K heating with wiggles and noise: the series the tolerance is stated for
    f = 20 + 10 * np.tanh((t - t.mean()) / 20) + 0.5 * np.sin(2.3 * t) + 0.05 * rng.standard_normal(t.size)
    whole = TemporalInterpolant(t, c=1.0, R0=1.0)
    te = np.linspace(t[150], t[230], 97)
    w = window(t, te[0], te[-1], n)
    part = TemporalInterpolant(t[w], c=1.0, R0=1.0)
    for d, tol in ((0, 1e-4), (1, 1e-4 * np.abs(whole(f, te, 1)).max())):
        np.testing.assert_allclose(part(f[w], te, d), whole(f, te, d), rtol=0, atol=tol)
    # and a much shorter window does not: the reach is not overly generous by orders of magnitude
    short = slice(w.start + n - 2, w.stop - n + 2)
    assert np.abs(TemporalInterpolant(t[short])(f[short], te) - whole(f, te)).max() > 1e-6


def test_a_flat_kernel_is_narrowed_and_reaches_a_window_not_the_whole_record():
    t = np.arange(500) * 0.02  # 50 Hz with c R0 = 1 s: 50 spacings, which the saddle system loses the digits of
    n = temporal_reach(t, c=1.0, R0=1.0)
    assert n == temporal_reach(t, c=1.0, R0=FLAT_KERNEL_SPACINGS * 0.02) <= t.size // 8
    # a chunk of a fast record gets the whole record's values and rates
    rng = np.random.default_rng(2)
    f = 20 + 3 * np.tanh(t - 5) + 0.05 * rng.standard_normal(t.size)
    te = np.linspace(t[200], t[260], 37)
    w = window(t, te[0], te[-1], n)
    whole, part = TemporalInterpolant(t, window=n), TemporalInterpolant(t[w], window=n)
    for d in (0, 1):
        np.testing.assert_allclose(part(f[w], te, d), whole(f, te, d), rtol=0, atol=1e-10)


def test_gather_refuses_overlapping_chunks():
    a = xr.Dataset({"v": (("time",), [1.0, 2.0])}, coords={"time": [0.0, 1.0]})
    b = xr.Dataset({"v": (("time",), [3.0])}, coords={"time": [1.0]})
    with pytest.raises(DataError, match="overlap or are out of order.*delete the results' chunks folder"):
        gathered([a, b])


def _write(path, text=""):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_dry_run_on_slurm_shows_a_job_per_chunk(tmp_path):
    """300 DIC stages with chunk_frames 100: three couple_chunk and three fields_chunk jobs on profiles/slurm."""
    for k in range(300):
        _write(tmp_path / "raw/dic" / f"stage_{k:04d}.csv")
    _write(tmp_path / "raw/ir/frames.irb")
    _write(tmp_path / "raw/markers.txt")
    _write(tmp_path / "raw/target.txt")
    cfg = {"demo": {"enabled": False},
           "setups": {"lab": {"markers": {"path": "raw/markers.txt"}, "target_image": {"path": "raw/target.txt"}}},
           "experiments": {"long": {"setup": "lab", "dic": {"path": "raw/dic"}, "ir": {"path": "raw/ir"}}},
           "execution": {"chunk_frames": 100}}
    with open(tmp_path / "config.yaml", "w") as fh:
        yaml.safe_dump(cfg, fh)
    res = subprocess.run([sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory",
                          str(tmp_path), "--configfile", str(tmp_path / "config.yaml"), "--profile",
                          str(ROOT / "profiles" / "slurm"), "-n", "--quiet", "rules"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    counts = {}
    for line in res.stdout.splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[1].isdigit():
            counts[parts[0]] = int(parts[1])
    assert counts.get("couple_chunk") == 3 and counts.get("fields_chunk") == 3, res.stdout
    assert counts.get("couple") == 1 and counts.get("fields") == 1, res.stdout


# --- the tiny demo whole and chunked -------------------------------------------------------------------------

_VARS = {"points": ("temperature", "temperature_pixel_gradient", "temperature_local_rate", "edge_distance",
                    "status", "visible", "pixel", "x"),
         "fields": ("temperature_gradient", "temperature_rate", "temperature_rate_local",
                    "temperature_rate_convective", "velocity", "strain", "equivalent_strain", "reference_basis")}


def _compare(whole: Path, chunked: Path):
    from irdic.store import open_store

    for kind, names in _VARS.items():
        a, b = open_store(whole / f"{kind}.zarr"), open_store(chunked / f"{kind}.zarr")
        assert set(a.data_vars) == set(b.data_vars) and dict(a.sizes) == dict(b.sizes), kind
        np.testing.assert_array_equal(a["time"].values, b["time"].values)
        for n in names:
            x, y = a[n].values.astype(float), b[n].values.astype(float)
            np.testing.assert_array_equal(np.isnan(x), np.isnan(y), err_msg=f"{kind}.{n}: missing values differ")
            ok = np.isfinite(x)
            # temperatures (K) absolutely, gradients and rates relative to their largest value
            tol = 1e-4 if n == "temperature" else 1e-4 * max(np.abs(x[ok]).max(), 1e-12)
            assert np.abs(x[ok] - y[ok]).max() <= tol, (kind, n, np.abs(x[ok] - y[ok]).max())
            # the record's first and last times are no exception
            for i in (0, -1):
                d = np.abs(x[i] - y[i])[ok[i]]
                assert d.size == 0 or d.max() <= tol, (kind, n, i, d.max())
        if kind == "points":
            assert {k: v for k, v in a.attrs.items() if k.startswith("count_")} == \
                   {k: v for k, v in b.attrs.items() if k.startswith("count_")}
            # the noise gains are the operator's: the same whatever the chunking
            ga = {k: v for k, v in a.attrs.items() if k.startswith("ir_noise_gain")}
            gb = {k: v for k, v in b.attrs.items() if k.startswith("ir_noise_gain")}
            assert ga.keys() == gb.keys() and ga
            # equal up to the rounding of separate processes, whose BLAS runs other thread counts (the
            # whole record on 2 threads, each chunk's job on its own): 2e-9 seen with the AVX2 kernels
            for k in ga:
                assert gb[k] == pytest.approx(ga[k], rel=1e-7), k
        else:
            # "auto" is resolved once on the whole record: every chunk and the whole record choose alike
            assert {k: v for k, v in a.attrs.items() if k.endswith("_chosen")} == \
                   {k: v for k, v in b.attrs.items() if k.endswith("_chosen")}
            std = b["temperature_std"].values
            assert np.isfinite(std[np.isfinite(b["temperature"].values)]).all()


def _whole_run(work, scale):
    """The half-shell demo at ``scale`` through pipeline.run, whole record (chunk_frames 0)."""
    from irdic.config import validate_config
    from irdic.pipeline import run

    with open(ROOT / "config" / "config.yaml") as fh:
        cfg = yaml.safe_load(fh)
    cfg["demo"].update(scale=scale, outdir=str(work / "demo"))
    for e in ("halfshell",):
        for k in ("dic", "ir"):
            cfg["experiments"][e][k]["path"] = str(work / "demo" / e / k)
    cfg["setups"]["lab"] = {"markers": {"path": str(work / "demo/setup/markers.txt")},
                            "target_image": {"path": str(work / "demo/setup/target.txt")}}
    cfg["experiments"] = {"halfshell": cfg["experiments"]["halfshell"]}
    cfg["results"] = str(work / "whole")
    cfg = validate_config(cfg)
    run(cfg, stages=("demo", "ingest", "calibrate", "couple", "fields"), threads=2)
    return work, cfg


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The tiny half-shell: a record shorter than the temporal kernel's reach (one global operator)."""
    return _whole_run(tmp_path_factory.mktemp("chunks"), "tiny")


@pytest.mark.slow
def test_chunked_long_record_equals_whole_record_at_its_ends(tmp_path):
    """The demo half-shell (61 IR frames at 2 Hz, 31 DIC stages at 1 Hz) is longer than the kernel's reach:
    the windowed temporal operators make every chunk equal the whole record, the first and last times too."""
    from irdic.numerics.temporal import temporal_window
    from irdic.pipeline import run
    from irdic.store import open_store

    work, cfg = _whole_run(tmp_path, "demo")
    assert temporal_window(open_store(work / "whole/halfshell/ir.zarr")["time"].values) is not None
    shutil.copytree(work / "whole", work / "chunked", ignore=shutil.ignore_patterns("points.zarr", "fields.zarr"))
    run(dict(cfg, results=str(work / "chunked"), execution={"chunk_frames": 8}), stages=("couple", "fields"),
        threads=2)
    assert len(list((work / "chunked/halfshell/chunks").glob("points-*.zarr"))) == 4
    _compare(work / "whole/halfshell", work / "chunked/halfshell")
    # the uncertainties are noise-probe estimates (their own random draws per job): equal in distribution
    a, b = open_store(work / "whole/halfshell/fields.zarr"), open_store(work / "chunked/halfshell/fields.zarr")
    assert a.attrs["temperature_smoothing_chosen"] == b.attrs["temperature_smoothing_chosen"]
    for n in ("temperature_std", "temperature_gradient_std", "temperature_rate_std", "max_principal_strain_std"):
        x, y = a[n].values, b[n].values
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0)
        assert ok.any(), n
        assert 0.8 <= np.median(y[ok] / x[ok]) <= 1.25, (n, np.median(y[ok] / x[ok]))


@pytest.mark.slow
def test_chunked_pipeline_equals_whole_record(tiny):
    from irdic.pipeline import run

    work, cfg = tiny
    shutil.copytree(work / "whole", work / "chunked", ignore=shutil.ignore_patterns("points.zarr", "fields.zarr"))
    chunked = dict(cfg, results=str(work / "chunked"), execution={"chunk_frames": 2})
    run(chunked, stages=("couple", "fields"), threads=2)
    assert len(list((work / "chunked/halfshell/chunks").glob("points-*.zarr"))) == 3
    _compare(work / "whole/halfshell", work / "chunked/halfshell")


@pytest.mark.slow
def test_chunked_snakemake_equals_whole_record(tiny):
    work, cfg = tiny
    wf = work / "wf"
    wf.mkdir()
    shutil.copytree(work / "whole", wf / "results", ignore=shutil.ignore_patterns("points.zarr", "fields.zarr"))
    sm = dict(cfg, results="results", execution={"chunk_frames": 2})
    with open(wf / "config.yaml", "w") as fh:
        yaml.safe_dump(sm, fh)
    res = subprocess.run([sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory", str(wf),
                          "--configfile", str(wf / "config.yaml"), "--cores", "2", "-p",
                          "results/halfshell/points.zarr", "results/halfshell/fields.zarr"],
                         capture_output=True, text=True, timeout=1200)
    assert res.returncode == 0, (res.stdout[-2000:], res.stderr[-4000:])
    stores = (wf / "results/halfshell/chunks").glob("*.zarr")
    assert sorted(p.name for p in stores if not p.name.startswith(".")) == \
        [f"{k}-{i}.zarr" for k in ("fields", "points") for i in range(3)]
    _compare(work / "whole/halfshell", wf / "results/halfshell")
