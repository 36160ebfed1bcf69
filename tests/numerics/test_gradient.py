"""In-plane temperature gradient and material rate against a ray-cast closed-form scene."""

import numpy as np
import pytest

from irdic.errors import ConfigError
from irdic.gradient import (
    material_rate,
    parameter_derivatives,
    projected_gradient,
    rate_from_series,
    spatial_gradient,
    surface_gradient,
)

# --- the scene: a tube under tension-torsion seen by an exact pinhole camera ----------
R, L = 15.0, 40.0


def lam(t):
    return 1 + 0.02 * t


def phi(t):
    return 0.05 * t


def position(S, Z, t):
    r = R / np.sqrt(lam(t))
    a = S / R + phi(t) * Z / L
    return np.stack([r * np.sin(a), lam(t) * Z, r * np.cos(a)], -1)


def tangents(S, Z, t):
    r = R / np.sqrt(lam(t))
    a = S / R + phi(t) * Z / L
    e_t = np.stack([np.cos(a), 0 * a, -np.sin(a)], -1)
    e_z = np.stack([0 * a, 1 + 0 * a, 0 * a], -1)
    return np.stack([(r / R) * e_t, (r * phi(t) / L) * e_t + lam(t) * e_z], -2)


def velocity(S, Z, t):
    r = R / np.sqrt(lam(t))
    rdot = -0.5 * R * lam(t) ** -1.5 * 0.02
    a = S / R + phi(t) * Z / L
    adot = 0.05 * Z / L
    return np.stack([rdot * np.sin(a) + r * adot * np.cos(a), 0.02 * Z, rdot * np.cos(a) - r * adot * np.sin(a)], -1)


def theta(S, Z, t):
    return 20 + 3 * np.sin(S / 10) * np.cos(Z / 15) + 0.5 * t + 0.02 * Z * t


def dtheta_dpsi(S, Z, t):
    return np.stack([0.3 * np.cos(S / 10) * np.cos(Z / 15), -0.2 * np.sin(S / 10) * np.sin(Z / 15) + 0.02 * t], -1)


def dtheta_dt(S, Z, t):
    return 0.5 + 0.02 * Z


def look_at(C, target):
    z = (target - C) / np.linalg.norm(target - C)
    x = np.cross(z, [0.0, 1.0, 0.0])  # image u to the right
    x /= np.linalg.norm(x)
    y = np.cross(z, x)  # image v downwards
    return np.stack([x, y, z])


C_CAM = np.array([60.0, 25.0, 320.0])
K = np.array([[1750.0, 0, 511.5], [0, 1750.0, 383.5], [0, 0, 1]])
ROT = look_at(C_CAM, np.zeros(3))
M = K @ np.c_[ROT, -ROT @ C_CAM]


def project(x):
    h = x @ M[:, :3].T + M[:, 3]
    return h[..., :2] / h[..., 2:]


def jacobian(x, uv):
    """Eq. derivProjection, written from the formula."""
    den = x @ M[2, :3] + M[2, 3]
    return (M[None, :2, :3] - uv[..., :, None] * M[None, 2, None, :3]) / den[..., None, None]


def image_temperature(uv, t):
    """Ray-cast IR field: the temperature of the tube point seen at pixel uv at time t."""
    d = np.einsum("ij,...j->...i", ROT.T @ np.linalg.inv(K), np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], -1))
    r = R / np.sqrt(lam(t))
    a = d[..., 0] ** 2 + d[..., 2] ** 2
    b = 2 * (C_CAM[0] * d[..., 0] + C_CAM[2] * d[..., 2])
    c = C_CAM[0] ** 2 + C_CAM[2] ** 2 - r * r
    tau = (-b - np.sqrt(b * b - 4 * a * c)) / (2 * a)  # the near (visible) hit
    p = C_CAM + tau[..., None] * d
    Z = p[..., 1] / lam(t)
    S = R * (np.arctan2(p[..., 0], p[..., 2]) - phi(t) * Z / L)
    return theta(S, Z, t)


def scene(t=2.0):
    S, Z = np.meshgrid(np.linspace(-12, 12, 7), np.linspace(-15, 15, 5))
    S, Z = S.ravel(), Z.ravel()
    x = position(S, Z, t)
    uv = project(x)
    J = jacobian(x, uv)
    du = 1e-3
    g_pix = np.stack([
        (image_temperature(uv + [du, 0], t) - image_temperature(uv - [du, 0], t)) / (2 * du),
        (image_temperature(uv + [0, du], t) - image_temperature(uv - [0, du], t)) / (2 * du),
    ], -1)
    dt = 1e-4
    local = (image_temperature(uv, t + dt) - image_temperature(uv, t - dt)) / (2 * dt)
    return S, Z, t, x, uv, J, g_pix, local


def test_scene_is_consistent():
    S, Z, t, x, uv, J, g_pix, local = scene()
    # the ray cast sees the material point itself
    np.testing.assert_allclose(image_temperature(uv, t), theta(S, Z, t), atol=1e-10)
    assert (uv[:, 0] > 0).all() and (uv[:, 0] < 1024).all() and (uv[:, 1] > 0).all() and (uv[:, 1] < 768).all()


