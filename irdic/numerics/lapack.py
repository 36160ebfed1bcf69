"""The BLAS and LAPACK routines of the hot loops, called so that they release the GIL.

scipy.linalg's wrappers (``cho_factor``, ``cho_solve``, ``solve_triangular``,
``blas.dtrsm``, ``lapack.dpotrf``, ...) hold Python's global interpreter lock
while the routine runs, so a stage's worker threads
(:func:`irdic.numerics.threads.parallel_map`) that factorise or solve run one
at a time: a second thread spinning in Python gets about a fifth of its
speed while one thread calls ``dpotrf``, against all of it during numpy's
``matmul`` (scipy 1.17, 2-core VM). The functions here call the same
routines of the same library (scipy's ``cython_blas`` and ``cython_lapack``
export their addresses) through :mod:`ctypes`, which releases the lock for
the call: the same routine on the same arguments and memory layout, so the
same numbers bit for bit, and the threads run at once.

Arrays are float64; matrices are passed in Fortran order (a copy where they
are not, as scipy's wrappers make one; a block of a Fortran-ordered matrix
as it is, with its leading dimension), right-hand sides of shape (n, k) or
(n,).
"""

from __future__ import annotations

import ctypes

import numpy as np
import scipy.linalg
import scipy.linalg.cython_blas as _cython_blas
import scipy.linalg.cython_lapack as _cython_lapack

__all__ = ["cho_factor", "cho_solve", "potrf", "potrs", "trsm", "trmm", "lu_solve"]

_CHAR = ctypes.c_char_p
_INT = ctypes.POINTER(ctypes.c_int)
_DOUBLE = ctypes.POINTER(ctypes.c_double)
_ARRAY = ctypes.c_void_p


def _routine(module, name, *argtypes):
    """The C routine ``name`` exported by scipy's Cython module, as a ctypes function (GIL released)."""
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype, get_name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
    get_pointer.restype, get_pointer.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    capsule = module.__pyx_capi__[name]
    return ctypes.CFUNCTYPE(None, *argtypes)(get_pointer(capsule, get_name(capsule)))


# side, uplo, transa, diag, m, n, alpha, a, lda, b, ldb
_dtrsm = _routine(_cython_blas, "dtrsm", _CHAR, _CHAR, _CHAR, _CHAR, _INT, _INT, _DOUBLE, _ARRAY, _INT, _ARRAY, _INT)
_dtrmm = _routine(_cython_blas, "dtrmm", _CHAR, _CHAR, _CHAR, _CHAR, _INT, _INT, _DOUBLE, _ARRAY, _INT, _ARRAY, _INT)
# uplo, n, a, lda, info
_dpotrf = _routine(_cython_lapack, "dpotrf", _CHAR, _INT, _ARRAY, _INT, _INT)
# uplo, n, nrhs, a, lda, b, ldb, info
_dpotrs = _routine(_cython_lapack, "dpotrs", _CHAR, _INT, _INT, _ARRAY, _INT, _ARRAY, _INT, _INT)


def _int(n):
    return ctypes.byref(ctypes.c_int(int(n)))


def _fortran(a, overwrite):
    """``a`` as a Fortran-ordered float64 array: itself where it is one and may be overwritten, else a copy."""
    a = np.asarray(a)
    if overwrite and a.dtype == np.float64 and a.flags.f_contiguous and a.flags.writeable:
        return a
    return np.array(a, dtype=np.float64, order="F", copy=True)


def _matrix(a):
    """A read-only matrix argument and its leading dimension: a Fortran-ordered float64 array or a block of
    one (e.g. a leading principal submatrix: columns ``lda`` apart) as it is, anything else as a Fortran copy
    (scipy's wrappers copy a block; the routine reads the same numbers either way)."""
    a = np.asarray(a)
    if a.ndim == 2 and a.dtype == np.float64 and a.strides[0] == 8 and a.strides[1] % 8 == 0 and \
            a.strides[1] // 8 >= max(1, a.shape[0]):
        return a, a.strides[1] // 8
    a = np.array(a, dtype=np.float64, order="F", copy=True)
    return a, max(1, a.shape[0])


def _square(a, what):
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ValueError(f"{what} must be a square matrix, got shape {a.shape}")


def _rhs(b, n, overwrite):
    """Right-hand sides (n, k) or (n,) in Fortran order (a copy unless ``overwrite``), their (m, k) and ldb."""
    b = _fortran(b, overwrite)
    if b.ndim not in (1, 2) or b.shape[0] != n:
        raise ValueError(f"right-hand sides must have {n} rows, got shape {b.shape}")
    k = 1 if b.ndim == 1 else b.shape[1]
    return b, k


