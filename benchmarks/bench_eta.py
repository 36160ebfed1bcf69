"""The couple stage's progress ETA: its reports recorded once, replayed under the cost model.

The ETA of :class:`irdic.logs.StageProgress` depends only on when each part
reported what share of itself, and on the cost model that weighs the parts
(:func:`irdic.coupling.compute.stage_costs`). ``--record`` runs the couple
stage on stores written by ``bench_couple_moving.py`` (each in a fresh
process, as a Snakemake rule runs it) and keeps those reports; a replay feeds
them, with a fake clock, to a ``StageProgress`` built from the cost model as
it is now, and prints the worst error of the duration the progress lines
predict from the first tenth of the run to the last (the figure of
``bench_couple_moving.py``'s "ETA" column). A new set of constants is judged
on the same runs without running them again.

Inputs: ``ROOT/dic.zarr``, ``ir.zarr``, ``cal.zarr`` per store. Outputs:
``ROOT/eta_events.json`` (``--record``; the couple stage's own store goes to
``ROOT/points_eta.zarr``) and the table.

    PYTHONPATH=$PWD python benchmarks/bench_eta.py --record STORE [STORE ...]
    PYTHONPATH=$PWD python benchmarks/bench_eta.py STORE [STORE ...]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

_RECORD = """
import json, sys, time
import irdic.coupling.compute as compute
import irdic.logs as logs
from irdic.stages import couple
events = []
def recorded(fn, kind):
    def wrapper(*a, **kw):
        events.append((kind, time.perf_counter(), a, kw))
        return fn(*a, **kw)
    return wrapper
compute.stage_costs = recorded(compute.stage_costs, "costs")
_init, _reweigh, _update = logs.StageProgress.__init__, logs.StageProgress.reweigh, logs.StageProgress.update
def init(self, what, parts, **kw):
    if what == "couple":
        events.append(("init", time.perf_counter(), [kw.get("threads"), kw.get("shares"), list(kw.get("beside", ()))], {}))
    _init(self, what, parts, **kw)
def reweigh(self, parts):
    if self.what == "couple":
        events.append(("reweigh", time.perf_counter(), [], {}))
    _reweigh(self, parts)
def update(self, part, fraction):
    if self.what == "couple":
        events.append(("update", time.perf_counter(), [part, float(fraction)], {}))
    return _update(self, part, fraction)
logs.StageProgress.__init__, logs.StageProgress.reweigh, logs.StageProgress.update = init, reweigh, update
root, threads = sys.argv[1], int(sys.argv[2])
couple.run({"dic": root + "/dic.zarr", "ir": root + "/ir.zarr", "calibration": root + "/cal.zarr"},
           {"store": root + "/points_eta.zarr"}, threads=threads, log=root + "/couple_eta.log")
events.append(("end", time.perf_counter(), [], {}))
json.dump(events, open(root + "/eta_events.json", "w"), default=float)
"""

_LINE = re.compile(r"([\d.]+) s elapsed, ETA (\d+) s")


def record(root: Path, threads: int) -> None:
    """The couple stage on ``root`` in a fresh process, its progress reports kept in ``root/eta_events.json``."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                                        os.environ.get("PYTHONPATH", "")]))
    # run outside the repository: the working directory comes first on sys.path
    subprocess.run([sys.executable, "-c", _RECORD, str(root.resolve()), str(threads)], env=env, check=True,
                   cwd=str(root.resolve()), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def replay(events: list) -> tuple[float, float, list[str]]:
    """The progress lines ``events`` give under the present cost model: (worst relative error of the predicted
    duration over the lines from 10 to 90 % of the run, the run's seconds from the progress's start, the
    lines)."""
    from irdic.coupling.compute import stage_costs
    from irdic.logs import StageProgress

    now, lines = [0.0], []

    class Lines:
        def info(self, fmt, line):
            lines.append(line)

    progress, costs, start, end = None, None, None, None
    for kind, t, args, kw in events:
        # the stage's ticker looks for a line every second between reports
        while progress is not None and now[0] + 1.0 < t:
            now[0] += 1.0
            with progress._lock:
                progress._line(now[0])
        now[0] = t
        if kind == "costs":
            costs = stage_costs(*args, **kw)
        elif kind == "init":
            start = t
            progress = StageProgress("couple", costs, threads=args[0], shares=args[1], beside=args[2],
                                     logger=Lines(), clock=lambda: now[0], tick=None)
        elif kind == "reweigh":
            progress.reweigh(costs)
        elif kind == "update":
            progress.update(*args)
        elif kind == "end":
            end = t
    seconds = end - start
    kept = [(float(m[1]), float(m[2])) for m in map(_LINE.search, lines)
            if m and 0.1 * seconds <= float(m[1]) <= 0.9 * seconds]
    worst = max((abs(el + eta - seconds) / seconds for el, eta in kept), default=float("nan"))
    return worst, seconds, lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("stores", nargs="+", type=Path, help="folders with dic.zarr, ir.zarr and cal.zarr")
    ap.add_argument("--record", action="store_true", help="run the couple stage on each store first")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    print("| store | couple s | worst ETA error from the first tenth |\n|---|---:|---:|")
    worst = []
    for root in args.stores:
        if args.record:
            record(root, args.threads)
        err, seconds, _ = replay(json.loads((root / "eta_events.json").read_text()))
        worst.append(err)
        print(f"| {root} | {seconds:.1f} | {100 * err:.1f} % |")
    print(f"| **worst** | | {100 * np.nanmax(worst):.1f} % |")


if __name__ == "__main__":
    main()
