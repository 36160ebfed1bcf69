"""Peak memory and time of the time-chunked couple and fields stages against the record length.

A demo-scale record with small frames: the tiny half-shell's geometry (273
DIC points, a ~120 x 90 px IR crop) held still, IR at 5 Hz with a heating
that varies smoothly in space and time, DIC at every second IR frame.
``--frames`` IR frames (default 500, 2,000 and 8,000) are written to
temporary stores; then, for each length, one fresh subprocess runs every
couple chunk, gathers points.zarr, runs every fields chunk and gathers
fields.zarr (``execution.chunk_frames`` DIC times per chunk), one chunk after
the other as a scheduler would run them as separate jobs. Its peak resident
memory is the largest of any one chunk (each frees its arrays before the
next), so it must stay flat while the time grows linearly with the record.

Usage::

    python benchmarks/bench_chunks.py [--frames 500 2000 8000] [--chunk-frames 100]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

IR_RATE = 5.0  # Hz: the paper's temporal kernel (c R0 = 1 s) then reaches ~41 frames


def _write_record(root: Path, n_frames: int) -> None:
    from irdic.camera import CameraModel
    from irdic.store import FrameStore, write_dataset
    from irdic.synthetic import experiment

    ex = experiment("halfshell", "tiny", ir_noise=0.0, dic_noise=0.0)
    base = ex.ir_stack().isel(time=0)
    u, v = base["u"].values.astype(np.int64), base["v"].values.astype(np.int64)
    uu, vv = np.meshgrid((u - u.mean()) / np.ptp(u), (v - v.mean()) / np.ptp(v))
    t_ir = np.arange(n_frames) / IR_RATE
    with FrameStore(root / "ir.zarr", "temperature", n_frames, ("v", "u"), {"v": v, "u": u},
                    var_attrs={"units": "degC"}) as fs:
        for i, t in enumerate(t_ir):
            # slow heating front plus a wiggle: smooth in time at the 5 Hz sampling
            frame = base.values + 2.0 * np.tanh((t - 0.5 * t_ir[-1]) / 60.0) * (1 + vv) + 0.3 * np.sin(0.7 * t) * uu
            fs.write(i, float(t), frame.astype(np.float32))
        fs.set_times(t_ir)
    dic = ex.dic()[["x"]].isel(time=[0])
    t_dic = t_ir[::2]
    x = np.repeat(dic["x"].values, t_dic.size, axis=0)  # the specimen held still
    ds = dic.isel(time=np.zeros(t_dic.size, int)).assign_coords(time=t_dic)
    ds["x"] = (ds["x"].dims, x, ds["x"].attrs)
    write_dataset(ds, root / "dic.zarr", stage="bench")
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    write_dataset(cal, root / "calibration.zarr", stage="bench")


_CHILD = r"""
import json, resource, sys, time
from irdic.chunks import chunk_path, n_chunks
from irdic.stages import couple, fields
from irdic.store import open_store
from irdic.threads import stage_threads
root, chunk_frames = sys.argv[1], int(sys.argv[2])
n = n_chunks(open_store(f"{root}/dic.zarr").sizes["time"], chunk_frames)
t0 = time.perf_counter()
with stage_threads(1):
    parts = [chunk_path(root, "points", i) for i in range(n)]
    for i, p in enumerate(parts):
        couple.run({"dic": f"{root}/dic.zarr", "ir": f"{root}/ir.zarr", "calibration": f"{root}/calibration.zarr"},
                   {"store": p}, chunk=(i, n))
    couple.run_gather({"chunks": parts}, {"store": f"{root}/points.zarr"})
    t1 = time.perf_counter()
    parts = [chunk_path(root, "fields", i) for i in range(n)]
    for i, p in enumerate(parts):
        fields.run({"points": f"{root}/points.zarr", "calibration": f"{root}/calibration.zarr"}, {"store": p},
                   chunk=(i, n))
    fields.run_gather({"chunks": parts}, {"store": f"{root}/fields.zarr"})
t2 = time.perf_counter()
print(json.dumps({"chunks": n, "couple_s": t1 - t0, "fields_s": t2 - t1,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, nargs="+", default=[500, 2000, 8000], help="IR frames of each record")
    ap.add_argument("--chunk-frames", type=int, default=100, help="DIC times per chunk (execution.chunk_frames)")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}; "
          f"IR {IR_RATE:g} Hz, DIC every 2nd frame, 273 points, chunk_frames {args.chunk_frames}")
    print(f"{'IR frames':>9} {'DIC times':>9} {'chunks':>6} {'ir.zarr MB':>10} {'couple s':>9} {'fields s':>9} "
          f"{'s/1000 fr':>9} {'peak RSS MB':>11}")
    for n in args.frames:
        root = Path(tempfile.mkdtemp(prefix="bench_chunks_"))
        try:
            _write_record(root, n)
            size = sum(f.stat().st_size for f in (root / "ir.zarr").rglob("*") if f.is_file()) / 2**20
            out = subprocess.run([sys.executable, "-c", _CHILD, str(root), str(args.chunk_frames)],
                                 capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            total = r["couple_s"] + r["fields_s"]
            print(f"{n:>9} {n // 2:>9} {r['chunks']:>6} {size:>10.1f} {r['couple_s']:>9.1f} {r['fields_s']:>9.1f} "
                  f"{1000 * total / n:>9.1f} {r['peak_rss_mb']:>11.0f}", flush=True)
        finally:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    start = time.perf_counter()
    main()
    print(f"total {time.perf_counter() - start:.0f} s")
