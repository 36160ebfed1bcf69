"""The irdic command line and the Snakemake-free pipeline."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from irdic.cli import main
from irdic.config import validate_config
from irdic.pipeline import run
from irdic.store import open_store
from irdic.synthetic.demo import MACHINE_CLOCK_OFFSET, MACHINE_COLUMNS

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    assert main(["demo", str(d / "demo"), "--scale", "tiny"]) == 0
    return d


def test_demo_never_deletes_a_foreign_folder(tmp_path, capsys):
    (tmp_path / "mydata").mkdir()
    (tmp_path / "mydata" / "specimen.txt").write_text("precious")
    assert main(["demo", str(tmp_path / "mydata"), "--scale", "tiny"]) == 2
    assert "which the demo did not write" in capsys.readouterr().err
    assert (tmp_path / "mydata" / "specimen.txt").read_text() == "precious"


def test_ingest_and_info(demo, capsys):
    assert main(["ingest-ir", str(demo / "demo/tube/ir"), str(demo / "ir.zarr")]) == 0
    out = capsys.readouterr().out
    assert "temperature" in out and "degC" in out and "stage: ingest-ir" in out
    assert main(["info", str(demo / "ir.zarr")]) == 0
    assert "dimensions: time=" in capsys.readouterr().out


def test_errors_are_one_line_and_exit_2(demo, capsys):
    (demo / "empty").mkdir()
    assert main(["ingest-dic", str(demo / "empty"), str(demo / "dic.zarr")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("irdic: error: ") and "folder contains no DIC exports" in err
    assert "Traceback" not in err
    assert main(["info", str(demo / "nothing.zarr")]) == 2
    assert "store not found" in capsys.readouterr().err


def _pipeline_config() -> dict:
    """The tiny demo's tube (with its machine record), paths relative to the demo's parent folder."""
    return {
        "demo": {"enabled": False},
        "setups": {"lab": {"markers": {"path": "demo/setup/markers.txt"},
                           "target_image": {"path": "demo/setup/target.txt"}}},
        "experiments": {"tube": {"setup": "lab", "dic": {"path": "demo/tube/dic"}, "ir": {"path": "demo/tube/ir"},
                                 "machine": {"path": "demo/tube/machine.csv", "columns": dict(MACHINE_COLUMNS),
                                             "time_offset": -MACHINE_CLOCK_OFFSET}}},
    }


@pytest.fixture(scope="module")
def pipelined(demo):
    """The tiny demo (tube, with its machine record) through pipeline.run: the output paths."""
    import os

    cwd = os.getcwd()
    os.chdir(demo)
    try:
        return run(validate_config(_pipeline_config()))
    finally:
        os.chdir(cwd)


def _outputs(paths) -> dict:
    """Fingerprints of every output of the tube's pipeline run (stores, figures, exports, page)."""
    from irdic.runs import fingerprint

    stores = [*paths["experiments"]["tube"].values(), paths["setups"]["lab"]["calibration"]]
    files = sorted(Path("results").glob("tube/figures/*.png")) + [Path("results/tube/points.csv"),
                                                                 Path("results/tube/paraview"),
                                                                 Path("results/report.html")]
    return {str(p): fingerprint(p) for p in [*stores, *files]}


