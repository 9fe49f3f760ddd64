"""The GMRES preconditioner of the reduced Newton systems and its reuse."""
import numpy as np

from hbm import FrictionContacts, HarmonicBalance, LinearStructure
from hbm.harmonic_balance import _PreconditionerCache
from hbm.preconditioner import HarmonicAveragedPreconditioner, MeanCoupledPreconditioner

from test_hbm_limits import chain


def _solver(H=3, ne=8, n=60, seed=1):
    """A chain of n masses with ne friction elements in 3 directions (distinct DOFs)."""
    M, K = chain(n, free=False)
    rng = np.random.default_rng(seed)
    pick = rng.permutation(n)[: 6 * ne].reshape(ne, 2, 3)
    c = FrictionContacts(pick, kt=50.0, kn=100.0, mu=0.3, n0=rng.uniform(0.2, 2.0, ne))
    s = LinearStructure(M, K, damping_ratio=0.02, n_modes=12)
    return HarmonicBalance(s, c, harmonics=H, samples=64, dense_limit=0), rng


def _reference_solution(**solver_kw):
    """The LU path's solution of ``_solver``'s chain at 0.95 of its first elastic frequency,
    40 N at DOF 0: (omega, force, Solution)."""
    ref, _ = _solver(**solver_kw)
    ref.dense_limit = 10 ** 6
    w = 0.95 * np.sqrt(ref.G.lam[~ref.G.rigid][0])
    f = np.zeros(ref.s.n)
    f[0] = 40.0
    return w, f, ref.solve(w, f)


def _kept_structure(rng, k, H):
    """Element Jacobians with only what the preconditioner keeps: any mean block D_00 and mean
    row D_0h, no force at the dynamic rows from the mean (D_h0 = 0), and at every dynamic row
    the same 3x3 block K (per element) on the diagonal, nothing between two dynamic rows."""
    nH = 2 * H + 1
    D = np.zeros((k, 3, nH, 3, nH))
    D[:, :, 0, :, :] = rng.normal(scale=40.0, size=(k, 3, 3, nH))
    K = rng.normal(scale=40.0, size=(k, 3, 3))
    for h in range(1, nH):
        D[:, :, h, :, h] = K
    return D.reshape(k, 3 * nH, 3 * nH)


def _parts(hb, nl, omega):
    cn = (3 * nl[:, None] + np.arange(3)).ravel()
    Ls = [hb.G.modal(h, omega) for h in range(hb.H + 1)]
    return hb.G.R[np.ix_(cn, cn)], hb.G.Psi[cn], Ls


def _real_receptance(hb, omega, cn):
    """The whole real harmonic receptance on cn: cosine/sine blocks of each complex G_h."""
    p, nH = cn.size, hb.nH
    G = np.zeros((nH * p, nH * p))
    G[:p, :p] = hb.G.matrix(0, omega, cn, cn).real
    for h in range(1, hb.H + 1):
        Gh = hb.G.matrix(h, omega, cn, cn)
        a, b = (2 * h - 1) * p, 2 * h * p
        G[a:a + p, a:a + p], G[a:a + p, b:b + p] = Gh.real, Gh.imag
        G[b:b + p, a:a + p], G[b:b + p, b:b + p] = -Gh.imag, Gh.real
    return G


