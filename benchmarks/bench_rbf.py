"""Benchmark of irdic.image_rbf at the paper's scale, against the obvious scipy approach.

Scene: a 1024 x 768 IR frame series in which an elliptical specimen region
(semi-axes 150 x 100 px, ~47k masked px) carries a drifting, growing hot spot
plus 0.05 K noise; 10,000 material points move slowly (tension-torsion-like
stretch and shear, ~2 px over the series). At every frame time ``evaluate_series``
returns Theta, dTheta/du, dTheta/dv and dTheta/dt at all points.

Reported:

1. total time and peak memory of ``evaluate_series`` at full size;
2. the obvious scipy approach, ``RBFInterpolator(kernel="inverse_multiquadric",
   epsilon=0.5, degree=1, neighbors=50)`` (the same IMQ as c = 2) per frame,
   derivatives by central differences (h = 0.01 px), timed on a few frames and
   extrapolated (it is given the same combined fields G_k, G'_k);
3. how the cost grows with frames and with points (two sizes each);
4. the cost of a mask that changes from frame to frame;
5. accuracy of both (and of bilinear / cubic) against the exact global
   interpolant on a smaller ellipse, by distance to the mask edge.

Usage: ``python benchmarks/bench_rbf.py [--frames 500] [--points 10000] [--threads 1]``
(``--quick`` for a smoke run). Prints tables; takes a few minutes at full size.
"""

from __future__ import annotations

import argparse
import os
import sys


def parse():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--frames", type=int, default=500, help="frames (and evaluation times)")
    p.add_argument("--points", type=int, default=10000, help="material points per time")
    p.add_argument("--width", type=int, default=1024)
    p.add_argument("--height", type=int, default=768)
    p.add_argument("--axes", type=float, nargs=2, default=(150.0, 100.0), help="ellipse semi-axes, px")
    p.add_argument("--scipy-frames", type=int, default=3, help="frames timed for the scipy approach")
    p.add_argument("--threads", type=int, default=None, help="BLAS threads (OPENBLAS_NUM_THREADS etc.)")
    p.add_argument("--no-scaling", action="store_true", help="skip the scaling runs")
    p.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
    return p.parse_args()


ARGS = parse() if __name__ == "__main__" else None
if ARGS is not None and ARGS.threads:
    # must be set before numpy loads BLAS
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(ARGS.threads)

import resource  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy.interpolate import RBFInterpolator  # noqa: E402

from irdic.image_rbf import (  # noqa: E402
    MaskedGridInterpolant,
    evaluate_series,
    exact_global_interpolant,
)
from irdic.numerics.temporal import TemporalInterpolant  # noqa: E402


def rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def scene(n_frames, n_points, H, W, a, b, seed=0, dt=0.5):
    """Frames (n, H, W) float32, times, mask, points (n, M, 2), analytic field."""
    rng = np.random.default_rng(seed)
    uc, vc = W / 2.0, H / 2.0
    V, U = np.mgrid[0:H, 0:W]
    mask = ((U - uc) / a) ** 2 + ((V - vc) / b) ** 2 <= 1.0
    t = np.arange(n_frames) * dt
    T = max(t[-1], dt)

    def field(u, v, tk):
        s = tk / T
        hot = 12.0 * s * np.exp(-((u - uc + 0.3 * a - 0.4 * a * s) ** 2 + (v - vc) ** 2) / (2 * (0.3 * a) ** 2))
        return 20.0 + 0.02 * tk + 0.01 * (u - uc) + hot

    frames = np.full((n_frames, H, W), 20.0, np.float32)
    v0, v1 = int(vc - b) - 2, int(vc + b) + 3
    u0, u1 = int(uc - a) - 2, int(uc + a) + 3
    Us, Vs = U[v0:v1, u0:u1], V[v0:v1, u0:u1]
    for k in range(n_frames):
        frames[k, v0:v1, u0:u1] = field(Us, Vs, t[k]) + rng.normal(0, 0.05, Us.shape)
    r = np.sqrt(rng.uniform(0, 1, n_points)) * 0.98
    ph = rng.uniform(0, 2 * np.pi, n_points)
    du, dv = a * r * np.cos(ph), b * r * np.sin(ph)
    s = (t / T)[:, None]
    pts = np.stack([uc + du + 0.01 * dv * s, vc + dv * (1 + 0.02 * s)], axis=-1)
    return frames, t, mask, pts, field


def time_series(n_frames, n_points, args, **kw):
    frames, t, mask, pts, _ = scene(n_frames, n_points, args.height, args.width, *args.axes)
    rss0 = rss_mb()
    t0, c0 = time.perf_counter(), time.process_time()
    res = evaluate_series(frames, t, t, pts, mask, **kw)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return (wall, cpu), rss0, rss_mb(), res, frames, t, mask, pts


