"""The max principal strain's std from the strain tensor's noise covariance
(:mod:`irdic.uncertainty.strain`), against analytic truth."""

import numpy as np
import pytest
from scipy.special import i0e, i1e

from irdic.uncertainty.regression_bias import BIAS_Z
from irdic.uncertainty.strain import below_noise_floor, max_principal_rms, tensor_components
from irdic.strain import principal_2d, strain, strain_components

#: the demo barrel's strain noise: mean and both deviatoric components alike (3.7-4.1e-5 each), here in units
#: of it; and an anisotropic, correlated one
BARREL = np.eye(3)
ANISO = np.array([[0.6, 0.3, 0.1], [0.3, 1.5, 0.2], [0.1, 0.2, 0.4]])


def _rice_mse(r0, s):
    """E[(|d + n| - r0)²] for a 2-D ``n ~ N(0, s² I)``, ``|d| = r0``: ``2 r0² + 2 s² - 2 r0 E|d + n|``, the Rice
    mean ``s √(π/2) L_½(-r0²/2s²)`` (``L_½``: Laguerre, with exponentially scaled Bessel functions)."""
    x = -r0 ** 2 / (2 * s * s)
    laguerre = (1 - x) * i0e(-x / 2) - x * i1e(-x / 2)
    return 2 * r0 ** 2 + 2 * s * s - 2 * r0 * s * np.sqrt(np.pi / 2) * laguerre


def _estimate_for(r0, C):
    """Components whose method-of-moments magnitude is ``r0`` (along d1), mean 0, for an isotropic ``C``."""
    lam = np.linalg.eigvalsh(C[1:, 1:])
    return np.array([0.0, np.sqrt(r0 ** 2 + lam.sum() + BIAS_Z * np.sqrt(2 * np.sum(lam ** 2))), 0.0])


def test_tensor_components_give_the_principal_values():
    E2 = np.array([[[0.03, 0.01], [0.01, -0.02]], [[0.0, 0.0], [0.0, 0.0]]])
    c = tensor_components(E2)
    e_max, e_min, _ = principal_2d(E2)
    np.testing.assert_allclose(c[:, 0] + np.hypot(c[:, 1], c[:, 2]), e_max, rtol=0, atol=1e-15)
    np.testing.assert_allclose(c[:, 0] - np.hypot(c[:, 1], c[:, 2]), e_min, rtol=0, atol=1e-15)


def test_strain_components_are_strains_tensor():
    rng = np.random.default_rng(2)
    a, A = rng.normal(size=(4, 5, 2, 3)), rng.normal(size=(5, 2, 3))
    np.testing.assert_array_equal(strain_components(a, A), strain(a, A, tensors=False).E2)


@pytest.mark.parametrize("r0", [0.0, 0.3, 1.0, 1.5, 3.0, 8.0])
def test_rms_is_the_rice_error_at_the_estimated_magnitude(r0):
    """Isotropic deviatoric noise σ², independent mean noise σ_m²: the MSE of ``m̂ + |d̂|`` about ``m + r0`` is
    ``σ_m² + 2 r0² + 2 σ² - 2 r0 E|d̂|`` (Rice); the quadrature within 1 % in std (8 x 8 nodes: 0.9 % worst, at
    r0 ~ σ), exact at r0 = 0 (a polynomial: ``σ_m² + 2 σ²``)."""
    s, s_m = 2e-5, 1e-5
    C = np.diag([s_m ** 2, s ** 2, s ** 2])
    got = max_principal_rms(_estimate_for(r0 * s, C), C)
    want = np.sqrt(s_m ** 2 + _rice_mse(r0 * s, s))
    assert got == pytest.approx(want, rel=1e-12 if r0 == 0 else 0.01)


@pytest.mark.parametrize("C", [BARREL, ANISO])
def test_far_from_degeneracy_the_linearised_std(C):
    """|d| >> noise: ``C_mm + 2 uᵀ C_dm + uᵀ C_d u`` (``u = d/|d|``), the linearised std."""
    comp = np.array([[0.5, 60.0, -80.0], [-3.0, 4.0, 9.0]])  # |d| = 100 (linear branch) and 9.8 (quadrature)
    got = max_principal_rms(comp, C)
    u = comp[:, 1:] / np.linalg.norm(comp[:, 1:], axis=1, keepdims=True)
    lin = np.sqrt(C[0, 0] + 2 * u @ C[1:, 0] + np.einsum("ni,ij,nj->n", u, C[1:, 1:], u))
    assert got[0] == pytest.approx(lin[0], rel=1e-12)
    assert got[1] == pytest.approx(lin[1], rel=0.01)


