"""Every stage entry limits BLAS/OpenMP to the threads it was given."""

import copy

import numpy as np
import pytest
import xarray as xr
from threadpoolctl import threadpool_info

import irdic.cli
import irdic.stages.couple
import irdic.stages.fields
from irdic import pipeline
from irdic.config import validate_config
from irdic.cli import main
from irdic.errors import ConfigError
from irdic.logs import stage_logging
from irdic.threads import default_threads, stage_threads, thread_budget


def _blas_threads_now():
    return {p["num_threads"] for p in threadpool_info() if p["user_api"] in ("blas", "openmp")}


def _blas():
    """The BLAS libraries' thread counts in force."""
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


@pytest.fixture
def recorder(monkeypatch):
    seen = []

    def fake(*args, **kwargs):
        # the computation of the stage, inside its entry: stores are neither read nor written
        seen.append((_blas_threads_now(), thread_budget()))
        return xr.Dataset(coords={"time": [0.0], "point": [0]})

    for stage, compute in ((irdic.stages.couple, "couple"), (irdic.stages.fields, "fields")):
        monkeypatch.setattr(stage, compute, fake)
        monkeypatch.setattr(stage, "open_store", lambda path, kind=None: None)
        monkeypatch.setattr(stage, "write_dataset", lambda *a, **k: None)
    # the fields entry checks that its stores belong together: none are read here
    monkeypatch.setattr(irdic.stages.fields, "fields_inputs", lambda *a: (None, None, None, None))
    return seen


_CONFIG = {
    "setups": {"lab": {"markers": {"path": "m.txt"}, "target_image": {"path": "t.txt"}}},
    "experiments": {"tube": {"setup": "lab", "dic": {"path": "dic"}, "ir": {"path": "ir"}}},
    "demo": {"enabled": False},
}


def test_pipeline_run_uses_the_given_threads(recorder):
    np.ones((4, 4)) @ np.ones((4, 4))  # make sure BLAS is loaded
    pipeline.run(validate_config(copy.deepcopy(_CONFIG)), stages=("couple", "fields"), threads=1)
    assert recorder == [({1}, 1), ({1}, 1)]
    # the limit ends with the stage
    assert thread_budget() == default_threads()


def test_cli_threads_option(recorder, monkeypatch):
    monkeypatch.setattr(irdic.cli, "describe_store", lambda path: "")
    assert main(["--threads", "1", "couple", "--dic", "d", "--ir", "i", "--calibration", "c", "--out", "o"]) == 0
    assert recorder == [({1}, 1)]


def test_cli_rejects_zero_threads(capsys):
    assert main(["--threads", "0", "info", "x.zarr"]) == 2
    err = capsys.readouterr().err
    assert "threads must be a whole number of CPU threads >= 1, got 0" in err


def test_snakemake_script_entry(tmp_path):
    with stage_logging(tmp_path / "log.txt", "couple", threads=1):
        assert _blas_threads_now() == {1}
        assert thread_budget() == 1
    assert "start (1 thread)" in (tmp_path / "log.txt").read_text()


def test_default_is_all_cores():
    with stage_threads() as n:
        assert n == default_threads() == thread_budget()


@pytest.mark.parametrize("bad", [0, -2, 1.5, "2", True])
def test_bad_thread_counts(bad):
    with pytest.raises(ConfigError, match="threads must be a whole number"):
        with stage_threads(bad):
            pass


class _FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_progress_rate_and_eta_exclude_the_setup():
    import logging

    from irdic.logs import Progress

    clock = _FakeClock()
    p = Progress(100, "evaluate_series", unit="times", logger=logging.getLogger("test"), clock=clock)
    # first chunk: 10 times after 20 s of one-off setup; no rate claimed yet
    clock.t = 20.0
    assert p.update(10) == "evaluate_series: 10/100 times, 20.0 s elapsed"
    # then a steady 2 times/s: rate and ETA are right and do not jump
    lines = []
    for done in range(20, 101, 10):
        clock.t += 5.0
        lines.append(p.update(done))
    assert lines[0] == "evaluate_series: 20/100 times, 2 times/s, ETA 40 s"
    assert lines[3] == "evaluate_series: 50/100 times, 2 times/s, ETA 25 s"
    assert lines[-1] == "evaluate_series: 100/100 times, 2 times/s, ETA 0 s"


