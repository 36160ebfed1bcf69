"""Footprint temperatures (issue 15): local-linear box values of the IR pixels, against analytic truth."""

import numpy as np

from irdic.noise import interpolation_noise_gains
from irdic.stages.footprint_temperature import FootprintOperator, footprint_side


def _disc(H=40, W=50, r=15.0):
    v, u = np.mgrid[:H, :W].astype(float)
    return (u - 24.3) ** 2 + (v - 19.6) ** 2 <= r * r, u, v


def test_linear_field_is_reproduced_up_to_the_mask_edge():
    # a cut box's plain mean would sit off the pixel: a bias of the gradient (0.8 K/px) times the shift
    mask, u, v = _disc()
    frames = np.stack([20.0 + 0.8 * u - 0.3 * v, 25.0 - 0.1 * u + 0.6 * v])
    out = FootprintOperator(3).frames(frames, mask)
    np.testing.assert_allclose(out[:, mask], frames[:, mask], atol=1e-9)
    # outside the mask the frames are left as they are
    np.testing.assert_array_equal(out[:, ~mask], frames[:, ~mask])


def test_quadratic_field_offset_and_noise_reduction():
    mask, u, v = _disc(r=18.0)
    side = 3
    frames = (0.02 * u ** 2 + 0.01 * v ** 2)[None]
    out = FootprintOperator(side).frames(frames, mask)[0]
    inner = np.zeros_like(mask)
    inner[1:-1, 1:-1] = mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:] & mask[:-2, :-2] \
        & mask[2:, 2:] & mask[:-2, 2:] & mask[2:, :-2] & mask[1:-1, 1:-1]
    # the box mean of a quadratic: the field plus (side² - 1) / 24 ∇²Θ, ∇²Θ = 2 (0.02 + 0.01) K/px²
    np.testing.assert_allclose(out[inner] - frames[0][inner], (side ** 2 - 1) / 24 * 0.06, atol=1e-12)
    rng = np.random.default_rng(1)
    noise = rng.standard_normal((20,) + mask.shape)
    f = FootprintOperator(side).frames(noise, mask)
    # white noise through a full box of side² pixels: std 1/side (0.333)
    assert abs(f[:, inner].std() - 1 / side) < 0.02, f[:, inner].std()
    # the couple stage's gain of the interpolated footprint temperature (probe): about 1/side of the plain one's
    t = np.arange(8) * 0.25
    g1 = interpolation_noise_gains(t, c=0.95, R0=1.0).temperature
    g3 = interpolation_noise_gains(t, c=0.95, R0=1.0, footprint=3).temperature
    assert 0.25 < g3 / g1 < 0.45, (g1, g3)


def test_footprint_side_is_the_largest_odd_box_within_the_point_spacing():
    for spacing, side in ((3.1, 3), (2.0, 1), (5.5, 5), (7.0, 5)):
        g = np.stack(np.meshgrid(np.arange(10) * spacing, np.arange(10) * spacing), -1).reshape(1, -1, 2)
        # the two fields of irdic.stages.visibility.Projection it reads
        fake = type("P", (), {"local": g, "in_frame": np.ones(g.shape[:2], bool)})()
        assert footprint_side(fake) == side, (spacing, footprint_side(fake))
