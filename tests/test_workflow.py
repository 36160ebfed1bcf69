"""The Snakemake workflow on the tiny demo, in a temporary folder.

The demo runs through the Snakemake Python API; dry runs (which rules a
change schedules) go through the command line, whose summary is easy to read.
"""

import copy
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from irdic.store import open_store

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake"]

pytestmark = pytest.mark.slow


def _config(tmp):
    with open(ROOT / "config" / "config.yaml") as fh:
        cfg = yaml.safe_load(fh)
    cfg["demo"]["scale"] = "tiny"
    return cfg


def _snakemake(workdir, *args, config=None):
    if config is not None:
        with open(workdir / "config.yaml", "w") as fh:
            yaml.safe_dump(config, fh)
    cmd = SNAKEMAKE + ["-s", str(ROOT / "Snakefile"), "--directory", str(workdir),
                       "--configfile", str(workdir / "config.yaml"), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600)


def _planned(result) -> set[str]:
    """Rule names a dry run would execute (from `--quiet rules` output)."""
    rules = set()
    for line in result.stdout.splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[1].isdigit() and parts[0] not in ("job", "total"):
            rules.add(parts[0])
    return rules


def _run_api(workdir, config):
    """Run the whole workflow with the Snakemake Python API (2 cores)."""
    from snakemake.api import SnakemakeApi
    from snakemake.settings.types import ConfigSettings, OutputSettings, ResourceSettings

    with open(workdir / "config.yaml", "w") as fh:
        yaml.safe_dump(config, fh)
    with SnakemakeApi(OutputSettings(quiet={"progress"})) as api:
        wf = api.workflow(resource_settings=ResourceSettings(cores=2),
                          config_settings=ConfigSettings(configfiles=[workdir / "config.yaml"]),
                          snakefile=ROOT / "Snakefile", workdir=workdir)
        wf.dag().execute_workflow(executor="local")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    work = tmp_path_factory.mktemp("wf")
    cfg = _config(work)
    cwd = os.getcwd()
    _run_api(work, cfg)
    assert os.getcwd() == cwd
    return work, cfg


def test_demo_runs_end_to_end(run):
    work, _ = run
    for exp in ("halfshell", "tube"):
        ir = open_store(work / "results" / exp / "ir.zarr")
        dic = open_store(work / "results" / exp / "dic.zarr")
        assert ir["temperature"].dims == ("time", "v", "u")
        assert dic["x"].dims == ("time", "point", "component")
        assert ir.attrs["irdic_stage"] == "ingest-ir" and dic.attrs["irdic_stage"] == "ingest-dic"
        # the demo's IR times start at 0 (first frame) and DIC times lie inside the IR span
        assert float(ir.time[0]) == 0.0 and float(dic.time[-1]) <= float(ir.time[-1]) + 1e-9
        truth = open_store(work / "resources" / "demo" / exp / "truth.zarr")
        np.testing.assert_allclose(dic.time.values, truth.time.values, atol=1e-9)
        pts = open_store(work / "results" / exp / "points.zarr")
        err = (pts.temperature - truth.temperature.sel(point=pts.point)).values[pts.visible.values]
        assert np.sqrt(np.mean(err**2)) < 0.1  # demo noise: 0.05 K in IR, 0.005 mm in DIC
        flds = open_store(work / "results" / exp / "fields.zarr")
        assert flds.attrs["irdic_stage"] == "fields"
        assert flds.temperature_gradient.dims == ("time", "point", "component")
        heat = open_store(work / "results" / exp / "heat.zarr")
        assert heat.attrs["irdic_stage"] == "heat" and heat.heat_source.dims == ("time", "point")
    cal = open_store(work / "results" / "setups" / "lab" / "calibration.zarr")
    assert float(cal["rms_px"]) < 0.05
    true_M = open_store(work / "resources" / "demo" / "setup" / "truth.zarr")["projection_matrix"].values
    M = cal["projection_matrix"].values
    # same camera: projections of points around the specimens agree to a few hundredths of a pixel
    X = np.random.default_rng(0).uniform([-40, -30, -20], [40, 30, 20], (500, 3))
    Xh = np.c_[X, np.ones(len(X))]
    p_true = (Xh @ true_M.T)[:, :2] / (Xh @ true_M.T)[:, 2:]
    p_cal = (Xh @ M.T)[:, :2] / (Xh @ M.T)[:, 2:]
    assert np.sqrt(np.mean(np.sum((p_true - p_cal) ** 2, axis=1))) < 0.03
    assert (work / "results" / "setups" / "lab" / "calibration.png").stat().st_size > 10_000
    for log in ("logs/tube/ingest_ir.log", "logs/setups/lab/calibrate.log", "logs/demo.log"):
        assert "done" in (work / "results" / log).read_text()
    # writers remove their lock files: none beside the stores after a complete run
    assert not [p for p in work.rglob(".*.lock") if ".snakemake" not in p.parts]


