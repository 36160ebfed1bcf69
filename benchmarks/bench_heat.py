"""The heat stage against the closed-form heat source, beside the plain lab approach on the same IR frames.

Scenes (the synthetic experiments of :mod:`irdic.synthetic`, closed-form
truth from :mod:`irdic.synthetic.laplacian`): the R 15 mm tube under
tension-torsion (moving) and the static R 40 mm half-shell patch ("barrel"),
steel (ρ 7850 kg/m³, c 470 J/(kg K), k 50 W/(m K)), τ = 60 s. Each scene
clean (noise-free frames and DIC) and realistic (0.05 K IR noise, 2-decimal
exports, mixed edge pixels, 0.003 mm DIC noise: the frames of
``bench_noisy_fields.realistic_stack``), coupled, through the fields stage
and the heat stage with their default settings.

The lab approach, on the same frames: each IR frame Gaussian-filtered
(``--lab-sigma`` px), the Laplacian by the five-point finite difference on
the pixel grid scaled by the pixel size on the specimen (mm/px, from the
DIC points' pixel positions), the rate by central differences of the
filtered frames in time at the fixed pixel, all sampled bilinearly at the
DIC points' pixel positions; Θ0 the first frame at the same pixel.

Errors over interior points (visible, 2 mm or more inside the DIC patch,
not the first or last DIC time): RMS relative to the largest true value
there; the coverage of ``heat_source_std`` (fraction within 1 and 2 std)
where ``heat_source_bias_dominated`` is False.

Usage (repository root, one BLAS thread on a shared machine)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_heat.py [--scale tiny|demo] [--scenes tube barrel]
        [--seed 3] [--lab-sigma 2.0]
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

from bench_noisy_fields import realistic_stack, scene  # noqa: E402

from irdic.camera import CameraModel  # noqa: E402
from irdic.heat.dataset import heat_dataset  # noqa: E402
from irdic.coupling import couple  # noqa: E402
from irdic.fields import fields  # noqa: E402
from irdic.synthetic.laplacian import temperature_laplacian  # noqa: E402

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
    ex = scene(name, scale, seed, 0.05 if realistic else 0.0, 0.003 if realistic else 0.0)
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
    h = heat_dataset(f, pts, {**MATERIAL, "laplacian_smoothing_time": time_spacing})
    t2 = time.perf_counter()
    tr = ex.truth().sel(point=pts.point)
    tt = tr.time.values[:, None]
    lap_true = temperature_laplacian(ex.specimen, tr.s.values[None], tr.h.values[None], tt)
    th_true = tr.temperature.values
    src_true = RHO * C * (tr.temperature_rate.values + (th_true - th_true[0]) / TAU) - K * 1e6 * lap_true
    m = pts.visible.values & (tr.patch_edge_distance.values >= 2.0)
    m[[0, -1]] = False
    lab_lap, lab_rate, lab_T = lab_approach(ir, pts, sigma, _mm_per_px(pts))
    lab_src = RHO * C * (lab_rate + (lab_T - lab_T[0]) / TAU) - K * 1e6 * lab_lap

    def rel(est, true):
        e = (est - true)[m]
        return float(np.sqrt(np.nanmean(e ** 2)) / np.nanmax(np.abs(true[m])))

    ok = m & ~h["heat_source_bias_dominated"].values
    z = np.abs(h["heat_source"].values - src_true)[m] / h["heat_source_std"].values[m]
    z_ok = np.abs(h["heat_source"].values - src_true)[ok] / h["heat_source_std"].values[ok]
    okl = m & ~h["temperature_laplacian_bias_dominated"].values
    zl = np.abs(h["temperature_laplacian"].values - lap_true)[okl] / h["temperature_laplacian_std"].values[okl]
    for k in spacings:
        hk = heat_dataset(f, pts, {**MATERIAL, "laplacian_smoothing": k})
        print(f"  {name} {'realistic' if realistic else 'clean'} spacing {k:g}: Laplacian "
              f"{100 * rel(hk['temperature_laplacian'].values, lap_true):.2f} %", flush=True)
    return {"scene": name, "data": "realistic" if realistic else "clean", "points": int(pts.point.size),
            "times": int(pts.time.size), "source": rel(h["heat_source"].values, src_true),
            "laplacian": rel(h["temperature_laplacian"].values, lap_true), "lab_source": rel(lab_src, src_true),
            "lab_laplacian": rel(lab_lap, lap_true), "cov1": float(np.nanmean(z <= 1)),
            "cov2": float(np.nanmean(z <= 2)), "cov1_ok": float(np.mean(z_ok <= 1)) if z_ok.size else float("nan"),
            "cov2_ok": float(np.mean(z_ok <= 2)) if z_ok.size else float("nan"), "lap_cov1": float(np.nanmean(zl <= 1)),
            "lap_cov2": float(np.nanmean(zl <= 2)), "flagged": float(1 - ok.sum() / m.sum()), "lap_flagged": float(1 - okl.sum() / m.sum()),
            "max_source": float(np.nanmax(np.abs(src_true[m]))), "max_lap": float(np.nanmax(np.abs(lap_true[m]))),
            "spacing": h.attrs["laplacian_spacing_chosen"] + "; in time: " + h.attrs["laplacian_smoothing_time_chosen"], "fields_s": t1 - t0, "heat_s": t2 - t1}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", default="demo", choices=["tiny", "demo", "paper"])
    ap.add_argument("--scenes", nargs="+", default=["tube", "barrel"], choices=["tube", "barrel"])
    ap.add_argument("--data", nargs="+", default=["clean", "realistic"], choices=["clean", "realistic"])
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--lab-sigma", type=float, default=2.0, help="Gaussian filter of the lab approach, px")
    ap.add_argument("--time-spacing", type=lambda v: v if v == "gcv" else (None if v == "none" else float(v)),
                    default="gcv", help="material.laplacian_smoothing_time: gcv, none or a number of DIC times")
    ap.add_argument("--spacings", type=float, nargs="*", default=[],
                    help="also the Laplacian's error at these fixed centre spacings (point spacings)")
    a = ap.parse_args(argv)
    print("| scene | data | points x times | source | Laplacian | lab source | lab Laplacian | source std 1/2 "
          "(all; unflagged, flagged share) | Laplacian std 1/2 (unflagged, flagged share) | spacing | fields s | "
          "heat s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in a.scenes:
        for data in a.data:
            r = measure(name, a.scale, a.seed, data == "realistic", a.lab_sigma, a.spacings, a.time_spacing)
            print(f"| {r['scene']} | {r['data']} | {r['points']} x {r['times']} | {100 * r['source']:.2f} % | "
                  f"{100 * r['laplacian']:.2f} % | {100 * r['lab_source']:.1f} % | {100 * r['lab_laplacian']:.1f} % | "
                  f"{r['cov1']:.2f} / {r['cov2']:.2f}; {r['cov1_ok']:.2f} / {r['cov2_ok']:.2f} "
                  f"({100 * r['flagged']:.0f} %) | {r['lap_cov1']:.2f} / {r['lap_cov2']:.2f} "
                  f"({100 * r['lap_flagged']:.0f} %) | {r['spacing']} | {r['fields_s']:.1f} | "
                  f"{r['heat_s']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