def test_the_dense_jacobian_is_identity_plus_receptance_times_friction_jacobian():
    # J = I + G D with G the whole real receptance and D scattered from the element blocks (the
    # element layout d n_H + h to the reduced layout h 3k + 3e + d), against the blockwise
    # product of ``_dense_jacobian``, also when written into a view of a larger (bordered) array
    for H in (1, 3):
        hb, rng = _solver(H=H)
        nl = np.array([1, 2, 4, 7])
        k, nH = nl.size, 2 * H + 1
        cn = (3 * nl[:, None] + np.arange(3)).ravel()
        omega = 0.8 * np.sqrt(hb.G.lam[~hb.G.rigid][0])
        Dg = rng.normal(scale=30.0, size=(k, 3 * nH, 3 * nH))
        D = np.zeros((nH * 3 * k,) * 2)
        for e in range(k):
            for i in range(3 * nH):
                for j in range(3 * nH):
                    (di, hi), (dj, hj) = divmod(i, nH), divmod(j, nH)
                    D[hi * 3 * k + 3 * e + di, hj * 3 * k + 3 * e + dj] = Dg[e, i, j]
        ref = np.eye(D.shape[0]) + _real_receptance(hb, omega, cn) @ D
        J = hb._dense_jacobian(omega, cn, Dg)
        assert np.abs(J - ref).max() <= 1e-12 * np.abs(ref).max()
        big = np.full((D.shape[0] + 1,) * 2, np.nan)
        hb._dense_jacobian(omega, cn, Dg, out=big[:-1, :-1])
        assert np.array_equal(big[:-1, :-1], J) and np.isnan(big[-1]).all() and np.isnan(big[:, -1]).all()
        # a single-precision view (the mixed-precision LU's matrix) is formed in single
        # precision: every entry within a few single-precision ulps of the double product's
        big32 = np.full((D.shape[0] + 1,) * 2, np.nan, dtype=np.float32)
        hb._dense_jacobian(omega, cn, Dg, out=big32[:-1, :-1])
        eps32 = float(np.finfo(np.float32).eps)
        assert np.abs(big32[:-1, :-1] - ref).max() <= 8 * eps32 * np.abs(ref).max()
        assert np.abs(big32[:-1, :-1] - ref).max() > 0 and np.isnan(big32[-1]).all()


def test_the_preconditioner_is_the_inverse_on_the_structure_it_keeps():
    # J formed densely from the complex receptance blocks (HarmonicBalance._dense_jacobian,
    # checked against the whole real receptance below), independently of the preconditioner's
    # Woodbury correction, explicit mean inverse and Gauss-Seidel sweep
    for H in (1, 3):
        hb, rng = _solver(H=H)
        nl = np.array([0, 2, 3, 5, 7])
        omega = 0.9 * np.sqrt(hb.G.lam[~hb.G.rigid][0])
        Dg = _kept_structure(rng, nl.size, H)
        J = hb._reduced(omega, nl, Dg, dense=True)[3]
        prec = MeanCoupledPreconditioner(*_parts(hb, nl, omega), Dg)
        X = rng.normal(size=(J.shape[0], 4))
        for x in X.T:
            assert np.linalg.norm(prec(J @ x) - x) <= 1e-10 * np.linalg.norm(x)
        # with a force at the dynamic rows from the mean it is no longer exact (the sweep is
        # one-sided), which the test above would see if the sweep ran the other way
        D5 = Dg.reshape(nl.size, 3, 2 * H + 1, 3, 2 * H + 1).copy()
        D5[:, :, 1, :, 0] = rng.normal(scale=40.0, size=(nl.size, 3, 3))
        J2 = hb._reduced(omega, nl, D5.reshape(Dg.shape), dense=True)[3]
        prec2 = MeanCoupledPreconditioner(*_parts(hb, nl, omega), D5.reshape(Dg.shape))
        x = X[:, 0]
        assert np.linalg.norm(prec2(J2 @ x) - x) > 1e-6 * np.linalg.norm(x)
        # and the harmonic-averaged peer, which replaces the mean block by the dynamic average,
        # is not exact on the first structure either
        avg = HarmonicAveragedPreconditioner(*_parts(hb, nl, omega), Dg)
        assert np.linalg.norm(avg(J @ x) - x) > 1e-3 * np.linalg.norm(x)


def test_gmres_with_each_preconditioner_gives_the_direct_solution():
    for name in ("patches", "element", "averaged", "mean-coupled", "two-level"):
        _check_gmres_solution(name)


def _check_gmres_solution(name):
    hb, _ = _solver(H=3)
    hb.preconditioner = name
    f = np.zeros(hb.s.n)
    f[0] = 40.0
    w = 0.95 * np.sqrt(hb.G.lam[~hb.G.rigid][0])
    direct = HarmonicBalance(hb.s, hb.c, harmonics=3, samples=64)
    s1, s2 = direct.solve(w, f), hb.solve(w, f)
    assert s2.n_nonlinear >= 4
    assert np.abs(s1.coefficients - s2.coefficients).max() <= 1e-7 * np.abs(s1.coefficients).max()
    # 3 k n_H unknowns per system; GMRES needed a small fraction of that
    assert hb.stats["gmres_iterations"] <= 0.25 * hb.stats["linear_solves"] * 3 * 8 * 7


