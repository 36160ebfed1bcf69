"""The heat stage against the closed-form heat source over a family of scenes, beside the plain lab approach.

Scenes (:mod:`_heat_family`, each through the coupling, the fields stage and
the heat stage with their default settings; closed-form truth): the R 15 mm
tube under tension-torsion (moving: stretch and twist), static half-shell
patches of R 30, 40 ("barrel") and 65 mm heated from the plate below, and
the R 40 mm patch with a narrow hot band (Gaussian, 4 mm) and with a hot spot
(Gaussian, 5 mm); steel (ρ 7850 kg/m³, c 470 J/(kg K), k 50 W/(m K)),
τ = 60 s. Each scene clean (noise-free frames and DIC) and realistic
(0.05 K IR noise, 2-decimal exports, mixed edge pixels, 0.003 mm DIC noise:
the frames of ``bench_noisy_fields.realistic_stack``).

``--surfaces``: the Laplacian alone on point clouds of other geometries
(:func:`surface_family`: a plane in a curvilinear parametrisation with a hot
spot and a hot band, a sphere cap with spherical harmonics, cylinders of
R 8 and 25 mm, the stretched and twisted tube), 0.05 K white noise,
2 decimals, 0.003 mm noise on the positions, the heat stage's regressions
with their defaults.

The lab approach, on the same frames: each IR frame Gaussian-filtered
(``--lab-sigma`` px), the Laplacian by the five-point finite difference on
the pixel grid scaled by the pixel size on the specimen (mm/px, from the
DIC points' pixel positions), the rate by central differences of the
filtered frames in time at the fixed pixel, all sampled bilinearly at the
DIC points' pixel positions; Θ0 the first frame at the same pixel.

Errors over interior points (visible, 2 mm or more inside the DIC patch,
not the first or last DIC time): RMS relative to the largest true value
there; the coverage of ``heat_source_std`` and ``temperature_laplacian_std``
(fraction of the errors within 1 and 2 std) and the RMS of error/std, over
all interior points and over those not flagged ``_bias_dominated``. The
last row of each table is the worst member.

Usage (repository root, one BLAS thread on a shared machine)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_heat.py [--scale tiny|demo] [--scenes tube barrel ...]
        [--seeds 3] [--lab-sigma 2.0] [--surfaces]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
import xarray as xr
from scipy import ndimage

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from _heat_family import FAMILY, family_scene, true_laplacian  # noqa: E402
from bench_noisy_fields import realistic_stack  # noqa: E402

from irdic.camera import CameraModel  # noqa: E402
from irdic.heat import smooth_in_time, surface_laplacian  # noqa: E402
from irdic.heat.laplacian import judging_weights  # noqa: E402
from irdic.heat.dataset import _aligned_points, heat_dataset  # noqa: E402
from irdic.coupling import couple  # noqa: E402
from irdic.fields import fields  # noqa: E402
from irdic.footprint.fields import pixel_pitch  # noqa: E402

RHO, C, K, TAU = 7850.0, 470.0, 50.0, 60.0
MATERIAL = dict(density=RHO, specific_heat=C, conductivity=K, loss_time_constant=TAU, reference_temperature=None,
                cooling=None, laplacian_smoothing="auto", laplacian_smoothing_time="gcv")


def _sample(frames, pix):
    """Bilinear samples (T, N) of ``frames`` (T, V, U) at pixel positions ``pix`` (T, N, 2) relative to the crop."""
    out = np.full(pix.shape[:2], np.nan)
    for i in range(frames.shape[0]):
        ok = np.isfinite(pix[i]).all(axis=1)
        out[i, ok] = ndimage.map_coordinates(frames[i], [pix[i, ok, 1], pix[i, ok, 0]], order=1, mode="nearest")
    return out


def lab_approach(ir, pts, sigma, mm_per_px):
    """Laplacian (K/mm²), rate (K/s) and temperature (degC) at the DIC points by the lab approach."""
    st = ir["temperature"]
    F = np.stack([ndimage.gaussian_filter(f.astype(float), sigma, mode="nearest") for f in st.values])
    lap = np.stack([ndimage.laplace(f, mode="nearest") for f in F]) / mm_per_px ** 2
    tir = st["time"].values
    rate = np.gradient(F, tir, axis=0)
    td = pts["time"].values
    idx = np.searchsorted(tir, td).clip(0, tir.size - 1)  # the DIC times are IR frame times
    pix = pts["pixel"].transpose("time", "point", "axis").values.astype(float)
    pix = pix - np.array([st["u"].values[0], st["v"].values[0]], float)
    out = [_sample(a[idx], pix) for a in (lap, rate, F)]
    return out


def _mm_per_px(pts):
    pix = pts["pixel"].transpose("time", "point", "axis").values[0]
    x = pts["x"].transpose("time", "point", "component").values[0]
    from scipy.spatial import cKDTree

    ok = np.isfinite(pix).all(axis=1) & np.isfinite(x).all(axis=1)
    d, j = cKDTree(x[ok]).query(x[ok], k=2)
    return float(np.median(d[:, 1] / np.linalg.norm(pix[ok] - pix[ok][j[:, 1]], axis=1)))


def measure(name, scale, seed, realistic, sigma, spacings=(), time_spacing="gcv"):
    ex = family_scene(name, scale, seed, 0.05 if realistic else 0.0, 0.003 if realistic else 0.0)
    stack = realistic_stack(ex, np.random.default_rng([seed, 15])) if realistic else \
        ex.ir_stack(noise=False).drop_vars("frame_number")
    ir = xr.Dataset({"temperature": stack})
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=cam.width, sensor_height=cam.height)
    pts = couple(ex.dic()[["x"]], ir, cal)
    t0 = time.perf_counter()
    f = fields(pts, cal)
    t1 = time.perf_counter()
    sep = pixel_pitch(pts.sel(point=f["point"].values), f["surface_parameter"].values)  # as the stage does
    h = heat_dataset(f, pts, {**MATERIAL, "laplacian_smoothing_time": time_spacing}, separation=sep)
    t2 = time.perf_counter()
    tr = ex.truth().sel(point=pts.point)
    tt = tr.time.values[:, None]
    lap_true = true_laplacian(ex.specimen, tr.s.values[None], tr.h.values[None], tt)
    th_true = tr.temperature.values
    src_true = RHO * C * (tr.temperature_rate.values + (th_true - th_true[0]) / TAU) - K * 1e6 * lap_true
    m = pts.visible.values & (tr.patch_edge_distance.values >= 2.0)
    m[[0, -1]] = False
    lab_lap, lab_rate, lab_T = lab_approach(ir, pts, sigma, _mm_per_px(pts))
    lab_src = RHO * C * (lab_rate + (lab_T - lab_T[0]) / TAU) - K * 1e6 * lab_lap

    def rel(est, true):
        e = (est - true)[m]
        return float(np.sqrt(np.nanmean(e ** 2)) / np.nanmax(np.abs(true[m])))

    out = {"scene": name, "seed": seed, "data": "realistic" if realistic else "clean",
           "points": int(pts.point.size), "times": int(pts.time.size),
           "source": rel(h["heat_source"].values, src_true),
           "laplacian": rel(h["temperature_laplacian"].values, lap_true),
           "lab_source": rel(lab_src, src_true), "lab_laplacian": rel(lab_lap, lap_true),
           "spacing": h.attrs["laplacian_spacing_chosen"].split(",")[0] + "; "
           + h.attrs["laplacian_smoothing_time_chosen"].replace("centres every ", ""),
           "fields_s": t1 - t0, "heat_s": t2 - t1}
    out.update(coverage(h, "heat_source", src_true, m, "src"))
    out.update(coverage(h, "temperature_laplacian", lap_true, m, "lap"))
    out["lap_truly"] = truly_biased(f, pts, tr, lap_true, m, sep)
    for k in spacings:
        hk = heat_dataset(f, pts, {**MATERIAL, "laplacian_smoothing": k}, separation=sep)
        print(f"  {name} {out['data']} spacing {k:g}: Laplacian "
              f"{100 * rel(hk['temperature_laplacian'].values, lap_true):.2f} %", flush=True)
    return out


def truly_biased(f, pts, tr, lap_true, m, sep):
    """The share of the points ``m`` where the Laplacian's regression bias (the heat stage's regressions, its
    spacings in space and time, on the exact temperatures and positions) exceeds its noise std: what
    ``temperature_laplacian_bias_dominated`` should flag."""
    psi = f["surface_parameter"].transpose("point", "param").values
    t = f["time"].values
    res, k_t = smooth_in_time(surface_laplacian(psi, _aligned_points(f, pts), f["x"].transpose(
        "time", "point", "component").values, separation=sep, time_weights=judging_weights(t)), t)
    clean = surface_laplacian(psi, tr.temperature.values, tr.x.transpose("time", "point", "component").values,
                              spacing=res.spacing)
    clean = smooth_in_time(clean, t, k_t if k_t > 1.0 else None)[0]
    return float(np.mean((np.abs(clean.laplacian - lap_true) > res.std)[m]))


def coverage(h, name, true, m, key):
    """``{key}_c1``, ``_c2`` (fractions within 1, 2 std), ``_rz`` (RMS of error/std) over ``m``; the same with
    ``_ok`` over the unflagged points; ``_flag`` the flagged share."""
    z = np.abs(h[name].values - true) / h[f"{name}_std"].values
    ok = m & ~h[f"{name}_bias_dominated"].values
    out = {}
    for tag, sel in (("", m), ("_ok", ok)):
        zz = z[sel]
        out.update({f"{key}_c1{tag}": float(np.mean(zz <= 1)) if zz.size else float("nan"),
                    f"{key}_c2{tag}": float(np.mean(zz <= 2)) if zz.size else float("nan"),
                    f"{key}_rz{tag}": float(np.sqrt(np.mean(zz ** 2))) if zz.size else float("nan")})
    out[f"{key}_flag"] = float(1 - ok.sum() / m.sum())
    return out


def _cov(r, key, tag=""):
    return f"{r[f'{key}_c1{tag}']:.2f} / {r[f'{key}_c2{tag}']:.2f} / {r[f'{key}_rz{tag}']:.2f}"


def _worst(rows, keys_max, keys_min):
    """The worst member: the largest of ``keys_max``, the smallest of ``keys_min`` (each over all rows); for the
    coverage, the fraction farthest from its target and the RMS of error/std farthest from 1."""
    w = {k: max(r[k] for r in rows) for k in keys_max}
    w.update({k: min(r[k] for r in rows) for k in keys_min})
    for key in ("src", "lap"):
        for tag in ("", "_ok"):
            for c, target in (("c1", 0.68), ("c2", 0.95)):
                vals = [r[f"{key}_{c}{tag}"] for r in rows if np.isfinite(r[f"{key}_{c}{tag}"])]
                w[f"{key}_{c}{tag}"] = max(vals, key=lambda v: abs(v - target)) if vals else float("nan")
            vals = [r[f"{key}_rz{tag}"] for r in rows if np.isfinite(r[f"{key}_rz{tag}"])]
            w[f"{key}_rz{tag}"] = max(vals, key=lambda v: abs(np.log(v))) if vals else float("nan")
        w[f"{key}_flag"] = max(r[f"{key}_flag"] for r in rows)
    return w


def surface_family(seed=3, noise=0.05, dic_noise=0.003, decimals=2):
    """Point clouds ``(name, psi (N, 2), x (T, N, 3), theta (T, N), true Laplacian (T, N), inner (N,))`` of other
    geometries, 0.6 mm apart, 24 times over which the temperature rises as ``0.5 + t/T``; closed-form truth."""
    rng = np.random.default_rng(seed)
    T = 24
    ramp = (0.5 + np.arange(T) / T)[:, None]

    def grid(lo1, hi1, lo2, hi2, h=0.6):
        a, b = np.meshgrid(np.arange(lo1, hi1, h), np.arange(lo2, hi2, h), indexing="ij")
        return np.c_[a.ravel(), b.ravel()] + rng.uniform(-0.2 * h, 0.2 * h, (a.size, 2))

    scenes = []
    # a plane in a curvilinear, non-orthogonal parametrisation: the ordinary Laplacian of Θ(X, Y)
    psi = grid(-15, 15, -15, 15)
    p1, p2 = psi.T
    X, Y = p1 + 0.01 * p2 ** 2, p2 + 0.005 * p1 * p2
    x = np.c_[X, Y, 0 * X]
    for label, w, band in (("plane, hot spot 3 mm", 3.0, False), ("plane, hot band 2.5 mm", 2.5, True)):
        r2 = (X - 2.0) ** 2 if band else (X - 2.0) ** 2 + (Y + 1.0) ** 2
        g = 8.0 * np.exp(-0.5 * r2 / w ** 2)
        lap = ((r2 / w ** 2 - (1.0 if band else 2.0)) / w ** 2) * g
        scenes.append((label, psi, np.repeat(x[None], T, 0), 20 + ramp * g, ramp * lap))
    # a sphere cap (R 20 mm) over its tangent plane: Y_l has the eigenvalue −l(l+1)/R²
    R = 20.0
    psi = grid(-12, 12, -12, 12)
    psi = psi[np.hypot(*psi.T) < 12]
    z = np.sqrt(R ** 2 - np.sum(psi ** 2, axis=1))
    c = z / R
    th = 10 * c + 20 * 0.5 * (3 * c ** 2 - 1) + 15 * psi[:, 0] * psi[:, 1] / R ** 2
    lap = -(2 * 10 * c + 6 * (th - 10 * c)) / R ** 2
    scenes.append(("sphere cap R 20", psi, np.repeat(np.c_[psi, z][None], T, 0), 20 + ramp * th, ramp * lap))
    # cylinders Ψ = (Rφ, z): Δ = ∂²/∂z² + R⁻² ∂²/∂φ²
    for R in (8.0, 25.0):
        psi = grid(-min(R * 1.4, 20), min(R * 1.4, 20), -15, 15)
        phi, zz = psi[:, 0] / R, psi[:, 1]
        x = np.c_[R * np.cos(phi), R * np.sin(phi), zz]
        th = 0.03 * zz ** 2 + 1.2 * np.cos(2 * phi) + 3.0 * np.exp(-0.5 * (zz / 3.0) ** 2)
        lap = (0.06 - 4.8 * np.cos(2 * phi) / R ** 2
               + 3.0 * np.exp(-0.5 * (zz / 3.0) ** 2) * (zz ** 2 / 9.0 - 1.0) / 9.0)
        scenes.append((f"cylinder R {R:g}, hot ring 3 mm", psi, np.repeat(x[None], T, 0), 20 + ramp * th,
                       ramp * lap))
    # the tube R 10 mm stretched (λ to 1.06) and twisted (γ to 0.04 /mm): Θ = A z'²/λ² + B cos 2(φ' − γ z'/λ)
    R = 10.0
    psi = grid(-15, 15, -20, 20)
    phi, zz = psi[:, 0] / R, psi[:, 1]
    lam, gam = np.linspace(1.0, 1.06, T), np.linspace(0.0, 0.04, T)
    x = np.stack([np.c_[R * np.cos(phi + g * zz), R * np.sin(phi + g * zz), lm * zz] for lm, g in zip(lam, gam)])
    th = 0.02 * zz ** 2 + 1.5 * np.cos(2 * phi)
    lap = np.stack([2 * 0.02 / lm ** 2 - 4 * 1.5 * np.cos(2 * phi) * ((g / lm) ** 2 + 1 / R ** 2)
                    for lm, g in zip(lam, gam)])
    scenes.append(("tube R 10, stretch + twist", psi, x, 20 + ramp * th, ramp * lap))
    out = []
    for label, psi, x, th, lap in scenes:
        noisy = th + rng.normal(0.0, noise, th.shape)
        noisy = noisy if decimals is None else np.round(noisy, decimals)
        xn = x + rng.normal(0.0, dic_noise, x.shape)
        out.append((label, psi, xn, noisy, lap))
    return out


def measure_surfaces(seed):
    """The Laplacian of the heat stage's regressions (defaults) on :func:`surface_family`: error and coverage."""
    from irdic.heat import laplacian_bias, with_bias
    from irdic.surface import edge_distance

    rows = []
    exact = surface_family(seed, 0.0, 0.0, None)
    for (label, psi, x, th, true), (_, _, x0, th0, _) in zip(surface_family(seed), exact):
        T = th.shape[0]
        t = np.arange(T, dtype=float)
        ops = {}
        res, k_t = smooth_in_time(surface_laplacian(psi, th, x, ops=ops, time_weights=judging_weights(t)), t)
        bias = laplacian_bias(psi, th, x, res, ops=ops)
        clean = smooth_in_time(surface_laplacian(psi, th0, x0, spacing=res.spacing), t, k_t if k_t > 1 else None)[0]
        full = with_bias(res, bias)
        m = np.broadcast_to(edge_distance(psi) >= 2.0, th.shape).copy()
        m[[0, -1]] = False
        e = (full.laplacian - true)[m]
        z = np.abs(e) / full.std[m]
        ok = m & ~(bias > res.std)
        zo = np.abs(full.laplacian - true)[ok] / full.std[ok]
        rows.append({"scene": label, "points": psi.shape[0], "times": T,
                     "laplacian": float(np.sqrt(np.mean(e ** 2)) / np.abs(true[m]).max()),
                     "lap_c1": float(np.mean(z <= 1)), "lap_c2": float(np.mean(z <= 2)),
                     "lap_rz": float(np.sqrt(np.mean(z ** 2))), "lap_c1_ok": float(np.mean(zo <= 1)),
                     "lap_c2_ok": float(np.mean(zo <= 2)), "lap_rz_ok": float(np.sqrt(np.mean(zo ** 2))),
                     "lap_flag": float(1 - ok.sum() / m.sum()), "spacing": f"{res.spacing:.3g}; {k_t:.3g}",
                     "lap_truly": float(np.mean((np.abs(clean.laplacian - true) > res.std)[m]))})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", default="demo", choices=["tiny", "demo", "paper"])
    ap.add_argument("--scenes", nargs="*", default=list(FAMILY), choices=list(FAMILY))
    ap.add_argument("--data", nargs="+", default=["clean", "realistic"], choices=["clean", "realistic"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[3])
    ap.add_argument("--lab-sigma", type=float, default=2.0, help="Gaussian filter of the lab approach, px")
    ap.add_argument("--time-spacing", type=lambda v: v if v == "gcv" else (None if v == "none" else float(v)),
                    default="gcv", help="material.laplacian_smoothing_time: gcv, none or a number of DIC times")
    ap.add_argument("--spacings", type=float, nargs="*", default=[],
                    help="also the Laplacian's error at these fixed centre spacings (point spacings)")
    ap.add_argument("--surfaces", action="store_true", help="also the Laplacian on the point-cloud family")
    a = ap.parse_args(argv)
    if a.scenes:
        print("| scene | seed | data | points x times | source | Laplacian | lab source | lab Laplacian | source std "
              "1 / 2 / RMS z (all; unflagged) | flagged | Laplacian std 1 / 2 / RMS z (all; unflagged) | "
              "flagged (truly) | "
              "spacing (space; time) | fields s | heat s |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for data in a.data:
        rows = []
        for name in a.scenes:
            for seed in a.seeds:
                r = measure(name, a.scale, seed, data == "realistic", a.lab_sigma, a.spacings, a.time_spacing)
                r["lab_ratio_src"] = r["lab_source"] / r["source"]
                r["lab_ratio_lap"] = r["lab_laplacian"] / r["laplacian"]
                r["heat_over_fields"] = r["heat_s"] / r["fields_s"]
                rows.append(r)
                _row(r)
        if len(rows) > 1:
            w = _worst(rows, ("source", "laplacian", "heat_over_fields", "fields_s", "heat_s", "lap_truly"),
                       ("lab_ratio_src", "lab_ratio_lap"))
            w.update(scene="**worst**", seed="-", data=data, points="-", times="-", spacing="-",
                     lab_source=float("nan"), lab_laplacian=float("nan"))
            _row(w, worst=True)
    if a.surfaces:
        print("\n| surface | seed | points x times | Laplacian | std 1 / 2 / RMS z (all; unflagged) | "
              "flagged (truly) | "
              "spacing |")
        print("|---|---|---|---|---|---|---|")
        rows = []
        for seed in a.seeds:
            for r in measure_surfaces(seed):
                rows.append(r)
                print(f"| {r['scene']} | {seed} | {r['points']} x {r['times']} | {100 * r['laplacian']:.2f} % | "
                      f"{_cov(r, 'lap')}; {_cov(r, 'lap', '_ok')} | {100 * r['lap_flag']:.0f} % "
                      f"({100 * r['lap_truly']:.0f} %) | {r['spacing']} |", flush=True)
        w = {"laplacian": max(r["laplacian"] for r in rows), "lap_flag": max(r["lap_flag"] for r in rows),
             "lap_truly": max(r["lap_truly"] for r in rows)}
        for tag in ("", "_ok"):
            for c, target in (("c1", 0.68), ("c2", 0.95)):
                w[f"lap_{c}{tag}"] = max((r[f"lap_{c}{tag}"] for r in rows), key=lambda v: abs(v - target))
            w[f"lap_rz{tag}"] = max((r[f"lap_rz{tag}"] for r in rows), key=lambda v: abs(np.log(v)))
        print(f"| **worst** | - | - | {100 * w['laplacian']:.2f} % | {_cov(w, 'lap')}; {_cov(w, 'lap', '_ok')} | "
              f"{100 * w['lap_flag']:.0f} % ({100 * w['lap_truly']:.0f} %) | - |")


def _row(r, worst=False):
    lab = (f"{r['lab_ratio_src']:.0f}x better | {r['lab_ratio_lap']:.0f}x better" if worst else
           f"{100 * r['lab_source']:.1f} % | {100 * r['lab_laplacian']:.1f} %")
    speed = (f"{r['heat_over_fields']:.2f} x fields" if worst else f"{r['fields_s']:.1f} | {r['heat_s']:.1f}")
    print(f"| {r['scene']} | {r['seed']} | {r['data']} | {r['points']} x {r['times']} | {100 * r['source']:.2f} % | "
          f"{100 * r['laplacian']:.2f} % | {lab} | {_cov(r, 'src')}; {_cov(r, 'src', '_ok')} | "
          f"{100 * r['src_flag']:.0f} % | {_cov(r, 'lap')}; {_cov(r, 'lap', '_ok')} | {100 * r['lap_flag']:.0f} % "
          f"({100 * r['lap_truly']:.0f} %) | "
          f"{r['spacing']} | {speed} |", flush=True)


if __name__ == "__main__":
    main()
