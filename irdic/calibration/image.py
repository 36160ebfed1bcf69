"""The IR image of a calibration target: one frame as an array, its noise and validity.

Pixel convention: ``u`` = column, ``v`` = row, full-sensor coordinates,
0-based, pixel centres on integers (a cropped image keeps its offset).
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibrationError
from ..io.stack import image_array  # noqa: F401 - public here too: the calibration reads its target through it

__all__ = ["image_array", "noise_sigma", "check_image", "saturation_error", "MAX_INVALID_FRACTION"]

#: Largest fraction of NaN (invalid) pixels accepted in a calibration target
#: image. Markers whose measurement window touches a NaN pixel are left out;
#: beyond a few percent of scattered NaN pixels that leaves too few markers,
#: or markers in a biased part of the image, for a trustworthy camera.
MAX_INVALID_FRACTION = 0.05

# ----------------------------------------------------------------------------- image


def noise_sigma(img: np.ndarray) -> float:
    """Pixel noise (K) from the median absolute difference of horizontal neighbours."""
    d = np.diff(img, axis=1)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return 0.0
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / np.sqrt(2.0))


def check_image(img: np.ndarray, min_contrast_k: float, where: str = "") -> tuple[np.ndarray, dict, np.ndarray]:
    """Refuse blank or invalid images; fill NaN pixels for the morphology only.

    Returns the image with NaN pixels set to the median (the top-hat needs a
    value everywhere), the clipping statistics and the mask of NaN pixels,
    which the marker measurement of
    :func:`irdic.calibration.detect_markers` uses to reject every marker that touches one.
    """
    finite = np.isfinite(img)
    if finite.mean() < 0.5:
        raise CalibrationError(f"{where}target image is mostly invalid: only {finite.mean():.0%} of its pixels are finite")
    bad_frac = 1.0 - float(finite.mean())
    if bad_frac > MAX_INVALID_FRACTION:
        raise CalibrationError(
            f"{where}target image has {bad_frac:.1%} invalid (NaN) pixels, more than the {MAX_INVALID_FRACTION:.0%} "
            "accepted; markers touching invalid pixels cannot be measured, so record the target again (or export "
            "it without masked or dead pixels)"
        )
    vals = img[finite]
    lo, hi = np.percentile(vals, [0.1, 99.9])
    # pure Gaussian noise spans 6.2 sigma between these percentiles
    noise = noise_sigma(img)
    if hi - lo < max(min_contrast_k, 7.0 * noise):
        raise CalibrationError(
            f"target image is blank: its temperatures span only {hi - lo:.3f} K (0.1 to 99.9 percentile, "
            f"{lo:.2f} to {hi:.2f} °C), less than min_contrast_k = {min_contrast_k:g} K or 7 x the pixel noise "
            f"({noise:.3f} K); markers cannot be seen"
        )
    return_clip = {name: (float(level), float(np.mean(vals == level)))
                   for name, level in (("maximum", vals.max()), ("minimum", vals.min()))}
    if not finite.all():
        img = np.where(finite, img, np.median(vals))
    return img, return_clip, ~finite


def saturation_error(clip: dict) -> CalibrationError | None:
    """An error naming the clipped extreme when a sizeable part of the image sits exactly on it."""
    name, (level, frac) = max(clip.items(), key=lambda kv: kv[1][1])
    if frac < 0.01:
        return None
    return CalibrationError(
        f"target image is saturated: {frac:.0%} of its pixels sit at the {name} {level:.2f} °C (clipped at the "
        "end of the camera's measurement range) and no markers were found; record the target with a range "
        "that covers its temperature"
    )