def test_a_preconditioner_is_reused_for_the_same_set_and_rebuilt_when_worn():
    hb, _ = _solver(H=3)
    G = hb.G
    nl = np.array([1, 2, 4])
    pre = _PreconditionerCache(G, nl, 10.0, None, None, None)
    assert pre.usable(G, nl, 10.0 * (1 + 0.5 * pre.REUSE_OMEGA))
    assert not pre.usable(G, nl, 10.0 * (1 + 2 * pre.REUSE_OMEGA))      # too far in frequency
    assert not pre.usable(G, np.array([1, 2, 5]), 10.0)                   # another set
    assert not pre.usable(object(), nl, 10.0)                             # another receptance
    pre.observe(10)
    pre.observe(int(pre.REUSE_GROWTH * 10 + pre.REUSE_SLACK))            # still fine
    assert pre.usable(G, nl, 10.0)
    pre.observe(int(pre.REUSE_GROWTH * 10 + pre.REUSE_SLACK) + 1)        # worn: rebuilt next
    assert not pre.usable(G, nl, 10.0)
    # along a sweep the solver builds fewer preconditioners than it solves systems (the cached
    # kinds; the element blocks are rebuilt at every solve and never counted)
    hb.preconditioner = "averaged"
    f = np.zeros(hb.s.n)
    f[0] = 40.0
    w = np.sqrt(hb.G.lam[~hb.G.rigid][0])
    hb.frf(0.9 * w, 1.1 * w, f, dof=0, max_points=15)
    assert 0 < hb.stats["preconditioners"] < hb.stats["linear_solves"]


def test_an_unknown_preconditioner_is_rejected_naming_the_choices():
    hb, _ = _solver(H=1)
    try:
        HarmonicBalance(hb.s, hb.c, preconditioner="ilu")
    except ValueError as e:
        assert "averaged|mean-coupled" in str(e) and "'ilu'" in str(e)
    else:
        raise AssertionError("accepted an unknown preconditioner")


def _element_layout_matrix(Dg: np.ndarray, k: int, nH: int) -> np.ndarray:
    """D scattered from element blocks (layout d n_H + h) to the reduced layout h 3k + 3e + d."""
    D = np.zeros((nH * 3 * k,) * 2)
    d, h = np.divmod(np.arange(3 * nH), nH)
    for e in range(k):
        rows = h * 3 * k + 3 * e + d
        D[np.ix_(rows, rows)] = Dg[e]
    return D


def _uncoupled_elements(rng, k: int, H: int):
    """(R, Psi, Ls, Dg) of k elements without coupling: a static flexibility block-diagonal over
    the elements (SPD 3 x 3 blocks), no modes, random friction Jacobians."""
    nH, p = 2 * H + 1, 3 * k
    R = np.zeros((p, p))
    for e in range(k):
        B = rng.normal(size=(3, 3))
        R[3 * e:3 * e + 3, 3 * e:3 * e + 3] = 1e-3 * (B @ B.T + 3 * np.eye(3))
    Ls = [np.zeros(1)] + [np.zeros(1, complex)] * H
    return R, np.zeros((p, 1)), Ls, rng.normal(scale=300.0, size=(k, 3 * nH, 3 * nH))


def test_element_blocks_invert_a_jacobian_without_coupling_between_elements():
    # a receptance without modes and with a static flexibility block-diagonal over the elements:
    # J = I + G D has no block outside the elements', and the element blocks are its inverse;
    # so is the two-level preconditioner (its element stage inverts what the averaged one left)
    from hbm.preconditioner import ElementBlockPreconditioner, TwoLevelPreconditioner
    rng = np.random.default_rng(4)
    for H in (1, 3):
        k, nH = 5, 2 * H + 1
        p = 3 * k
        R, Psi, Ls, Dg = _uncoupled_elements(rng, k, H)
        G = np.kron(np.eye(nH), R)
        J = np.eye(nH * p) + G @ _element_layout_matrix(Dg, k, nH)
        E = ElementBlockPreconditioner(R, Psi, Ls, Dg)
        X = rng.normal(size=(nH * p, 3))
        for x in X.T:
            assert np.linalg.norm(E(J @ x) - x) <= 1e-10 * np.linalg.norm(x)
        two = TwoLevelPreconditioner(HarmonicAveragedPreconditioner(R, Psi, Ls, Dg), E, lambda v: J @ v)
        assert np.linalg.norm(two(J @ X[:, 0]) - X[:, 0]) <= 1e-10 * np.linalg.norm(X[:, 0])