def scipy_per_frame(frames, t, mask, pts, n_timed):
    """Obvious approach: one RBFInterpolator per field and time; FD derivatives."""
    vv, uu = np.nonzero(mask)
    xy = np.c_[uu, vv].astype(float)
    ti = TemporalInterpolant(t)
    F = frames[:, vv, uu].astype(float)
    h = 0.01
    out = []
    t0 = time.perf_counter()
    for k in range(n_timed):
        G = F[k]  # eval time = frame time: the frame itself
        Gd = ti.weights(t[k:k + 1], 1)[0] @ F
        p = pts[k]
        ig = RBFInterpolator(xy, G, kernel="inverse_multiquadric", epsilon=0.5, degree=1, neighbors=50)
        val = ig(p)
        gu = (ig(p + [h, 0]) - ig(p - [h, 0])) / (2 * h)
        gv = (ig(p + [0, h]) - ig(p - [0, h])) / (2 * h)
        rate = RBFInterpolator(xy, Gd, kernel="inverse_multiquadric", epsilon=0.5, degree=1, neighbors=50)(p)
        out.append((val, gu, gv, rate))
    return (time.perf_counter() - t0) / n_timed, out


def accuracy_table(args):
    """Errors against the exact global interpolant on a smaller ellipse."""
    a, b = (25.0, 17.0) if args.quick else (50.0, 34.0)
    H, W = int(2 * b + 40), int(2 * a + 40)
    rng = np.random.default_rng(5)
    frames, t, mask, pts, field = scene(3, 4000, H, W, a, b, seed=5)
    V, U = np.mgrid[0:H, 0:W]
    noisy = frames[2].astype(float)
    clean = field(U, V, t[2])
    p = pts[2] + rng.uniform(-0.5, 0.5, pts[2].shape)
    vv, uu = np.nonzero(mask)
    rows = []
    for label, data in (("noisy (0.05 K)", noisy), ("noise-free", clean)):
        t0 = time.perf_counter()
        ex = exact_global_interpolant(mask, data, p, max_pixels=20000)
        t_ex = time.perf_counter() - t0
        truth = field(p[:, 0], p[:, 1], t[2])
        ok = np.isfinite(ex.value)
        d = ex.edge_distance
        res = {"exact global": (ex.value, ex.du, ex.dv)}
        for m in ("rbf", "bilinear", "cubic"):
            r = MaskedGridInterpolant(mask, method=m).fit(data).evaluate(p)
            res[m] = (r.value, r.du, r.dv)
        sp = RBFInterpolator(np.c_[uu, vv].astype(float), data[vv, uu], kernel="inverse_multiquadric",
                             epsilon=0.5, degree=1, neighbors=50)
        h = 0.01
        res["scipy nb=50"] = (sp(p), (sp(p + [h, 0]) - sp(p - [h, 0])) / (2 * h),
                              (sp(p + [0, h]) - sp(p - [0, h])) / (2 * h))
        rows.append((label, mask.sum(), t_ex, ok, d, ex, truth, res))
    return rows


def band_stats(err, d, edges=(0, 0.5, 2, 5, 12, np.inf)):
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        s = (d >= lo) & (d < hi)
        out.append((lo, hi, int(s.sum()), float(np.nanmax(err[s])) if s.any() else np.nan))
    return out