def test_nothing_to_do_after_a_run(run):
    work, cfg = run
    res = _snakemake(work, "-n", "--quiet", "rules", config=cfg)
    assert res.returncode == 0, res.stderr[-3000:]
    assert _planned(res) == set()


def test_parameter_change_reruns_only_dependent_stages(run):
    work, cfg = run
    changed = copy.deepcopy(cfg)
    changed["calibration"]["distortion"] = "k1"
    res = _snakemake(work, "-n", "--quiet", "rules", config=changed)
    assert _planned(res) == {"calibrate", "couple", "fields", "heat", "heat_figure", "all", "figures", "export",
                             "report_html"}
    changed = copy.deepcopy(cfg)
    changed["experiments"]["tube"]["ir"]["time_offset"] = 0.5
    res = _snakemake(work, "-n", "--quiet", "rules", config=changed)
    # the tube's machine record is also put on the IR frame times (machine.zarr): it follows the IR series
    assert _planned(res) == {"ingest_ir", "ingest_machine", "couple", "fields", "heat", "heat_figure", "all", "figures",
                             "export", "report_html"}
    changed = copy.deepcopy(cfg)
    changed["interpolation"]["c_space"] = 1.5
    res = _snakemake(work, "-n", "--quiet", "rules", config=changed)
    assert _planned(res) == {"couple", "fields", "heat", "heat_figure", "all", "figures", "export", "report_html"}
    changed = copy.deepcopy(cfg)
    changed["fields"]["temperature_smoothing"] = "gcv"
    res = _snakemake(work, "-n", "--quiet", "rules", config=changed)
    assert _planned(res) == {"fields", "heat", "heat_figure", "all", "figures", "export", "report_html"}
    changed = copy.deepcopy(cfg)
    changed["experiments"]["tube"]["material"]["loss_time_constant"] = 30.0
    res = _snakemake(work, "-n", "--quiet", "rules", config=changed)
    assert _planned(res) == {"heat", "heat_figure", "export", "all", "report_html"}
    changed = copy.deepcopy(cfg)
    changed["experiments"]["tube"]["report"] = {"times": [1.0], "points": []}
    res = _snakemake(work, "-n", "--quiet", "rules", config=changed)
    assert _planned(res) == {"figures", "heat_figure", "report_html", "all"}  # the page shows the new figures
    changed = copy.deepcopy(cfg)
    changed["export"] = {"paraview_every": 2}
    res = _snakemake(work, "-n", "--quiet", "rules", config=changed)
    assert _planned(res) == {"export", "all", "report_html"}  # the page's header lists the non-default parameters
    _snakemake(work, "-n", config=cfg)  # leave the config as the run had it


def test_an_edited_demo_file_reruns_what_reads_it(run):
    """The demo's files are real inputs of the ingest rules (the demo is a checkpoint), not just its manifest."""
    work, cfg = run
    frame = sorted((work / "resources" / "demo" / "tube" / "ir").iterdir())[3]
    before, content = frame.stat(), frame.read_bytes()
    try:
        # edited after the run (Snakemake compares the checksum of a newer input: the bytes must change)
        frame.write_bytes(content + b"\n")
        os.utime(frame, ns=(before.st_atime_ns, before.st_mtime_ns + 10**12))
        res = _snakemake(work, "-n", config=cfg)  # (with --quiet rules, an mtime-only change prints no summary)
        assert res.returncode == 0, res.stderr[-3000:]
        planned = {ln.split()[1].rstrip(":") for ln in (res.stdout + res.stderr).splitlines()
                   if ln.startswith(("rule ", "localrule ", "checkpoint "))}
        # the tube's IR series and what depends on it; the half-shell and the calibration are untouched
        assert planned == {"ingest_ir", "ingest_machine", "couple", "fields", "heat", "heat_figure", "all", "figures",
                           "export", "report_html"}, planned
        assert f"Updated input files: resources/demo/tube/ir/{frame.name}" in res.stdout + res.stderr
        res = _snakemake(work, "-n", "results/halfshell/points.zarr", config=cfg)
        assert "Nothing to be done" in res.stdout + res.stderr
    finally:
        frame.write_bytes(content)
        os.utime(frame, ns=(before.st_atime_ns, before.st_mtime_ns))


