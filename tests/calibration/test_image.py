"""Multi-frame target images (irdic.calibration.image.mean_frame): a still target's frames are averaged, a moving
one is refused, and the mean frame calibrates as a target of higher contrast."""

import numpy as np
import pytest
import xarray as xr
from scipy import ndimage

from irdic.calibration import calibrate
from irdic.calibration.image import MAX_DRIFT_PX, mean_frame, noise_sigma
from irdic.camera import load_camera
from irdic.errors import CalibrationError
from irdic.synthetic.camera import lab_camera
from irdic.synthetic.target import clicked_seeds, open_book_target

from .test_solve import OBLIQUE, specimen_points


def _frames(clean: xr.DataArray, n: int, noise: float, seed: int, shift_px: float = 0.0, drift_k: float = 0.0):
    """``n`` frames of ``clean`` with independent pixel noise, each shifted by N(0, shift_px) px and offset by
    ``drift_k`` K per frame."""
    rng = np.random.default_rng(seed)
    img = clean.values.astype(float)
    out = []
    for k in range(n):
        f = ndimage.shift(img, rng.normal(0.0, shift_px, 2), order=3, mode="nearest") if shift_px else img
        out.append(f + rng.normal(0.0, noise, img.shape) + k * drift_k)
    return xr.DataArray(np.stack(out), dims=("time", "v", "u"),
                        coords={"time": np.arange(n, dtype=float), "v": clean.v.values, "u": clean.u.values},
                        attrs=dict(clean.attrs))


@pytest.fixture(scope="module")
def clean_oblique():
    return open_book_target(lab_camera(**OBLIQUE), noise=0.0, contrast=0.3, seed=62)


def test_still_frames_are_averaged_to_a_lower_noise(clean_oblique):
    """Nine frames of 0.1 K noise, a uniform drift of 0.02 K per frame (not a motion): their mean has 0.1 / 3 K."""
    frames = _frames(clean_oblique.image, 9, 0.1, seed=0, drift_k=0.02)
    mean = mean_frame(frames)
    assert mean.dims == ("v", "u") and mean.attrs["frames_averaged"] == 9
    np.testing.assert_allclose(noise_sigma(mean.values), 0.1 / 3, rtol=0.1)
    single = clean_oblique.image
    assert mean_frame(single) is single


def test_a_moving_target_is_refused(clean_oblique):
    """Frames shifted by 0.3 px RMS blur in their mean: refused with the motion and the limit in px."""
    frames = _frames(clean_oblique.image, 6, 0.1, seed=1, shift_px=0.3)
    with pytest.raises(CalibrationError, match=rf"target.tif: the target moved between the 6 frames .*\(~0\.[2-5]\d "
                                               rf"px RMS, more than {MAX_DRIFT_PX:g} px\)"):
        mean_frame(frames, where="target.tif: ")


def test_the_mean_of_frames_calibrates_a_faint_oblique_target():
    """Noise field 62, oblique, contrast/noise 3: one frame calibrates 0.14 px from the true camera (goal 0.12 px,
    the fit near its Cramer-Rao bound); the mean of four frames of the same still target, 0.07 px or better."""
    tg = open_book_target(lab_camera(**OBLIQUE), noise=0.0, contrast=0.3, seed=62)
    frames = _frames(tg.image, 4, 0.1, seed=62)
    cal = calibrate(mean_frame(frames), tg.markers, seeds=clicked_seeds(tg, 8, sigma_px=2.0, seed=62))
    x = specimen_points()
    assert np.sqrt(np.mean(np.sum((load_camera(cal).project(x) - tg.camera.project(x)) ** 2, axis=1))) < 0.07