def main(args):
    if args.quick:
        args.frames, args.points, args.scipy_frames = 40, 2000, 1
    print(f"irdic.image_rbf benchmark: {args.frames} frames, {args.points} points, frame {args.width} x "
          f"{args.height}, ellipse {args.axes[0]:g} x {args.axes[1]:g} px, BLAS threads "
          f"{os.environ.get('OPENBLAS_NUM_THREADS', 'default')}, CPUs {os.cpu_count()}")

    (wall, cpu), rss0, rss1, res, frames, t, mask, pts = time_series(args.frames, args.points, args)
    n_ok = int(np.isfinite(res.theta).sum())
    print("\n1. evaluate_series (method='rbf'), full size")
    print(f"   masked px {int(mask.sum())}, (time, point) pairs {res.theta.size}, finite {n_ok}")
    print(f"   wall time {wall:8.2f} s   ({wall / args.frames * 1e3:.1f} ms per time); process CPU "
          f"time {cpu:.2f} s (other load on the machine inflates wall time)")
    print(f"   frames array {frames.nbytes / 2**20:8.0f} MiB; peak RSS before call {rss0:8.0f} MiB, "
          f"after {rss1:8.0f} MiB (process, frames included)")

    print("\n2. scipy RBFInterpolator(IMQ eps=0.5, degree=1, neighbors=50) per frame, FD derivatives")
    c0 = time.process_time()
    per, sp = scipy_per_frame(frames, t, mask, pts, args.scipy_frames)
    per_cpu = (time.process_time() - c0) / args.scipy_frames
    full = per * args.frames
    print(f"   {per:8.2f} s per time (mean of {args.scipy_frames}; CPU {per_cpu:.2f} s), extrapolated to "
          f"{args.frames} times: {full:8.1f} s  -> irdic.image_rbf is {full / wall:5.1f} x faster "
          f"(CPU: {per_cpu * args.frames / cpu:5.1f} x)")
    for k, (val, gu, gv, rate) in enumerate(sp):
        ok = np.isfinite(res.theta[k])
        d = np.abs(val[ok] - res.theta[k][ok])
        print(f"   frame {k}: |scipy - irdic| max theta {d.max():.2e} K, du "
              f"{np.abs(gu[ok] - res.dtheta_du[k][ok]).max():.2e} K/px, rate "
              f"{np.abs(rate[ok] - res.dtheta_dt[k][ok]).max():.2e} K/s")
    del frames, res

    if not args.no_scaling:
        print("\n3. scaling (same scene, fewer frames or points)")
        print(f"   {'frames':>7s} {'points':>7s} {'wall s':>8s} {'CPU s':>8s} {'CPU ms/time':>12s}")
        print(f"   {args.frames:7d} {args.points:7d} {wall:8.2f} {cpu:8.2f} {cpu / args.frames * 1e3:12.1f}")
        F4, F2 = max(2, args.frames // 4), max(2, args.frames // 2)
        for nf, npts in ((F2, args.points), (F4, args.points), (F4, args.points // 2)):
            w, c = time_series(nf, npts, args)[0]
            print(f"   {nf:7d} {npts:7d} {w:8.2f} {c:8.2f} {c / nf * 1e3:12.1f}")

    print("\n4. moving mask: the lower half of the ellipse edge creeps down 0.1 px per frame")
    nf = min(args.frames, 40)
    frames, t, mask, pts, _ = scene(nf, args.points, args.height, args.width, *args.axes)
    V, U = np.mgrid[0:args.height, 0:args.width]
    a, b = args.axes
    uc, vc = args.width / 2.0, args.height / 2.0
    masks = np.empty((nf,) + mask.shape, bool)
    for k in range(nf):
        bk = np.where(V > vc, b + 0.1 * k, b)
        masks[k] = ((U - uc) / a) ** 2 + ((V - vc) / bk) ** 2 <= 1.0
    n_changes = int(sum(not np.array_equal(masks[k], masks[k - 1]) for k in range(1, nf)))
    c0 = time.process_time()
    evaluate_series(frames, t, t, pts, mask)
    c_fixed = time.process_time() - c0
    c0 = time.process_time()
    evaluate_series(frames, t, t, pts, masks)
    c_moving = time.process_time() - c0
    print(f"   {nf} frames, CPU time: fixed mask {c_fixed:.2f} s, moving mask ({n_changes} changes) "
          f"{c_moving:.2f} s -> {(c_moving - c_fixed) / max(n_changes, 1):.2f} s per change")
    del frames, masks

    print("\n5. accuracy against the exact global interpolant (dense solve), smaller ellipse")
    for label, n_mask, t_ex, ok, d, ex, truth, res in accuracy_table(args):
        print(f"   field {label}, {n_mask} masked px (exact solve {t_ex:.1f} s); max |error| per "
              "edge-distance band [px]")
        edges = (0, 0.5, 2, 5, 12, np.inf)
        head = "".join(f"{f'[{lo:g},{hi:g})':>11s}" for lo, hi in zip(edges[:-1], edges[1:]))
        print(f"   {'method':<14s}{'quantity':<10s}{head}")
        for name, (val, gu, gv) in res.items():
            refs = [("vs exact", val, ex.value), ("du exact", gu, ex.du)] if name != "exact global" else []
            refs.append(("vs truth", val, truth))
            for qty, x, y in refs:
                st = band_stats(np.abs(x - y)[ok], d[ok], edges)
                print(f"   {name:<14s}{qty:<10s}" + "".join(f"{m:11.1e}" for _, _, _, m in st))
        counts = band_stats(np.zeros(ok.sum()), d[ok], edges)
        print(f"   {'points':<24s}" + "".join(f"{c:11d}" for _, _, c, _ in counts))
    return 0


if __name__ == "__main__":
    sys.exit(main(ARGS))
