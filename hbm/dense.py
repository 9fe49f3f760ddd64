"""Dense LU solves with the sign of the determinant, in mixed precision above a size.

The continuation needs the sign of the bordered Newton matrix's determinant at corner folds
(``continuation``), and the harmonic balance falls back to a dense LU when GMRES fails. At the
resonator's top level these LUs (7414 unknowns, 14-17 per curve) took 35 % of a sweep: 77 s of
219 s for the baseline (profile, session 8).

Above :data:`MIXED_SIZE` unknowns the matrix is factorized in single precision (``sgetrf``,
2.3 times faster than ``dgetrf`` at 7414 unknowns here: 2.6 s against 5.9 s) and the solution is
refined in double precision against the double-precision matrix (classical iterative refinement,
as LAPACK's ``dsgesv``; it converges like (cond(A) eps_single)^k). The determinant's sign comes
from the single-precision factors only when it is certified:

    rcond_1(A) > SIGN_MARGIN * max(eta, eps_single),

with rcond_1 the LAPACK estimate of 1 / (||A||_1 ||A^-1||_1) (``sgecon``) and eta the normwise
backward error of the single-precision solve. The factors are those of A + E with
||E|| / ||A|| about eta, and det(A + tE) keeps its sign for t in [0, 1] when
||E||_1 < 1 / ||A^-1||_1; the margin covers the estimator (usually within a factor 3) and the
backward error's spread over directions. The bordered matrices of the default model's top-level
sweeps had rcond 7e-6 to 1e-3 (single and double estimates equal to 3 digits) and every
single-precision sign equalled the double one. When the sign is not certified, or the
refinement does not reach double precision in :data:`REFINE_ITERATIONS`, the matrix is
factorized in double precision (as below :data:`MIXED_SIZE`).
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.linalg import lapack

#: smallest system factorized in single precision (below it a double LU costs little)
MIXED_SIZE = 1500
#: refinement steps before the double-precision factorization is used instead
REFINE_ITERATIONS = 10
#: the single-precision sign is used only when rcond exceeds this times the backward error
SIGN_MARGIN = 30.0
_EPS32 = float(np.finfo(np.float32).eps)
_EPS64 = float(np.finfo(np.float64).eps)


def _sign(lu: np.ndarray, piv: np.ndarray) -> int:
    """Sign of det from LU factors with 0-based row interchanges ``piv``."""
    d = np.diag(lu)
    negative = int(np.count_nonzero(d < 0)) + int(np.count_nonzero(piv != np.arange(piv.size)))
    return 0 if not np.all(d) else (-1 if negative % 2 else 1)


def _double(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, int]:
    """LU in double precision of A (overwritten), its solution of A X = B and the sign of det A.
    A^T is factorized: it is Fortran-ordered when A is C-ordered, so LAPACK needs no copy."""
    lu, piv, info = lapack.dgetrf(A.T, overwrite_a=True)
    if info < 0:
        raise ValueError(f"dgetrf: illegal argument {-info}")
    X, info = lapack.dgetrs(lu, piv, B, trans=1)
    return X, _sign(lu, piv)


def lu_solve(A: np.ndarray, B: np.ndarray, stats: dict | None = None) -> np.ndarray:
    """Solve A X = B by LU when the determinant's sign is not needed (a float64 A).

    Above :data:`MIXED_SIZE` the single-precision factors are kept whatever rcond, as long as
    the refinement reaches double precision (the stopping test of ``dsgesv``); only a stall
    factorizes in double. The sign certificate of :func:`lu_solve_sign` sent the stiff layer
    joint's Newton systems (rcond below 2e-6) to a second, double-precision LU although their
    refinement converged: 7 of 14 on its backbone (default model), about 5 s each.

    Args and Returns: as :func:`lu_solve_sign`, without the sign.
    """
    return lu_solve_sign(A, B, stats, certify=False)[0]


def lu_solve_sign(A: np.ndarray, B: np.ndarray, stats: dict | None = None,
                  matvec: Callable | None = None,
                  rebuild: Callable | None = None, certify: bool = True) -> tuple[np.ndarray, int]:
    """Solve A X = B by LU and return the sign of det A.

    Args:
        A: (n, n) C-ordered, float64 or (n >= MIXED_SIZE only) float32; overwritten (it holds
            factors afterwards, or is unchanged after a mixed-precision solve of a float64 A).
            A float32 A is the matrix to single precision, formed so by the caller (in single
            precision arithmetic: its entries within a few ulps of the rounded ones, a fifth of
            the time of forming it in double); then ``matvec`` and ``rebuild`` are needed.
        B: (n, m) or (n,) right-hand sides.
        stats: optional counters, incremented: "lu_single" (mixed-precision solves that kept
            the single-precision factors), "lu_double" (double-precision factorizations).
        matvec: x (n,) -> A x in double precision (the refinement's residuals of a float32 A).
        rebuild: () -> A as float64 (C-ordered), for the double-precision factorization when a
            float32 A's sign is not certified or its refinement stalls.
        certify: use single-precision factors only when their sign is certified (False: the
            sign returned may be wrong, the solution is not; :func:`lu_solve`).
    Returns:
        (X with B's shape, sign of det A: +1 or -1, 0 if a pivot is exactly zero).
    """
    n = A.shape[0]
    B2 = B.reshape(n, -1)
    single = A.dtype == np.float32
    if single and (matvec is None or rebuild is None):
        raise ValueError("a float32 matrix needs matvec and rebuild")
    if n >= MIXED_SIZE or single:
        out = _mixed(A, B2, matvec if single else None, certify)
        if out is not None:
            if stats is not None:
                stats["lu_single"] = stats.get("lu_single", 0) + 1
            return out[0].reshape(B.shape), out[1]
        if single:
            A = rebuild()
    if stats is not None:
        stats["lu_double"] = stats.get("lu_double", 0) + 1
    X, sign = _double(A, np.array(B2, dtype=float, order="F"))
    return X.reshape(B.shape), sign


def _mixed(A: np.ndarray, B: np.ndarray, matvec: Callable | None = None,
           certify: bool = True) -> tuple[np.ndarray, int] | None:
    """Single-precision LU of A (A^T, Fortran-ordered), refined in double precision; None when
    the sign is not certified (``certify``) or the refinement stalls (the caller factorizes in
    double).
    A float32 A is factorized in place and the residuals come from ``matvec``; a float64 A is
    copied to single precision and kept for the residuals."""
    if A.dtype == np.float32:
        At32 = A.T                                     # Fortran-ordered view: factorized in place

        def residual(X):
            return B - np.stack([matvec(X[:, j]) for j in range(X.shape[1])], axis=1)
    else:
        At32 = A.T.astype(np.float32)                  # Fortran-ordered A^T, no copy in LAPACK

        def residual(X):
            return B - A @ X
    absA = np.abs(At32)
    a1 = float(absA.sum(axis=1, dtype=np.float64).max())     # ||A||_1 (column sums of A)
    ainf = float(absA.sum(axis=0, dtype=np.float64).max())   # ||A||_inf
    del absA
    lu, piv, info = lapack.sgetrf(At32, overwrite_a=True)
    if info != 0:
        return None                                    # exactly singular in single precision
    # rcond of A^T in the infinity norm is rcond of A in the 1-norm
    rcond = lapack.sgecon(lu, a1, norm="I")[0] if certify else None

    def solve32(R: np.ndarray) -> np.ndarray:
        Y, _ = lapack.sgetrs(lu, piv, R.astype(np.float32), trans=1)
        return Y.astype(np.float64)

    X = solve32(B)
    b1 = np.abs(B).sum(axis=0)
    for it in range(REFINE_ITERATIONS + 1):
        R = residual(X)
        # normwise backward error per column, infinity norm for the stopping test (as dsgesv)
        if it == 0:
            eta = float(np.max(np.abs(R).sum(axis=0) / (a1 * np.abs(X).sum(axis=0) + b1)))
            if certify and not rcond > SIGN_MARGIN * max(eta, _EPS32):
                return None
        if np.all(np.abs(R).max(axis=0) <= np.sqrt(A.shape[0]) * _EPS64 * ainf * np.abs(X).max(axis=0)):
            return X, _sign(lu, piv)
        if it < REFINE_ITERATIONS:
            X = X + solve32(R)
    return None
