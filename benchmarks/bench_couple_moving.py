"""Benchmark of couple + fields on a moving specimen, against the scipy way.

The tube in tension-torsion all along (irdic.synthetic, 10 Hz IR and DIC,
by default 300 x 300 frames and 78 x 168 = 13,104 DIC points) is written to
temporary stores; ``couple`` and then ``fields`` each run in a fresh
process, as the workflow's rules do, so a stage's peak RSS and threads are
its own (the job's peak is the larger of the two). In the same run, the scipy way: ``RBFInterpolator(kernel=
"inverse_multiquadric", epsilon=0.5, degree=1, neighbors=50)`` on the masked
pixels of the IR frame at each DIC time, evaluated at the projected points and
at four offsets for difference-quotient gradients, timed on ``--subset`` DIC
times and extrapolated to all.

Usage::

    python benchmarks/bench_couple_moving.py [--frames 300] [--points 13104] [--threads 1]
        [--scaling] [--two-jobs]
    python benchmarks/bench_couple_moving.py --sweep [--quick] [--threads 2] [--subset 4]

``--scaling`` adds rows for 150/300/600 frames and 6k/13k/26k points;
``--two-jobs`` runs two couple + fields jobs at once (one thread each) and
compares with one alone.

``--sweep``: the paper-scale tube seen from closer (``_tube.sweep_tube``:
~58,000 specimen pixels, 13,104 points, 300 DIC times and IR frames at 10 Hz)
in cycles of tension-torsion whose outline moves 0, 0.2, 0.5, 1 and 2 px per
frame (``--speeds``), each row with the scipy way timed in the same run: every
row, the worst, and how the cost per DIC time grows from the slowest to the
fastest outline. Per stage the wall and CPU seconds, peak RSS and where the time
goes (couple: the IR clock, the masks, the interpolation; fields: the
uncertainty probes); the load average before and after each row.
``--quick``: 60 frames and 3,000 points, the scipy way on 2 times (a minute or
two per row; for a check, not for the figures). With ``--two-jobs`` the
fastest row's job runs twice at once (one thread each) against once alone on
one thread. Each stage's progress lines, from the first tenth of the run to
the last, give the worst error of the duration they predict (elapsed + ETA
against the stage's time from the start of its progress) and, stricter near
the end, of the ETA against the time that was left.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _tube  # noqa: E402

_STAGE = """
import json, resource, sys, time
from irdic.stages import couple, fields
stage, root, tag, threads = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
parts = {}

def timed(module, name, label):
    import importlib
    mod = importlib.import_module(module)
    fn = getattr(mod, name)
    def wrapper(*a, **kw):
        t, c = time.perf_counter(), time.process_time()
        try:
            return fn(*a, **kw)
        finally:
            parts[label] = parts.get(label, 0.0) + time.perf_counter() - t
            parts[label + "_cpu"] = parts.get(label + "_cpu", 0.0) + time.process_time() - c
    setattr(mod, name, wrapper)

if stage == "couple":
    timed("irdic.coupling.compute", "ir_clock", "clock")
    timed("irdic.coupling.compute", "masks_and_facing", "masks")
    timed("irdic.coupling.compute", "evaluate_series", "interpolation")
else:
    timed("irdic.fields.space_time", "uncertainties", "probes")
    timed("irdic.fields.compute", "with_strain_std", "probes")  # the strain's noise probes, run after the IR terms
# when the stage's progress starts (after its inputs are read): the ETA's reference is the time from there
import irdic.logs
_init = irdic.logs.StageProgress.__init__
def _started(self, *a, **kw):
    parts.setdefault("progress_start", time.perf_counter() - t0)
    _init(self, *a, **kw)
irdic.logs.StageProgress.__init__ = _started
t0 = time.perf_counter()
log = root + f"/{stage}{tag}.log"
if stage == "couple":
    couple.run({"dic": root + "/dic.zarr", "ir": root + "/ir.zarr", "calibration": root + "/cal.zarr"},
               {"store": root + f"/points{tag}.zarr"}, threads=threads, log=log)
else:
    fields.run({"points": root + f"/points{tag}.zarr", "calibration": root + "/cal.zarr"},
               {"store": root + f"/fields{tag}.zarr"}, threads=threads, log=log)
ru = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"seconds": time.perf_counter() - t0, "cpu": ru.ru_utime + ru.ru_stime,
                  "peak_gb": ru.ru_maxrss / 2**20, "parts": parts}))