def test_a_rerun_skips_what_is_unchanged_and_redoes_what_an_edit_touches(demo, pipelined, monkeypatch, caplog):
    """irdic run after a complete run writes nothing; an edited IR frame re-runs its ingest (and the machine
    record put on its times), not the DIC ingest; --force redoes a job anyway."""
    import logging
    import os

    monkeypatch.chdir(demo)
    cfg = validate_config(_pipeline_config())
    before = _outputs(pipelined)
    assert all(v is not None for v in before.values()) and len(before) >= 12
    with caplog.at_level(logging.INFO, logger="irdic"):
        run(cfg)
    assert _outputs(pipelined) == before  # nothing rewritten: a Snakemake run after it has nothing to do either
    skipped = [r.getMessage() for r in caplog.records if "up to date" in r.getMessage()]
    assert len(skipped) == 9, skipped  # 3 ingests, calibrate, couple, fields, figures, export, report
    frame = sorted(Path("demo/tube/ir").iterdir())[2]
    st = frame.stat()
    os.utime(frame, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    run(cfg, stages=("ingest", "calibrate"))
    after = _outputs(pipelined)
    changed = {k for k in before if before[k] != after[k]}
    assert changed == {str(pipelined["experiments"]["tube"]["ir"]), str(pipelined["experiments"]["tube"]["machine"])}
    run(cfg, stages=("calibrate",), force=True)
    assert _outputs(pipelined)[str(pipelined["setups"]["lab"]["calibration"])] != after[
        str(pipelined["setups"]["lab"]["calibration"])]


def test_pipeline_runs_without_snakemake(demo, pipelined, monkeypatch):
    monkeypatch.chdir(demo)
    paths = pipelined
    f = open_store(paths["experiments"]["tube"]["fields"])
    _check_against_truth(f, open_store(paths["experiments"]["tube"]["points"]), open_store("demo/tube/truth.zarr"))
    for name in ("temperature", "gradient", "rate", "history", "strain", "load"):
        assert (demo / "results/tube/figures" / f"{name}.png").exists()
    assert (demo / "results/tube/paraview/points.pvd").exists()
    assert (demo / "results/tube/points.csv").exists()
    # the load: analytic force and torque of the tube (F = E A u / L, T = G J phi / L) at the DIC times
    truth = open_store(demo / "demo/tube/truth.zarr")
    np.testing.assert_allclose(f.time.values, truth.time.values)
    sig = {str(n): f.signal_value.sel(signal=n).values for n in f.signal.values}
    F, T = truth.force.values, truth.torque.values
    # N, N m: the ~25 mm tube is loaded plastically, within the range of a 100 kN / 1 kN m machine
    assert 30e3 < F.max() < 100e3 and -100e3 < F.min() and 100 < T.max() < 1000 and -1000 < T.min()
    np.testing.assert_allclose(sig["force"], F, rtol=1e-12)
    np.testing.assert_allclose(sig["Kraft"], F / 1000.0, rtol=1e-12)
    np.testing.assert_allclose(sig["Drehmoment"], T, rtol=1e-12)
    assert np.isnan(sig["torque"][2]) and np.isfinite(np.delete(sig["torque"], 2)).all()  # stage 2 lacks it
    # the machine record (50 Hz, 9 decimals) on the DIC clock: the offset applied with the right sign
    np.testing.assert_allclose(sig["machine_force"], F / 1000.0, rtol=0, atol=1e-6 * F.max() / 1000.0)
    np.testing.assert_allclose(sig["machine_torque"], T, rtol=0, atol=1e-6 * T.max())
    np.testing.assert_allclose(sig["machine_angle"], truth.angle.values, rtol=0, atol=1e-6)
    assert dict(zip(f.signal.values, f.signal_unit.values))["machine_force"] == "kN"
    import pandas as pd

    table = pd.read_csv(demo / "results/tube/points.csv")
    for col in ("force [N]", "Kraft [kN]", "machine_force [kN]", "machine_torque [N*m]"):
        assert col in table.columns
    np.testing.assert_allclose(table.groupby("time [s]")["force [N]"].first().to_numpy(), F, rtol=1e-12)


def _check_against_truth(f, pts, truth):
    """The tiny noisy demo's fields against its analytic truth, on points well inside the visible region.

    The demo adds 0.05 K of IR noise and 0.005 mm of DIC noise, and the
    default settings interpolate (no smoothing): the bounds are those noise
    levels carried through, with the measured values noted.
    """
    truth = truth.sel(point=f.point)
    inner = pts.visible.values & (truth.patch_edge_distance.values >= 2.0)
    inner[[0, -1]] = False  # the ends of the series have one-sided time derivatives
    assert inner.sum() > 100
    rms = lambda a: float(np.sqrt(np.mean(a[inner] ** 2)))  # noqa: E731
    # the interpolation passes the 0.05 K IR noise of the demo through (measured 0.046 K)
    assert rms(f.temperature.values - truth.temperature.values) <= 1.5 * 0.05
    # the material rate to 30 % of its range (measured 21 %); the in-plane gradient of the tiny noisy demo is
    # dominated by the pixel noise without smoothing, so only its presence is checked here
    r = truth.temperature_rate.values
    assert rms(f.temperature_rate.values - r) <= 0.3 * np.abs(r[inner]).max()
    assert np.isfinite(f.temperature_gradient.values[inner]).all()
    # strain from 0.005 mm DIC noise at ~1 mm point spacing (measured 0.003)
    assert rms(f.max_principal_strain.values - truth.strain_max.values) <= 5e-3


def test_stage_commands_match_the_pipeline(demo, pipelined, monkeypatch):
    """The CLI's stage commands and pipeline.run call the same entries: same stores (defaults from the schema)."""
    import xarray as xr

    monkeypatch.chdir(demo)
    r, c = "results/tube", "cli"
    steps = [["ingest-ir", "demo/tube/ir", f"{c}/ir.zarr"], ["ingest-dic", "demo/tube/dic", f"{c}/dic.zarr"],
             ["calibrate", "--markers", "demo/setup/markers.txt", "--target", "demo/setup/target.txt",
              "--out", f"{c}/cal.zarr"],
             ["couple", "--dic", f"{c}/dic.zarr", "--ir", f"{c}/ir.zarr", "--calibration", f"{c}/cal.zarr",
              "--out", f"{c}/points.zarr"],
             ["fields", "--points", f"{c}/points.zarr", "--calibration", f"{c}/cal.zarr", "--dic", f"{c}/dic.zarr",
              "--machine", f"{r}/machine.zarr", "--out", f"{c}/fields.zarr"]]
    for argv in steps:
        assert main(argv) == 0, argv
    for name in ("dic", "ir", "points", "fields"):
        xr.testing.assert_allclose(open_store(f"{c}/{name}.zarr"), open_store(f"{r}/{name}.zarr"), rtol=1e-9)
    xr.testing.assert_allclose(open_store(f"{c}/cal.zarr"), open_store("results/setups/lab/calibration.zarr"),
                               rtol=1e-9)


def test_fields_command_refuses_a_bad_smoothing(demo, capsys):
    assert main(["fields", "--points", "p.zarr", "--calibration", "c.zarr", "--out", "f.zarr",
                 "--temperature-smoothing", "lots"]) == 2
    assert "--temperature-smoothing must be none, gcv or a number >= 1, got 'lots'" in capsys.readouterr().err


def test_machine_clock_offset_sign(demo):
    """time_offset is added to the machine times: the wrong sign puts every DIC time outside the record."""
    from irdic.errors import IrdicWarning
    from irdic.signals import read_machine, signals_at

    truth = open_store(demo / "demo/tube/truth.zarr")
    t = truth.time.values
    right = read_machine(demo / "demo/tube/machine.csv", columns=MACHINE_COLUMNS, time_offset=-MACHINE_CLOCK_OFFSET)
    s = signals_at(t, machine=right)
    np.testing.assert_allclose(s.signal_value.sel(signal="machine_force").values, truth.force.values / 1000.0,
                               atol=1e-6 * truth.force.values.max() / 1000.0)
    wrong = read_machine(demo / "demo/tube/machine.csv", columns=MACHINE_COLUMNS, time_offset=MACHINE_CLOCK_OFFSET)
    with pytest.warns(IrdicWarning, match="check machine.time_offset"):
        s = signals_at(t, machine=wrong)
    assert np.isnan(s.signal_value.values).all()


def test_ingest_refuses_to_overwrite_a_users_folder_or_file(demo, tmp_path, capsys):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "results.xlsx").write_text("precious")
    assert main(["ingest-ir", str(demo / "demo/tube/ir"), str(victim)]) == 2
    err = capsys.readouterr().err
    assert f"irdic: error: {victim}: output path exists and is a folder that irdic did not write" in err
    assert "Traceback" not in err and [ln for ln in err.splitlines() if not ln[:2].isdigit()] == [err.splitlines()[-1]]
    assert (victim / "results.xlsx").read_text() == "precious"
    afile = tmp_path / "notes.txt"
    afile.write_text("precious")
    assert main(["ingest-ir", str(demo / "demo/tube/ir"), str(afile)]) == 2
    assert "is a file that irdic did not write" in capsys.readouterr().err
    assert afile.read_text() == "precious"
    # its own store is replaced, as before
    assert main(["ingest-ir", str(demo / "demo/tube/ir"), str(tmp_path / "ir.zarr")]) == 0
    assert main(["ingest-ir", str(demo / "demo/tube/ir"), str(tmp_path / "ir.zarr")]) == 0
    # and nothing beside it once done: no lock file, no temporary
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["ir.zarr", "victim", "notes.txt"]), list(tmp_path.iterdir())


