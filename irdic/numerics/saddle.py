"""The factorised saddle-point system of a kernel interpolant with polynomial terms.

``[[A, P], [P^T, 0]] [x; y] = [f; q]`` with ``A`` the (IMQ, positive definite)
kernel matrix of the centres and ``P`` the monomials at the centres, full
column rank. Used by the image interpolant (pixel tiles and stencils), the
surface (global and local tiles) and the temporal interpolant.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg

from . import lapack

__all__ = ["SaddleFactor", "solve_dense"]

log = logging.getLogger(__name__)


class SaddleFactor:
    """Factorised ``[[A, P], [P^T, 0]]`` with ``A`` symmetric positive definite.

    Parameters
    ----------
    A : ndarray, shape (K, K)
        Kernel matrix.
    P : ndarray, shape (K, m)
        Monomials at the centres, full column rank.
    rebuild : callable, optional
        Returns ``A`` again. Given, the Cholesky factorisation may overwrite
        ``A`` in place (large matrices), and the LU fallback rebuilds it.

    Notes
    -----
    Cholesky ``A = L L^T`` and the small Schur complement
    ``S = P^T A^-1 P`` (its inverse, m x m). When round-off makes ``A``
    numerically indefinite (very flat kernels, ``c R0`` much larger than the
    centre spacing) an LU factorisation of the whole saddle matrix is used
    instead.
    """

    def __init__(self, A, P, rebuild=None):
        self.K = A.shape[0]
        self.P = P
        self.lu = None
        self.cho = None
        self._blocks = None
        try:
            # the GIL-free routines (numerics.lapack): the stages' worker threads factorise tiles at once
            self.cho = lapack.cho_factor(A, lower=True, overwrite_a=rebuild is not None)
            self._schur(lapack.cho_solve(self.cho, P))
            self.nbytes = A.nbytes + P.nbytes + self.Y.nbytes
            return
        except np.linalg.LinAlgError:
            pass
        log.debug("kernel matrix (%d) not numerically positive definite: LU of the saddle system", self.K)
        self.cho = None
        A = rebuild() if rebuild is not None else A
        n, m = self.K, P.shape[1]
        S = np.zeros((n + m, n + m))
        S[:n, :n] = A
        S[:n, n:] = P
        S[n:, :n] = P.T
        self.lu = scipy.linalg.lu_factor(S, overwrite_a=True, check_finite=False)
        self.nbytes = S.nbytes + P.nbytes

    @classmethod
    def from_cholesky(cls, L, P):
        """The factor of ``[[A, P], [P^T, 0]]`` from a given lower Cholesky factor ``L`` of ``A``.

        Parameters
        ----------
        L : ndarray, shape (K, K)
            Lower triangular, ``A = L L^T`` (the upper triangle is ignored),
            e.g. assembled block by block when ``A`` extends a matrix whose
            factor is already known.
        P : ndarray, shape (K, m)
            Monomials at the centres, full column rank.

        Returns
        -------
        SaddleFactor
        """
        self = cls.__new__(cls)
        self.K = L.shape[0]
        self.P = P
        self.lu = None
        self.cho = (L, True)
        self._blocks = None
        # Y = A^-1 P comes with the first solve (one pass over the factor
        # instead of two): an edge tile is often solved only once
        self._Y = None
        self.nbytes = L.nbytes + 2 * P.nbytes
        return self

    @classmethod
    def from_blocks(cls, L_ss, X, L_rr, P):
        """The factor of ``[[A, P], [P^T, 0]]`` from the blocks of the Cholesky factor of ``A``.

        Parameters
        ----------
        L_ss : ndarray, shape (s, s)
            Lower Cholesky factor of the leading block ``A_ss`` (may be shared
            by many factors: it is not copied).
        X : ndarray, shape (s, r)
            ``L_ss^-1 A_sr``, i.e. ``L_rs^T``.
        L_rr : ndarray, shape (r, r)
            Lower Cholesky factor of ``A_rr - X^T X``.
        P : ndarray, shape (s + r, m)

        Returns
        -------
        SaddleFactor

        Notes
        -----
        ``L = [[L_ss, 0], [X^T, L_rr]]`` is never assembled: solves go block
        by block, and many factors that extend one ``L_ss`` hold only their
        own ``(s + r) r`` numbers.
        """
        self = cls.from_cholesky(L_rr, P)
        self.K = P.shape[0]
        self.cho = None
        self._blocks = (L_ss, X, L_rr)
        self.nbytes = X.nbytes + L_rr.nbytes + 2 * P.nbytes
        return self

    def _cho_solve(self, F):
        """``A^-1 F`` by the Cholesky factor, whole or in blocks."""
        if self._blocks is None:
            return lapack.cho_solve(self.cho, F)
        L_ss, X, L_rr = self._blocks
        s = L_ss.shape[0]
        # BLAS trsm directly: this runs for every tile and time, and
        # solve_triangular's checks cost as much as the solve itself here
        trsm = lapack.trsm
        y_s = trsm(1.0, L_ss, F[:s], lower=True)
        y_r = trsm(1.0, L_rr, F[s:] - X.T @ y_s, lower=True, overwrite_b=True)
        x_r = trsm(1.0, L_rr, y_r, lower=True, trans_a=True, overwrite_b=True)
        x_s = trsm(1.0, L_ss, y_s - X @ x_r, lower=True, trans_a=True, overwrite_b=True)
        return np.concatenate([x_s, x_r])

    def _schur(self, Y):
        # _Y last: a thread that sees it set (a cached tile solved by two threads) sees _S_inv too
        self._S_inv = np.linalg.inv(self.P.T @ Y)
        self._Y = Y

    @property
    def Y(self):
        """``A^-1 P``, shape (K, m) (Cholesky path only)."""
        if self._Y is None:
            self._schur(self._cho_solve(self.P))
        return self._Y

    @property
    def S_inv(self):
        """``(P^T A^-1 P)^-1``, shape (m, m) (Cholesky path only)."""
        if self._Y is None:
            self._schur(self._cho_solve(self.P))
        return self._S_inv

    def solve(self, F, Q=None):
        """Solve ``A x + P y = F``, ``P^T x = Q`` (``Q = 0`` when None).

        Parameters
        ----------
        F : ndarray, shape (K, k)
        Q : ndarray, shape (m, k), optional

        Returns
        -------
        x : ndarray, shape (K, k)
        y : ndarray, shape (m, k)
        """
        if self.lu is not None:
            rhs = np.concatenate([F, np.zeros((self.P.shape[1], F.shape[1])) if Q is None else Q])
            sol = lapack.lu_solve(self.lu, rhs)
            return sol[: self.K], sol[self.K:]
        if self._Y is None:
            m = self.P.shape[1]
            Z = self._cho_solve(np.concatenate([self.P, F], axis=1))
            self._schur(Z[:, :m].copy())
            X = Z[:, m:]
        else:
            X = self._cho_solve(F)
        rhs = self.P.T @ X
        if Q is not None:
            rhs -= Q
        y = self.S_inv @ rhs
        X -= self.Y @ y
        return X, y

    def weights(self, B, Q):
        """Weights ``w`` with ``w @ f`` = a linear functional of the interpolant of ``f``.

        Parameters
        ----------
        B : ndarray, shape (n_f, K)
            Kernel part of the functionals (the functional applied to each
            centre's kernel).
        Q : ndarray, shape (n_f, m)
            Monomial part.

        Returns
        -------
        ndarray, shape (n_f, K)
        """
        if self.lu is not None:
            rhs = np.concatenate([B, Q], axis=1).T
            return lapack.lu_solve(self.lu, rhs, trans=1)[: self.K].T
        return self.solve(B.T, Q.T)[0].T

    def coefficients(self, F):
        """Kernel and monomial coefficients of the interpolant of ``F`` (K, k).

        Returns ``(alpha, beta)`` of shapes (K, k), (m, k). Unlike
        :meth:`solve` the Schur step uses ``Y^T F`` (``= P^T A^-1 F``), which
        saves one product with the large ``A^-1 F`` for many columns.
        """
        if self.lu is not None:
            return self.solve(F)
        Z = self._cho_solve(F)
        beta = self.S_inv @ (self.Y.T @ F)
        Z -= self.Y @ beta
        return Z, beta


def solve_dense(A, P, f, q):
    """Solve one small saddle-point system ``[[A, P], [P^T, 0]] [x; y] = [f; q]`` by dense LU.

    For systems solved once, where a factorisation is not reused (e.g. the
    few-sample temporal fill of a gap).

    Parameters
    ----------
    A : ndarray, shape (n, n)
    P : ndarray, shape (n, m)
    f : ndarray, shape (n,) or (n, k)
    q : ndarray, shape (m,) or (m, k)

    Returns
    -------
    x : ndarray, shape (n,) or (n, k)
    y : ndarray, shape (m,) or (m, k)
    """
    n, m = P.shape
    S = np.zeros((n + m, n + m))
    S[:n, :n] = A
    S[:n, n:] = P
    S[n:, :n] = P.T
    sol = np.linalg.solve(S, np.concatenate([f, q]))
    return sol[:n], sol[n:]
