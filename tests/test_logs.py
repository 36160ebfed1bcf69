"""One-line stage errors: the log line a failed stage writes, and how the workflow finds it again."""

import contextlib
import logging
import os
import subprocess
import sys
import time

import numpy as np
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


@contextlib.contextmanager
def _masks_done(parts: dict, name: str):
    """A couple StageProgress on a fake clock whose masks (10 model seconds) took 1 s per tenth:
    ``(progress, now)``, ``now[0]`` the clock to move on."""
    from irdic.logs import StageProgress, report

    now = [0.0]
    with StageProgress("couple", parts, logger=logging.getLogger(name), clock=lambda: now[0], tick=None) as sp:
        for k in range(1, 11):
            now[0] = float(k)
            report("masks", k / 10)
        yield sp, now


def test_stage_progress_a_part_that_stops_early_is_not_fast_work():
    """The IR clock finds no motion and stops after 1 s instead of the 6 s expected: the ETA stays that of the
    other parts at their own speed (without re-weighting it would count 6 s of work done in 1 s)."""
    from irdic.logs import report

    with _masks_done({"masks": 10.0, "clock": 6.0, "interpolation": 20.0}, "irdic.test_stop_early") as (sp, now):
        report("clock", 0.0)
        now[0] = 11.0
        report("clock", 1.0)
        now[0] = 16.0
        report("interpolation", 0.25)
        f, eta = sp._state(now[0])
        # 15 s of the 20 s interpolation left at the speed of the masks and the interpolation so far
        assert eta == pytest.approx(15.0, rel=0.02)
        assert f == pytest.approx(16.0 / 31.0, rel=0.02)


def test_stage_progress_running_part_at_its_own_pace():
    """The interpolation runs at half the pace the model gives it relative to the masks: once it has reported a
    quarter of itself (a fifth since its first report), the ETA is its own rest at its own pace (not the masks'
    pace) plus the last part at the stage's pace so far (16 model seconds in 22 s)."""
    from irdic.logs import report

    with _masks_done({"masks": 10.0, "interpolation": 20.0, "rest": 5.0}, "irdic.test_own_pace") as (sp, now):
        for k in range(1, 7):  # 40 s for the whole part instead of 20
            now[0] = 10.0 + 2.0 * k
            report("interpolation", k / 20)
        _, eta = sp._state(now[0])
        assert eta == pytest.approx(0.7 * 40.0 + 5.0 / (16.0 / 22.0), rel=0.01)


def test_stage_progress_own_pace_counts_from_the_first_step():
    """The interpolation prepares for 6 s (its caches and factors) before its first step, then does a tenth of
    itself per second: at 0.4 (more than a fifth done since that step) its ETA is its rest at that pace (6 s),
    not at the pace since its start with the preparation in it (13.5 s)."""
    from irdic.logs import report

    with _masks_done({"masks": 10.0, "interpolation": 20.0}, "irdic.test_first_step") as (sp, now):
        report("interpolation", 0.0)
        for k in range(1, 5):
            now[0] = 15.0 + k
            report("interpolation", k / 10)
        _, eta = sp._state(now[0])
        assert eta == pytest.approx(6.0, rel=0.01)


def test_stage_progress_part_beside_the_others():
    """The IR clock (4 s of one core) runs on one of 2 threads beside the masks (10 s of one core, all parallel):
    the masks go at half speed until the clock ends at 4 s, then on both threads to 7 s, the interpolation
    (10 s of one core) to 12 s. From the first report on, the ETA says 12 s (without the clock's share of the time
    the masks' half speed made it 24 s)."""
    from irdic.logs import StageProgress, report

    now = [0.0]
    parts = {"masks": 10.0, "clock": 4.0, "interpolation": 10.0}
    with StageProgress("couple", parts, threads=2, logger=logging.getLogger("irdic.test_beside"),
                       clock=lambda: now[0], tick=None, beside=("clock",)) as sp:
        report("clock", 0.0)
        ends = []
        for t in (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0):
            now[0] = t
            if t == 4.0:
                report("clock", 1.0)
            report("masks", (t if t <= 4.0 else 4.0 + 2.0 * (t - 4.0)) / 10.0)
            ends.append(t + sp._state(t)[1])
            if t == 2.0:  # the masks' fifth and the clock's half (its share of the time) of 12 s
                assert sp.fraction() == pytest.approx(2.0 / 12.0)
        for k in range(1, 10):
            now[0] = 7.0 + 0.5 * k
            report("interpolation", k / 10)
            ends.append(now[0] + sp._state(now[0])[1])
        assert ends == pytest.approx([12.0] * len(ends), rel=1e-9)


