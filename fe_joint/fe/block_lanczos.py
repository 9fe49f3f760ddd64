"""The lowest eigenpairs of K phi = lambda M phi by block Lanczos on K^-1 M, with a Cholesky
factor of K that the caller keeps anyway (the fixed-interface modes of Craig–Bampton: K_II's
factor also gives the constraint modes).

Why not SLEPc's Krylov–Schur there: it applies K^-1 to one vector at a time, and a MUMPS solve of
one right-hand side reads the whole factor (memory-bound: 33 ms serially on the default model's
interior, 58 000 DOFs per rank, against 7 ms per column in blocks of 8), and it factorizes K_II
itself before the condensation factorizes it again. Default model (77 modes below 60 kHz):
SLEPc 12.0 s on 2 ranks and 17.5 s serially (with the inertia count), this 8.1 and 10.9 s, the
frequencies equal to 7e-12 (README "Speed", session 21).

The method (Golub & Underwood 1977; Grimes, Lewis & Simon 1994 for the shift-inverted
generalized problem): the basis V of the block Krylov space of K^-1 M from a random start is
kept M-orthonormal by classical Gram–Schmidt twice and a Cholesky QR twice per block (full
reorthogonalization); T = V^T M K^-1 M V is projected as the blocks are made; its Ritz pairs
(mu, y) give lambda = 1/mu, and the residual of the shift-inverted problem,
||K^-1 M x - mu x||_M / |mu|, is the norm of the next block's row of T times y: SLEPc's default
convergence test (relative, on the transformed problem), at the same tolerance. No restarts:
the basis grows until the wanted pairs converge, within a memory budget.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from mpi4py import MPI
from petsc4py import PETSc

#: columns per block: 8 on the default model's interior (a serial prototype with the count and
#: the factorization, 4 / 8 / 16 / 24 columns: 10.9 / 10.9 / 13.0 / 16.5 s, 224 / 280 / 368 / 480
#: vectors; larger blocks need more vectors, smaller ones more passes over the basis)
BLOCK = 8
#: the basis may grow to this many times the wanted pairs, and to at least MIN_VECTORS (plus two
#: blocks): the default model's 77 modes converged at 280 vectors (3.6 times), the 12 lowest of
#: the test's box joint at 112 (9 times)
MAX_GROWTH = 8
MIN_VECTORS = 256
#: relative residual of the shift-inverted problem (SLEPc's default test and the tolerance of
#: ``modal.solve_eigenproblem``)
TOL = 1e-8
#: memory of the basis and its M-products together, per rank, MB (above it: None, the caller
#: uses SLEPc)
BUDGET_MB = 1000.0


def lowest_modes(K: PETSc.Mat, M: PETSc.Mat, factor: PETSc.Mat, nev: int, block: int = BLOCK,
                 tol: float = TOL, budget_mb: float = BUDGET_MB,
                 seed: int = 0) -> tuple[np.ndarray, list] | None:
    """The ``nev`` lowest eigenpairs of K phi = lambda M phi (K positive definite). Collective.

    Args:
        K, M: assembled symmetric PETSc matrices (same layout), K positive definite.
        factor: K's Cholesky factor (a factored Mat with ``matSolve``).
        nev: eigenpairs wanted (>= 1).
        block: columns per block.
        tol: relative residual of the shift-inverted problem.
        budget_mb: largest basis (with its M-products) per rank, MB.
        seed: the random start's seed (drawn over the global rows, the same for any rank count).
    Returns:
        (Ritz values lambda ascending (nev,), Ritz vectors as M-orthonormal Vecs), or None when
        the basis would exceed ``budget_mb`` or the pairs did not converge within
        max(``MAX_GROWTH`` ``nev``, ``MIN_VECTORS``) vectors (the caller then uses SLEPc).
    """
    if nev < 1:
        raise ValueError(f"nev must be >= 1, got {nev}")
    comm = K.getComm().tompi4py()
    n_glob = K.getSize()[0]
    lo, hi = K.getOwnershipRange()
    cap = min(max(MAX_GROWTH * nev, MIN_VECTORS) + 2 * block, n_glob)
    if comm.allreduce(2 * 8 * (hi - lo) * cap / 1e6 > budget_mb, op=MPI.LOR) or cap < nev + block:
        return None
    basis = _Basis(K, M, lo, hi, cap)
    start = np.random.default_rng(seed).standard_normal((n_glob, block))[lo:hi]
    try:
        basis.add(start)
        cols = []                               # T's column blocks: T[:m, j b:(j + 1) b]
        while basis.m + block <= cap:
            k = basis.m
            W = basis.solve(factor, basis.MV[:, k - block:k])
            basis.add(W)
            cols.append(basis.gram_mv(W))
            mu, Y, res = _ritz(cols, k, block)
            if k >= nev and np.all(res[:nev] <= tol):
                X = basis.V[:, :k] @ Y[:, :nev]
                return 1.0 / mu[:nev], [basis.vec(X[:, j]) for j in range(nev)]
    except np.linalg.LinAlgError:     # a block without full rank (an exhausted Krylov space)
        pass
    return None


def _ritz(cols: list, k: int, block: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ritz pairs of T's leading k x k part, largest mu first, and their relative residuals
    (T is the same on every rank, ``_Basis._gram``, and so are they).

    Column block j of T holds rows up to block j + 1 (the rest vanish in exact arithmetic): the
    upper triangle is kept and mirrored; the last column block's rows past k are the next
    block's coupling, which gives each pair's residual."""
    T = np.zeros((k + block, k))
    for j, c in enumerate(cols):
        T[:c.shape[0], j * block:(j + 1) * block] = c
    Tu = np.triu(T[:k])
    mu, Y = np.linalg.eigh(Tu + np.triu(Tu, 1).T)
    mu, Y = mu[::-1], Y[:, ::-1]
    return mu, Y, np.linalg.norm(T[k:] @ Y, axis=0) / np.abs(mu)


