"""Benchmark of the ingest stage: throughput and memory versus series length.

Writes synthetic IRBIS text series (crop exports) of two lengths, ingests
them with :func:`irdic.ingest.ir.ingest_ir` on one thread, and reports wall time, MB/s of text
per wall second and per CPU second (``time.process_time``, all threads of the process: the
figure that stays meaningful on a shared machine) and the peak of Python-allocated memory (tracemalloc): the peak must not grow
with the number of frames, because frames are streamed into the store. In
the same run, the obvious approach (read every frame with ``numpy.loadtxt``
into one array, then ``xarray.Dataset.to_zarr``) is timed for comparison.

Usage::

    python benchmarks/bench_ingest.py [--width 360 --height 260 --frames 40 160]
"""

from __future__ import annotations

import argparse
import os
import warnings
import platform
import shutil
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import xarray as xr

from irdic.ingest.ir import ingest_ir
from irdic.threads import stage_threads
from irdic.synthetic.writers import write_irbis


def write_series(folder: Path, n: int, width: int, height: int) -> int:
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    v, u = np.mgrid[:height, :width]
    base = 22.0 + 0.01 * u + 0.02 * v
    for k in range(n):
        write_irbis(folder / f"f_{k:05d}.txt", base + 0.1 * k + rng.normal(0, 0.05, base.shape),
                    ms=1000.0 + 250.0 * k, frame_index=k, start_pos=(300, 200), sensor_size=(1024, 768))
    return sum(f.stat().st_size for f in folder.iterdir())


def measure(fn, repeats: int = 3):
    """Wall and CPU time of a plain run (best of ``repeats`` each), then the tracemalloc peak of another run
    (tracemalloc slows allocation-heavy code several fold, so it is not timed)."""
    walls, cpus = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return min(walls), min(cpus), peak / 2**20


def ingest_one_thread(src: Path, out: Path) -> None:
    with stage_threads(1):
        ingest_ir(src, out)


def naive(folder: Path, out: Path) -> None:
    frames = []
    for f in sorted(folder.iterdir()):
        lines = f.read_text(encoding="cp1252").splitlines()
        start = lines.index("[Data]") + 1
        frames.append(np.loadtxt(lines[start:], delimiter="\t", dtype=np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xr.Dataset({"temperature": (("time", "v", "u"), np.stack(frames))}).to_zarr(out, mode="w")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=360)
    ap.add_argument("--height", type=int, default=260)
    ap.add_argument("--frames", type=int, nargs="+", default=[40, 160])
    args = ap.parse_args()
    print(f"machine: {platform.machine()} {platform.processor() or ''}, python {platform.python_version()}")
    print(f"frame {args.width} x {args.height} px (IRBIS text, TAB, 2 decimals); load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"{'frames':>7} {'MB text':>8} {'irdic s':>8} {'MB/s':>6} {'cpu s':>6} {'MB/s/core':>9} {'peak MiB':>9} | "
          f"{'loadtxt s':>9} {'MB/s':>6} {'cpu s':>6} {'MB/s/core':>9} {'peak MiB':>9}")
    root = Path(tempfile.mkdtemp(prefix="bench_ingest_"))
    try:
        for n in args.frames:
            src = root / f"s{n}"
            size = write_series(src, n, args.width, args.height) / 1e6
            dt, cpu, peak = measure(lambda: ingest_one_thread(src, root / f"ir{n}.zarr"))
            dt2, cpu2, peak2 = measure(lambda: naive(src, root / f"naive{n}.zarr"))
            print(f"{n:>7} {size:>8.1f} {dt:>8.2f} {size / dt:>6.0f} {cpu:>6.2f} {size / cpu:>9.0f} {peak:>9.1f} | "
                  f"{dt2:>9.2f} {size / dt2:>6.0f} {cpu2:>6.2f} {size / cpu2:>9.0f} {peak2:>9.1f}")
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
