"""Dense LU solves with the determinant's sign (hbm.dense): mixed precision against numpy's
double-precision solve and slogdet."""
from __future__ import annotations

import numpy as np
import pytest

from hbm import dense


def _matrix(n: int, rng, singular_values=None) -> np.ndarray:
    """A random n x n matrix with the given singular values (default: 1 ... 10), det sign
    random."""
    U, _ = np.linalg.qr(rng.normal(size=(n, n)))
    V, _ = np.linalg.qr(rng.normal(size=(n, n)))
    s = np.linspace(1.0, 10.0, n) if singular_values is None else singular_values
    return (U * s) @ V.T


@pytest.mark.parametrize("n", [40, dense.MIXED_SIZE + 7])
def test_solution_and_sign_equal_double_precision(n: int) -> None:
    """Below MIXED_SIZE a double LU, above it a single LU refined in double precision: the
    solution equals numpy's to double precision (residual at the dsgesv stopping test), the sign
    is slogdet's, for both signs, and A is untouched by a mixed solve."""
    rng = np.random.default_rng(n)
    for flip in (1.0, -1.0):
        A = _matrix(n, rng)
        A[0] *= flip
        B = rng.normal(size=(n, 2))
        ref = np.linalg.solve(A, B)
        st = {}
        A0 = A.copy()
        X, sign = dense.lu_solve_sign(A, B, st)
        assert sign == int(np.linalg.slogdet(A0)[0])
        assert np.abs(X - ref).max() <= 1e-12 * np.abs(ref).max()
        r = np.abs(B - A0 @ X).max(axis=0)
        assert np.all(r <= np.sqrt(n) * np.finfo(float).eps * np.abs(A0).sum(axis=1).max()
                      * np.abs(X).max(axis=0))
        mixed = n >= dense.MIXED_SIZE
        assert st == ({"lu_single": 1} if mixed else {"lu_double": 1})
        if mixed:
            assert np.array_equal(A, A0)
        x1, s1 = dense.lu_solve_sign(A0.copy(), B[:, 0])        # a vector right-hand side
        assert x1.shape == (n,) and s1 == sign and np.allclose(x1, ref[:, 0], rtol=0, atol=1e-12)


def test_uncertified_sign_uses_double_precision() -> None:
    """A matrix with condition number 1e6: the refinement would converge (cond x eps_single =
    0.06) but the sign is not certified (rcond 1e-6 below SIGN_MARGIN x eps_single = 3.6e-6), so
    the double LU gives it, and it is slogdet's."""
    n = dense.MIXED_SIZE + 3
    rng = np.random.default_rng(5)
    sv = np.ones(n)
    sv[-1] = 1e-6
    A = _matrix(n, rng, sv)
    B = rng.normal(size=(n, 1))
    st = {}
    X, sign = dense.lu_solve_sign(A.copy(), B, st)
    assert st == {"lu_double": 1}
    assert sign == int(np.linalg.slogdet(A)[0])
    assert np.linalg.norm(A @ X - B) <= 1e-13 * np.linalg.norm(A, 2) * np.linalg.norm(X)


def test_solve_without_sign_keeps_single_precision_factors() -> None:
    """lu_solve, where no sign is needed: the condition-1e6 matrix whose sign is not certified
    keeps its single-precision factors (the refinement converges, cond x eps_single = 0.06) and
    the solution is the double-precision one; at condition 1e9 the refinement stalls and the
    double LU solves it."""
    n = dense.MIXED_SIZE + 3
    rng = np.random.default_rng(5)
    for cond, kind in ((1e6, "lu_single"), (1e9, "lu_double")):
        sv = np.ones(n)
        sv[-1] = 1.0 / cond
        A = _matrix(n, rng, sv)
        B = rng.normal(size=(n, 2))
        st = {}
        X = dense.lu_solve(A.copy(), B, st)
        assert st == {kind: 1}
        r = np.abs(B - A @ X).max(axis=0)
        assert np.all(r <= np.sqrt(n) * np.finfo(float).eps * np.abs(A).sum(axis=1).max()
                      * np.abs(X).max(axis=0))


def test_sign_from_factors() -> None:
    """_sign: the product of the pivots' signs and of the row interchanges; 0 for a zero pivot."""
    lu = np.diag([2.0, -1.0, 3.0])
    assert dense._sign(lu, np.array([0, 1, 2])) == -1
    assert dense._sign(lu, np.array([1, 1, 2])) == 1          # one interchange
    assert dense._sign(np.diag([1.0, 0.0, 1.0]), np.array([0, 1, 2])) == 0


def test_single_precision_matrix_with_double_operator() -> None:
    """A matrix formed in single precision (the caller's float32 A): factorized in place, the
    refinement's residuals from the double-precision operator, so the solution is the double
    matrix's to double precision and the sign is its slogdet's; an uncertified sign rebuilds the
    double matrix and factorizes that."""
    n = dense.MIXED_SIZE + 5
    rng = np.random.default_rng(11)
    A = _matrix(n, rng)
    A[0] *= -1
    B = rng.normal(size=(n, 2))
    ref = np.linalg.solve(A, B)
    calls = []

    def rebuild():
        calls.append(1)
        return A.copy()
    st = {}
    X, sign = dense.lu_solve_sign(A.astype(np.float32), B, st, matvec=lambda x: A @ x,
                                  rebuild=rebuild)
    assert st == {"lu_single": 1} and not calls
    assert sign == int(np.linalg.slogdet(A)[0]) == -1
    assert np.abs(X - ref).max() <= 1e-12 * np.abs(ref).max()
    # condition number 1e6: not certified in single precision -> the rebuilt double matrix
    sv = np.ones(n)
    sv[-1] = 1e-6
    A = _matrix(n, rng, sv)
    st = {}
    X, sign = dense.lu_solve_sign(A.astype(np.float32), B[:, :1], st, matvec=lambda x: A @ x,
                                  rebuild=rebuild)
    assert st == {"lu_double": 1} and len(calls) == 1
    assert sign == int(np.linalg.slogdet(A)[0])
    assert np.linalg.norm(A @ X - B[:, :1]) <= 1e-13 * np.linalg.norm(A, 2) * np.linalg.norm(X)
    with pytest.raises(ValueError, match="matvec and rebuild"):
        dense.lu_solve_sign(A.astype(np.float32), B, st)
