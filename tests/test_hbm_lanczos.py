"""Block Lanczos for the receptance's modes (hbm.lanczos) against analytic eigenvalues and the
receptance it gives against direct solves of the dynamic stiffness."""
import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from hbm import lanczos
from hbm.structure import LinearStructure, Receptance


def consistent_mass_chain(N: int, k: float = 100.0, me: float = 0.02):
    """Free-free chain of N linear bar elements (N + 1 nodes), stiffness k and consistent mass
    me per element. Its eigenvalues are (6 k / me) (1 - cos t) / (2 + cos t), t = j pi / N
    (the cosine modes satisfy the free ends by reflection)."""
    n = N + 1
    K, M = np.zeros((n, n)), np.zeros((n, n))
    for e in range(N):
        i = [e, e + 1]
        K[np.ix_(i, i)] += k * np.array([[1.0, -1.0], [-1.0, 1.0]])
        M[np.ix_(i, i)] += me / 6 * np.array([[2.0, 1.0], [1.0, 2.0]])
    t = np.arange(n) * np.pi / N
    return K, M, 6 * k / me * (1 - np.cos(t)) / (2 + np.cos(t))


def test_lowest_modes_of_a_consistent_mass_chain():
    K, M, exact = consistent_mass_chain(600)
    m = 30
    shift = -1e-3 * exact[1]
    modes = lanczos.lowest_modes(K, M, m, shift, np.linalg.cholesky(M))
    assert modes is not None
    # the rigid mode's zero to round-off of the first elastic eigenvalue, the rest relatively
    assert abs(modes.lam[0]) <= 1e-9 * exact[1]
    assert np.max(np.abs(modes.lam[1:] - exact[1:m]) / exact[1:m]) <= 1e-9
    assert np.abs(modes.Phi.T @ M @ modes.Phi - np.eye(m)).max() <= 1e-10
    res = np.linalg.norm(K @ modes.Phi - (M @ modes.Phi) * modes.lam, axis=0)
    assert res.max() <= lanczos.TOL * np.abs(K).sum(axis=0).max() * np.linalg.norm(modes.Phi, axis=0).min()


@pytest.mark.parametrize("m", [0, 602, 2.5, True])
def test_lowest_modes_reject_a_bad_count(m):
    K, M, exact = consistent_mass_chain(600)
    with pytest.raises(ValueError, match=r"m must be an integer in \[1, 601\]"):
        lanczos.lowest_modes(K, M, m, -1e-3 * exact[1], np.linalg.cholesky(M))


def test_lowest_modes_give_up_within_the_block_limit(monkeypatch):
    """Too few blocks allowed: None (the receptance then takes LAPACK's eigh), never unconverged pairs."""
    K, M, exact = consistent_mass_chain(600)
    monkeypatch.setattr(lanczos, "MAX_BLOCKS", lanczos.MIN_BLOCKS)
    assert lanczos.lowest_modes(K, M, 30, -1e-3 * exact[1], np.linalg.cholesky(M)) is None


def _chain_receptance_case(N: int = 600):
    """The chain with a stuck pair between nodes 100 and 400 and a grounded pair at node 250."""
    K, M, _ = consistent_mass_chain(N)
    n = N + 1
    rows = [0, 0, 1]
    cols = [100, 400, 250]
    B = sp.csr_matrix((np.array([1.0, -1.0, 1.0]), (rows, cols)), shape=(2, n))
    k0 = np.array([50.0, 20.0])
    C = 1e-4 * K
    return K, M, C, B, k0


@pytest.mark.parametrize("max_blocks", [lanczos.MAX_BLOCKS, lanczos.MIN_BLOCKS])
def test_receptance_by_lanczos_against_direct_solves(monkeypatch, max_blocks):
    """20 of 601 modes kept: the receptance equals B (K~ - w^2 M + i w C)^-1 B^T within the
    truncation's bound w^2 / (lambda_21 - w^2) (the discarded modes' response taken as static),
    the static one B K~^-1 B^T, and the
    discarded modes' static response their modal sum (LAPACK's full eigh), whether the modes
    come from the Lanczos or (too few blocks allowed) from the fallback eigh."""
    monkeypatch.setattr(lanczos, "MAX_BLOCKS", max_blocks)
    found = []
    orig = lanczos.lowest_modes

    def spy(*a, **k):
        out = orig(*a, **k)
        found.append(out is not None)
        return out
    monkeypatch.setattr(lanczos, "lowest_modes", spy)
    K, M, C, B, k0 = _chain_receptance_case()
    Bd = B.toarray()
    Kb = K + Bd.T @ np.diag(k0) @ Bd
    m = 20
    G = Receptance(LinearStructure(M, K, C, n_modes=m), B, k0)
    assert found == [max_blocks > lanczos.MIN_BLOCKS]
    lam, Phi = sla.eigh(Kb, M)
    for w in (0.05 * np.sqrt(lam[0]), 0.2 * np.sqrt(lam[m - 1])):
        Gd = Bd @ np.linalg.solve(Kb - w**2 * M + 1j * w * C, Bd.T)
        err = np.abs(G.matrix(1, w) - Gd).max() / np.abs(Gd).max()
        assert err <= 1.1 * w**2 / (lam[m] - w**2)
    # the grounded structure has no rigid mode: G_0 = B K~^-1 B^T
    G0 = Bd @ np.linalg.solve(Kb, Bd.T)
    assert np.abs(G.matrix(0, 1.0) - G0).max() <= 1e-8 * np.abs(G0).max()
    y = np.linspace(-1.0, 1.0, K.shape[0])
    ref = Phi[:, m:] @ (Phi[:, m:].T @ y / lam[m:])
    assert np.abs(G.residual_full(y) - ref).max() <= 1e-7 * np.abs(ref).max()


def test_free_free_receptance_by_lanczos_keeps_rigid_motion_out_of_the_static_one():
    """Without the grounded pair the chain is free-free: one rigid mode, found and kept; the
    static receptance of the self-equilibrated pair load is the pseudo-inverse's."""
    K, M, C, B, k0 = _chain_receptance_case()
    B = B[:1]
    k0 = k0[:1]
    Bd = B.toarray()
    Kb = K + Bd.T @ np.diag(k0) @ Bd
    G = Receptance(LinearStructure(M, K, C, n_modes=20), B, k0)
    assert G.rigid.sum() == 1 and G.rigid[0]
    u = Bd @ np.linalg.pinv(Kb) @ Bd.T
    assert abs(G.matrix(0, 1.0)[0, 0].real - u[0, 0]) <= 1e-8 * abs(u[0, 0])