"""


def _grid(points: int) -> tuple[int, int]:
    # the 78 x 168 aspect of the 13,104-point grid
    n_x = max(3, int(round(np.sqrt(points * 78 / 168))))
    return n_x, max(3, int(round(points / n_x)))


def write_experiment(root: Path, frames: int, points: int, ir_noise: float = 0.05, ex=None):
    """Stores of the moving tube (or of ``ex``) under ``root``; returns the experiment."""
    from irdic.camera import CameraModel
    from irdic.store import FrameStore, write_dataset

    if ex is None:
        ex = _tube.tube(frames, _grid(points), ir_noise=ir_noise, dic_noise=0.005 if ir_noise else 0.0)
    r = ex.renderer
    with FrameStore(root / "ir.zarr", "temperature", ex.ir_times.size, ("v", "u"),
                    {"v": r.v.astype(np.int64), "u": r.u.astype(np.int64)}, var_attrs={"units": "degC"}) as fs:
        for i, frame in enumerate(ex.ir_frames(noise=ir_noise > 0)):
            fs.write(i, float(ex.ir_times[i]), frame.values)
    write_dataset(ex.dic(), root / "dic.zarr", stage="ingest-dic")
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    write_dataset(cal, root / "cal.zarr", stage="calibrate")
    return ex


def run_stage(stage: str, root: Path, tag: str = "", threads: int = 1) -> dict:
    """One stage in a fresh process, as a Snakemake rule runs it: its seconds and peak RSS (GB)."""
    import json

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                                        os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", _STAGE, stage, str(root), tag, str(threads)], env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    if proc.returncode:
        raise SystemExit(f"{stage} subprocess failed ({proc.returncode})")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["eta"] = eta_error(root / f"{stage}{tag}.log", stage, out["seconds"] - out["parts"].pop("progress_start", 0.0))
    return out


_ETA_LINE = re.compile(r"(?P<stage>\w+): (?P<pct>\d+) % of the work, (?P<el>[\d.]+) s elapsed, ETA (?P<eta>\d+) s")


def eta_error(log: Path, stage: str, seconds: float) -> tuple[float, float, float]:
    """The stage's progress lines against its run time from the start of its progress (``seconds``: its inputs
    read, its store written), over the lines from the first tenth of the run to the last tenth: the worst
    relative error of the duration they predict (elapsed + ETA against ``seconds``), the worst relative error
    of the ETA against the time that was left (stricter near the end), and the part of the run that had
    passed at the first line (NaN without lines)."""
    lines = [m for m in map(_ETA_LINE.search, log.read_text().splitlines() if log.exists() else []) if m
             and m["stage"] == stage]
    if not lines:
        return float("nan"), float("nan"), float("nan")
    first = float(lines[0]["el"]) / seconds
    kept = [(float(m["el"]), float(m["eta"])) for m in lines if 0.1 * seconds <= float(m["el"]) <= 0.9 * seconds]
    if not kept:
        return float("nan"), float("nan"), first
    return (max(abs(el + eta - seconds) / seconds for el, eta in kept),
            max(abs(el + eta - seconds) / (seconds - el) for el, eta in kept), first)


def run_job(root: Path, tag: str = "", threads: int = 1) -> dict:
    """couple, then fields, each in its own process: seconds of each, peak RSS of each and of the job."""
    c, f = run_stage("couple", root, tag, threads), run_stage("fields", root, tag, threads)
    return {"couple": c["seconds"], "fields": f["seconds"], "peak_couple": c["peak_gb"],
            "peak_fields": f["peak_gb"], "peak_gb": max(c["peak_gb"], f["peak_gb"]), "cpu_couple": c["cpu"],
            "cpu_fields": f["cpu"], "parts": {**c["parts"], **f["parts"]}, "eta": (c["eta"], f["eta"])}


def scipy_way(root: Path, ex, subset: int, cpu: bool = False) -> tuple[float, float]:
    """Seconds per DIC time of the scipy way (CPU seconds with ``cpu``), and its T RMS against the truth on
    those times."""
    from scipy.interpolate import RBFInterpolator

    from irdic.store import open_store

    pts = open_store(root / "points.zarr")
    ir = open_store(root / "ir.zarr")
    tr = ex.truth().sel(point=pts.point)
    r = ex.renderer
    u0, v0 = int(r.u[0]), int(r.v[0])
    ks = np.linspace(1, pts.sizes["time"] - 2, subset).astype(int)
    spent, errs = 0.0, []
    h = 0.5
    for k in ks:
        n = int(np.argmin(np.abs(ex.ir_times - float(pts.time[k]))))  # DIC times coincide with IR frames
        frame = ir.temperature[n].values
        ok = pts.visible.values[k]
        p = pts.pixel.values[k][ok]
        from irdic.footprint.mask import specimen_mask

        clock = time.process_time if cpu else time.perf_counter
        t1 = clock()
        mk = specimen_mask(p - [u0, v0], np.arange(r.u.size), np.arange(r.v.size), erosion_px=1.0)
        vv, uu = np.nonzero(mk)
        rbf = RBFInterpolator(np.c_[uu + u0, vv + v0].astype(float), frame[vv, uu],
                              kernel="inverse_multiquadric", epsilon=0.5, degree=1, neighbors=50)
        val = rbf(p)
        _ = (rbf(p + [h, 0]) - rbf(p - [h, 0])) / (2 * h), (rbf(p + [0, h]) - rbf(p - [0, h])) / (2 * h)
        spent += clock() - t1
        errs.append(val - tr.temperature.values[k][ok])
    e = np.concatenate(errs)
    return spent / len(ks), float(np.sqrt(np.mean(e**2)))


def one(frames: int, points: int, threads: int, subset: int, two_jobs: bool = False) -> None:
    root = Path(tempfile.mkdtemp(prefix="bench_moving_"))
    try:
        t0 = time.perf_counter()
        ex = write_experiment(root, frames, points)
        print(f"tube: {ex.s.size} points, {ex.dic_times.size} DIC x {ex.ir_times.size} IR frames of "
              f"{ex.renderer.v.size} x {ex.renderer.u.size} px (written in {time.perf_counter() - t0:.0f} s)", flush=True)
        alone = run_job(root, "", threads)
        tot = alone["couple"] + alone["fields"]
        print(f"  irdic: couple {alone['couple']:.1f} s + fields {alone['fields']:.1f} s = {tot:.1f} s, "
              f"peak RSS {alone['peak_gb']:.2f} GB (couple {alone['peak_couple']:.2f}, fields "
              f"{alone['peak_fields']:.2f}; {threads} thread(s)); ETA from the first tenth, worst error of the "
              f"duration (of the time left): couple {_eta(alone['eta'][0])}, fields {_eta(alone['eta'][1])}", flush=True)
        if subset:
            from irdic.store import open_store

            pts = open_store(root / "points.zarr")
            tr = ex.truth().sel(point=pts.point)
            vis = pts.visible.values
            err = pts.temperature.values[vis] - tr.temperature.values[vis]
            per, rms = scipy_way(root, ex, subset)
            full = per * ex.dic_times.size
            print(f"  scipy way: {per:.2f} s per DIC time x {ex.dic_times.size} = {full:.0f} s "
                  f"({full / alone['couple']:.1f} x couple); T RMS vs truth on {subset} times: scipy {rms:.4f} K, "
                  f"irdic (all) {np.sqrt(np.mean(err**2)):.4f} K", flush=True)
        if two_jobs:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(2) as pool:
                ra, rb = pool.map(lambda tag: run_job(root, tag, 1), ("_a", "_b"))
            for name, rr in (("job 1", ra), ("job 2", rb)):
                t = rr["couple"] + rr["fields"]
                print(f"  two jobs at once, {name}: {t:.1f} s = {t / tot:.2f} x alone", flush=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)


SPEEDS = (0.0, 0.2, 0.5, 1.0, 2.0)


def two_at_once(root: Path) -> None:
    """Two couple + fields jobs at once on the same stores, one thread each, against one such job alone."""
    from concurrent.futures import ThreadPoolExecutor

    load0 = os.getloadavg()[0]
    alone = run_job(root, "_1", 1)
    t1 = alone["couple"] + alone["fields"]
    with ThreadPoolExecutor(2) as pool:
        both = list(pool.map(lambda tag: run_job(root, tag, 1), ("_a", "_b")))
    print(f"two jobs at once (1 thread each) against one alone on 1 thread ({t1:.1f} s, peak "
          f"{alone['peak_gb']:.2f} GB): " + ", ".join(f"{(r['couple'] + r['fields']) / t1:.2f} x" for r in both)
          + f" (load {load0:.1f} / {os.getloadavg()[0]:.1f})", flush=True)


def _eta(e):
    """``worst error of the duration % (of the time left %; first line at % of the run)``."""
    return f"{100 * e[0]:.0f} % ({100 * e[1]:.0f} %; first at {100 * e[2]:.0f} %)"


def sweep(speeds, frames: int, points: int, threads: int, subset: int, two_jobs: bool = False) -> None:
    """Couple + fields and the scipy way on the sweep tube at each outline speed; every row and the worst.

    Wall seconds (CPU seconds in brackets, all threads); the scipy way's ratio
    to couple in wall and in CPU seconds (the CPU ratio holds on a loaded machine).
    """
    rows = []
    print("| outline px/frame | couple s | clock / masks / interpolation s | fields s | probes s | total s | "
          "peak RSS GB (couple / fields) | scipy s per DIC time | scipy / couple | couple s per DIC time | "
          "ETA from the first tenth: worst error of the duration (of the time left) (couple / fields) | load "
          "before / after |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")

    def both(p, k):
        return f"{p.get(k, 0):.1f} ({p.get(k + '_cpu', 0):.0f})"

    for speed in speeds:
        root = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
        try:
            load0 = os.getloadavg()[0]
            ex = _tube.sweep_tube(speed, frames, _grid(points))
            write_experiment(root, frames, points, ex=ex)
            job = run_job(root, "", threads)
            if subset:
                per, _ = scipy_way(root, ex, subset)
                per_cpu, _ = scipy_way(root, ex, subset, cpu=True)
            else:
                per = per_cpu = float("nan")
            load1 = os.getloadavg()[0]
            n_t = ex.dic_times.size
            p = job["parts"]
            row = dict(speed=ex.outline_speed, couple=job["couple"], fields=job["fields"], cpu=job["cpu_couple"],
                       ratio=per * n_t / job["couple"], ratio_cpu=per_cpu * n_t / job["cpu_couple"],
                       per_time=job["couple"] / n_t, per_time_cpu=job["cpu_couple"] / n_t,
                       fields_cpu=job["cpu_fields"])
            rows.append(row)
            print(f"| {ex.outline_speed:.2f} | {job['couple']:.1f} ({job['cpu_couple']:.0f}) | "
                  f"{both(p, 'clock')} / {both(p, 'masks')} / {both(p, 'interpolation')} | "
                  f"{job['fields']:.1f} ({job['cpu_fields']:.0f}) | {both(p, 'probes')} | "
                  f"{job['couple'] + job['fields']:.1f} ({job['cpu_couple'] + job['cpu_fields']:.0f}) | "
                  f"{job['peak_couple']:.2f} / {job['peak_fields']:.2f} | {per:.2f} ({per_cpu:.2f}) | "
                  f"{row['ratio']:.1f} ({row['ratio_cpu']:.1f}) | {row['per_time']:.3f} ({row['per_time_cpu']:.3f}) | "
                  f"{_eta(job['eta'][0])} / {_eta(job['eta'][1])} | {load0:.1f} / {load1:.1f} |", flush=True)
            if two_jobs and speed == max(speeds):
                two_at_once(root)
        finally:
            shutil.rmtree(root, ignore_errors=True)
    worst = max(rows, key=lambda r: r["couple"] + r["fields"])
    slow, fast = min(rows, key=lambda r: r["speed"]), max(rows, key=lambda r: r["speed"])
    print(f"worst row: outline {worst['speed']:.2f} px/frame, couple + fields {worst['couple'] + worst['fields']:.1f} s "
          f"({worst['cpu'] + worst['fields_cpu']:.0f} CPU s); scipy / couple at worst "
          f"{min(r['ratio'] for r in rows):.1f} x ({min(r['ratio_cpu'] for r in rows):.1f} x in CPU s); couple per DIC "
          f"time {fast['per_time'] / slow['per_time']:.2f} x ({fast['per_time_cpu'] / slow['per_time_cpu']:.2f} x in "
          f"CPU s) from {slow['speed']:.2f} to {fast['speed']:.2f} px/frame; fields / couple at worst "
          f"{max(r['fields'] / r['couple'] for r in rows):.2f} ({max(r['fields_cpu'] / r['cpu'] for r in rows):.2f} "
          "in CPU s)", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--points", type=int, default=13104)
    ap.add_argument("--threads", type=int, default=1, help="threads of the stage subprocess")
    ap.add_argument("--subset", type=int, default=4, help="DIC times for the scipy way (0: skip)")
    ap.add_argument("--scaling", action="store_true", help="rows for 150/300/600 frames and 6k/13k/26k points")
    ap.add_argument("--two-jobs", action="store_true", help="two jobs at once against one alone")
    ap.add_argument("--sweep", action="store_true", help="the sweep tube at each outline speed (see the module doc)")
    ap.add_argument("--speeds", type=float, nargs="+", default=SPEEDS, help="outline speeds of --sweep, px per frame")
    ap.add_argument("--quick", action="store_true", help="--sweep on 60 frames and 3,000 points")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}, "
          f"python {platform.python_version()}")
    if args.sweep:
        quick = args.quick
        sweep(args.speeds, 60 if quick else args.frames, 3000 if quick else args.points, args.threads,
              min(args.subset, 2) if quick else args.subset, args.two_jobs)
        return
    one(args.frames, args.points, args.threads, args.subset, args.two_jobs)
    if args.scaling:
        for f in (150, 300, 600):
            if f != args.frames:
                one(f, args.points, args.threads, 0)
        for p in (6000, 26000):
            one(args.frames, p, args.threads, 0)


if __name__ == "__main__":
    main()