def test_stage_progress_beside_part_that_stops_early():
    """A clock beside the masks that finds no motion and ends after 0.5 s of the 4 s expected weighs the time it
    took: the ETA stays that of the masks and the interpolation."""
    from irdic.logs import StageProgress, report

    now = [0.0]
    parts = {"masks": 10.0, "clock": 4.0, "interpolation": 10.0}
    with StageProgress("couple", parts, threads=2, logger=logging.getLogger("irdic.test_beside_early"),
                       clock=lambda: now[0], tick=None, beside=("clock",)) as sp:
        report("clock", 0.0)
        now[0] = 0.5
        report("masks", 0.05)
        report("clock", 1.0)
        now[0] = 3.0
        report("masks", 0.55)
        # masks 5 model seconds then at 2 threads per second: 2.25 s to go, then the interpolation's 5 s
        assert sp._state(3.0)[1] == pytest.approx(2.25 + 5.0, rel=0.02)


def test_stage_progress_reweighs_the_parts_not_yet_begun():
    """Costs known only once the stage has begun (the couple stage's specimen pixels after the projection)
    replace those of the parts that have reported no progress yet (a part that has only started, like the
    couple stage's masks while they plan which to build, included); a part with progress keeps its own, and
    the ETA follows the new model."""
    from irdic.logs import StageProgress, report, reweigh

    now = [0.0]
    parts = {"setup": 4.0, "masks": 10.0, "interpolation": 20.0}
    with StageProgress("couple", parts, logger=logging.getLogger("irdic.test_reweigh"), clock=lambda: now[0],
                       tick=None) as sp:
        now[0] = 4.0
        report("setup", 1.0)
        reweigh({"setup": 40.0, "masks": 5.0, "interpolation": 5.0, "nonsense": 1.0})
        assert sp.weights == {"setup": 4.0, "masks": 5.0, "interpolation": 5.0}
        assert sp.total == 14.0
        # one model second per second so far: 10 s left
        assert sp._state(now[0])[1] == pytest.approx(10.0)
        report("masks", 0.0)
        reweigh({"masks": 6.0})  # started, no progress yet: replaced
        assert sp.weights["masks"] == 6.0 and sp.total == 15.0
        reweigh({"masks": 5.0})
        report("masks", 0.5)
        reweigh({"masks": 50.0})  # progress reported: kept
        assert sp.weights["masks"] == 5.0
    reweigh({"masks": 1.0})  # outside a stage: nothing


def test_couple_cost_model_counts_the_specimen_pixels_and_the_masks_built():
    """The IR clock costs per pixel and the interpolation per pixel of the outline as well as per point: a
    specimen with four times the pixels costs more in the clock, one with twice the outline more in the
    interpolation (by its edge windows), the other parts the same; the outline defaults to a square's; the
    masks, and the interpolation's edge windows, cost per mask built (the default: one per DIC time), the
    clock per DIC time of the whole record and point it keeps (points denser than the pixels thinned); the pixels
    and the outline are the area and perimeter of the points' convex hull at their first time seen (a 30 x 20 px
    rectangle: 600 and 100)."""
    from irdic.coupling.compute import (CLOCK_POINTS_PER_PIXEL, MASK_OUTLINE_COST, PIXEL_COSTS, PIXELS_PER_POINT,
                                        STAGE_COSTS, specimen_extent, stage_costs)

    few, many = stage_costs(300, 13104, 300, 12641, outline=490), stage_costs(300, 13104, 300, 4 * 12641, outline=490)
    assert many["clock"] > 1.5 * few["clock"] and many["interpolation"] == few["interpolation"]
    assert all(many[k] == few[k] for k in ("setup", "masks", "rest", "write"))
    longer = stage_costs(300, 13104, 300, 12641, outline=980)
    assert longer["interpolation"] - few["interpolation"] == pytest.approx(
        300 * 490 * (PIXEL_COSTS["interpolation"] + MASK_OUTLINE_COST))
    assert all(longer[k] == few[k] for k in few if k != "interpolation")
    assert stage_costs(300, 13104, 300, 12641) == stage_costs(300, 13104, 300, 12641, outline=4 * np.sqrt(12641))
    assert stage_costs(300, 13104, 300) == stage_costs(300, 13104, 300, PIXELS_PER_POINT * 13104)
    reused = stage_costs(300, 13104, 300, 12641, outline=490, n_masks=30)
    assert few["masks"] - reused["masks"] == pytest.approx(270 * 13104 * STAGE_COSTS["masks"])
    assert few["interpolation"] - reused["interpolation"] == pytest.approx(270 * 490 * MASK_OUTLINE_COST)
    assert reused["clock"] == few["clock"]
    assert stage_costs(300, 13104, 300, 12641, outline=490, n_masks=300) == few
    dense, kept = stage_costs(300, 26180, 300, 14300), stage_costs(300, CLOCK_POINTS_PER_PIXEL * 14300, 300, 14300)
    assert dense["clock"] == pytest.approx(kept["clock"]) and dense["masks"] > 4 * kept["masks"]
    chunk = stage_costs(30, 13104, 300, 12641, outline=490, n_record=300)
    assert chunk["clock"] == few["clock"] and chunk["interpolation"] == pytest.approx(few["interpolation"] / 10)
    u, v = np.meshgrid(np.linspace(10, 40, 7), np.linspace(5, 25, 5))
    local = np.stack([np.full((35, 2), np.nan), np.column_stack([u.ravel(), v.ravel()])])
    seen = np.ones((2, 35), bool)
    assert specimen_extent(local, seen) == pytest.approx((600.0, 100.0))
    assert specimen_extent(local[:, :2], seen[:, :2]) == (0.0, 0.0)


