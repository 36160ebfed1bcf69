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