def test_figures_exports_and_report(run):
    work, cfg = run
    for exp in ("halfshell", "tube"):
        for name in ("temperature", "gradient", "rate", "history", "strain", "heat"):
            assert (work / "results" / exp / "figures" / f"{name}.png").stat().st_size > 10_000
        assert (work / "results" / exp / "paraview" / "points.pvd").exists()
        assert (work / "results" / exp / "points.csv").stat().st_size > 1_000
    res = _snakemake(work, "--report", str(work / "report.html"), config=cfg)
    assert res.returncode == 0, res.stderr[-3000:]
    html = (work / "report.html").read_text(encoding="utf-8")
    assert "In-plane temperature gradient of experiment <strong>tube</strong>" in html


def test_bad_config_is_reported_with_the_key(tmp_path):
    cfg = _config(tmp_path)
    cfg["calibration"]["polarty"] = "dark"
    res = _snakemake(tmp_path, "-n", config=cfg)
    assert res.returncode != 0
    # the message is the last thing on the screen, alone: no stack lines after it
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("irdic: error: invalid configuration: calibration.polarty: unknown key"), res.stderr
    assert 'File "' not in res.stderr and "Traceback" not in res.stderr


def test_nested_command_line_numbers_are_accepted(tmp_path):
    """`--config execution="{chunk_frames: 2}"`: Snakemake passes "2" as a string; it reads as the number."""
    cfg = _config(tmp_path)
    res = _snakemake(tmp_path, "-n", "--quiet", "rules", "--config", "execution={chunk_frames: 2}", config=cfg)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "couple_chunk" in _planned(res)
    res = _snakemake(tmp_path, "-n", "--config", "execution={chunk_frames: eight}", config=cfg)
    assert res.returncode != 0
    assert res.stderr.strip().splitlines()[-1] == ("irdic: error: invalid configuration: execution.chunk_frames: "
                                                   "'eight' is not of type 'integer'")


def test_rules_are_thin_and_logged():
    """Every rule has a log and a benchmark; common.smk imports os and uses no other rule file's names."""
    import re

    rules_dir = ROOT / "workflow" / "rules"
    for f in sorted(rules_dir.glob("*.smk")):
        blocks = re.split(r"^rule ", f.read_text(), flags=re.M)[1:]
        for b in blocks:
            name = b.split(":", 1)[0]
            assert "\n    log:" in b and "\n    benchmark:" in b, f"{f.name}: rule {name}"
            assert ".get(" not in b, f"{f.name}: rule {name} repeats a default of the schema"
    common = (rules_dir / "common.smk").read_text()
    assert re.search(r"^import os$", common, flags=re.M)
    assert not re.search(r"(?<![.\w])FIGURES\b", common)  # irdic.plot.FIGURES, not report.smk's
    for script in sorted((ROOT / "scripts").glob("*.py")):
        text = script.read_text()
        assert "from irdic.stages import" in text and ".run(" in text, script.name
        assert "Inputs\n------" in text and "Outputs\n-------" in text, script.name