def test_fields_cost_model_places_the_choice_of_the_smoothing_where_it_runs():
    """The choice of the smoothing (GCV, the gradient's risk) costs per stage judged (at most GCV_STAGES), per
    point of its patch (at most GCV_MAX_POINTS) and per point of the record: a record longer than GCV_STAGES,
    or a time chunk, makes all of it before the surface is fitted (the surface part); a shorter whole record
    makes the surface's in its fit and the temperature's in the regression part; with every smoothing
    configured (a number or null), none."""
    from irdic.fields.compute import GCV_COST, GCV_SURFACE_SHARE, _chooses, stage_costs
    from irdic.fields.smoothing import GCV_STAGES
    from irdic.surface.regression import GCV_MAX_POINTS

    plain = stage_costs(300, 13104, gcv=False)
    choice = GCV_STAGES * (GCV_COST[0] * GCV_MAX_POINTS + GCV_COST[1] * 13104)
    long = stage_costs(300, 13104)
    assert long["surface"] - plain["surface"] == pytest.approx(choice)
    assert all(long[k] == plain[k] for k in plain if k != "surface")
    short, short_plain = stage_costs(200, 13104), stage_costs(200, 13104, gcv=False)
    assert short["surface"] - short_plain["surface"] == pytest.approx(GCV_SURFACE_SHARE * choice * 200 / GCV_STAGES)
    assert short["regression"] - short_plain["regression"] == pytest.approx(
        (1 - GCV_SURFACE_SHARE) * choice * 200 / GCV_STAGES)
    chunk = stage_costs(50, 13104, n_record=200, chunked=True)
    assert chunk["surface"] - stage_costs(50, 13104, gcv=False)["surface"] == pytest.approx(choice * 200 / GCV_STAGES)
    few = stage_costs(300, 2000)
    assert few["surface"] - stage_costs(300, 2000, gcv=False)["surface"] == pytest.approx(
        GCV_STAGES * (GCV_COST[0] + GCV_COST[1]) * 2000)
    configured = {"surface_smoothing": 8.0, "surface_smoothing_time": None, "temperature_smoothing": None,
                  "temperature_smoothing_space": 12.0}
    assert not _chooses(configured)
    assert _chooses({**configured, "temperature_smoothing": "auto"})
    assert _chooses({**configured, "surface_smoothing": "gcv"})


def test_couple_cost_model_spares_the_clock_of_a_still_specimen():
    """Points that stay within MIN_MOTION_PX are refused by the clock's motion check before its search: the
    model keeps STILL_CLOCK_SHARE of the clock and every other part; the motion is the largest distance of a
    point from its first position (unseen positions left out)."""
    from irdic.coupling.compute import STILL_CLOCK_SHARE, _motion_px, stage_costs
    from irdic.timing.offset import MIN_MOTION_PX

    moving, still = stage_costs(300, 13104, 300, 12641), stage_costs(300, 13104, 300, 12641, still=True)
    assert still["clock"] == pytest.approx(STILL_CLOCK_SHARE * moving["clock"])
    assert all(still[k] == moving[k] for k in moving if k != "clock")
    local = np.zeros((4, 3, 2))
    local[2, 1] = [0.3, 0.4]  # 0.5 px
    local[3, 2] = np.nan
    assert _motion_px(local) == pytest.approx(0.5)
    assert not _motion_px(local) < MIN_MOTION_PX
    local[2, 1] = [0.3, 0.0]
    assert _motion_px(local) < MIN_MOTION_PX
