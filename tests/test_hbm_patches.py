"""The two-level preconditioner of the reduced Newton systems: element blocks and a coarse space of
patches of elements (``hbm.preconditioner.PatchSpace``, ``PatchPreconditioner``)."""
import numpy as np
import pytest
import scipy.sparse.linalg as spla

from hbm.preconditioner import (ElementBlockPreconditioner, PatchPreconditioner, PatchSpace,
                                interface_patches)


def _grid(nx: int, ny: int, pitch: float = 1.0) -> np.ndarray:
    x, y = np.meshgrid(np.arange(nx) * pitch, np.arange(ny) * pitch, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel()])


def _interface(nx: int, ny: int, H: int, m: int = 6, seed: int = 0):
    """A synthetic joint: k = nx ny elements on a grid, a static flexibility that couples them
    smoothly (an exponential kernel, SPD, times an SPD 3 x 3 block), m smooth modes with complex
    factors per harmonic, and friction Jacobians of released springs (R_ee D_e = -0.05 ... -0.1,
    plus a random part coupling the harmonics) whose coupling through the neighbours is several
    times their own block's, as on the resonator's top-level curves (R_ee D_e about -0.3 there,
    the neighbours' normalized coupling summing to about 3).

    Returns: xy (k, 2), R (p, p), Psi (p, m), Ls, Dg (k, 3 n_H, 3 n_H)."""
    rng = np.random.default_rng(seed)
    xy = _grid(nx, ny)
    k, nH = xy.shape[0], 2 * H + 1
    r = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    B = np.array([[1.0, 0.1, 0.0], [0.1, 1.0, 0.05], [0.0, 0.05, 0.6]])
    R = 1e-3 * np.kron(np.exp(-r / 2.0), B)
    phase = rng.uniform(0, 2 * np.pi, size=(m, 3))
    Psi = np.stack([np.cos(0.3 * (j + 1) * xy[:, 0, None] + 0.2 * j * xy[:, 1, None] + phase[j])
                    for j in range(m)], axis=-1).reshape(3 * k, m) * 1e-2
    lam = np.linspace(20.0, 40.0, m)
    Ls = [1.0 / lam] + [1.0 / (lam - 0.5 * h ** 2 + 0.05j) for h in range(1, H + 1)]
    Dg = -100.0 * np.eye(3 * nH)[None] * rng.uniform(0.5, 1.0, size=(k, 1, 1))
    Dg = Dg + rng.normal(scale=10.0, size=(k, 3 * nH, 3 * nH))
    return xy, R, Psi, Ls, Dg


def _dense_jacobian(R, Psi, Ls, Dg):
    """J = I + G D formed densely: G the real harmonic receptance (cosine/sine blocks of each
    complex G_h = R + Psi L_h Psi^T), D scattered from the element blocks (layout d n_H + h) to
    the reduced layout h 3k + 3e + d."""
    p, k = R.shape[0], Dg.shape[0]
    H = len(Ls) - 1
    nH = 2 * H + 1
    G = np.zeros((nH * p, nH * p))
    G[:p, :p] = R + (Psi * Ls[0].real) @ Psi.T
    for h in range(1, H + 1):
        Gh = R + (Psi * Ls[h]) @ Psi.T
        a, b = (2 * h - 1) * p, 2 * h * p
        G[a:a + p, a:a + p], G[a:a + p, b:b + p] = Gh.real, Gh.imag
        G[b:b + p, a:a + p], G[b:b + p, b:b + p] = -Gh.imag, Gh.real
    D = np.zeros_like(G)
    d, h = np.divmod(np.arange(3 * nH), nH)
    for e in range(k):
        rows = h * p + 3 * e + d
        D[np.ix_(rows, rows)] = Dg[e]
    return np.eye(nH * p) + G @ D


def _coarse_basis(space: PatchSpace) -> np.ndarray:
    n = space.nc * space.nH * 3
    return np.column_stack([space.prolong(c) for c in np.eye(n)])


def test_patches_are_compact_groups_of_neighbours_on_a_grid():
    # 12 x 12 elements into 9 patches through R's coupling alone: every patch about 16 elements
    # and about a 4 x 4 square (an ideal one has its members within 2.2 pitches of its centroid)
    xy, R, *_ = _interface(12, 12, H=1)
    lab = interface_patches(R, 9)
    assert lab.shape == (144,) and lab.min() == 0
    sizes = np.bincount(lab)
    assert sizes.size == 9 and sizes.min() >= 8 and sizes.max() <= 28
    for c in range(9):
        members = xy[lab == c]
        assert np.linalg.norm(members - members.mean(axis=0), axis=1).max() <= 3.6
    # the patch count is clipped to [1, k]
    assert np.array_equal(interface_patches(R, 1), np.zeros(144, int))
    assert np.unique(interface_patches(R[:12, :12], 50)).size == 4


def test_the_coarse_space_is_orthonormal_and_restriction_is_its_transpose():
    _, R, Psi, Ls, Dg = _interface(9, 7, H=2)
    space = PatchSpace(R, Psi, nH=5, per_patch=10)
    assert space.nc == round(63 / 10)
    Z = _coarse_basis(space)
    assert np.allclose(Z.T @ Z, np.eye(Z.shape[1]), atol=1e-14)
    # each column is one patch's uniform motion in one direction on one harmonic row
    assert np.all(np.count_nonzero(Z, axis=0) == np.repeat(space.size, 5 * 3))
    r = np.random.default_rng(1).normal(size=Z.shape[0])
    assert np.allclose(space.restrict(r), Z.T @ r, rtol=0, atol=1e-13 * np.abs(r).sum())


