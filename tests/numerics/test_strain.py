"""In-plane strain from tangent vectors against closed-form deformations."""

import numpy as np
import pytest

from irdic.errors import ConfigError
from irdic.strain import (
    deformation_gradient,
    equivalent_strain,
    principal_2d,
    reference_basis,
    strain,
    strain_tensor,
)


def _rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_affine_deformation_of_a_tilted_plane_is_exact():
    rng = np.random.default_rng(1)
    Rp = _rot([1, 2, 0.5], 0.7)
    # reference tangents: a skew, non-unit parametrisation of a tilted plane
    A = np.stack([Rp @ [1.3, 0.2, 0.0], Rp @ [-0.4, 0.9, 0.0]])
    N = Rp @ [0, 0, 1.0]
    F0 = np.eye(3) + 0.05 * rng.standard_normal((3, 3))
    a = A @ F0.T  # a_alpha = F0 A_alpha
    st = strain(a, A)
    P0 = np.eye(3) - np.outer(N, N)
    E_true = 0.5 * (P0 @ F0.T @ F0 @ P0 - P0)
    np.testing.assert_allclose(st.E, E_true, atol=1e-14)
    # F maps the reference tangents onto the current ones and kills the normal
    np.testing.assert_allclose(st.F @ A.T, a.T, atol=1e-14)
    np.testing.assert_allclose(st.F @ N, 0, atol=1e-14)
    np.testing.assert_allclose(st.F, deformation_gradient(a, A), atol=0)
    # principal values = the two non-zero eigenvalues of E_true
    w, v = np.linalg.eigh(E_true)
    w_in = w[np.argsort(np.abs(v.T @ N))[:2]]  # drop the normal eigenvector
    np.testing.assert_allclose([st.e_max, st.e_min], np.sort(w_in)[::-1], atol=1e-14)
    # directions: unit, in plane, eigenvectors of E, mutually orthogonal
    for d, e in ((st.direction_max, st.e_max), (st.direction_min, st.e_min)):
        assert abs(np.linalg.norm(d) - 1) < 1e-14 and abs(d @ N) < 1e-14
        np.testing.assert_allclose(E_true @ d, e * d, atol=1e-14)
    assert abs(st.direction_max @ st.direction_min) < 1e-14
    # 2x2 components in the orthonormal reference basis
    B = st.basis
    np.testing.assert_allclose(B @ B.T, np.eye(2), atol=1e-14)
    np.testing.assert_allclose(B[0], A[0] / np.linalg.norm(A[0]), atol=1e-15)
    np.testing.assert_allclose(st.E2, B @ E_true @ B.T, atol=1e-14)
    # current directions: F N / |F N|, orthogonal (principal axes of the left stretch)
    np.testing.assert_allclose(st.direction_max_current,
                               F0 @ st.direction_max / np.linalg.norm(F0 @ st.direction_max), atol=1e-14)
    assert abs(st.direction_max_current @ st.direction_min_current) < 1e-13
    np.testing.assert_allclose(st.stretch_max, np.sqrt(1 + 2 * st.e_max), rtol=1e-15)


def test_tube_tension_torsion_closed_form():
    # tube R = 15, gauge 40 mm, stretch lam, twist phi, isochoric radius r = R / sqrt(lam)
    R, L, lam, phi = 15.0, 40.0, 1.04, 0.3
    r = R / np.sqrt(lam)
    theta = np.linspace(-1.2, 1.2, 7)
    Z = np.linspace(-20, 20, 5)[:, None]
    ang = theta + phi * Z / L
    e_t = np.stack([np.cos(ang), np.zeros_like(ang), -np.sin(ang)], -1)  # e_theta, current
    e_z = np.broadcast_to([0.0, 1.0, 0.0], e_t.shape)
    e_t0 = np.broadcast_to(np.stack([np.cos(theta), 0 * theta, -np.sin(theta)], -1), e_t.shape)
    A = np.stack([e_t0, e_z], axis=-2)  # (S, Z) reference tangents (S = R theta)
    a = np.stack([(r / R) * e_t, (r * phi / L) * e_t + lam * e_z], axis=-2)
    st = strain(a, A)
    C = np.array([[(r / R) ** 2, (r / R) * (r * phi / L)], [(r / R) * (r * phi / L), lam**2 + (r * phi / L) ** 2]])
    E2 = 0.5 * (C - np.eye(2))
    np.testing.assert_allclose(st.E2, np.broadcast_to(E2, st.E2.shape), atol=1e-14)
    E3 = (E2[0, 0] * np.einsum("...i,...j->...ij", e_t0, e_t0)
          + E2[0, 1] * (np.einsum("...i,...j->...ij", e_t0, e_z) + np.einsum("...i,...j->...ij", e_z, e_t0))
          + E2[1, 1] * np.einsum("...i,...j->...ij", e_z, e_z))
    np.testing.assert_allclose(st.E, E3, atol=1e-14)
    w = np.linalg.eigvalsh(E2)
    np.testing.assert_allclose(st.e_max, w[1], atol=1e-14)
    np.testing.assert_allclose(st.e_min, w[0], atol=1e-14)
    assert st.e_max.shape == (5, 7)
    # concrete values of this load case
    assert st.e_max.flat[0] == pytest.approx(0.077216, abs=2e-6)
    assert st.e_min.flat[0] == pytest.approx(-0.049562, abs=2e-6)


