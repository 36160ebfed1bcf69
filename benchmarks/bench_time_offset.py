"""Benchmark of ``time_offset: auto``: accuracy against known offsets, and cost next to the couple stage.

Scenes (irdic.synthetic), each with realistic exports (0.05 K NETD, 2
decimals, mixed edge pixels, 0.003 mm DIC noise) or noise-free ones:

- ``demo``: the demo tube, IR 4 Hz, DIC 2 Hz (IR faster), 41 frames, 1,581 points;
- ``strong``: the same with a stronger temperature pattern (40 % around the
  tube, 6 K of heating), as in tests/test_time_offset.py;
- ``moving``: the moving tube of bench_couple_moving.py, IR and DIC at 10 Hz
  (the same rate), ``--frames`` frames, ``--points`` points.

For each scene and offset (in IR frame periods) and seed, the IR clock is
put that far behind the DIC clock and the offset estimated
(:func:`irdic.timing.clock.ir_clock`); the table gives the error in frame
periods, the stated uncertainty, the error over the uncertainty, and the
seconds of the estimate. The couple stage runs once per scene with ``auto``
(estimate included) and once with the true offset: the estimate's share of
couple, and the point temperatures' RMS error against the truth with each.

Usage (repository root, one BLAS thread on a shared machine)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_time_offset.py [--scenes demo strong moving]
        [--offsets -3.3 -0.45 0.2 1.7] [--seeds 2] [--clean] [--frames 150] [--points 6000]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import _tube  # noqa: E402

from irdic.camera import CameraModel  # noqa: E402
from irdic.errors import IrdicError, IrdicWarning  # noqa: E402
from irdic.timing.clock import ir_clock  # noqa: E402
from irdic.coupling import couple  # noqa: E402
from irdic.synthetic import Tube, experiment  # noqa: E402
from irdic.synthetic.render import realistic_stack  # noqa: E402
from tests._clock_scenes import DECIMALS, DIC_NOISE, IR_NOISE, STRONG_TUBE  # noqa: E402


def scene(name: str, realistic: bool, seed: int, frames: int, points: int):
    dn = DIC_NOISE if realistic else 0.0
    if name == "moving":
        n_x = max(3, int(round(np.sqrt(points * 78 / 168))))
        ex = _tube.tube(frames, (n_x, max(3, int(round(points / n_x)))), ir_noise=IR_NOISE, dic_noise=dn)
    else:
        ex = experiment("tube", "demo", ir_noise=IR_NOISE, dic_noise=dn, seed=seed,
                        specimen=Tube(**STRONG_TUBE) if name == "strong" else None)
    rng = np.random.default_rng([seed, 30])
    frames_ = realistic_stack(ex.renderer, ex.ir_times, rng, noise=IR_NOISE if realistic else 0.0,
                              decimals=DECIMALS if realistic else None, mixed_edges=realistic)
    r = ex.renderer
    ir = xr.Dataset({"temperature": (("time", "v", "u"), frames_)},
                    coords={"time": ex.ir_times, "v": r.v.astype(np.int64), "u": r.u.astype(np.int64)})
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    return ex, ex.dic()[["x"]], ir, cal


def rms(points, ex) -> float:
    tr = ex.truth().sel(point=points.point)
    ok = points.visible.values & np.isfinite(tr.temperature.values)
    return float(np.sqrt(np.mean((points.temperature.values - tr.temperature.values)[ok] ** 2)))


def run_scene(name, args, realistic) -> None:
    rows = []
    for seed in range(args.seeds):
        ex, dic, ir, cal = scene(name, realistic, seed, args.frames, args.points)
        period = float(np.median(np.diff(ex.ir_times)))
        for k in args.offsets:
            tau = k * period
            shifted = ir.assign_coords(time=ex.ir_times - tau).assign_attrs(time_offset="auto")
            t0 = time.perf_counter()
            try:
                _, a = ir_clock(dic, shifted, cal, name)
            except IrdicError as exc:
                print(f"| {name} | {seed} | {k:+.2f} | refused: {str(exc)[:90]}... |", flush=True)
                continue
            sec = time.perf_counter() - t0
            err, std = (a["ir_time_offset"] - tau) / period, a["ir_time_offset_std"] / period
            rows.append((err, std, sec))
            print(f"| {name} | {seed} | {k:+.2f} | {err:+.3f} | {std:.3f} | {err / std:+.2f} | {sec:.2f} |", flush=True)
    if not rows:
        return
    e = np.array(rows)
    print(f"{name} ({'realistic' if realistic else 'noise-free'}): {len(rows)} estimates, max |error| "
          f"{np.abs(e[:, 0]).max():.3f} frames, within 3 std {np.mean(np.abs(e[:, 0]) <= 3 * e[:, 1]):.2f}, "
          f"RMS error/std {np.sqrt(np.mean((e[:, 0] / e[:, 1]) ** 2)):.2f}, estimate {e[:, 2].mean():.2f} s", flush=True)
    # cost and point temperatures, first seed, the largest offset
    ex, dic, ir, cal = scene(name, realistic, 0, args.frames, args.points)
    tau = max(args.offsets, key=abs) * float(np.median(np.diff(ex.ir_times)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IrdicWarning)
        t0 = time.perf_counter()
        auto = couple(dic, ir.assign_coords(time=ex.ir_times - tau).assign_attrs(time_offset="auto"), cal)
        t1 = time.perf_counter()
        known = couple(dic, ir.assign_attrs(time_offset=0.0), cal)
        t2 = time.perf_counter()
    t0e = time.perf_counter()
    ir_clock(dic, ir.assign_coords(time=ex.ir_times - tau).assign_attrs(time_offset="auto"), cal, name)
    est = time.perf_counter() - t0e
    print(f"{name}: couple with auto {t1 - t0:.1f} s (estimate {est:.2f} s = {100 * est / (t1 - t0 - est):.1f} % of "
          f"couple), with the true offset {t2 - t1:.1f} s (its own check included); T RMS vs truth: auto "
          f"{rms(auto, ex):.4f} K, true offset {rms(known, ex):.4f} K", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["demo", "strong", "moving"])
    ap.add_argument("--offsets", nargs="+", type=float, default=[-3.3, -0.45, 0.2, 1.7], help="IR frame periods")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--clean", action="store_true", help="noise-free exports instead of realistic ones")
    ap.add_argument("--frames", type=int, default=150, help="moving scene: IR frames = DIC stages")
    ap.add_argument("--points", type=int, default=6000, help="moving scene: DIC points")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}, "
          f"python {platform.python_version()}")
    print("| scene | seed | offset (frames) | error (frames) | std (frames) | error/std | estimate (s) |")
    print("|---|---|---|---|---|---|---|")
    for name in args.scenes:
        run_scene(name, args, not args.clean)


if __name__ == "__main__":
    main()