def _raiser(exc):
    def describe_store(path):
        raise exc

    return describe_store


@pytest.mark.parametrize(
    "exc, code, line",
    [
        (OSError(28, "No space left on device", "results/tube/ir.zarr"), 1,
         "irdic: error: results/tube/ir.zarr: No space left on device"),
        (PermissionError(13, "Permission denied"), 1, "irdic: error: Permission denied"),
        (MemoryError(), 1, "irdic: error: out of memory; process fewer frames or points at a time"),
        (KeyboardInterrupt(), 130, "irdic: interrupted; outputs being written were discarded"),
        (ValueError("boom\nsecond line"), 1, "irdic: internal error: ValueError: boom second line (a bug in irdic; "
                                              "run again with --debug"),
    ],
)
def test_every_error_is_one_line_without_traceback(monkeypatch, capsys, exc, code, line):
    import irdic.cli

    monkeypatch.setattr(irdic.cli, "describe_store", _raiser(exc))
    assert main(["info", "x.zarr"]) == code
    err = capsys.readouterr().err
    assert err.startswith(line) and err.count("\n") == 1 and "Traceback" not in err
    for argv in (["--debug", "info", "x.zarr"], ["info", "x.zarr", "--debug"]):
        assert main(argv) == code
        err = capsys.readouterr().err
        assert "Traceback" in err and err.rstrip().splitlines()[-1].startswith(line)


