"""Tests of irdic.numerics.saddle: the one saddle-point factorisation and its LU fallback."""

from __future__ import annotations

import numpy as np

from irdic.numerics.imq import imq_matrix
from irdic.numerics.saddle import SaddleFactor, solve_dense


def _system(n=40, ce=2.0, seed=3):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 10, (n, 2))
    return imq_matrix(x, x, ce), np.c_[np.ones(n), x], rng


def _dense(A, P, F, Q):
    n, m = P.shape
    S = np.block([[A, P], [P.T, np.zeros((m, m))]])
    sol = np.linalg.solve(S, np.concatenate([F, Q]))
    return sol[:n], sol[n:]


def test_solve_weights_coefficients_agree_with_the_dense_system():
    A, P, rng = _system()
    F = rng.standard_normal((40, 5))
    Q = rng.standard_normal((3, 5))
    fac = SaddleFactor(A.copy(), P)
    x_ref, y_ref = _dense(A, P, F, Q)
    x, y = fac.solve(F, Q)
    np.testing.assert_allclose(x, x_ref, atol=1e-8 * np.abs(x_ref).max())
    np.testing.assert_allclose(y, y_ref, atol=1e-8 * np.abs(y_ref).max())
    # weights are the transposed solve: W @ f = functional of the interpolant of f
    B = rng.standard_normal((7, 40))
    Qb = rng.standard_normal((7, 3))
    np.testing.assert_allclose(fac.weights(B, Qb), fac.solve(B.T, Qb.T)[0].T, rtol=0, atol=1e-12)
    a0, b0 = _dense(A, P, F, np.zeros((3, 5)))
    a, b = fac.coefficients(F)
    np.testing.assert_allclose(a, a0, atol=1e-8 * np.abs(a0).max())
    np.testing.assert_allclose(b, b0, atol=1e-8 * np.abs(b0).max())


def test_lu_fallback_when_the_kernel_matrix_is_not_positive_definite():
    # a flat kernel (c R0 = 400 x the spacing) is positive definite in exact
    # arithmetic but not numerically: the Cholesky fails, the LU of the whole
    # saddle matrix still reproduces linear data exactly
    x = np.stack(np.meshgrid(np.arange(8.0), np.arange(8.0)), -1).reshape(-1, 2)
    A = imq_matrix(x, x, 400.0)
    P = np.c_[np.ones(len(x)), x]
    fac = SaddleFactor(A.copy(), P, rebuild=lambda: imq_matrix(x, x, 400.0))
    assert fac.lu is not None and fac.cho is None
    f = (1.0 + 0.5 * x[:, 0] - 2.0 * x[:, 1])[:, None]
    alpha, beta = fac.coefficients(f)
    np.testing.assert_allclose(A @ alpha + P @ beta, f, atol=1e-6)
    np.testing.assert_allclose(beta[:, 0], [1.0, 0.5, -2.0], atol=1e-6)
    # the weights of "value at a point" reproduce linear data there
    q = np.array([[2.5, 3.25], [6.1, 0.4]])
    w = fac.weights(imq_matrix(q, x, 400.0), np.c_[np.ones(2), q])
    np.testing.assert_allclose(w @ f[:, 0], 1.0 + 0.5 * q[:, 0] - 2.0 * q[:, 1], atol=1e-4)


def test_solve_dense_matches_the_factorisation():
    A, P, rng = _system(12, 1.0)
    f = rng.standard_normal(12)
    q = np.array([1.0, 0.0, 0.0])
    x, y = solve_dense(A, P, f, q)
    x2, y2 = SaddleFactor(A, P).solve(f[:, None], q[:, None])
    np.testing.assert_allclose(x, x2[:, 0], atol=1e-9 * np.abs(x).max())
    np.testing.assert_allclose(y, y2[:, 0], atol=1e-9 * np.abs(y).max())


def test_from_cholesky_matches_the_factorisation():
    A, P, rng = _system()
    F = rng.standard_normal((40, 4))
    L = np.linalg.cholesky(A)
    L[np.triu_indices(40, 1)] = np.nan  # the upper triangle is never read
    ref = SaddleFactor(A.copy(), P)
    x0, y0 = ref.solve(F)
    # Y = A^-1 P comes with the first solve, or on its own when asked for first
    for first_solve in (True, False):
        fac = SaddleFactor.from_cholesky(np.asfortranarray(L), P)
        if not first_solve:
            np.testing.assert_allclose(fac.S_inv, ref.S_inv, rtol=1e-9)
        for _ in range(2):
            x, y = fac.solve(F)
            np.testing.assert_allclose(x, x0, atol=1e-9 * np.abs(x0).max())
            np.testing.assert_allclose(y, y0, atol=1e-9 * np.abs(y0).max())
        np.testing.assert_allclose(fac.Y, ref.Y, atol=1e-9 * np.abs(ref.Y).max())


def test_from_blocks_matches_the_factorisation():
    A, P, rng = _system()
    F = rng.standard_normal((40, 4))
    s = 25
    L_ss = np.linalg.cholesky(A[:s, :s])
    X = np.linalg.solve(L_ss, A[:s, s:])
    L_rr = np.linalg.cholesky(A[s:, s:] - X.T @ X)
    ref = SaddleFactor(A.copy(), P)
    x0, y0 = ref.solve(F)
    fac = SaddleFactor.from_blocks(np.asfortranarray(L_ss), np.asfortranarray(X), L_rr, P)
    for _ in range(2):  # the first solve also gives Y
        x, y = fac.solve(F)
        np.testing.assert_allclose(x, x0, atol=1e-9 * np.abs(x0).max())
        np.testing.assert_allclose(y, y0, atol=1e-9 * np.abs(y0).max())
    np.testing.assert_allclose(fac.coefficients(F)[0], ref.coefficients(F)[0], atol=1e-9 * np.abs(x0).max())
