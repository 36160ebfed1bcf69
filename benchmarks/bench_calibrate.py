"""Time and accuracy of one full calibration, next to the obvious approach.

irdic: :func:`irdic.calibration.calibrate` (top-hat detection with windowed,
background-subtracted centroids; seeds -> Hungarian correspondence;
Hartley-normalised DLT; Levenberg-Marquardt refinement; perspective bias
correction; leave-one-out outlier check) on the synthetic open-book target
(84 markers, 0.04 K noise, :func:`irdic.synthetic.lab_camera` poses).

Obvious approach: Otsu threshold + ``skimage.measure.regionprops`` centroid
(of the thresholded region, and intensity-weighted on the raw image), the
same correspondence, and a plain unnormalised DLT (SVD of the raw system).

Accuracy is measured against the true camera: reprojection RMS of the
markers, and the RMS distance between true and calibrated projections of
points on a specimen-like cylinder patch in front of the target.

Usage::

    python benchmarks/bench_calibrate.py [--repeat 5] [--poses 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from skimage.filters import threshold_otsu  # noqa: E402
from skimage.measure import label, regionprops  # noqa: E402

from irdic.calibration import calibrate  # noqa: E402
from irdic.camera import load_camera  # noqa: E402
from irdic.calibration import detect_markers  # noqa: E402
from irdic.calibration.correspondence import assign  # noqa: E402
from irdic.synthetic.camera import lab_camera  # noqa: E402
from irdic.synthetic.target import open_book_target  # noqa: E402

POSES = [dict(), dict(distance=400.0, azimuth_deg=-12.0, elevation_deg=-6.0, roll_deg=-2.0),
         dict(distance=520.0, azimuth_deg=25.0, elevation_deg=18.0, roll_deg=4.0),
         dict(distance=300.0, azimuth_deg=30.0, elevation_deg=5.0)]


def specimen_points(n=2000, seed=1):
    rng = np.random.default_rng(seed)
    phi = rng.uniform(-0.6, 0.6, n)
    y = rng.uniform(-20, 20, n)
    return np.column_stack([30 * np.sin(phi), y, -15 + 30 * np.cos(phi)])


def plain_dlt(x, uv):
    """The textbook DLT without normalisation: SVD of the raw 2N x 12 system."""
    n = len(x)
    Xh = np.hstack([x, np.ones((n, 1))])
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = Xh
    A[0::2, 8:12] = -uv[:, :1] * Xh
    A[1::2, 4:8] = Xh
    A[1::2, 8:12] = -uv[:, 1:] * Xh
    M = np.linalg.svd(A)[2][-1].reshape(3, 4)
    return M / np.linalg.norm(M[2, :3])


def project(M, x):
    h = x @ M[:, :3].T + M[:, 3]
    return h[:, :2] / h[:, 2:3]


def regionprops_centres(image, weighted):
    img = image.values.astype(np.float64)
    dark = img < threshold_otsu(img)  # markers are dark; the background too, so keep compact blobs
    props = regionprops(label(dark), intensity_image=img.max() - img)
    out = [p.centroid_weighted if weighted else p.centroid for p in props if 10 <= p.area <= 600
           and p.eccentricity < 0.95 and p.solidity > 0.85]
    return np.array(out)[:, ::-1]  # (row, col) -> (u, v)


def rms(a):
    return float(np.sqrt(np.mean(np.sum(a**2, axis=-1))))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--poses", type=int, default=3)
    args = ap.parse_args(argv)
    xs = specimen_points()
    print(f"{'pose':>4} {'method':<38} {'time s':>8} {'marker RMS px':>14} {'specimen RMS px':>16} {'max px':>8}")
    for k, pose in enumerate(POSES[: args.poses]):
        tg = open_book_target(lab_camera(**pose), seed=k)
        cam = tg.camera
        ids = tg.markers.marker.values
        pix = tg.truth.marker_pixel.values
        rng = np.random.default_rng(k)
        seeds = {int(ids[i]): (pix[i] + rng.uniform(-2, 2, 2)).tolist() for i in (3, 17, 30, 47, 66, 79)}
        truth_xs = cam.project(xs)
        times = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for _ in range(args.repeat):
                t = time.perf_counter()
                cal = calibrate(tg.image, tg.markers, seeds=seeds)
                times.append(time.perf_counter() - t)
        err = load_camera(cal).project(xs) - truth_xs
        print(f"{k:>4} {'irdic calibrate (full)':<38} {statistics.median(times):8.3f} {float(cal.rms_px):14.4f} "
              f"{rms(err):16.4f} {np.abs(err).max():8.4f}")
        t = time.perf_counter()
        det = detect_markers(tg.image)
        t_det = time.perf_counter() - t
        D = np.column_stack([det.u.values, det.v.values])
        for name, fn in (("regionprops centroid + plain DLT", lambda: regionprops_centres(tg.image, False)),
                         ("regionprops weighted + plain DLT", lambda: regionprops_centres(tg.image, True)),
                         ("irdic detection + plain DLT", lambda: D)):
            t = time.perf_counter()
            C = fn()
            mi, di = assign(pix, C, 3.0)
            M = plain_dlt(tg.markers.x.values[mi], C[di])
            dt = time.perf_counter() - t + (t_det if name.startswith("irdic") else 0.0)
            res = project(M, tg.markers.x.values[mi]) - C[di]
            err = project(M, xs) - truth_xs
            print(f"{k:>4} {name + f' ({len(mi)} m.)':<38} {dt:8.3f} {rms(res):14.4f} {rms(err):16.4f} "
                  f"{np.abs(err).max():8.4f}")


if __name__ == "__main__":
    main()