def test_rigid_motion_gives_zero_strain_and_no_directions():
    A = np.array([[1.0, 0, 0], [0.3, 1.0, 0]])
    Q = _rot([0.2, -1, 0.4], 1.1)
    st = strain(A @ Q.T, A)
    np.testing.assert_allclose(st.E, 0, atol=1e-15)
    assert np.isnan(st.direction_max).all() and np.isnan(st.direction_min).all()
    assert st.equivalent == pytest.approx(0, abs=1e-15)


def test_broadcast_reference_against_time_and_nan_propagation():
    A = np.tile(np.array([[1.0, 0, 0], [0, 1.0, 0]]), (4, 1, 1))  # (N, 2, 3)
    a = np.stack([A * 1.0, A * 1.1, A * 1.2])  # (T, N, 2, 3): equibiaxial
    a[1, 2, 0, 0] = np.nan
    st = strain(a, A)
    assert st.E.shape == (3, 4, 3, 3) and st.e_max.shape == (3, 4)
    np.testing.assert_allclose(st.e_max[2], 0.5 * (1.2**2 - 1), rtol=1e-14)
    assert np.isnan(st.e_max[1, 2]) and np.isfinite(st.e_max[1, [0, 1, 3]]).all()


def test_degenerate_reference_gives_nan():
    A = np.array([[1.0, 0, 0], [2.0, 0, 0]])  # parallel tangents
    st = strain(A, A)
    assert np.isnan(st.E).all() and np.isnan(st.e_max)


def test_equivalent_strain_formula():
    eps = 0.02
    # uniaxial, incompressible: e2 = -e1 / 2 gives eps
    assert equivalent_strain(eps, -eps / 2) == pytest.approx(eps, rel=1e-14)
    # pure shear in plane: 2 / sqrt(3) gamma
    assert equivalent_strain(eps, -eps) == pytest.approx(2 / np.sqrt(3) * eps, rel=1e-14)
    # equibiaxial: thickness strain -2 eps, von Mises 2 eps
    assert equivalent_strain(eps, eps) == pytest.approx(2 * eps, rel=1e-14)


def test_principal_2d_angle():
    th = 0.3
    Q = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    E2 = Q @ np.diag([0.03, -0.01]) @ Q.T
    e1, e2, ang = principal_2d(E2)
    assert (e1, e2) == pytest.approx((0.03, -0.01), abs=1e-15)
    assert ang == pytest.approx(th, abs=1e-13)


def test_reference_basis_is_right_handed():
    A = np.array([[2.0, 0, 0], [1.0, 3.0, 0]])
    B, n = reference_basis(A)
    np.testing.assert_allclose(n, [0, 0, 1])
    np.testing.assert_allclose(np.cross(B[0], B[1]), n, atol=1e-15)


def test_bad_shapes_are_config_errors():
    with pytest.raises(ConfigError, match=r"tangents must have shape \(\.\.\., 2, 3\).*\(3, 3\)"):
        strain(np.eye(3), np.eye(3)[:2])
    with pytest.raises(ConfigError, match="do not broadcast"):
        strain(np.zeros((4, 2, 3)), np.zeros((5, 2, 3)))
    with pytest.raises(ConfigError, match="ref_tangents must be an array of numbers"):
        strain(np.zeros((2, 3)), [["a", "b", "c"], ["d", "e", "f"]])


def test_tensors_can_be_left_out_and_rebuilt():
    rng = np.random.default_rng(2)
    A = np.stack([[1.0, 0.1, 0.0], [0.0, 1.0, 0.2]]) + 0.01 * rng.standard_normal((6, 2, 3))
    a = A + 0.02 * rng.standard_normal((3, 6, 2, 3))
    full = strain(a, A)
    lean = strain(a, A, tensors=False)
    assert lean.E is None and lean.F is None
    np.testing.assert_array_equal(lean.e_max, full.e_max)
    np.testing.assert_allclose(strain_tensor(lean.E2, lean.basis), full.E, atol=1e-15)


def test_strain_in_blocks_of_times_on_threads_equals_the_whole():
    from irdic.strain import _strain
    from irdic.threads import stage_threads

    rng = np.random.default_rng(3)
    A = rng.normal(size=(40, 2, 3))
    a = A + 0.02 * rng.normal(size=(7, 40, 2, 3))
    a[2, 5] = np.nan
    with stage_threads(2):
        got = strain(a, A, tensors=False)
    want = _strain(a, A, (7, 40), False)
    for name in got._fields:
        x, y = getattr(got, name), getattr(want, name)
        assert (x is None and y is None) or np.array_equal(x, y, equal_nan=True), name
