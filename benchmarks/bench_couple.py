"""Benchmark of the couple stage at paper scale, against the obvious scipy approach.

The paper's half-shell at ``scale="paper"`` (irdic.synthetic: ~10,000 DIC
points, 501 IR frames of a ~290 x 200 px specimen region inside a crop of the
1024 x 768 sensor, DIC at half the IR rate) is written to temporary stores;
:func:`irdic.stages.couple.run` then runs in a fresh subprocess so that its
peak resident memory is the stage's own. A second run evaluates at every IR
frame time (501 DIC times, as when both systems run at the same rate).

In the same run, the obvious approach, ``scipy.interpolate.RBFInterpolator(
kernel="inverse_multiquadric", epsilon=1/2, degree=1, neighbors=50)`` over the
masked pixels of each frame with derivatives by central differences, is
timed on a few DIC times and extrapolated; both are compared with the
analytic truth at those times.

Usage::

    python benchmarks/bench_couple.py [--subset 4] [--threads 1]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subset", type=int, default=4, help="DIC times for the scipy comparison")
    ap.add_argument("--threads", type=int, default=1, help="BLAS threads of the couple subprocess")
    args = ap.parse_args()

    import xarray as xr

    from irdic.camera import CameraModel
    from irdic.store import FrameStore, write_dataset
    from irdic.synthetic import halfshell_experiment

    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}")
    root = Path(tempfile.mkdtemp(prefix="bench_couple_"))
    try:
        t0 = time.perf_counter()
        ex = halfshell_experiment("paper")
        dic = ex.dic()
        truth = ex.truth()
        r = ex.renderer
        with FrameStore(root / "ir.zarr", "temperature", ex.ir_times.size, ("v", "u"),
                        {"v": r.v.astype(np.int64), "u": r.u.astype(np.int64)},
                        var_attrs={"units": "degC"}) as fs:
            for i, frame in enumerate(ex.ir_frames()):
                fs.write(i, float(ex.ir_times[i]), frame.values)
        write_dataset(dic, root / "dic.zarr", stage="bench")
        cam = ex.camera
        cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
        cal.attrs.update(sensor_width=1024, sensor_height=768)
        write_dataset(cal, root / "cal.zarr", stage="bench")
        # the same static specimen sampled at every IR frame time
        x0 = dic.x.isel(time=0).values
        dic_all = xr.Dataset({"x": (("time", "point", "component"), np.broadcast_to(x0, (ex.ir_times.size,) + x0.shape).copy())},
                             coords={"time": ex.ir_times, "point": dic.point.values, "component": ["x", "y", "z"]})
        write_dataset(dic_all, root / "dic_all.zarr", stage="bench")
        print(f"data: {dic.sizes['point']} points, {dic.sizes['time']} DIC times, {ex.ir_times.size} IR frames of "
              f"{r.v.size} x {r.u.size} px (built in {time.perf_counter() - t0:.0f} s)")

        env = dict(os.environ, OPENBLAS_NUM_THREADS=str(args.threads), OMP_NUM_THREADS=str(args.threads))
        for name, d in (("DIC at half the IR rate", "dic.zarr"), ("DIC at every IR frame", "dic_all.zarr")):
            code = ("import time; from irdic.stages import couple; t=time.perf_counter(); "
                    f"couple.run({{'dic': {str(root / d)!r}, 'ir': {str(root / 'ir.zarr')!r}, "
                    f"'calibration': {str(root / 'cal.zarr')!r}}}, {{'store': {str(root / ('points_' + d))!r}}}); "
                    "print(time.perf_counter()-t)")
            before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
            out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
            peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
            wall = float(out.stdout.strip().splitlines()[-1])
            print(f"irdic couple, {name}: {wall:.1f} s, peak RSS {max(peak, before) / 2**20:.2f} GB")

        from irdic.store import open_store

        pts = open_store(root / "points_dic.zarr")
        tr = truth.sel(point=pts.point)
        vis = pts.visible.values
        err = pts.temperature.values - tr.temperature.values
        inner = vis & (tr.patch_edge_distance.values >= 2)
        print(f"irdic accuracy (0.05 K IR noise): T RMS {np.sqrt(np.mean(err[vis]**2)):.4f} K all visible, "
              f"{np.sqrt(np.mean(err[inner]**2)):.4f} K >= 2 mm inside")

        # the obvious scipy approach on a few DIC times
        from scipy.interpolate import RBFInterpolator

        ir = open_store(root / "ir.zarr")
        ks = np.linspace(1, dic.sizes["time"] - 2, args.subset).astype(int)
        mask_px = None
        t_sc = 0.0
        errs_sc, errs_ir = [], []
        h = 0.05
        for k in ks:
            t = float(dic.time[k])
            n = int(np.argmin(np.abs(ex.ir_times - t)))  # DIC times coincide with IR frames here
            frame = ir.temperature[n].values
            pix = pts.pixel.values[k]
            ok = pts.visible.values[k]
            if mask_px is None:
                from irdic.footprint.mask import specimen_mask

                m = specimen_mask(pix[ok] - [r.u[0], r.v[0]], np.arange(r.u.size), np.arange(r.v.size), erosion_px=1.0)
                vv, uu = np.nonzero(m)
                mask_px = np.column_stack([uu + int(r.u[0]), vv + int(r.v[0])])
            t1 = time.perf_counter()
            rbf = RBFInterpolator(mask_px.astype(float), frame[mask_px[:, 1] - int(r.v[0]), mask_px[:, 0] - int(r.u[0])],
                                  kernel="inverse_multiquadric", epsilon=0.5, degree=1, neighbors=50)
            p = pix[ok]
            val = rbf(p)
            _ = (rbf(p + [h, 0]) - rbf(p - [h, 0])) / (2 * h), (rbf(p + [0, h]) - rbf(p - [0, h])) / (2 * h)
            t_sc += time.perf_counter() - t1
            errs_sc.append(val - tr.temperature.values[k][ok])
            errs_ir.append(pts.temperature.values[k][ok] - tr.temperature.values[k][ok])
        per = t_sc / len(ks)
        full = per * dic.sizes["time"]
        print(f"scipy RBFInterpolator(neighbors=50) + finite differences: {per:.2f} s per DIC time, "
              f"{full:.0f} s extrapolated to {dic.sizes['time']} times (no temporal interpolation, no local rate)")
        e1, e2 = np.concatenate(errs_sc), np.concatenate(errs_ir)
        print(f"accuracy on those {len(ks)} times: scipy {np.sqrt(np.mean(e1**2)):.4f} K RMS, "
              f"irdic {np.sqrt(np.mean(e2**2)):.4f} K RMS")
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
