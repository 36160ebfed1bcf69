"""One-line stage errors: the log line a failed stage writes, and how the workflow finds it again."""

import os
import subprocess
import sys
import time

import pytest

from irdic.errors import DataError
from irdic.logs import exit_on_error, failures, stage_logging


def test_a_failed_stage_is_found_in_its_log_and_printed_on_one_line(tmp_path):
    log = tmp_path / "logs" / "s07" / "couple.log"
    started = time.time() - 1
    with pytest.raises(SystemExit) as e:
        with stage_logging(log, "couple", threads=1):
            raise DataError("points.zarr: times\nnot increasing")
    assert str(e.value) == "irdic couple failed: points.zarr: times not increasing"
    ok = tmp_path / "logs" / "s07" / "fields.log"
    with stage_logging(ok, "fields", threads=1):
        pass
    assert failures(tmp_path / "logs", since=started) == ["irdic couple failed: points.zarr: times not increasing"]
    # a log from an earlier run is not this run's failure
    os.utime(log, (started - 100, started - 100))
    assert failures(tmp_path / "logs", since=started) == []
    assert failures(tmp_path / "nothing", since=started) == []


def test_show_last_prints_after_everything_else_at_exit():
    code = ("import sys; from irdic.logs import show_last; show_last(['irdic couple failed: x']); "
            "print('snakemake summary', file=sys.stderr); raise SystemExit(1)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 1
    assert res.stderr.splitlines() == ["snakemake summary", "", "irdic couple failed: x"]


def test_exit_on_error_gives_the_message_alone(capsys):
    with pytest.raises(SystemExit) as e:
        with exit_on_error():
            raise DataError("a\n b")
    assert e.value.code == 1
    assert capsys.readouterr().err == "irdic: error: a b\n"
    with exit_on_error():  # nothing raised: nothing printed
        pass
    assert capsys.readouterr().err == ""


def test_stage_progress_eta_from_the_cost_model():
    """The stage's ETA from its parts' expected costs: right when the model's ratios are, from the first tenth."""
    import logging

    from irdic.logs import StageProgress, report

    now = [0.0]
    lines = []

    class Capture(logging.Handler):
        def emit(self, record):
            lines.append(record.getMessage())

    logger = logging.getLogger("irdic.test_stage_progress")
    logger.setLevel(logging.INFO)
    logger.addHandler(Capture())
    # masks 20 s of one core of which half runs in parallel, interpolation 60 s all parallel: on 2 threads
    # 15 s + 30 s; the run goes at the model's pace, 2 model seconds per second
    with StageProgress("couple", {"masks": 20.0, "clock": 12.0, "interpolation": 60.0}, threads=2,
                       shares={"masks": 0.5, "clock": 0.0}, logger=logger, clock=lambda: now[0], tick=None) as sp:
        for k in range(1, 11):
            now[0] = 0.75 * k
            report("masks", k / 10)
        report("nonsense", 1.0)  # a part the model does not hold: ignored
        report("clock", 0.0)
        # the clock reports its end only: meanwhile its expected share of the time passes at the speed so far
        now[0] = 10.5
        assert sp.fraction() == pytest.approx(21.0 / 57.0)
        assert sp._line(now[0]).startswith("couple: 37 % of the work, 10.5 s elapsed, ETA 18 s")
        now[0] = 13.5
        report("clock", 1.0)
        for k in range(1, 11):
            now[0] = 13.5 + 1.5 * k
            report("interpolation", k / 10)
    report("masks", 1.0)  # outside the stage: nothing
    assert sp.fraction() == 1.0
    assert lines[0].startswith("couple: 11 % of the work, 3.0 s elapsed, ETA 26 s")  # 28.5 s in all
    assert lines[-1].startswith("couple: 100 % of the work, 28.5 s elapsed, ETA 0 s")
    etas = [(float(ln.split()[6]), float(ln.split()[10])) for ln in lines]
    assert all(abs(el + eta - 28.5) <= 1.0 for el, eta in etas)  # the ETA rounded to whole seconds