def test_in_plane_gradient_is_exact_for_exact_inputs():
    S, Z, t, x, uv, J, g_pix, local = scene()
    a = tangents(S, Z, t)
    grad = surface_gradient(g_pix, J, a)
    # closed form: dTheta/dPsi^alpha a^alpha with the analytic dual vectors
    g = np.einsum("nai,nbi->nab", a, a)
    dual = np.einsum("nab,nbi->nai", np.linalg.inv(g), a)
    truth = np.einsum("na,nai->ni", dtheta_dpsi(S, Z, t), dual)
    scale = np.abs(truth).max()
    assert scale > 0.1
    np.testing.assert_allclose(grad, truth, atol=1e-7 * scale)
    np.testing.assert_allclose(parameter_derivatives(g_pix, J, a), dtheta_dpsi(S, Z, t), atol=1e-7 * scale)
    # equivalently the tangential part of J^T g
    n = np.cross(a[:, 0], a[:, 1])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(projected_gradient(g_pix, J, n), truth, atol=1e-7 * scale)
    # and it is tangent: no normal component
    assert np.abs(np.einsum("ni,ni->n", grad, n)).max() < 1e-12


def test_material_rate_is_exact_for_exact_inputs():
    S, Z, t, x, uv, J, g_pix, local = scene()
    v = velocity(S, Z, t)
    # the analytic velocity agrees with a finite difference of the motion
    np.testing.assert_allclose(v, (position(S, Z, t + 1e-5) - position(S, Z, t - 1e-5)) / 2e-5, atol=1e-8)
    r = material_rate(local, g_pix, J, v)
    truth = dtheta_dt(S, Z, t)
    np.testing.assert_allclose(r.rate, truth, atol=2e-6)
    np.testing.assert_allclose(r.local + r.convective, r.rate, atol=1e-15)
    np.testing.assert_allclose(r.local, local, atol=0)
    # the convective part matters here: the point moves across the image
    assert np.abs(r.convective).max() > 0.01
    np.testing.assert_allclose(spatial_gradient(g_pix, J) @ np.ones(3), np.einsum("nk,nki->n", g_pix, J), atol=1e-15)


def test_broadcasting_and_nan_propagation():
    S, Z, t, x, uv, J, g_pix, local = scene()
    a = tangents(S, Z, t)
    g2 = np.stack([g_pix, g_pix])  # (T=2, N, 2)
    g2[1, 3] = np.nan
    grad = surface_gradient(g2, J, a)
    assert grad.shape == (2, S.size, 3)
    assert np.isnan(grad[1, 3]).all() and np.isfinite(grad[0]).all() and np.isfinite(np.delete(grad[1], 3, 0)).all()
    r = material_rate(np.stack([local, local]), g2, J, velocity(S, Z, t))
    assert r.rate.shape == (2, S.size) and np.isnan(r.rate[1, 3]) and np.isfinite(r.rate[0]).all()
    # degenerate tangents: NaN, no warning
    a_bad = a.copy()
    a_bad[0, 1] = a_bad[0, 0]
    assert np.isnan(surface_gradient(g_pix, J, a_bad)[0]).all()


def test_bad_input_messages():
    with pytest.raises(ConfigError, match=r"J must have shape \(\.\.\., 2, 3\), got \(3, 3\)"):
        spatial_gradient(np.zeros(2), np.zeros((3, 3)))
    with pytest.raises(ConfigError, match=r"g_pix must have shape \(\.\.\., 2\)"):
        spatial_gradient(np.zeros(3), np.zeros((2, 3)))
    with pytest.raises(ConfigError, match=r"do not broadcast: g_pix \(4,\), J \(5,\)"):
        spatial_gradient(np.zeros((4, 2)), np.zeros((5, 2, 3)))
    with pytest.raises(ConfigError, match="velocity must have shape"):
        material_rate(np.zeros(4), np.zeros((4, 2)), np.zeros((4, 2, 3)), np.zeros((4, 2)))


def heating_series(n_points, seed, noise):
    """A half-shell-like heating: 2 Hz for 250 s, per point amplitude and lag."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 250.01, 0.5)
    amp = rng.uniform(10, 60, n_points)
    tau = rng.uniform(40, 90, n_points)
    f = 22 + amp * (1 - np.exp(-t[:, None] / tau)) + 0.5 * np.sin(2 * np.pi * t[:, None] / 60)
    fd = amp / tau * np.exp(-t[:, None] / tau) + 0.5 * 2 * np.pi / 60 * np.cos(2 * np.pi * t[:, None] / 60)
    return t, f + rng.normal(0, noise, f.shape), fd


def test_smoothing_reduces_the_rate_error_of_noisy_temperatures():
    t, theta_noisy, truth = heating_series(300, 0, 0.05)
    inner = (t > 5) & (t < t[-1] - 5)
    r_int, _ = rate_from_series(theta_noisy, t)
    r_gcv, value = rate_from_series(theta_noisy, t, smoothing="gcv")
    e_int = np.sqrt(np.mean((r_int - truth)[inner] ** 2))
    e_gcv = np.sqrt(np.mean((r_gcv - truth)[inner] ** 2))
    # exact interpolation passes the 0.05 K noise into the rate (~0.14 K/s at 2 Hz)
    assert 0.1 < e_int < 0.2
    assert e_int / e_gcv >= 3.0
    assert e_gcv < 0.01
    # the smoothed values are closer to the truth than the noisy data
    clean = heating_series(300, 0, 0.0)[1]
    assert np.sqrt(np.mean((value - clean) ** 2)) < 0.5 * 0.05


def test_rate_from_clean_series_matches_interpolant():
    t, f, truth = heating_series(5, 1, 0.0)
    r, v = rate_from_series(f, t)
    inner = (t > 5) & (t < t[-1] - 5)
    np.testing.assert_allclose(v, f, atol=1e-12)  # interpolation at the stage times
    # the paper's interpolant (c = 1, R0 = 1 s at 2 Hz): 0.03 % of the peak rate 1.5 K/s
    assert np.abs(r - truth)[inner].max() < 5e-4
