"""Benchmark of the surface stage: x(Psi, t), tangents, velocity, geometry, strain.

Scene: the paper's half-shell (R = 65 mm, +-36.87 deg, 50 mm high) on a DIC
grid regular in the material coordinates (S = arc length, h = height), under a
closed-form motion with known tangents, velocity and strains:

    x(S, h, t) = (R (1 + al) sin(S/R), h (1 + be), R (1 + al) cos(S/R) - R),
    al = 0.01 (1 - exp(-t/60)),  be = 0.02 (1 - exp(-t/60)) (1 + 0.2 sin(t / 7))

(stages 1 s apart), 1 % of the points missing in half of the later stages.
Every configuration runs in a fresh process so that its peak memory
(``ru_maxrss``) is its own.

    python benchmarks/bench_surface.py                 # everything (several minutes)
    python benchmarks/bench_surface.py --quick         # small sizes only
    python benchmarks/bench_surface.py --worker 10000 500 auto   # one configuration

Reported per configuration: wall time of ``fit_surface`` (parameters, fill,
temporal and spatial operators), of ``surface_geometry`` and of ``strain``;
peak resident memory; tangent and strain errors against the truth for points
at least 2 mm inside the edge and stages not at the ends (strain: not the first
or last; velocity: not the first or last two). The comparison
runs ``scipy.interpolate.RBFInterpolator(kernel="inverse_multiquadric",
epsilon=1/c, degree=1)`` per stage with tangents by central differences
(step 1e-4 mm) and velocities by central differences between stages.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

R, H, HALF = 65.0, 50.0, np.radians(36.87)


def scene(n_points, n_stages, seed=0):
    """Grid of about ``n_points`` points (aspect of the half-shell), stages 1 s apart."""
    smax = R * HALF - 1.0
    ratio = (2 * smax) / (H - 2)
    ny = max(4, int(round(np.sqrt(n_points / ratio))))
    nx = max(4, int(round(n_points / ny)))
    S, h = np.meshgrid(np.linspace(-smax, smax, nx), np.linspace(1, H - 1, ny))
    S, h = S.ravel(), h.ravel()
    t = np.arange(n_stages, dtype=float)
    al = 0.01 * (1 - np.exp(-t / 60))
    be = 0.02 * (1 - np.exp(-t / 60)) * (1 + 0.2 * np.sin(t / 7))
    X = np.empty((n_stages, S.size, 3))
    for k in range(n_stages):
        X[k] = np.c_[R * (1 + al[k]) * np.sin(S / R), h * (1 + be[k]), R * (1 + al[k]) * np.cos(S / R) - R]
    rng = np.random.default_rng(seed)
    for k in range(1, n_stages):
        if rng.random() < 0.5:
            X[k, rng.choice(S.size, max(1, S.size // 100), replace=False)] = np.nan
    e_S = np.c_[np.cos(S / R), 0 * S, -np.sin(S / R)]
    e_h = np.c_[0 * S, 1 + 0 * S, 0 * S]
    truth = dict(al=al, be=be, e_S=e_S, e_h=e_h, edge=np.minimum(smax - np.abs(S), np.minimum(h - 1, H - 1 - h)))
    return t, X, truth


def errors(t, sf_tangents, ref_tangents, psi, truth, e_max):
    """Tangent (metric) and strain errors against the truth, inner points and stages."""
    al, be = truth["al"], truth["be"]
    inner = truth["edge"] >= 2
    mid = slice(1, len(t) - 1)
    # metric error: invariant to the in-plane parametrisation (plane projection here)
    A = ref_tangents
    g = np.einsum("tnai,tnbi->tnab", sf_tangents[mid][:, inner], sf_tangents[mid][:, inner])
    # the exact metric in the same parameters: a_alpha = F A_alpha with F = (1 + al) e_S e_S + (1 + be) e_h e_h
    e_S, e_h = truth["e_S"][inner], truth["e_h"][inner]
    AS = np.einsum("nai,ni->na", A[inner], e_S)
    Ah = np.einsum("nai,ni->na", A[inner], e_h)
    g_true = ((1 + al[mid])[:, None, None, None] ** 2 * AS[None, :, :, None] * AS[None, :, None, :]
              + (1 + be[mid])[:, None, None, None] ** 2 * Ah[None, :, :, None] * Ah[None, :, None, :])
    metric_err = np.abs(g - g_true).max()
    e_true = np.maximum(((1 + al[mid]) ** 2 - 1) / 2, ((1 + be[mid]) ** 2 - 1) / 2)
    se = e_max[mid][:, inner] - e_true[:, None]
    return float(metric_err), float(np.sqrt(np.mean(se**2))), float(np.abs(se).max())


def worker(n_points, n_stages, solver, fill):
    from irdic.strain import strain
    from irdic.surface import fit_surface, surface_geometry

    t, X, truth = scene(n_points, n_stages)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    sf = fit_surface(X, t, solver=solver, fill=fill)
    t1 = time.perf_counter()
    geo = surface_geometry(sf.tangents)
    t2 = time.perf_counter()
    st = strain(sf.tangents, sf.ref_tangents, tensors=False)
    t3 = time.perf_counter()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    merr, srms, smax = errors(t, sf.tangents, sf.ref_tangents, sf.psi, truth, st.e_max)
    # velocity error against the closed form
    dal = 0.01 / 60 * np.exp(-t / 60)
    dbe = (0.02 / 60 * np.exp(-t / 60) * (1 + 0.2 * np.sin(t / 7))
           + 0.02 * (1 - np.exp(-t / 60)) * 0.2 / 7 * np.cos(t / 7))
    X0 = X[0]
    ok0 = np.isfinite(X0).all(axis=1)
    v_true = np.stack([np.c_[dal[k] * X0[:, 0], dbe[k] * X0[:, 1], dal[k] * (X0[:, 2] + R)] for k in range(len(t))])
    inner = truth["edge"] >= 2
    verr = np.abs(sf.velocity - v_true)[2:-2][:, inner & ok0]
    return dict(
        points=int(X.shape[1]), stages=int(n_stages), solver=sf.info.get("solver"), fill=fill,
        fit_s=round(t1 - t0, 2), geometry_s=round(t2 - t1, 2), strain_s=round(t3 - t2, 2),
        total_s=round(t3 - t0, 2), peak_GB=round(peak / 2**20, 2), data_GB=round(base / 2**20, 2),
        metric_err_max=merr, strain_rms=srms, strain_max=smax, velocity_err_max=float(verr.max()),
        velocity_err_rms=float(np.sqrt(np.mean(verr**2))), velocity_scale=float(np.abs(v_true).max()),
        filled=sf.info["n_filled"], normal_nan=int(np.isnan(geo.normal).any(axis=-1).sum()),
    )


def scipy_worker(n_points, n_stages, c=0.95):
    """The obvious approach: RBFInterpolator per stage, finite differences for d/dPsi and d/dt."""
    from scipy.interpolate import RBFInterpolator

    from irdic.strain import strain
    from irdic.surface import surface_parameters

    t, X, truth = scene(n_points, n_stages)
    t0 = time.perf_counter()
    psi, _ = surface_parameters(X)
    h = 1e-4
    tang = np.empty((n_stages, X.shape[1], 2, 3))
    for k in range(n_stages):
        ok = np.isfinite(X[k]).all(axis=1)
        rbf = RBFInterpolator(psi[ok], X[k, ok], kernel="inverse_multiquadric", epsilon=1 / c, degree=1)
        for a, d in enumerate(([h, 0], [0, h])):
            tang[k, :, a] = (rbf(psi + d) - rbf(psi - d)) / (2 * h)
        X[k, ~ok] = rbf(psi[~ok])  # fill for the time differences
    vel = np.gradient(X, t, axis=0)
    t1 = time.perf_counter()
    st = strain(tang, tang[0], tensors=False)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    merr, srms, smax = errors(t, tang, tang[0], psi, truth, st.e_max)
    dal = 0.01 / 60 * np.exp(-t / 60)
    dbe = (0.02 / 60 * np.exp(-t / 60) * (1 + 0.2 * np.sin(t / 7))
           + 0.02 * (1 - np.exp(-t / 60)) * 0.2 / 7 * np.cos(t / 7))
    X0 = scene(n_points, n_stages)[1][0]
    v_true = np.stack([np.c_[dal[k] * X0[:, 0], dbe[k] * X0[:, 1], dal[k] * (X0[:, 2] + R)] for k in range(len(t))])
    inner = truth["edge"] >= 2
    verr = np.abs(vel - v_true)[2:-2][:, inner]
    return dict(points=int(X.shape[1]), stages=int(n_stages), solver="scipy RBFInterpolator per stage + FD",
                fit_s=round(t1 - t0, 2), total_s=round(t1 - t0, 2), peak_GB=round(peak / 2**20, 2),
                metric_err_max=merr, strain_rms=srms, strain_max=smax, velocity_err_max=float(verr.max()),
                velocity_err_rms=float(np.sqrt(np.mean(verr**2))))


def run(args):
    cmd = [sys.executable, __file__, "--worker", *map(str, args)]
    out = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    if out.returncode != 0:
        return {"config": args, "error": out.stderr[-2000:]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes only")
    ap.add_argument("--no-global", action="store_true", help="skip the global solver at paper scale")
    ap.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    ap.add_argument("--json", help="write all results to this file")
    a = ap.parse_args()
    if a.worker:
        if a.worker[0] == "scipy":
            res = scipy_worker(int(a.worker[1]), int(a.worker[2]))
        else:
            n, m, solver = int(a.worker[0]), int(a.worker[1]), a.worker[2]
            fill = a.worker[3] if len(a.worker) > 3 else "both"
            res = worker(n, m, solver, fill)
        print(json.dumps(res))
        return
    configs = []
    if a.quick:
        configs += [(2500, 50, "auto"), (2500, 100, "auto"), (5000, 50, "auto")]
        compare = [(2500, 50, "auto"), ("scipy", 2500, 50)]
    else:
        configs += [(10000, 500, "auto"), (5000, 500, "auto"), (10000, 250, "auto"), (20000, 250, "auto")]
        if not a.no_global:
            configs += [(10000, 500, "global")]
        compare = [(3000, 40, "auto"), (3000, 40, "global"), ("scipy", 3000, 40)]
    results = []
    for cfg in configs + compare:
        r = run(cfg)
        results.append(r)
        print(json.dumps(r), flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