def test_every_store_describes_itself(run):
    """Every variable and coordinate of every store has a long_name, floats a unit; no per-file dataset leftovers."""
    import warnings

    import xarray as xr

    from irdic.vocabulary import allowed_dataset_attr

    work, _ = run
    stores = sorted((work / "results").glob("**/*.zarr"))
    assert len(stores) >= 10
    for path in stores:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # plain xarray opens every store without a warning
            ds = xr.open_zarr(path)
        for name, v in ds.variables.items():
            assert v.attrs.get("long_name"), f"{path.name}: {name} has no long_name"
            # signal_value holds signals of different units: the unit of each is the coordinate signal_unit
            if v.dtype.kind == "f" and not name.startswith("signal_value"):
                assert "units" in v.attrs, f"{path.relative_to(work)}: {name} has no units"
        extra = [k for k in ds.attrs if not allowed_dataset_attr(k)]
        assert not extra, f"{path.relative_to(work)}: dataset attributes {extra}"
        for leftover in ("stage_index", "n_invalid", "stage_name", "frame_index", "units", "long_name"):
            assert leftover not in ds.attrs, f"{path.relative_to(work)}: {leftover}"


def test_default_run_writes_the_html_report_with_captions(run):
    work, _ = run
    page = (work / "results" / "report.html").read_text(encoding="utf-8")
    assert page.count("<img") == 1 + 2 * 7  # the calibration and seven figures per experiment (heat included)
    assert "Temperature (°C) at the DIC points of experiment tube at t = " in page
    assert "extrapolated from the specimen mask edge" in page
    # this configuration's run: titled with it, a table of contents, the calibration captioned, a header
    assert "<h1>irdic results of config.yaml</h1>" in page and "<ol class='toc'>" in page
    heads = [ln.split(">")[1].split("<")[0] for ln in page.splitlines() if ln.startswith("<h2 id=")]
    assert heads == ["setup lab", "experiment halfshell", "experiment tube"]
    assert "<b>calibration</b>: IR image of the reference object" in page
    assert "<code>demo.scale: &quot;tiny&quot;</code>" in page  # the non-default parameters
    assert "fields.zarr: temperature_smoothing auto → " in page  # what auto chose, with why


def test_missing_input_folders_are_named_by_their_keys_all_at_once(tmp_path):
    cfg = _config(tmp_path)
    cfg["demo"]["enabled"] = False
    cfg["setups"] = {"bench": {"markers": {"path": "raw/calib/markers.txt"},
                               "target_image": {"path": "raw/calib/target.txt"}}}
    cfg["experiments"] = {"s07": {"setup": "bench", "dic": {"path": "raw/s07/aramis/"},
                                  "ir": {"path": "raw/s07/ir/"}}}
    (tmp_path / "raw" / "s07" / "ir").mkdir(parents=True)
    res = _snakemake(tmp_path, "-n", config=cfg)
    out = res.stderr + res.stdout
    assert res.returncode != 0
    assert "4 configured input(s) not found" in out
    for key in ("setups.bench.markers.path", "setups.bench.target_image.path", "experiments.s07.dic.path: "
                "raw/s07/aramis: no such file or folder", "experiments.s07.ir.path: raw/s07/ir: folder contains no"):
        assert key in out, key


def test_a_failing_stage_shows_the_irdic_message_without_a_traceback(tmp_path):
    """A stage that fails on the user's data: its one-line message on stderr and in the rule's log."""
    cfg = _config(tmp_path)
    cfg["demo"]["enabled"] = False
    (tmp_path / "raw" / "ir").mkdir(parents=True)
    (tmp_path / "raw" / "ir" / "frame_1.csv").write_text("not an IR export\n")
    cfg["setups"] = {"bench": {"markers": {"path": "raw/ir/frame_1.csv"},
                               "target_image": {"path": "raw/ir/frame_1.csv"}}}
    cfg["experiments"] = {"s07": {"setup": "bench", "dic": {"path": "raw/ir"}, "ir": {"path": "raw/ir"}}}
    res = _snakemake(tmp_path, "--cores", "1", f"results/s07/ir.zarr", config=cfg)
    assert res.returncode != 0
    log = (tmp_path / "results" / "logs" / "s07" / "ingest_ir.log").read_text()
    line = next(ln for ln in res.stderr.splitlines() if ln.startswith("irdic ingest-ir failed: "))
    assert "frame_1.csv" in line and line.split("failed: ", 1)[1] in log
    assert "Traceback" not in res.stderr
    # after Snakemake's job report and summary, the irdic message comes last, alone on its line
    tail = res.stderr.rstrip().splitlines()
    assert tail[-1] == line and tail[-2] == "", tail[-4:]
