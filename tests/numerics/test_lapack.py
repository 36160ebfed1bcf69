"""The GIL-free BLAS/LAPACK calls: the same numbers as scipy.linalg's wrappers, bit for bit."""

import ctypes

import numpy as np
import pytest
import scipy.linalg
from scipy.linalg import blas, lapack as scipy_lapack

from irdic.numerics import lapack


def _spd(rng, n):
    a = rng.standard_normal((n, n))
    return a @ a.T + n * np.eye(n)


@pytest.mark.parametrize("n, k", [(1, 1), (7, 3), (300, 40)])
def test_cholesky_factor_and_solve_equal_scipys(n, k):
    rng = np.random.default_rng(n)
    a = _spd(rng, n)
    b = rng.standard_normal((n, k))
    ours, theirs = lapack.cho_factor(a, lower=True), scipy.linalg.cho_factor(a, lower=True, check_finite=False)
    np.testing.assert_array_equal(np.tril(ours[0]), np.tril(theirs[0]))
    np.testing.assert_array_equal(lapack.cho_solve(ours, b), scipy.linalg.cho_solve(theirs, b, check_finite=False))
    np.testing.assert_array_equal(lapack.cho_solve(ours, b[:, 0]),
                                  scipy.linalg.cho_solve(theirs, b[:, 0], check_finite=False))
    c, info = lapack.potrf(a, lower=True)
    c_s, info_s = scipy_lapack.dpotrf(a, lower=1, clean=0)
    assert info == info_s == 0
    np.testing.assert_array_equal(c, c_s)  # the other triangle kept as scipy keeps it (clean=0)
    np.testing.assert_array_equal(lapack.potrs(c, b, lower=True)[0], scipy_lapack.dpotrs(c_s, b, lower=1)[0])


@pytest.mark.parametrize("trans", [False, True])
def test_triangular_products_and_solves_equal_scipys_on_blocks_and_copies(trans):
    rng = np.random.default_rng(3)
    L = np.asfortranarray(np.tril(scipy.linalg.cholesky(_spd(rng, 200), lower=True)))
    b = rng.standard_normal((200, 17))
    for a in (L, L[:57, :57], np.ascontiguousarray(L[:31, :31]), L.T[:40, :40]):  # Fortran, block, C, C view
        lower = bool(np.allclose(a, np.tril(a)))
        m = a.shape[0]
        np.testing.assert_array_equal(lapack.trsm(1.0, a, b[:m], lower=lower, trans_a=trans),
                                      blas.dtrsm(1.0, a, b[:m], lower=lower, trans_a=trans))
        np.testing.assert_array_equal(lapack.trmm(2.5, a, b[:m], lower=lower, trans_a=trans),
                                      blas.dtrmm(2.5, a, b[:m], lower=lower, trans_a=trans))


def test_right_hand_sides_overwritten_only_when_asked():
    rng = np.random.default_rng(5)
    L = np.tril(scipy.linalg.cholesky(_spd(rng, 20), lower=True))
    b = np.asfortranarray(rng.standard_normal((20, 4)))
    kept = b.copy()
    x = lapack.trsm(1.0, L, b, lower=True)
    np.testing.assert_array_equal(b, kept)
    y = lapack.trsm(1.0, L, b, lower=True, overwrite_b=True)
    assert y is b
    np.testing.assert_array_equal(y, x)


def test_not_positive_definite_raises_linalgerror():
    with pytest.raises(np.linalg.LinAlgError, match="2-th leading minor"):
        lapack.cho_factor(np.diag([1.0, -1.0, 1.0]))


def test_shapes_are_checked():
    with pytest.raises(ValueError, match="square"):
        lapack.trsm(1.0, np.ones((3, 2)), np.ones((3, 1)))
    with pytest.raises(ValueError, match="3 rows"):
        lapack.trsm(1.0, np.eye(3), np.ones((2, 1)))


def test_routines_are_called_without_the_gil():
    # ctypes releases the GIL for CFUNCTYPE functions, not for PYFUNCTYPE ones
    for f in (lapack._dtrsm, lapack._dtrmm, lapack._dpotrf, lapack._dpotrs):
        assert not f._flags_ & ctypes._FUNCFLAG_PYTHONAPI


def test_lu_solves_on_one_factorisation_from_threads_equal_the_serial_solve():
    # scipy's getrs wrapper shifts the shared pivots in place with the GIL released: concurrent solves with one
    # factorisation returned wrong solutions (about half of them, scipy 1.17.1) before the private copy
    from irdic.numerics.threads import parallel_map
    from irdic.threads import blas_threads, stage_threads

    rng = np.random.default_rng(0)
    a = rng.normal(size=(60, 60)) + 10 * np.eye(60)
    b = rng.normal(size=(60, 300))
    lu = scipy.linalg.lu_factor(a)
    with stage_threads(2):
        with blas_threads(1):
            ref = lapack.lu_solve(lu, b)
        out = [x for _ in range(50) for x in parallel_map(lambda _: lapack.lu_solve(lu, b), range(4))]
    np.testing.assert_allclose(ref, scipy.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    assert all(np.array_equal(x, ref) for x in out)
    np.testing.assert_allclose(lapack.lu_solve(lu, b, trans=1), scipy.linalg.solve(a.T, b), rtol=1e-10, atol=1e-12)


def test_no_module_solves_with_scipys_lu_solve_directly():
    # every LU solve goes through lapack.lu_solve (private pivots): the fill's and the saddle factor's LU factors
    # are shared by the stage's threads
    from pathlib import Path

    import irdic

    root = Path(irdic.__file__).parent
    direct = [str(f.relative_to(root)) for f in root.rglob("*.py")
              if f.name != "lapack.py" and "linalg.lu_solve(" in f.read_text(encoding="utf-8")]
    assert direct == []
