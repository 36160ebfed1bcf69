"""Throughput of the IR readers, compared with the obvious alternatives.

Prints three tables:

1. IRBIS text: MB/s of irdic's parser on the real sample files next to
   ``numpy.loadtxt``, ``pandas.read_csv`` (C engine) and ``numpy.fromstring``
   on the same data section (bytes already in memory; best and median of
   ``--repeat`` runs, single thread).
2. ``.irb``: MB/s of :func:`irdic.io.irb.read_irb` on the samples and on a
   synthetic 1024 x 768 x ``--frames`` sequence written with
   :func:`~irdic.synthetic.writers.write_irb`, next to reading the same file's bytes
   (``open().read()`` in 16 MiB pieces; the file is in the page cache, so
   this is the memory-copy ceiling, not the disk).
3. Peak Python-heap memory (tracemalloc) of iterating a short and a long
   sequence with :func:`~irdic.io.irb.iter_irb_frames`: it must not grow
   with the sequence length.

Usage::

    python benchmarks/bench_ingest_ir.py [--repeat 20] [--frames 100]
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import sys
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from irdic.io.irb import count_irb_frames, iter_irb_frames, read_irb  # noqa: E402
from irdic.synthetic.writers import write_irb  # noqa: E402
from irdic.io.irbis import parse_irbis, read_irbis  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def timed(fn, repeat: int) -> tuple[float, float]:
    """Best and median wall time (s) of ``repeat`` calls after one warm-up call."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), statistics.median(times)


def data_section(raw: bytes) -> bytes:
    i = raw.index(b"[Data]")
    return raw[raw.index(b"\n", i) + 1:]


def bench_irbis(sample_dir: Path, repeat: int) -> list[tuple]:
    rows = []
    for path in sorted((sample_dir / "irbis-text").glob("*.txt")):
        raw = path.read_bytes()
        data = data_section(raw)
        mb = len(raw) / 1e6
        ref = np.loadtxt(io.BytesIO(data))
        _, mine = parse_irbis(raw, path)
        assert np.array_equal(mine, ref), "irdic and numpy disagree"

        def np_fromstring():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                return np.fromstring(data, dtype=np.float64, sep=" ")

        cases = [
            ("irdic read_irbis (file -> DataArray)", lambda: read_irbis(path)),
            ("irdic parse_irbis (bytes)", lambda: parse_irbis(raw, path)),
            ("numpy.loadtxt (data section)", lambda: np.loadtxt(io.BytesIO(data))),
            ("pandas.read_csv C engine (data section)",
             lambda: pd.read_csv(io.BytesIO(data), sep="\t", header=None, engine="c").to_numpy()),
            ("numpy.fromstring sep=' ' (data section)", np_fromstring),
        ]
        for name, fn in cases:
            best, med = timed(fn, repeat)
            rows.append((path.name, name, mb / best, mb / med, best * 1e3))
    return rows


def raw_read(path: Path) -> int:
    n = 0
    with open(path, "rb", buffering=0) as fh:
        while chunk := fh.read(16 << 20):
            n += len(chunk)
    return n


def iterate(path: Path) -> int:
    n = 0
    for _, frame in iter_irb_frames(path):
        n += frame.size
    return n


def bench_irb(sample_dir: Path, workdir: Path, frames: int, width: int, height: int, repeat: int) -> list[tuple]:
    rows = []
    for path in sorted((sample_dir / "irb").glob("*.irb")):
        mb = path.stat().st_size / 1e6
        best, med = timed(lambda: read_irb(path), repeat)
        rows.append((path.name, "read_irb", mb / best, mb / med, best * 1e3))
    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:height, 0:width]
    base = 20 + 10 * np.exp(-((u - width / 2) ** 2 + (v - height / 2) ** 2) / (2 * 150.0 ** 2))
    seq = workdir / f"synthetic_{width}x{height}x{frames}.irb"
    t0 = time.perf_counter()
    stack = np.empty((frames, height, width), np.float32)
    for k in range(frames):
        stack[k] = base + 0.05 * k + 0.05 * rng.standard_normal(base.shape)
    write_irb(seq, stack, np.arange(frames) * 0.5)
    t_write = time.perf_counter() - t0
    del stack
    mb = seq.stat().st_size / 1e6
    reps = max(3, repeat // 5)
    for name, fn in [("raw read of the bytes (page cache)", lambda: raw_read(seq)),
                     ("count_irb_frames (directory only)", lambda: count_irb_frames(seq)),
                     ("iter_irb_frames (stream)", lambda: iterate(seq)),
                     ("read_irb (whole stack)", lambda: read_irb(seq))]:
        best, med = timed(fn, reps)
        rows.append((seq.name, name, mb / best, mb / med, best * 1e3))
    rows.append((seq.name, f"write_irb ({mb:.0f} MB, once)", mb / t_write, mb / t_write, t_write * 1e3))
    return rows


def bench_memory(workdir: Path, width: int, height: int) -> list[tuple]:
    frame = np.linspace(15, 35, width * height, dtype=np.float32).reshape(height, width)
    rows = []
    for n in (5, 50):
        path = workdir / f"mem_{n}.irb"
        write_irb(path, np.broadcast_to(frame, (n, height, width)))
        tracemalloc.start()
        count = iterate(path)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        rows.append((n, count // (width * height), peak / 2**20, path.stat().st_size / 2**20))
        path.unlink()
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=Path, default=ROOT.parent / "shared" / "samples",
                    help="folder of the real sample files (default: ../shared/samples)")
    ap.add_argument("--repeat", type=int, default=20, help="timed repetitions per case (default 20)")
    ap.add_argument("--frames", type=int, default=100, help="frames of the synthetic sequence (default 100)")
    ap.add_argument("--width", type=int, default=1024)
    ap.add_argument("--height", type=int, default=768)
    ap.add_argument("--workdir", type=Path, default=None, help="where the synthetic .irb goes (default: a temp dir)")
    args = ap.parse_args(argv)
    if not args.samples.is_dir():
        print(f"sample folder {args.samples} not found", file=sys.stderr)
        return 2
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, pandas {pd.__version__}, "
          f"{os.cpu_count()} CPU(s), single-threaded\n")

    print("1. IRBIS text export: parse throughput (MB of file per s)")
    print(f"{'file':18s} {'method':42s} {'best MB/s':>10s} {'median':>8s} {'best ms':>8s}")
    for r in bench_irbis(args.samples, args.repeat):
        print(f"{r[0]:18s} {r[1]:42s} {r[2]:10.1f} {r[3]:8.1f} {r[4]:8.2f}")

    with tempfile.TemporaryDirectory(dir=args.workdir) as tmp:
        work = Path(tmp)
        print("\n2. .irb: read throughput (MB of file per s)")
        print(f"{'file':30s} {'method':36s} {'best MB/s':>10s} {'median':>8s} {'best ms':>9s}")
        for r in bench_irb(args.samples, work, args.frames, args.width, args.height, args.repeat):
            print(f"{r[0]:30s} {r[1]:36s} {r[2]:10.1f} {r[3]:8.1f} {r[4]:9.1f}")
        print(f"\n3. peak traced memory while streaming {args.width} x {args.height} frames")
        print(f"{'frames':>7s} {'seen':>6s} {'peak MiB':>9s} {'file MiB':>9s}")
        for r in bench_memory(work, args.width, args.height):
            print(f"{r[0]:7d} {r[1]:6d} {r[2]:9.2f} {r[3]:9.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