def test_an_element_whose_own_block_is_singular_is_left_unpreconditioned():
    """An element block I + G_ee D_e that is singular (here D_e = -G_ee^-1 on every harmonic)
    gets the identity; the other elements keep their exact inverses."""
    from hbm.preconditioner import ElementBlockPreconditioner
    rng = np.random.default_rng(7)
    H, k = 1, 4
    nH, p = 2 * H + 1, 12
    R, Psi, Ls, Dg = _uncoupled_elements(rng, k, H)
    bad = 2
    Dg[bad] = -np.kron(np.linalg.inv(R[3 * bad:3 * bad + 3, 3 * bad:3 * bad + 3]), np.eye(nH))
    E = ElementBlockPreconditioner(R, Psi, Ls, Dg)
    assert np.array_equal(E.inv[bad], np.eye(3 * nH))
    G = np.kron(np.eye(nH), R)
    J = np.eye(nH * p) + G @ _element_layout_matrix(Dg, k, nH)
    x = rng.normal(size=nH * p)
    x[E.idx[bad]] = 0.0                    # the well-posed elements' part: inverted exactly
    assert np.linalg.norm(E(J @ x) - x) <= 1e-10 * np.linalg.norm(x)

def test_element_and_two_level_preconditioners_solve_the_same_systems():
    # the GMRES path with each preconditioner gives the dense LU's solution of a chain with
    # friction elements, and the two-level one needs fewer iterations than the averaged one
    hbs = {}
    for pc in ("averaged", "element", "two-level"):
        hb, _ = _solver(H=3)
        hb.preconditioner = pc
        hbs[pc] = hb
    w, f, s0 = _reference_solution(H=3)
    assert s0.n_nonlinear >= 4
    its = {}
    for pc, hb in hbs.items():
        sol = hb.solve(w, f)
        assert np.abs(sol.coefficients - s0.coefficients).max() <= 1e-8 * np.abs(s0.coefficients).max()
        its[pc] = hb.stats["gmres_iterations"] / max(hb.stats["linear_solves"], 1)
    assert its["two-level"] < its["averaged"]


def test_inexact_newton_stops_gmres_at_the_residual_the_step_needs(monkeypatch):
    """The forcing term (``KRYLOV_FORCING``): a Newton step's GMRES tolerance is 0.1 tol x the
    response norm over ||b||, kept within [krylov_tol, KRYLOV_ETA_MAX]; the solution equals the
    one with every solve at krylov_tol (and the dense LU's) to the Newton tolerance, in fewer
    GMRES iterations."""
    import hbm.harmonic_balance as hbm_hb
    hb, _ = _solver(H=3)
    assert hb.krylov_rtol(1.0, None) == hb.krylov_tol
    assert hb.krylov_rtol(1.0, 1e-30) == hb.krylov_tol
    assert hb.krylov_rtol(1.0, 1.0) == hbm_hb.KRYLOV_ETA_MAX
    assert hb.krylov_rtol(2.0, 1e-6) == 5e-7
    hb, _ = _solver(H=3, ne=20, n=150)
    f = np.zeros(hb.s.n)
    f[0] = 40.0
    w = 0.95 * np.sqrt(hb.G.lam[~hb.G.rigid][0])
    direct = HarmonicBalance(hb.s, hb.c, harmonics=3, samples=64).solve(w, f)
    runs, default = {}, hbm_hb.KRYLOV_FORCING
    for forcing in (default, 0.0):                        # 0: every solve at krylov_tol
        monkeypatch.setattr(hbm_hb, "KRYLOV_FORCING", forcing)
        hb, _ = _solver(H=3, ne=20, n=150)                 # 13 nonlinear elements, 273 unknowns
        runs[forcing] = (hb.solve(w, f), hb.stats["gmres_iterations"], hb.stats["linear_solves"])
    (inexact, its, n), (exact, its0, n0) = runs[default], runs[0.0]
    assert inexact.n_nonlinear >= 10 and n == n0 >= 5     # the same Newton iterations
    scale = np.abs(direct.coefficients).max()
    for s in (inexact, exact):
        assert np.abs(s.coefficients - direct.coefficients).max() <= 1e-7 * scale
    assert its <= 0.85 * its0           # measured 273 against 359