def test_version(capsys):
    from irdic import __version__

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"irdic {__version__}"


def test_run_help_describes_itself(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps lines at the terminal width
    assert "without Snakemake" in out and "--set KEY=VALUE" in out and "report" in out


def test_set_is_checked_by_the_schema_with_its_messages(demo, capsys):
    base = ["couple", "--dic", "d.zarr", "--ir", "i.zarr", "--calibration", "c.zarr", "--out", "p.zarr"]
    assert main(base + ["--set", "interpolation.c_space=wide"]) == 2
    err = capsys.readouterr().err
    assert "invalid configuration: interpolation.c_space: 'wide' is not of type 'number'" in err
    assert main(base + ["--set", "interpolation.c_spce=2"]) == 2
    assert "interpolation.c_spce: unknown key; allowed here:" in capsys.readouterr().err
    assert main(base + ["--set", "fields.c_space=2"]) == 2
    assert "irdic couple takes interpolation.KEY=VALUE" in capsys.readouterr().err
    assert main(base + ["--set", "interpolation"]) == 2
    assert "expected section.key=value" in capsys.readouterr().err


def test_set_reaches_the_stage(demo, pipelined, monkeypatch):
    """``--set fields.c_space=...`` is what the fields stage stores as its parameter; the others keep the defaults."""
    import json

    monkeypatch.chdir(demo)
    r = "results/tube"
    assert main(["fields", "--points", f"{r}/points.zarr", "--calibration", "results/setups/lab/calibration.zarr",
                 "--out", "set/fields.zarr", "--set", "fields.c_space=1.3"]) == 0
    params = json.loads(open_store("set/fields.zarr").attrs["irdic_parameters"])
    ref = json.loads(open_store(f"{r}/fields.zarr").attrs["irdic_parameters"])
    assert params["c_space"] == 1.3 and ref["c_space"] != 1.3
    assert {k: v for k, v in params.items() if k != "c_space"} == {k: v for k, v in ref.items() if k != "c_space"}


def test_run_set_changes_the_configuration(tmp_path, capsys):
    cfg = tmp_path / "config.yaml"
    cfg.write_text("setups: {lab: {markers: {path: m.txt}, target_image: {path: t.txt}}}\n"
                   "experiments: {s07: {setup: lab, dic: {path: dic/}, ir: {path: ir/}}}\n")
    assert main(["run", "--config", str(cfg), "--set", "interpolation.method=spline"]) == 2
    err = capsys.readouterr().err
    assert "with --set: invalid configuration: interpolation.method: 'spline' is not one of" in err
    # a valid --set passes; then the missing inputs are named by their keys, all at once
    assert main(["run", "--config", str(cfg), "--set", "interpolation.c_space=2.5"]) == 2
    err = capsys.readouterr().err
    assert "4 configured input(s) not found" in err and "experiments.s07.dic.path: dic: no such file or folder" in err


def test_figures_export_report_and_info_commands(demo, pipelined, monkeypatch, capsys):
    from irdic.report import figure_caption

    monkeypatch.chdir(demo)
    r = "results/tube"
    assert main(["figures", "--points", f"{r}/points.zarr", "--fields", f"{r}/fields.zarr", "--out", "figs",
                 "--experiment", "tube", "--times", "2", "--point-ids", "1"]) == 0
    caption = figure_caption("figs/temperature.png")
    assert "Temperature (°C) at the DIC points of experiment tube at t = 2 s (DIC times), drawn on the current" in caption
    # at 2 s the true temperature spans 0.14 K (5-95 %), the demo's IR noise is 0.05 K: rightly flagged
    assert caption.startswith("Noise-dominated at t = 2 s")
    history = figure_caption("figs/history.png")
    assert "x = (" not in history and "extrapolated from the specimen mask edge" in history
    assert main(["export", "--points", f"{r}/points.zarr", "--out", "exp", "--set", "export.csv_points=all"]) == 0
    assert (demo / "exp" / "points.csv").stat().st_size > 1000 and (demo / "exp" / "paraview" / "points.pvd").exists()
    capsys.readouterr()
    assert main(["report", "results", "--out", "page.html"]) == 0
    page = (demo / "page.html").read_text(encoding="utf-8")
    assert "<h2 id='s1'>experiment tube</h2>" in page and "drawn on the current (deformed) surface" in page
    assert "<h1>irdic results of results</h1>" in page and "auto chose" in page
    assert main(["report", "nowhere"]) == 2
    assert "nowhere: results folder not found" in capsys.readouterr().err
    assert main(["info", f"{r}/points.zarr"]) == 0
    out = capsys.readouterr().out
    assert "meaning of status:" in out and "5  outside specimen mask" in out
    lines = out.splitlines()
    coord = [ln for ln in lines if ln.startswith("    time ") or ln.startswith("    point ")]
    # aligned: the dims column starts at the same place in every row
    assert len({ln.index("(") for ln in coord}) == 1
    t = open_store(f"{r}/points.zarr")["time"].values
    assert f"{t.min():.6g} .. {t.max():.6g}" in out
