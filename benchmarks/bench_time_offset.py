"""Benchmark of ``time_offset: auto``: accuracy against known offsets over a family of moving scenes, and cost.

Members (tests/_clock_scenes.py ``FAMILY``; irdic.synthetic tubes under
tension-torsion), each with realistic exports (0.05 K NETD, 2 decimals,
mixed edge pixels, 0.003 mm DIC noise) and noise-free ones:

- ``weak-tiny``, ``weak-demo``: the default tube (a weak pattern: 4 % around
  the tube, 4 K of heating), tiny (12 frames at 2 Hz, DIC 1 Hz) and demo (41
  frames at 4 Hz, DIC 2 Hz); ``weak-demo-same-rate``: IR at the DIC rate;
- ``strong-demo``: 40 % around the tube, 6 K; ``stretch-only``,
  ``twist-only``: one load each; ``fast-load``: the loading in 2 s instead of
  5; ``slow-small``: half the stretch, 10 deg of twist over 9 s, 2 K;
- ``moving``: the moving tube of bench_couple_moving.py, IR and DIC at 10 Hz,
  ``--frames`` frames and ``--points`` points (cost at a larger size);
- ``scene:NAME`` and ``scene:SEED``: a member of the noisy fields' scene
  family (:mod:`irdic.synthetic.family`, demo scale): the fixed members by
  name (plates, a sphere cap, a barrel, cylinders; static, stretched,
  twisted; smooth, edge, band and spot patterns) or one drawn from a seed
  (a row's seed is added to the member's noise seed: seed 0 is the noise
  of bench_noisy_fields.py; ``--same-rate``: only the IR frames at the DIC
  times, whose IR runs at twice the DIC rate). Their realistic exports are the
  family's own (its member's IR noise, decimals and DIC noise);
  ``--scene-family`` puts every fixed member and the members drawn from
  seeds 101-404 and 505-1006 in place of ``--members``.

For each member, offset (IR frame periods) and seed the IR clock is put
that far behind the DIC clock and the offset estimated
(:func:`irdic.timing.clock.ir_clock`): one row per estimate (error and
stated standard uncertainty in frame periods, their ratio, seconds), then
per member and over all the worst error, the share within 3 std and the
RMS of error/std. With ``--couple`` the couple stage runs per member with
``auto`` (the first offset, first seed) and with the true offset: the
estimate's share of couple (the couple stage runs the estimate also to
check a configured offset; ``--repeat`` timings each, interleaved, the
fastest kept), and the point temperatures' RMS error against the truth
with each. With ``--monte-carlo N`` each member's realistic
export is drawn with N noise seeds (the offsets taken in turn): the scatter
of the errors against the stated std and against the Cramér-Rao bound of
the rank-one model with a free pattern (:func:`cramer_rao`: every pixel of
the DIC patch, every frame, the analytic temperature and motion).

Usage (repository root, one BLAS thread on a shared machine)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_time_offset.py [--members weak-tiny strong-demo ...]
        [--offsets -4 -1.7 -0.3 0.3 1.7 4] [--seeds 2] [--exports realistic clean] [--couple]
        [--monte-carlo 24] [--repeat 3] [--frames 100] [--points 4000]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_time_offset.py --scene-family --seeds 1 --offsets -3.4 -0.6 0.3 1.7
        [--same-rate]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings
import zlib
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import _tube  # noqa: E402

from irdic.camera import CameraModel  # noqa: E402
from irdic.coupling import couple  # noqa: E402
from irdic.errors import IrdicError, IrdicWarning  # noqa: E402
from irdic.synthetic import family  # noqa: E402
from irdic.synthetic.render import realistic_stack  # noqa: E402
from irdic.timing.clock import ir_clock  # noqa: E402
from tests._clock_scenes import DECIMALS, DIC_NOISE, FAMILY, IR_NOISE, at_dic_times, family_scene  # noqa: E402


def moving_scene(realistic: bool, seed: int, frames: int, points: int, offset_frames: float):
    n_x = max(3, int(round(np.sqrt(points * 78 / 168))))
    ex = _tube.tube(frames, (n_x, max(3, int(round(points / n_x)))), ir_noise=IR_NOISE,
                    dic_noise=DIC_NOISE if realistic else 0.0)
    rng = np.random.default_rng([seed, 30])
    fr = realistic_stack(ex.renderer, ex.ir_times, rng, noise=IR_NOISE if realistic else 0.0,
                         decimals=DECIMALS if realistic else None, mixed_edges=realistic)
    r = ex.renderer
    period = float(np.median(np.diff(ex.ir_times)))
    offset = offset_frames * period
    ir = xr.Dataset({"temperature": (("time", "v", "u"), fr)},
                    coords={"time": ex.ir_times - offset, "v": r.v.astype(np.int64), "u": r.u.astype(np.int64)},
                    attrs={"time_offset": "auto"})
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    return ex.dic()[["x"]], ir, cal, ex, offset, period


_RENDERED: dict = {}


#: the drawn members of ``--scene-family`` (the noisy fields benchmark's seeds and the eleven unseen ones)
SCENE_SEEDS = (101, 202, 303, 404, 505, 606, 707, 808, 919, 1001, 1002, 1003, 1004, 1005, 1006)


def family_member(name: str, realistic: bool, seed: int, same_rate: bool = False):
    """``scene:NAME`` / ``scene:SEED`` (:mod:`irdic.synthetic.family`) as :func:`family_scene` returns a member;
    ``same_rate``: only the IR frames at the DIC times (the family's IR runs at twice the DIC rate)."""
    key = name.split(":", 1)[1]
    sc = family.draw(int(key), noise_seed=int(key) + seed) if key.isdigit() else family.member(key, noise_seed=seed)
    dic, ir, cal = sc.inputs(0.0, realistic=realistic)
    if same_rate:
        ir = ir.isel(time=at_dic_times(ir["time"].values, sc.dic_times))
    return dic, ir, cal, sc, None, float(np.median(np.diff(ir["time"].values)))


def refusal(message: str) -> str:
    """The reason of a refusal in a few words (the checks of :mod:`irdic.timing.checks` and
    :mod:`irdic.timing.offset`)."""
    for words, reason in (("a static specimen carries", "no motion"),
                          ("changes its shape on the material (heat", "pattern changes shape (models disagree)"),
                          ("each frame misfits", "frames misfit the model"),
                          ("the offset shows where", "too little information"),
                          ("end of the searched range", "minimum at the range's end"),
                          ("do not single out", "no single minimum"),
                          ("do not follow the DIC motion", "frames do not follow the motion"),
                          ("redrawn", "unstable under redrawn noise"),
                          ("fit the frames equally well", "two offsets fit equally well")):
        if words in message:
            return reason
    return message[:80]


def scene(member, offset_frames, realistic, seed, args):
    """The member rendered once per (exports, seed), its IR clock ``offset_frames`` periods behind."""
    key = (member, realistic, seed)
    if key not in _RENDERED:
        _RENDERED.clear()
        _RENDERED[key] = (moving_scene(realistic, seed, args.frames, args.points, 0.0) if member == "moving"
                          else family_member(member, realistic, seed, args.same_rate) if member.startswith("scene:")
                          else family_scene(member, 0.0, realistic=realistic, seed=seed))
    dic, ir, cal, ex, _, period = _RENDERED[key]
    offset = offset_frames * period
    return dic, ir.assign_coords(time=ir["time"].values - offset), cal, ex, offset, period


def rms(points, ex) -> float:
    tr = ex.truth().sel(point=points.point)
    ok = points.visible.values & np.isfinite(tr.temperature.values)
    return float(np.sqrt(np.mean((points.temperature.values - tr.temperature.values)[ok] ** 2)))


def summary(label, rows, refused):
    if not rows:
        print(f"{label}: no estimate, {refused} refused", flush=True)
        return
    e = np.array(rows)
    z = e[:, 0] / e[:, 1]
    print(f"{label}: {len(rows)} estimates, {refused} refused, max |error| {np.abs(e[:, 0]).max():.3f} frames, "
          f"std {e[:, 1].min():.3f}-{e[:, 1].max():.3f}, within 3 std {np.sum(np.abs(z) <= 3)}/{len(z)}, "
          f"RMS error/std {np.sqrt(np.mean(z ** 2)):.2f}, estimate {e[:, 2].mean():.2f} s", flush=True)


def cramer_rao(ex, times, sigma: float = IR_NOISE) -> float:
    """The Cramér-Rao bound (IR frame periods) of the offset from frames at ``times`` with white pixel noise
    ``sigma`` (K), under the rank-one model with a free pattern (a level and an amplitude per frame).

    The information is ``sum w Z^2 / sigma^2`` over a fine grid of the DIC patch (``w`` its pixels per grid
    point) and the frames, ``Z`` the temperature's rate at the fixed pixel due to the motion (the material
    coordinates' rate there times the material gradient) with every direction the model absorbs projected out:
    per frame a level and the pattern's amplitude, per material point any pattern times the amplitudes.
    """
    spec, cam = ex.specimen, ex.camera
    t = np.asarray(times, float)
    s0, s1, h0, h1 = ex.patch
    S, H = (a.ravel() for a in np.meshgrid(np.linspace(s0, s1, 80), np.linspace(h0, h1, 140), indexing="ij"))

    def image(s, h, tt):
        return cam.project(spec.position(s[None], h[None], tt[:, None]).reshape(-1, 3)).reshape(tt.size, -1, 2)

    e, dt = 1e-3, 1e-4
    Js = (image(S + e, H, t) - image(S - e, H, t)) / (2 * e)
    Jh = (image(S, H + e, t) - image(S, H - e, t)) / (2 * e)
    W = (image(S, H, t + dt) - image(S, H, t - dt)) / (2 * dt)
    det = Js[..., 0] * Jh[..., 1] - Js[..., 1] * Jh[..., 0]
    rate_s = (Jh[..., 1] * W[..., 0] - Jh[..., 0] * W[..., 1]) / det
    rate_h = (-Js[..., 1] * W[..., 0] + Js[..., 0] * W[..., 1]) / det
    Ts, Th, _ = spec.temperature_derivatives(S[None], H[None], t[:, None])
    D = Ts * rate_s + Th * rate_h
    w = np.abs(det).mean(axis=0) * (s1 - s0) / 79 * (h1 - h0) / 139
    T = spec.temperature(S[None], H[None], t[:, None])
    u, sv, vt = np.linalg.svd(T - T.mean(axis=1, keepdims=True), full_matrices=False)
    if sv[1] > 1e-6 * sv[0]:  # a pattern that is not rank-one: no bound of this model
        return np.nan
    V = np.stack([np.ones_like(S), vt[0]])
    Z = D - np.linalg.solve((V * w) @ V.T, (V * w) @ D.T).T @ V
    Z -= np.outer(u[:, 0], u[:, 0] @ Z)
    return float(1.0 / np.sqrt(np.sum(Z**2 * w) / sigma**2) / np.median(np.diff(t)))


def monte_carlo(member, args):
    """``args.monte_carlo`` noise seeds of the member's realistic export (seeds of its own: members do not share
    a draw), the offsets in turn."""
    rows, refused = [], 0
    first = 1000 * (zlib.crc32(member.encode()) % 1000)
    for i in range(args.monte_carlo):
        k = args.offsets[i % len(args.offsets)]
        dic, ir, cal, ex, offset, period = scene(member, k, True, first + i, args)
        try:
            _, a = ir_clock(dic, ir.assign_attrs(time_offset="auto"), cal, member)
        except IrdicError:
            refused += 1
            continue
        rows.append(((a["ir_time_offset"] - offset) / period, a["ir_time_offset_std"] / period))
    bound = cramer_rao(ex, ir["time"].values + offset, np.hypot(IR_NOISE, 10.0**-DECIMALS / np.sqrt(12)))
    cells = [member, f"{len(rows)} / {refused}"] + ["-"] * 5 + [f"{bound:.3f}", "-"]
    if rows:
        err, std = np.array(rows).T
        cells[2:7] = [f"{err.mean():+.3f}", f"{err.std():.3f} +- {err.std() / np.sqrt(2 * len(err)):.3f}",
                      f"{np.abs(err).max():.3f}", f"{std.mean():.3f}", f"{np.sqrt(np.mean((err / std) ** 2)):.2f}"]
        cells[8] = f"{err.std() / bound:.2f}"
    print("| " + " | ".join(cells) + " |", flush=True)


def _timed(call):
    t0 = time.perf_counter()
    try:
        return call(), time.perf_counter() - t0
    except IrdicError as exc:
        return exc, time.perf_counter() - t0


def cost_and_temperatures(member, realistic, args):
    """The estimate alone and the couple stage with the true offset (it checks that offset with its own
    estimate), ``--repeat`` times each, interleaved, the fastest kept; the couple stage with ``auto``; the first
    offset of ``--offsets``, seed 0; the point temperatures against the truth."""
    k = args.offsets[0]
    dic, ir, cal, ex, offset, _ = scene(member, k, realistic, 0, args)
    true_ir = ir.assign_coords(time=ir["time"].values + offset).assign_attrs(time_offset=offset)
    est, cpl = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IrdicWarning)
        for _ in range(args.repeat):
            refused, sec = _timed(lambda: ir_clock(dic, ir.assign_attrs(time_offset="auto"), cal, member))
            est.append(sec)
            known, sec = _timed(lambda: couple(dic, true_ir, cal))
            cpl.append(sec)
        auto, t_auto = (None, 0.0) if isinstance(refused, IrdicError) else \
            _timed(lambda: couple(dic, ir.assign_attrs(time_offset="auto"), cal))
    e, c, b = min(est), min(cpl), rms(known, ex)
    line = (f"{member} ({'realistic' if realistic else 'noise-free'}), {k:+.2f} frames: estimate {e:.2f} s, couple "
            f"with the true offset {c:.1f} s with it: the estimate is {100 * e / (c - e):.1f} % of the rest "
            f"(fastest of {args.repeat})")
    if auto is None:
        line += f"; auto refused ({str(refused)[:60]}...); T RMS vs truth, true offset {b:.5f} K"
    else:
        a = rms(auto, ex)
        line += (f"; couple with auto {t_auto:.1f} s; T RMS vs truth: auto {a:.5f} K, true offset {b:.5f} K "
                 f"({100 * (a - b) / b:+.1f} %)")
    print(line, f"load {os.getloadavg()[0]:.1f}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", nargs="+", default=list(FAMILY))
    ap.add_argument("--offsets", nargs="+", type=float, default=[-4.0, -1.7, -0.3, 0.3, 1.7, 4.0],
                    help="IR frame periods")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--exports", nargs="+", default=["realistic", "clean"], choices=["realistic", "clean"])
    ap.add_argument("--couple", action="store_true", help="cost and point temperatures against the true offset")
    ap.add_argument("--monte-carlo", type=int, default=0, help="noise seeds per member (realistic exports)")
    ap.add_argument("--repeat", type=int, default=1, help="--couple: timings per figure (the fastest kept)")
    ap.add_argument("--frames", type=int, default=100, help="moving member: IR frames = DIC stages")
    ap.add_argument("--points", type=int, default=4000, help="moving member: DIC points")
    ap.add_argument("--scene-family", action="store_true",
                    help="the noisy fields' scene family in place of --members (scene:NAME, scene:SEED)")
    ap.add_argument("--same-rate", action="store_true", help="scene members: the IR frames at the DIC times only")
    args = ap.parse_args()
    if args.scene_family:
        args.members = [f"scene:{m}" for m in (*family.FIXED, *SCENE_SEEDS)]
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}, "
          f"python {platform.python_version()}")
    if args.monte_carlo:
        print("\n| member | estimates / refused | mean error | scatter | max \\|error\\| | mean std | RMS error/std "
              "| Cramér-Rao bound | scatter / bound |\n|---|---|---|---|---|---|---|---|---|")
        for member in args.members:
            monte_carlo(member, args)
        print(f"load average at the end {os.getloadavg()[0]:.1f}")
        return
    for exports in args.exports:
        realistic = exports == "realistic"
        everything, refused_all = [], 0
        print(f"\n{exports} exports\n\n| member | seed | offset (frames) | error (frames) | std (frames) | error/std "
              f"| estimate (s) |\n|---|---|---|---|---|---|---|")
        for member in args.members:
            rows, refused = [], 0
            for seed in range(args.seeds if realistic else 1):
                for k in args.offsets:
                    dic, ir, cal, _, offset, period = scene(member, k, realistic, seed, args)
                    t0 = time.perf_counter()
                    try:
                        _, a = ir_clock(dic, ir.assign_attrs(time_offset="auto"), cal, member)
                    except IrdicError as exc:
                        refused += 1
                        print(f"| {member} | {seed} | {k:+.2f} | refused: {refusal(str(exc))} | | | |", flush=True)
                        continue
                    sec = time.perf_counter() - t0
                    err, std = (a["ir_time_offset"] - offset) / period, a["ir_time_offset_std"] / period
                    rows.append((err, std, sec))
                    print(f"| {member} | {seed} | {k:+.2f} | {err:+.4f} | {std:.4f} | {err / std:+.2f} | {sec:.2f} |",
                          flush=True)
            summary(f"{member} ({exports})", rows, refused)
            everything += rows
            refused_all += refused
            if args.couple:
                cost_and_temperatures(member, realistic, args)
        summary(f"all members ({exports})", everything, refused_all)


if __name__ == "__main__":
    main()
