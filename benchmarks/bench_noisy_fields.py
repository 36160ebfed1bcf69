"""Noisy data over a family of scenes: the default configuration against the analytic truth, every member.

The members come from :mod:`irdic.synthetic.family`: the fixed, named ones
(:data:`~irdic.synthetic.family.FIXED`: shells, tubes, plates, a sphere cap,
a barrel; static, stretched, twisted; heated smoothly, from an edge, by a
narrow moving band or a hot spot) and fresh members drawn from new seeds,
each with its own noise (IR 0.02-0.1 K, 2 or 3 decimals, mixed edge pixels;
DIC 0.001-0.005 mm; 0-2 % failed points), point spacing (0.3-1 mm) and
camera pose. Each is coupled and run through the fields stage with the
DEFAULT configuration (``auto`` smoothing everywhere).

Errors over interior points (visible, 2 mm or more inside the DIC patch,
not the first or last DIC time):

- in-plane gradient: RMS of ``|g - g_true|`` over RMS of ``|g_true|``;
- rate: RMS of the error over RMS of the true rate;
- max principal strain: RMS of the error;
- temperature: RMS error of ``fields.temperature`` (denoised).

Uncertainty, over the interior points not flagged ``*_bias_dominated``
(the share flagged in brackets): the fraction of errors within 1 and 2
stated std (gradient: per component) and the RMS of error/std. Goals:
gradient and rate 3 %, denoised temperature 0.015 K, strain 1e-3; 0.60-0.76
/ 0.92-0.98 within 1 / 2 std, RMS of error/std 0.8-1.25. The last rows give
the worst member of each column; ``*`` marks a miss.

Usage (repository root, one BLAS thread on a shared machine)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_noisy_fields.py [--scale tiny|demo] [--members NAME ...]
        [--fresh 4] [--draw-seeds S ...] [--json results.json]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_noisy_fields.py --members strip-band --noise-seeds 1 2 3 4

``--fresh N`` draws N members from seeds taken from the clock (printed, so
a run can be repeated with ``--draw-seeds``). ``--noise-seeds``: a Monte
Carlo check of the uncertainties: each seed is another noise realisation of
the same member; coverage per seed and pooled.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
import xarray as xr

from irdic.coupling import couple
from irdic.fields import fields
from irdic.synthetic import family, render

#: goals: relative RMS of gradient and rate, RMS of the denoised temperature (K) and the strain
GOALS = {"gradient": 0.03, "rate": 0.03, "temperature": 0.015, "strain": 1e-3}
COVER_1, COVER_2, Z_RMS = (0.60, 0.76), (0.92, 0.98), (0.8, 1.25)
FIELDS = (("temperature", "temperature"), ("temperature_gradient", "temperature_gradient"),
          ("temperature_rate", "temperature_rate"), ("max_principal_strain", "strain_max"))
SHORT = {"temperature": "T", "temperature_gradient": "gradient", "temperature_rate": "rate",
         "max_principal_strain": "strain"}


def realistic_stack(ex, rng, decimals=2) -> xr.DataArray:
    """IR frames of an experiment with mixed edge pixels, pixel noise and rounding (float32, deg C)."""
    r = ex.renderer
    frames = render.realistic_stack(r, ex.ir_times, rng, noise=ex.ir_noise, decimals=decimals)
    return xr.DataArray(frames, dims=("time", "v", "u"),
                        coords={"time": ex.ir_times, "v": r.v.astype(np.int64), "u": r.u.astype(np.int64)},
                        attrs={"units": "°C"}, name="temperature")


def interior(pts, tr) -> np.ndarray:
    """(T, N): visible, 2 mm or more inside the DIC patch, not the first or last DIC time."""
    m = pts.visible.values & (tr.patch_edge_distance.values >= 2.0)
    m[[0, -1]] = False
    return m


def errors(f, tr, m) -> dict:
    """The accuracy figures of a fields dataset ``f`` against the truth ``tr`` over the mask ``m``."""
    rms = lambda a: float(np.sqrt(np.nanmean(np.square(a)))) if np.size(a) else float("nan")  # noqa: E731
    g_true = tr.temperature_gradient.values
    g_err = np.linalg.norm(f.temperature_gradient.values - g_true, axis=-1)
    r_true = tr.temperature_rate.values
    return {"gradient": rms(g_err[m]) / rms(np.linalg.norm(g_true[m], axis=-1)),
            "rate": rms((f.temperature_rate.values - r_true)[m]) / rms(r_true[m]),
            "strain": rms((f.max_principal_strain.values - tr.strain_max.values)[m]),
            "temperature": rms((f.temperature.values - tr.temperature.values)[m]),
            "true_strain": rms(tr.strain_max.values[m])}


def coverage(f, tr, m) -> dict:
    """Per field: (within 1 std, within 2 std, RMS of error/std, share flagged, n, n1, n2, sum z²) over the
    interior points not flagged bias-dominated."""
    out = {}
    for v, true in FIELDS:
        mv = m if f[v].ndim == 2 else np.repeat(m[..., None], f[v].shape[-1], axis=-1)
        mm = mv & ~f[f"{v}_bias_dominated"].values
        z = np.abs(f[v].values - tr[true].values)[mm] / f[f"{v}_std"].values[mm]
        z = z[np.isfinite(z)]
        n = max(1, z.size)
        out[v] = (float(np.sum(z <= 1) / n), float(np.sum(z <= 2) / n), float(np.sqrt(np.sum(z * z) / n)),
                  float(1 - mm.sum() / max(1, mv.sum())), int(z.size), int(np.sum(z <= 1)), int(np.sum(z <= 2)),
                  float(np.sum(z * z)))
    return out


def measure(scene) -> dict:
    """Couple and fields (default configuration) of a :class:`~irdic.synthetic.family.Scene`, against its truth."""
    t0 = time.perf_counter()
    dic, ir, cal = scene.inputs()
    t1 = time.perf_counter()
    pts = couple(dic, ir, cal)
    t2 = time.perf_counter()
    f = fields(pts, cal)
    t3 = time.perf_counter()
    tr = scene.truth().sel(point=pts.point)
    m = interior(pts, tr)
    return {"name": scene.name, "describe": scene.describe(), "kinds": scene.kinds, "points": int(pts.point.size),
            "interior": int(m.sum()), **errors(f, tr, m),
            "chosen": {k: f.attrs.get(f"{k}_chosen") for k in
                       ("surface_smoothing", "temperature_smoothing", "temperature_smoothing_space")},
            "dic_noise_mm": f.attrs.get("dic_noise_mm"), "ir_noise_k": f.attrs.get("ir_noise_k"),
            "render_s": t1 - t0, "couple_s": t2 - t1, "fields_s": t3 - t2, "coverage": coverage(f, tr, m)}


def _misses(r) -> list[str]:
    """The goals member result ``r`` misses."""
    out = [k for k, g in GOALS.items() if not r[k] <= g]
    for v, c in r["coverage"].items():
        if c[4] == 0:
            continue
        if not (COVER_1[0] <= c[0] <= COVER_1[1] and COVER_2[0] <= c[1] <= COVER_2[1] and Z_RMS[0] <= c[2] <= Z_RMS[1]):
            out.append(f"{SHORT[v]} coverage")
    return out


def _cell_cov(c, worst=False):
    mark = "" if (COVER_1[0] <= c[0] <= COVER_1[1] and COVER_2[0] <= c[1] <= COVER_2[1]
                  and Z_RMS[0] <= c[2] <= Z_RMS[1]) else "*"
    return f"{c[0]:.2f} / {c[1]:.2f} / {c[2]:.2f}{mark}" + ("" if worst else f" ({100 * c[3]:.0f} %)")


def report(results):
    """Markdown tables: every member's errors and coverage, and the worst member per column."""
    print("\n| member | kinds | gradient | rate | denoised T | strain (true RMS) | s (couple + fields) |")
    print("|---|---|---|---|---|---|---|")
    for r in results:
        def mk(k, text):
            return text + ("*" if not r[k] <= GOALS[k] else "")
        g, rt = f"{100 * r['gradient']:.2f} %", f"{100 * r['rate']:.2f} %"
        print(f"| {r['name']} | {' / '.join(r['kinds'])} | {mk('gradient', g)} | {mk('rate', rt)} | "
              f"{mk('temperature', '%.4f K' % r['temperature'])} | {mk('strain', '%.2g' % r['strain'])} "
              f"({r['true_strain']:.2g}) | {r['couple_s'] + r['fields_s']:.0f} |")
    worst = {k: max(results, key=lambda r: r[k] if np.isfinite(r[k]) else np.inf) for k in GOALS}
    print(f"| **worst** | | {100 * worst['gradient']['gradient']:.2f} % ({worst['gradient']['name']}) | "
          f"{100 * worst['rate']['rate']:.2f} % ({worst['rate']['name']}) | "
          f"{worst['temperature']['temperature']:.4f} K ({worst['temperature']['name']}) | "
          f"{worst['strain']['strain']:.2g} ({worst['strain']['name']}) | |")
    print("\nWithin 1 / 2 std / RMS of error/std (share flagged bias-dominated):\n")
    print("| member | " + " | ".join(SHORT[v] for v, _ in FIELDS) + " |")
    print("|---" * (len(FIELDS) + 1) + "|")
    for r in results:
        print(f"| {r['name']} | " + " | ".join(_cell_cov(r["coverage"][v]) for v, _ in FIELDS) + " |")
    cells = []
    for v, _ in FIELDS:
        cs = [(r["coverage"][v], r["name"]) for r in results if r["coverage"][v][4] > 0]
        if not cs:
            cells.append("-")
            continue
        lo1 = min(cs, key=lambda c: c[0][0])
        hi1 = max(cs, key=lambda c: c[0][0])
        lo2 = min(cs, key=lambda c: c[0][1])
        hi2 = max(cs, key=lambda c: c[0][1])
        zr = max(cs, key=lambda c: abs(np.log(c[0][2])))
        cells.append(f"1 std {lo1[0][0]:.2f}-{hi1[0][0]:.2f}, 2 std {lo2[0][1]:.2f}-{hi2[0][1]:.2f}, "
                     f"z {zr[0][2]:.2f} ({zr[1]})")
    print("| **range** | " + " | ".join(cells) + " |")
    missed = {r["name"]: _misses(r) for r in results}
    print("\nGoals missed: " + ("; ".join(f"{k}: {', '.join(v)}" for k, v in missed.items() if v) or "none"))


