"""The lowest eigenpairs of a dense pencil K phi = lambda M phi by block Lanczos on the shifted
inverse, in the standard form that M's Cholesky factor gives.

Why: every joint's receptance (:class:`~hbm.structure.Receptance`) needs the lowest modes of the
linear base, a dense pencil (2198 DOFs, 60 modes on the default model). LAPACK's subset ``eigh``
(dsygvx) reduces and tridiagonalizes the whole matrix, about 1.0 s; a study builds about forty
receptances (curves, v3 passes, backbones, the speed stage's rows). Here K - sigma M is factorized
once (the receptance's static flexibility needs that factor anyway) and a few blocks of its
inverse applied to M give the modes (issue 16, session 27: README "Speed").

The method (Golub & Underwood 1977; Grimes, Lewis & Simon 1994): with M = L L^T, the problem is
A y = lambda y, A = L^-1 K L^-T, phi = L^-T y, and S = (A - sigma)^-1 = L^T (K - sigma M)^-1 L.
The basis V of the block Krylov space of S from a random start (a fixed seed: the same modes in
every process) is kept orthonormal by classical Gram-Schmidt twice before and after each new
block's rank-revealing normalization (full reorthogonalization: S maps the rigid-body modes
about 1e5 times more strongly than the elastic ones, so a new block's remainder is small and
would otherwise lose its orthogonality). The Ritz pairs come from the projection of K itself,
not of S: S's projection holds the small lambda to the round-off of its largest entry, the
rigid modes' 1 / -sigma, which is 1e-7 of the 60th mode's 1 / lambda. The pairs are accepted
when every wanted one's backward error ||K phi - lambda M phi|| / (||K||_1 ||phi||) is below
``tol``; the basis grows a block at a time up to ``max_blocks``, else None (the caller uses
LAPACK's eigh).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg as sla
from scipy.linalg import blas

#: the backward error ||K phi - lambda M phi|| / (||K||_1 ||phi||) every returned pair meets.
#: LAPACK's dense eigh reaches about 1e-13 on the default model's pencil; its eigenvalues of
#: the breathing mode from two drivers (dsygvx, dsygvd) differ by 8e-8 relative (M's condition
#: number is 7e9), so 1e-9 is as good as the data
TOL = 1e-9
#: blocks built before the first test, and at most (each block is ``m`` plus a margin columns)
MIN_BLOCKS, MAX_BLOCKS = 4, 8


class Modes(NamedTuple):
    """Lowest eigenpairs and the factor of the shifted pencil.

    Attributes:
        lam: (m,) eigenvalues, ascending, (rad/s)².
        Phi: (n, m) eigenvectors, M-orthonormal.
        factor: ``scipy.linalg.cho_factor`` of K - shift M (lower).
        shift: the shift, (rad/s)².
    """
    lam: np.ndarray
    Phi: np.ndarray
    factor: tuple
    shift: float


def block_size(m: int) -> int:
    """Columns per block for m wanted pairs: m and a third more (at least 8). On the default
    model's pencil (60 modes, the 52nd to 80th within 4.5-5.6e4 Hz), 80 columns converged in 5
    blocks to a backward error of 4.5e-10 (0.6 s against 1.1 s for LAPACK's eigh), 60 in 5 only
    to 1e-8."""
    return m + max(8, m // 3)


def shifted_factor(K: np.ndarray, M: np.ndarray, shift: float) -> tuple:
    """Cholesky factor of K - shift M (lower, ``cho_factor``); LinAlgError if not positive definite."""
    return sla.cho_factor(K - shift * M, lower=True, check_finite=False, overwrite_a=True)


def lowest_modes(K: np.ndarray, M: np.ndarray, m: int, shift: float, chol_m: np.ndarray,
                 factor: tuple | None = None, tol: float = TOL, seed: int = 0) -> Modes | None:
    """The m lowest eigenpairs of K phi = lambda M phi by block shift-invert Lanczos.

    Args:
        K: (n, n) symmetric, K - shift M positive definite (N/mm).
        M: (n, n) symmetric positive definite (t).
        m: pairs wanted, 1 <= m; the basis needs (m + margin) * MIN_BLOCKS <= n.
        shift: below the lowest eigenvalue, (rad/s)².
        chol_m: lower Cholesky factor L of M (M = L L^T), as ``numpy.linalg.cholesky`` gives.
        factor: ``shifted_factor(K, M, shift)`` when the caller has it.
        tol: backward error each pair must meet (:data:`TOL`).
        seed: the random start's seed.
    Returns:
        :class:`Modes`, or None when the pairs did not converge within :data:`MAX_BLOCKS`
        blocks or the basis would not fit (the caller then uses a dense eigh).
    Raises:
        ValueError: m is not an integer in [1, n].
        numpy.linalg.LinAlgError: K - shift M is not positive definite.
    """
    n = K.shape[0]
    if isinstance(m, bool) or int(m) != m or not 1 <= m <= n:
        raise ValueError(f"m must be an integer in [1, {n}], got {m!r}")
    b = block_size(int(m))
    cap = min(MAX_BLOCKS * b, n)
    if MIN_BLOCKS * b > n:
        return None
    if factor is None:
        factor = shifted_factor(K, M, shift)
    Lf = np.asfortranarray(chol_m)
    knorm = float(np.abs(K).sum(axis=0).max())
    V = np.empty((n, cap), order="F")              # orthonormal basis (standard form)
    P = np.empty((n, cap), order="F")              # L^-T V: M-orthonormal in the original form
    KP = np.empty((n, cap), order="F")             # K L^-T V
    start = np.random.default_rng(seed).standard_normal((n, b))
    V[:, :b] = np.linalg.qr(start)[0]
    lo, k = 0, b                                    # the last block is V[:, lo:k]
    done = 0                                        # columns of P and KP made so far
    for blocks in range(2, MAX_BLOCKS + 1):
        new = _extend(V, k, _apply(Lf, factor, V[:, lo:k]), cap)
        if new is None:
            return None
        lo, k = k, new
        if blocks < MIN_BLOCKS:
            continue
        P[:, done:k] = sla.solve_triangular(Lf, V[:, done:k], lower=True, trans="T",
                                             check_finite=False)
        KP[:, done:k] = K @ P[:, done:k]
        done = k
        out = _ritz(Lf, V[:, :k], P[:, :k], KP[:, :k], m, knorm, tol)
        if out is not None:
            return Modes(out[0], out[1], factor, float(shift))
    return None


def _apply(Lf: np.ndarray, factor: tuple, X: np.ndarray) -> np.ndarray:
    """S X = L^T (K - shift M)^-1 L X for a block X (n, b)."""
    Y = blas.dtrmm(1.0, Lf, X, lower=1)
    Y = sla.cho_solve(factor, Y, check_finite=False, overwrite_b=True)
    return blas.dtrmm(1.0, Lf, Y, lower=1, trans_a=1)


def _extend(V: np.ndarray, k: int, W: np.ndarray, cap: int) -> int | None:
    """Append to V[:, :k] the orthonormalized part of W not in its span; returns the new column
    count, None when nothing new is left (an exhausted Krylov space or a full basis)."""
    if k >= cap:
        return None
    Vk = V[:, :k]
    size = float(np.linalg.norm(W, axis=0).max())
    for _ in range(2):
        W -= Vk @ (Vk.T @ W)
    U, s, _ = np.linalg.svd(W, full_matrices=False)
    # directions below the round-off of the block before its projection carry no information
    X = U[:, s > 1e-12 * size]
    if X.shape[1] == 0:
        return None
    # normalizing a small remainder magnifies what is left of V in it: project again
    for _ in range(2):
        X -= Vk @ (Vk.T @ X)
    X = np.linalg.qr(X)[0]
    j = min(X.shape[1], cap - k)
    V[:, k:k + j] = X[:, :j]
    return k + j


def _ritz(Lf, V, P, KP, m: int, knorm: float, tol: float):
    """Ritz pairs of K on span(P) (P M-orthonormal), the m lowest, if each meets ``tol``."""
    H = P.T @ KP
    lam, Y = np.linalg.eigh(0.5 * (H + H.T))
    lam, Y = lam[:m], Y[:, :m]
    Phi = P @ Y
    MPhi = blas.dtrmm(1.0, Lf, np.asfortranarray(V @ Y), lower=1)   # M P Y = L V Y
    res = np.linalg.norm(KP @ Y - MPhi * lam, axis=0)
    if np.all(res <= tol * knorm * np.linalg.norm(Phi, axis=0)):
        return lam, Phi
    return None