@pytest.mark.parametrize("C", [BARREL, ANISO])
def test_zero_tensor_plus_noise_is_covered(C):
    """A static specimen: true tensor 0, estimates with Gaussian noise of known covariance. The std covers the
    error 0.60-0.76 within 1 std and 0.92-0.98 within 2 (barrel-like noise 0.64 / 0.94, anisotropic 0.66 / 0.93
    over 40,000 draws). The spread of ``e_max`` about the noisy estimate, what the probes measured before,
    covered 0.53 / 0.87: it is not the error's RMS where the max eigenvalue is not differentiable."""
    rng = np.random.default_rng(4)
    x = rng.multivariate_normal(np.zeros(3), C, size=40_000)
    err = x[:, 0] + np.hypot(x[:, 1], x[:, 2])  # the true e_max is 0
    z = np.abs(err) / max_principal_rms(x, C)
    assert 0.60 <= np.mean(z <= 1) <= 0.76 and 0.92 <= np.mean(z <= 2) <= 0.98, (np.mean(z <= 1), np.mean(z <= 2))
    # the std there is the error's RMS, its upward bias included
    assert np.sqrt(np.mean(err ** 2)) == pytest.approx(np.sqrt(np.mean(max_principal_rms(x, C) ** 2)), rel=0.05)


@pytest.mark.parametrize("r0", [0.5, 1.0, 2.0, 4.0, 10.0])
def test_covered_through_the_degeneracy(r0):
    """A tensor passing through near-equi-biaxial states: the coverage stays near the bands at every |d|
    (measured 0.67-0.77 / 0.95-0.97; the estimate's magnitude resolved only beyond one standard error of the
    noise, conservative near |d| ~ σ)."""
    rng = np.random.default_rng(5)
    true = np.array([0.2, 0.6 * r0, 0.8 * r0])
    x = true + rng.multivariate_normal(np.zeros(3), ANISO, size=20_000)
    err = x[:, 0] + np.hypot(x[:, 1], x[:, 2]) - (0.2 + r0)
    z = np.abs(err) / max_principal_rms(x, ANISO)
    assert 0.60 <= np.mean(z <= 1) <= 0.80 and 0.92 <= np.mean(z <= 2) <= 0.98, (np.mean(z <= 1), np.mean(z <= 2))


def test_nan_and_noise_floor():
    C = np.broadcast_to(BARREL, (3, 3, 3)).copy()
    C[1, 0, 0] = np.nan
    comp = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    out = max_principal_rms(comp, C)
    assert out[0] == pytest.approx(np.sqrt(3.0)) and np.isnan(out[1:]).all()
    np.testing.assert_array_equal(below_noise_floor([0.1, 5.0, 1.0, 1.0], [1.0, 1.0, 0.0, np.nan]),
                                  [True, False, False, False])


def test_probe_draws_the_record_in_blocks_as_at_once(monkeypatch):
    """A strain probe keeps its record-length noise at the probed stages only and draws it a block of stages at
    a time: the same numbers as one draw of the whole record from the same generator."""
    from types import SimpleNamespace

    from irdic.uncertainty import strain as us

    T, N = 40, 30
    sf = SimpleNamespace(info={}, stage_used=np.ones(T, bool), x=np.zeros((T, N, 3)))
    t = np.arange(T, dtype=float)
    sub = np.array([0, 3, 4, 17, 39])
    probe = us._StrainProbe(np.zeros((T, N, 3)), sf, t, sub, None)
    assert probe.stagewise
    monkeypatch.setattr(us, "_DRAW_BLOCK", 7 * N * 3)  # blocks of 7 stages
    dx, dref = probe.draw(np.random.default_rng(5), 0.003)
    assert dref is None
    np.testing.assert_array_equal(dx, (np.random.default_rng(5).standard_normal((T, N, 3)) * 0.003)[sub])
