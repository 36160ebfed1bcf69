"""The IR image of a calibration target: one frame as an array, its noise and validity.

Pixel convention: ``u`` = column, ``v`` = row, full-sensor coordinates,
0-based, pixel centres on integers (a cropped image keeps its offset).
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibrationError
from ..validation import image_array

__all__ = ["image_array", "mean_frame", "noise_sigma", "check_image", "saturation_error", "MAX_INVALID_FRACTION",
           "MAX_DRIFT_PX"]

#: Largest RMS motion (px) of the target between the frames of a multi-frame
#: target image: the mean of moving frames blurs the markers.
MAX_DRIFT_PX = 0.05

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


def mean_frame(image, where: str = ""):
    """The mean of a multi-frame target image (dims ``time``, ``v``, ``u``), checked for motion; other images
    as they are.

    Averaging ``N`` frames of a still target divides the pixel noise by
    ``sqrt(N)``: a faint target seen obliquely is calibrated as if its
    contrast were ``sqrt(N)`` times higher. A target that moves between the
    frames blurs in their mean.

    Parameters
    ----------
    image : xarray.DataArray or array_like
        The target image; a DataArray with a ``time`` dimension of length > 1
        is averaged over it (NaN pixels ignored).
    where : str
        Prefix of the error message (the file).

    Returns
    -------
    xarray.DataArray or array_like
        ``image`` itself, or the mean frame (dims ``v``, ``u``, the same
        coordinates, attrs ``frames_averaged``).

    Raises
    ------
    CalibrationError
        The target moved between the frames by more than
        :data:`MAX_DRIFT_PX` RMS.

    Notes
    -----
    A motion of ``δ`` px RMS adds ``|∇I|² δ²`` to the temporal variance
    ``s²`` of a pixel with the spatial gradient ``∇I`` of the mean frame; a
    uniform drift of the temperature adds the same to every pixel. ``δ²`` is
    the slope of the least-squares line of ``s²`` on ``|∇I|²`` over the
    pixels (the noise's sample mean and variance are independent, so the
    noise in ``∇I`` does not bias it); the target is refused where the slope
    exceeds ``MAX_DRIFT_PX²`` by three of its standard errors (a faint
    target's gradients are small and its slope noisy).
    """
    import xarray as xr

    if not (isinstance(image, xr.DataArray) and "time" in image.dims and image.sizes["time"] > 1):
        return image
    frames = image.transpose("time", "v", "u")
    mean = frames.mean("time", skipna=True)
    v = np.asarray(frames.values, dtype=np.float64)
    m = np.asarray(mean.values, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        s2 = np.nanvar(v, axis=0, ddof=1)
        gv, gu = np.gradient(m)
        g2 = gv ** 2 + gu ** 2
    ok = np.isfinite(s2) & np.isfinite(g2)
    if ok.sum() > 100:
        # the temporal variance regressed on the squared gradient over all pixels: slope δ², with its standard error
        x, y = g2[ok] - g2[ok].mean(), s2[ok] - s2[ok].mean()
        sxx = float(x @ x)
        slope = float(x @ y) / max(sxx, 1e-300)
        se = float(np.sqrt(np.sum((y - slope * x) ** 2) / (x.size - 2) / max(sxx, 1e-300)))
        if slope - 3.0 * se > MAX_DRIFT_PX ** 2:
            raise CalibrationError(
                f"{where}the target moved between the {v.shape[0]} frames of the target image (~{np.sqrt(slope):.2f} "
                f"px RMS, more than {MAX_DRIFT_PX:g} px): their mean would blur the markers; give one frame, or "
                "frames of a still target"
            )
    return mean.assign_attrs({**image.attrs, "frames_averaged": int(v.shape[0])})