def potrf(a, lower=False, overwrite_a=False):
    """Cholesky factor of the symmetric positive definite ``a`` (n, n): ``(c, info)`` as
    ``scipy.linalg.lapack.dpotrf(a, lower, clean=0)``: the other triangle keeps ``a``'s entries; ``info > 0``:
    the leading minor of that order is not positive definite."""
    c = _fortran(a, overwrite_a)
    _square(c, "a")
    info = ctypes.c_int(0)
    n = c.shape[0]
    if n:
        _dpotrf(b"L" if lower else b"U", _int(n), c.ctypes.data, _int(max(1, n)), ctypes.byref(info))
    return c, info.value


def potrs(c, b, lower=False, overwrite_b=False):
    """``a^-1 b`` from the Cholesky factor ``c`` of :func:`potrf`: ``(x, info)`` as
    ``scipy.linalg.lapack.dpotrs``."""
    c, ldc = _matrix(c)
    _square(c, "c")
    n = c.shape[0]
    x, k = _rhs(b, n, overwrite_b)
    info = ctypes.c_int(0)
    if n and k:
        _dpotrs(b"L" if lower else b"U", _int(n), _int(k), c.ctypes.data, _int(ldc), x.ctypes.data,
                _int(max(1, n)), ctypes.byref(info))
    return x, info.value


def cho_factor(a, lower=False, overwrite_a=False):
    """``(c, lower)`` as ``scipy.linalg.cho_factor(a, lower, overwrite_a, check_finite=False)``.

    Raises
    ------
    numpy.linalg.LinAlgError
        ``a`` is not (numerically) positive definite.
    """
    c, info = potrf(a, lower=lower, overwrite_a=overwrite_a)
    if info > 0:
        raise np.linalg.LinAlgError(f"{info}-th leading minor of the array is not positive definite")
    if info < 0:
        raise ValueError(f"LAPACK reported an illegal value in {-info}-th argument of dpotrf")
    return c, lower


def cho_solve(c_and_lower, b, overwrite_b=False):
    """``a^-1 b`` as ``scipy.linalg.cho_solve(c_and_lower, b, overwrite_b, check_finite=False)``."""
    c, lower = c_and_lower
    x, info = potrs(c, b, lower=lower, overwrite_b=overwrite_b)
    if info != 0:
        raise ValueError(f"LAPACK reported an illegal value in {-info}-th argument of dpotrs")
    return x


def _triangular(routine, alpha, a, b, lower, trans_a, overwrite_b):
    a, lda = _matrix(a)
    _square(a, "a")
    n = a.shape[0]
    b, k = _rhs(b, n, overwrite_b)
    if n and k:
        routine(b"L", b"L" if lower else b"U", b"T" if trans_a else b"N", b"N", _int(n), _int(k),
                ctypes.byref(ctypes.c_double(alpha)), a.ctypes.data, _int(lda), b.ctypes.data, _int(max(1, n)))
    return b


def trsm(alpha, a, b, lower=False, trans_a=False, overwrite_b=False):
    """``alpha op(a)^-1 b`` for triangular ``a`` (n, n), as ``scipy.linalg.blas.dtrsm`` (left side, non-unit
    diagonal)."""
    return _triangular(_dtrsm, alpha, a, b, lower, trans_a, overwrite_b)


def trmm(alpha, a, b, lower=False, trans_a=False, overwrite_b=False):
    """``alpha op(a) b`` for triangular ``a`` (n, n), as ``scipy.linalg.blas.dtrmm`` (left side, non-unit
    diagonal)."""
    return _triangular(_dtrmm, alpha, a, b, lower, trans_a, overwrite_b)


def lu_solve(lu_and_piv, b, trans=0):
    """``scipy.linalg.lu_solve`` with a private copy of the pivots: safe on a factorisation shared by threads.

    Two threads solving with one factorisation at once through scipy's
    ``getrs`` wrapper get wrong solutions without an error (scipy 1.17.1:
    183 of 400 concurrent solves of a 60 x 60 system wrong, by up to 1.2 on a
    solution of order 1; 295 of 400 at 400 x 400, by up to 52). The wrapper
    changes the pivot array during the call: with a copy of the pivots per
    call every solve is right, the LU matrix itself still shared.
    """
    lu, piv = lu_and_piv
    return scipy.linalg.lu_solve((lu, np.array(piv, copy=True)), b, trans=trans, check_finite=False)