class _Basis:
    """An M-orthonormal basis V (local rows, Fortran-ordered: its leading columns are one
    contiguous block) and MV = M V."""

    def __init__(self, K: PETSc.Mat, M: PETSc.Mat, lo: int, hi: int, cap: int) -> None:
        self.K, self.M, self.comm = K, M, K.getComm().tompi4py()
        self.n_loc, self.n_glob = hi - lo, K.getSize()[0]
        # pages are committed as the columns are written
        self.V = np.empty((self.n_loc, cap), order="F")
        self.MV = np.empty((self.n_loc, cap), order="F")
        self.m = 0

    def _dense(self, X: np.ndarray) -> PETSc.Mat:
        A = PETSc.Mat().createDense([(self.n_loc, self.n_glob), (PETSc.DECIDE, X.shape[1])],
                                    array=np.asfortranarray(X), comm=self.K.getComm())
        A.assemble()
        return A

    def _gram(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        """A^T B summed over the ranks, the same bits on every rank (rank 0's sum: the
        decisions taken from it, a Cholesky that fails, a converged pair, are then the same
        everywhere)."""
        G = A.T @ B
        self.comm.Allreduce(MPI.IN_PLACE, G, op=MPI.SUM)
        self.comm.Bcast(G, root=0)
        return G

    def solve(self, factor: PETSc.Mat, B: np.ndarray) -> np.ndarray:
        """K^-1 B for a block B (local rows): one multi-column MUMPS solve."""
        Bm = self._dense(B)
        Xm = Bm.duplicate()
        factor.matSolve(Bm, Xm)
        X = Xm.getDenseArray().copy()
        Bm.destroy()
        Xm.destroy()
        return X

    def _m_times(self, X: np.ndarray) -> np.ndarray:
        Xm = self._dense(X)
        Y = self.M.matMult(Xm)
        out = Y.getDenseArray().copy()
        Xm.destroy()
        Y.destroy()
        return out

    def add(self, W: np.ndarray) -> None:
        """Append W, M-orthogonalized against V and M-orthonormalized (twice each)."""
        m, b = self.m, W.shape[1]
        for _ in range(2):
            if m:
                W = W - self.V[:, :m] @ self._gram(self.MV[:, :m], W)
            MW = self._m_times(W)
            L = np.linalg.cholesky(_sym(self._gram(W, MW)))
            W = sla.solve_triangular(L, W.T, lower=True).T
            MW = sla.solve_triangular(L, MW.T, lower=True).T
        self.V[:, m:m + b], self.MV[:, m:m + b] = W, MW
        self.m = m + b

    def gram_mv(self, W: np.ndarray) -> np.ndarray:
        """(M V)^T W over the whole basis, (m, b)."""
        return self._gram(self.MV[:, :self.m], W)

    def vec(self, x: np.ndarray) -> PETSc.Vec:
        v = self.K.createVecRight()
        v.getArray()[:] = x
        return v


def _sym(A: np.ndarray) -> np.ndarray:
    return 0.5 * (A + A.T)