def test_progress_reports_about_every_tenth():
    import logging

    from irdic.logs import Progress

    clock = _FakeClock()
    p = Progress(1000, "ingest IR", unit="frames", logger=logging.getLogger("test"), clock=clock)
    said = []
    for i in range(1, 1001):
        clock.t += 0.01
        if p.update(i):
            said.append(i)
    assert said == list(range(100, 1001, 100))


def test_pools_keep_to_the_budget():
    """A stage's pools run at most its threads: a pool inside a pool's worker runs inline, and the job run beside
    a map takes one of the pool's workers, not one more."""
    import threading
    import time

    from irdic.numerics.threads import map_beside, parallel_map, worker_slices, workers

    busy, peak, lock = [0], [0], threading.Lock()

    def work(_):
        with lock:
            busy[0] += 1
            peak[0] = max(peak[0], busy[0])
        time.sleep(0.02)
        with lock:
            busy[0] -= 1
        return threading.get_ident()

    with stage_threads(2):
        assert workers() == 2
        nested = parallel_map(lambda i: (workers(), parallel_map(work, range(4))), range(4))
        assert [n for n, _ in nested] == [1] * 4
        # the inner maps ran on their outer worker's own thread
        assert all(len(set(ids)) == 1 for _, ids in nested)
        assert peak[0] <= 2
        peak[0] = 0
        first, rest = map_beside(lambda: work(None), work, range(6))
        assert peak[0] <= 2 and len(rest) == 6
        # the job started first: the items shared the other worker until it was done
        assert first in rest
        assert worker_slices(5) == [slice(0, 3), slice(3, 6)] and worker_slices(0) == []

        # BLAS on one thread per worker while a pool runs, the stage's threads again after it
        before = _blas()
        assert all(n == [1] * len(n) for n in parallel_map(lambda _: _blas(), range(2)))
        assert _blas() == before
        done, built = map_beside(_blas, lambda _: _blas(), range(2))
        assert all(n == [1] * len(n) for n in [done, *built]) and _blas() == before
    with stage_threads(1):
        peak[0] = 0
        first, rest = map_beside(lambda: work(None), work, range(3))
        assert peak[0] == 1 and set(rest) == {first} == {threading.get_ident()}


def test_both_takes_a_free_thread_of_the_stage_only():
    """``both`` runs its second job on a thread the stage has free: a pool of two outside any pool, the worker the
    items of ``map_beside`` leave free; else in the caller, after the first."""
    import threading
    import time

    from irdic.numerics.threads import both, map_beside

    busy, peak, lock = [0], [0], threading.Lock()

    def job(seconds):
        def run():
            with lock:
                busy[0] += 1
                peak[0] = max(peak[0], busy[0])
            time.sleep(seconds)
            with lock:
                busy[0] -= 1
            return threading.get_ident()
        return run

    with stage_threads(2):
        a, b = both(job(0.05), job(0.05))
        assert a != b and peak[0] == 2
        # beside quick items the second job goes to the worker they leave free ...
        peak[0] = 0
        (a, b), _ = map_beside(lambda: both(job(0.3), job(0.05)), lambda _: job(0.01)(), range(2))
        assert a != b and peak[0] == 2
        # ... and where the items keep it busy, it runs after the first, on the same thread
        peak[0] = 0
        (a, b), items = map_beside(lambda: both(job(0.01), job(0.01)), lambda _: job(0.4)(), range(1))
        assert a == b != items[0] and peak[0] == 2
        # an error of the first job is raised, its second job not run by another worker
        ran = []

        def fail():
            raise ValueError("first")

        with pytest.raises(ValueError, match="first"):
            map_beside(lambda: both(fail, lambda: ran.append(1)), lambda _: job(0.2)(), range(1))
        assert not ran
    with stage_threads(1):
        assert both(job(0.01), job(0.01)) == (threading.get_ident(),) * 2


def test_blas_limit_outlives_the_blocks_of_other_threads_inside_it():
    # the limit is the process's: a worker leaving its own block while the pool's is open must not lift it
    # (the workers' BLAS would then run more threads than the stage was given)
    import threading

    from irdic.threads import blas_threads

    with stage_threads(2):
        before = _blas()
        seen = []

        def worker():
            with blas_threads(1):
                seen.append(_blas())

        with blas_threads(1):
            t = threading.Thread(target=worker)
            t.start()
            t.join()
            seen.append(_blas())  # the worker's block is over, the pool's not yet
        assert len(seen) == 2 and all(n == [1] * len(n) for n in seen)
        assert _blas() == before
