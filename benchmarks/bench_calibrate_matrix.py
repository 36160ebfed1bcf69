"""Calibration on harder targets: poses x marker contrast/noise x plate gradient, clicked seeds.

Every case renders the synthetic open-book target (area-integrated marker
edges, :func:`irdic.synthetic.target.open_book_target`) with 0.1 K pixel
noise and a marker contrast of 5.5, 0.6 or 0.3 K (contrast/noise 55, 6, 3),
without and with a 4 K temperature gradient across the plate, and
calibrates it with :func:`irdic.calibration.calibrate` from 8 clicked seeds
(true marker projections + N(0, 2 px), :func:`irdic.synthetic.target.clicked_seeds`).

Reported per case: the projection error against the true camera (RMS
distance between true and calibrated projections of points on a
specimen-like cylinder patch in front of the target, px), the markers used,
and the wall and CPU time of ``calibrate`` (detection included; the time goal
of 5 s is judged on the CPU time, one BLAS thread).

Usage::

    python benchmarks/bench_calibrate_matrix.py [--seed 0] [--poses oblique] [--levels 3] [--gradients 0]
"""

from __future__ import annotations

import argparse
import os
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from irdic.calibration import calibrate  # noqa: E402
from irdic.camera import load_camera  # noqa: E402
from irdic.errors import IrdicError  # noqa: E402
from irdic.synthetic.camera import lab_camera  # noqa: E402
from irdic.synthetic.target import clicked_seeds, open_book_target  # noqa: E402

#: name -> lab_camera arguments; the angles of the two wings to the line of sight are printed
POSES = {
    "lab": dict(),
    "left-low": dict(distance=400.0, azimuth_deg=-12.0, elevation_deg=-6.0, roll_deg=-2.0),
    "oblique": dict(distance=450.0, azimuth_deg=41.0, elevation_deg=8.0, roll_deg=2.0),
}
NOISE = 0.1
CONTRASTS = (5.5, 0.6, 0.3)
GOAL = {55: 0.03, 6: 0.06, 3: 0.12}


def specimen_points(n=2000, seed=1):
    rng = np.random.default_rng(seed)
    phi = rng.uniform(-0.6, 0.6, n)
    y = rng.uniform(-20, 20, n)
    return np.column_stack([30 * np.sin(phi), y, -15 + 30 * np.cos(phi)])


def run_case(pose, contrast, gradient, seed):
    cam = lab_camera(**POSES[pose])
    tg = open_book_target(cam, noise=NOISE, contrast=contrast, gradient_k=gradient, seed=seed)
    seeds = clicked_seeds(tg, 8, sigma_px=2.0, seed=seed)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        cal = calibrate(tg.image, tg.markers, seeds=seeds)
    except IrdicError as exc:
        return dict(error=str(exc), time=time.perf_counter() - t0)
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    x = specimen_points()
    err = np.hypot(*(load_camera(cal).project(x) - cam.project(x)).T)
    return dict(rms=float(np.sqrt(np.mean(err**2))), used=int(cal.attrs["n_used"]), time=dt, cpu=cpu)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--poses", nargs="+", choices=list(POSES), default=list(POSES), help="poses to run")
    ap.add_argument("--levels", nargs="+", type=int, choices=sorted(GOAL), default=sorted(GOAL, reverse=True),
                    help="contrast/noise levels to run")
    ap.add_argument("--gradients", nargs="+", type=float, default=[0.0, 4.0], help="plate gradients to run, K")
    args = ap.parse_args(argv)
    for name in args.poses:
        kw = POSES[name]
        cam = lab_camera(**kw)
        tg = open_book_target(cam, noise=0.0, supersample=2)
        d = cam.C - tg.book.hinge_point
        ang = np.degrees(np.arccos(tg.book.n @ (d / np.linalg.norm(d))))
        print(f"pose {name}: wings seen at {ang[0]:.0f} and {ang[1]:.0f} deg from their normals")
    print(f"{'pose':9s} {'C/N':>4s} {'grad':>5s} {'used':>5s} {'RMS px':>8s} {'goal':>6s} {'time s':>7s} {'cpu s':>6s}")
    ok = True
    for name in args.poses:
        for c in CONTRASTS:
            cn = round(c / NOISE)
            if cn not in args.levels:
                continue
            for g in args.gradients:
                r = run_case(name, c, g, args.seed)
                if "error" in r:
                    ok = False
                    print(f"{name:9s} {cn:4d} {g:4.0f}K  FAILED ({r['time']:.1f} s): {r['error'][:300]}")
                    continue
                # the time goal on CPU time: on a shared machine the wall time is set by the other jobs
                good = r["rms"] <= GOAL[cn] and r["cpu"] < 5.0
                ok &= good
                print(f"{name:9s} {cn:4d} {g:4.0f}K {r['used']:5d} {r['rms']:8.4f} {GOAL[cn]:6.2f} "
                      f"{r['time']:7.2f} {r['cpu']:6.2f}{'' if good else '  MISSED'}", flush=True)
    print("all cases within the goals" if ok else "some cases missed the goals")


if __name__ == "__main__":
    main()