@pytest.mark.parametrize("H", [1, 3])
def test_the_coarse_matrix_and_rows_are_those_of_the_dense_jacobian(H):
    # Z^T J Z (assembled from D's blocks, no product with J) and Z^T J z (from the coarse rows of
    # R and Psi) against the dense J; after the coarse correction the preconditioned residual
    # has no component left in the coarse space: Z^T (r - J M r) = 0 (A-DEF2's property)
    _, R, Psi, Ls, Dg = _interface(8, 6, H=H, seed=H)
    J = _dense_jacobian(R, Psi, Ls, Dg)
    space = PatchSpace(R, Psi, nH=2 * H + 1, per_patch=8)
    M = PatchPreconditioner(space, R, Psi, Ls, Dg)
    Z = _coarse_basis(space)
    Ac = Z.T @ J @ Z
    assert M.coarse.lu is not None
    C = M.coarse.solve(Ac)
    assert np.abs(C - np.eye(Ac.shape[0])).max() <= 1e-10
    rng = np.random.default_rng(2)
    z = rng.normal(size=J.shape[0])
    assert np.linalg.norm(M.coarse_rows(z) - Z.T @ (J @ z)) <= 1e-12 * np.linalg.norm(Z.T @ (J @ z))
    r = rng.normal(size=J.shape[0])
    assert np.linalg.norm(Z.T @ (r - J @ M(r))) <= 1e-10 * np.linalg.norm(r)


def _gmres_iterations(J, M, b):
    it = [0]

    def count(_):
        it[0] += 1
    P = J.shape[0]
    x, info = spla.gmres(spla.LinearOperator((P, P), matvec=lambda v: J @ v), b,
                         M=spla.LinearOperator((P, P), matvec=M), tol=1e-10, atol=0.0,
                         restart=300, maxiter=4, callback=count, callback_type="pr_norm")
    assert info == 0
    return x, it[0]


def test_the_patches_cut_gmres_iterations_where_elements_couple_smoothly():
    # released springs on a smoothly coupled interface, the top-level curves' situation: the
    # element blocks leave the smooth coupling, the patches take it; same solution as the LU
    H = 3
    _, R, Psi, Ls, Dg = _interface(12, 10, H=H)
    J = _dense_jacobian(R, Psi, Ls, Dg)
    b = np.random.default_rng(3).normal(size=J.shape[0])
    exact = np.linalg.solve(J, b)
    x_e, it_e = _gmres_iterations(J, ElementBlockPreconditioner(R, Psi, Ls, Dg), b)
    space = PatchSpace(R, Psi, nH=2 * H + 1)
    x_p, it_p = _gmres_iterations(J, PatchPreconditioner(space, R, Psi, Ls, Dg), b)
    for x in (x_e, x_p):
        assert np.linalg.norm(x - exact) <= 1e-8 * np.linalg.norm(exact)
    assert it_p <= 0.5 * it_e


def test_a_singular_coarse_matrix_leaves_the_element_blocks_alone():
    # one patch, the mean harmonic only, D = -s I with s = 1 / (the largest eigenvalue of
    # Z^T G Z): Z^T J Z = I - s Z^T G Z is singular, and the preconditioner is the element blocks'
    _, R, Psi, Ls, _ = _interface(4, 3, H=0)
    k = 12
    space = PatchSpace(R, Psi, nH=1, per_patch=100)
    assert space.nc == 1
    Z = _coarse_basis(space)
    G0 = R + (Psi * Ls[0]) @ Psi.T
    s = 1.0 / np.linalg.eigvalsh(Z.T @ G0 @ Z).max()
    Dg = -s * np.repeat(np.eye(3)[None], k, axis=0)
    M = PatchPreconditioner(space, R, Psi, Ls, Dg)
    assert M.coarse.lu is None
    r = np.random.default_rng(5).normal(size=3 * k)
    assert np.array_equal(M(r), ElementBlockPreconditioner(R, Psi, Ls, Dg)(r))


def test_the_coarse_level_is_switched_on_and_off_by_the_gmres_iterations(monkeypatch):
    # COARSE_ON / COARSE_OFF on a chain with friction elements (every Newton system on the GMRES
    # path): never on where the element blocks alone always count as enough, on from the second
    # solve where they never do (its coarse factor built, then reused for the same set), and on
    # and off in turn where the coarse level never counts as paying; the same solution each time
    import hbm.harmonic_balance as hbm_hb
    from test_hbm_preconditioner import _reference_solution, _solver
    w, f, s0 = _reference_solution(H=3, ne=20, n=150)
    assert s0.n_nonlinear >= 8
    used = {}
    for name, on, off in (("never", 10 ** 6, 0), ("always", -1, 0), ("alternate", -1, 10 ** 6)):
        monkeypatch.setattr(hbm_hb, "COARSE_ON", on)
        monkeypatch.setattr(hbm_hb, "COARSE_OFF", off)
        hb, _ = _solver(H=3, ne=20, n=150)
        assert hb.preconditioner == "patches"
        flags = []
        orig = hb._krylov

        def krylov(*a, **k):
            out = orig(*a, **k)
            flags.append(hb._coarse_used)
            return out
        hb._krylov = krylov
        sol = hb.solve(w, f)
        assert np.abs(sol.coefficients - s0.coefficients).max() <= 1e-7 * np.abs(s0.coefficients).max()
        used[name] = (flags, hb.stats["preconditioners"])
    flags, setups = used["never"]
    assert len(flags) >= 3 and not any(flags) and setups == 0
    flags, setups = used["always"]
    assert not flags[0] and all(flags[1:]) and 1 <= setups < len(flags) - 1
    flags, _ = used["alternate"]
    assert flags[:4] == [False, True, False, True]
