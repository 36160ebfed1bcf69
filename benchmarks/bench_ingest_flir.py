"""Benchmark of FLIR ``.seq`` ingest: throughput and memory versus record length.

Writes FLIR ``.seq`` records (uncompressed 16-bit counts, SC660 constants)
with :func:`irdic.synthetic.writers.write_flir`, then times on one thread:

- ``read``: :func:`irdic.io.flir.iter_flir_frames` alone (follow the FFF
  chain, parse each frame's camera info, counts to °C);
- ``ingest``: :func:`irdic.ingest.ir.ingest_ir` into ``ir.zarr``
  (headers pass, decode, checks, the store);
- ``fromfile``: the obvious way, ``numpy.fromfile`` of each frame's pixels at
  offsets known beforehand (no chain, no camera info) and the formula of
  :func:`irdic.io.flir_planck.counts_to_celsius` on every pixel, into one
  float32 array in memory.

MB/s are file bytes per wall second and per CPU second of the process
(``time.process_time``, kernel time included: the figure that stays
meaningful on a shared machine); the peak is that of Python-allocated memory
(tracemalloc, a run of its own). Streaming keeps the peak of ``read`` and
``ingest`` flat in the number of frames; ``fromfile`` holds the whole record.
``--store-dir`` puts ``ir.zarr`` elsewhere (``/dev/shm``: the ingest without
the file system's cost of writing the chunk files).

Usage::

    python benchmarks/bench_ingest_flir.py [--width 640 --height 480 --frames 100 1000]
    python benchmarks/bench_ingest_flir.py --quick   # 320 x 240, 50 and 200 frames
    python benchmarks/bench_ingest_flir.py --frames 1000 --store-dir /dev/shm
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from irdic.io.flir import iter_flir_frames, iter_flir_headers
from irdic.io.flir_planck import counts_to_celsius
from irdic.ingest.ir import ingest_ir
from irdic.parameters import schema_defaults
from irdic.synthetic.writers import write_flir
from irdic.threads import stage_threads

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_ingest import measure  # noqa: E402  (best wall and CPU time, then the tracemalloc peak)


def write_record(path: Path, n: int, width: int, height: int) -> int:
    rng = np.random.default_rng(0)
    v, u = np.mgrid[:height, :width]
    base = 22.0 + 0.01 * u + 0.02 * v

    def frames():
        for k in range(n):
            yield base + 0.01 * k + rng.normal(0, 0.05, base.shape)

    write_flir(path, frames(), times=[1.7e9 + k / 50.0 for k in range(n)])
    return path.stat().st_size


def read_all(path: Path) -> None:
    with stage_threads(1):
        for _meta, _frame in iter_flir_frames(path):
            pass


def ingest(path: Path, out: Path) -> None:
    with stage_threads(1), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ingest_ir(path, out)


def fromfile(path: Path, offsets: list[int], width: int, height: int, params: dict) -> np.ndarray:
    out = np.empty((len(offsets), height, width), np.float32)
    for k, off in enumerate(offsets):
        counts = np.fromfile(path, "<u2", count=width * height, offset=off)
        out[k] = counts_to_celsius(counts, params).reshape(height, width)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--frames", type=int, nargs="+", default=[100, 1000])
    ap.add_argument("--repeats", type=int, default=3, help="timed runs of each (the best counts)")
    ap.add_argument("--store-dir", type=Path, default=None, help="folder of the ir.zarr written (default: "
                    "the temporary folder of the .seq files)")
    ap.add_argument("--quick", action="store_true", help="320 x 240 px, 50 and 200 frames, one repeat")
    args = ap.parse_args()
    if args.quick:
        args.width, args.height, args.frames, args.repeats = 320, 240, [50, 200], 1
    print(f"machine: {platform.machine()} {platform.processor() or ''}, python {platform.python_version()}")
    print(f"frame {args.width} x {args.height} px, uncompressed .seq; load average {os.getloadavg()[0]:.1f} "
          f"on {os.cpu_count()} cores")
    schema_defaults("ir_source")  # the configuration schema is parsed once per process: not part of any row
    root = Path(tempfile.mkdtemp(prefix="bench_ingest_flir_"))
    stores = Path(tempfile.mkdtemp(prefix="bench_ingest_flir_", dir=args.store_dir)) if args.store_dir else root
    print(f"ir.zarr written under {stores}")
    print(f"{'frames':>6} {'MB':>6} | {'read MB/s':>9} {'/cpu':>6} {'peak MiB':>8} | {'ingest MB/s':>11} {'/cpu':>6} "
          f"{'peak MiB':>8} | {'fromfile MB/s':>13} {'/cpu':>6} {'peak MiB':>8}")
    try:
        for n in args.frames:
            src = root / f"r{n}.seq"
            mb = write_record(src, n, args.width, args.height) / 1e6
            heads = list(iter_flir_headers(src))
            offsets = [h["offset"] + 64 + 2 * 32 + (128 if k == 0 else 0) + 2476 + 32 for k, h in enumerate(heads)]
            params = heads[0]["params"]
            rows = []
            for fn in (lambda: read_all(src), lambda: ingest(src, stores / f"ir{n}.zarr"),
                       lambda: fromfile(src, offsets, args.width, args.height, params)):
                wall, cpu, peak = measure(fn, args.repeats)
                rows.append(f"{mb / wall:>9.0f} {mb / cpu:>6.0f} {peak:>8.1f}")
                shutil.rmtree(stores / f"ir{n}.zarr", ignore_errors=True)
            print(f"{n:>6} {mb:>6.0f} | {rows[0]} | {rows[1]:>22} | {rows[2]:>24}")
            src.unlink()
    finally:
        shutil.rmtree(root, ignore_errors=True)
        shutil.rmtree(stores, ignore_errors=True)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