def monte_carlo(name, scale, seeds, drawn=None):
    """The coverage of one member over noise realisations: per seed and pooled."""
    runs = []
    for s in seeds:
        sc = family.draw(drawn, scale, noise_seed=s) if drawn is not None else family.member(name, scale, noise_seed=s)
        runs.append(measure(sc))
    print(f"\n{runs[0]['name']}: {runs[0]['describe']}")
    print("errors per seed: gradient " + ", ".join(f"{100 * r['gradient']:.2f}" for r in runs) + " %, rate "
          + ", ".join(f"{100 * r['rate']:.2f}" for r in runs) + " %, T "
          + ", ".join(f"{r['temperature']:.4f}" for r in runs) + " K, strain "
          + ", ".join(f"{r['strain']:.2g}" for r in runs))
    print("| within 1 / 2 std / RMS z | " + " | ".join(f"seed {s}" for s in seeds) + " | pooled |")
    print("|---" * (len(seeds) + 2) + "|")
    for v, _ in FIELDS:
        c = np.array([r["coverage"][v] for r in runs])
        n = max(1.0, c[:, 4].sum())
        pooled = (c[:, 5].sum() / n, c[:, 6].sum() / n, np.sqrt(c[:, 7].sum() / n), float(np.mean(c[:, 3])))
        print(f"| {SHORT[v]} | " + " | ".join(_cell_cov(r["coverage"][v]) for r in runs)
              + f" | **{_cell_cov(pooled)}** |")
    return runs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", default="demo", choices=tuple(family.FAMILY_SCALES))
    ap.add_argument("--members", nargs="*", default=None, choices=tuple(family.FIXED),
                    help="fixed members to run (default all)")
    ap.add_argument("--fresh", type=int, default=4, help="members drawn from fresh seeds (default 4)")
    ap.add_argument("--draw-seeds", type=int, nargs="*", default=None, help="draw these members instead of fresh ones")
    ap.add_argument("--noise-seeds", type=int, nargs="+", help="Monte Carlo over noise realisations")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)
    started = time.perf_counter()
    load = os.getloadavg()[0]
    if args.noise_seeds:
        runs = []
        for name in args.members or []:
            runs += monte_carlo(name, args.scale, args.noise_seeds)
        for s in args.draw_seeds or []:
            runs += monte_carlo(None, args.scale, args.noise_seeds, drawn=s)
        results = runs
    else:
        names = list(family.FIXED) if args.members is None else args.members
        seeds = args.draw_seeds
        if seeds is None:
            base = int(time.time()) % 1_000_000
            seeds = [base + 7919 * i for i in range(args.fresh)]
        print(f"load average {load:.1f}; scale {args.scale}; fixed {names}; drawn seeds {seeds}", flush=True)
        results = []
        for sc in [lambda n=n: family.member(n, args.scale) for n in names] + \
                  [lambda s=s: family.draw(s, args.scale) for s in seeds]:
            scene = sc()
            r = measure(scene)
            print(f"{r['name']}: {r['describe']}; chosen {r['chosen']}; estimated noise DIC "
                  f"{r['dic_noise_mm']:.4f} mm, IR {r['ir_noise_k']:.4f} K; render {r['render_s']:.0f} s, couple "
                  f"{r['couple_s']:.0f} s, fields {r['fields_s']:.0f} s", flush=True)
            results.append(r)
        report(results)
    print(f"\n{time.perf_counter() - started:.0f} s; load average at the start {load:.1f}, at the end "
          f"{os.getloadavg()[0]:.1f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))


if __name__ == "__main__":
    main()
