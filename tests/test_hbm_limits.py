"""Limits, rigid-body handling, energy balance, Krylov path and input validation."""
import numpy as np
import scipy.linalg as sla
import pytest

from hbm import ConvergenceError, FrictionContacts, HarmonicBalance, LinearStructure
from hbm.structure import Receptance
from hbm.harmonic_balance import _contact_operator


def free_free_pair(n_extra=0):
    """Two 3-DOF masses (x, y, z) joined by springs: free-free (3 rigid translations)."""
    m1, m2, k = 2.0, 1.0, 50.0
    M = np.diag([m1] * 3 + [m2] * 3)
    K = np.zeros((6, 6))
    for d in range(3):
        K[np.ix_([d, d + 3], [d, d + 3])] += k * np.array([[1, -1], [-1, 1]])
    C = 0.004 * K + 0.01 * M
    return M, K, C


def linear_response(M, K, C, F, w):
    return np.linalg.solve(K - w**2 * M + 1j * w * C, F)


def contact(mu, n0=5.0):
    return FrictionContacts(np.array([[[0, 1, 2], [3, 4, 5]]]), kt=40.0, kn=100.0, mu=mu, n0=n0)


F = np.array([1.0, 0.3, 0.0, 0.0, 0.0, 0.0])


def stuck_stiffness(K):
    Ks = K.copy()
    for d, kk in enumerate([40.0, 40.0, 100.0]):
        Ks[np.ix_([d, d + 3], [d, d + 3])] += kk * np.array([[1, -1], [-1, 1]])
    return Ks


@pytest.mark.parametrize("w", [2.0, 6.0, 13.0])
def test_mu_large_gives_linear_stuck_frf(w):
    M, K, C = free_free_pair()
    hb = HarmonicBalance(LinearStructure(M, K, C), contact(1e6), harmonics=3)
    sol = hb.solve(w, F)
    q = linear_response(M, stuck_stiffness(K), C, F, w)
    z = sol.coefficients[1] - 1j * sol.coefficients[2]
    assert np.abs(z - q).max() <= 1e-9 * np.abs(q).max()
    assert np.abs(sol.coefficients[[0, 3, 4, 5, 6]]).max() <= 1e-12 * np.abs(q).max()


@pytest.mark.parametrize("w", [2.0, 9.0])
def test_mu_zero_gives_frf_without_tangential_springs(w):
    M, K, C = free_free_pair()
    hb = HarmonicBalance(LinearStructure(M, K, C), contact(0.0), harmonics=3)
    sol = hb.solve(w, F)
    Kn = K.copy()
    Kn[np.ix_([2, 5], [2, 5])] += 100.0 * np.array([[1, -1], [-1, 1]])   # normal spring stays
    q = linear_response(M, Kn, C, F, w)
    z = sol.coefficients[1] - 1j * sol.coefficients[2]
    assert np.abs(z - q).max() <= 1e-8 * np.abs(q).max()


def test_zero_force_zero_response():
    M, K, C = free_free_pair()
    hb = HarmonicBalance(LinearStructure(M, K, C), contact(0.3), harmonics=3)
    sol = hb.solve(7.0, np.zeros(6))
    assert np.all(sol.coefficients == 0.0)
    assert np.all(hb.element_results(sol).energy == 0.0)


def test_energy_balance_closes():
    M, K, C = free_free_pair()
    hb = HarmonicBalance(LinearStructure(M, K, C), contact(0.2), harmonics=3, samples=128)
    w = 8.0
    sol = hb.solve(w, 5.0 * F)
    er = hb.element_results(sol)
    assert er.status[0] in (1, 2) and er.energy[0] > 0
    X = sol.coefficients
    W_in = np.pi * (5.0 * F) @ X[2]
    W_visc = sum(np.pi * h**2 * w * (X[2 * h - 1] @ C @ X[2 * h - 1] + X[2 * h] @ C @ X[2 * h])
                 for h in range(1, 4))
    W_fric = er.energy.sum()
    assert W_fric > 0.05 * W_in
    assert abs(W_in - W_visc - W_fric) <= 1e-6 * W_in


def chain(n, free=True):
    """n masses in a chain of springs (free-free if free), x DOFs only."""
    M = np.diag(np.linspace(1.0, 2.0, n))
    K = np.zeros((n, n))
    for i in range(n - 1):
        K[np.ix_([i, i + 1], [i, i + 1])] += (100.0 + 10 * i) * np.array([[1, -1], [-1, 1]])
    if not free:
        K[0, 0] += 100.0
    return M, K


def test_receptance_residual_flexibility_and_rigid_modes():
    n = 12
    M, K = chain(n)
    C = 0.002 * K
    dofs = np.array([[[3, -1, -1], [7, -1, -1]], [[5, -1, -1], [-1, -1, -1]]])
    B = _contact_operator(dofs, n)
    k0 = np.array([30.0, 0, 0, 0, 0, 0])
    Bd = B.toarray()
    Kb = K + Bd.T @ np.diag(k0) @ Bd
    s_full = LinearStructure(M, K, C, n_modes=n)
    s_trunc = LinearStructure(M, K, C, n_modes=4)
    errs = []
    for w in (0.3, 2.0):
        Gd = Bd @ np.linalg.solve(Kb - w**2 * M + 1j * w * C, Bd.T)
        Gf = Receptance(s_full, B, k0).matrix(1, w)
        assert np.abs(Gf - Gd).max() <= 1e-9 * np.abs(Gd).max()
        # truncated (4 of 12 modes) + static residual flexibility: exact as w -> 0, error growing
        # like (w / w_cut)^2 below the first discarded mode
        Gt = Receptance(s_trunc, B, k0).matrix(1, w)
        errs.append(np.abs(Gt - Gd).max() / np.abs(Gd).max())
    assert errs[0] <= 1e-4 and errs[1] <= 1e-2
    assert errs[0] < errs[1] / 20
    # static (h = 0) flexibility without the rigid-body mode: for the self-equilibrated pair load
    # (+1 on DOF 3, -1 on DOF 7) the relative displacement follows from the pseudo-inverse
    f = np.zeros(n)
    f[3], f[7] = 1.0, -1.0
    u_pinv = Bd[0] @ np.linalg.pinv(Kb) @ f
    for s_ in (s_full, s_trunc):
        G0 = Receptance(s_, B, k0).matrix(0, 1.0)
        assert abs(G0[0, 0].real - u_pinv) <= 1e-9 * abs(u_pinv)
    # the static response of the discarded modes (the receptance's Cholesky solve minus its kept
    # modes) is their modal sum, taken from a dense generalized eigendecomposition of (K~, M)
    lam, Phi = sla.eigh(Kb, M)
    y = np.linspace(-1.0, 1.0, n)
    ref = Phi[:, 4:] @ (Phi[:, 4:].T @ y / lam[4:])
    got = Receptance(s_trunc, B, k0).residual_full(y)
    assert np.abs(got - ref).max() <= 1e-9 * np.abs(ref).max()


def test_receptances_of_two_contact_maps_on_one_structure():
    """Receptances of two contact maps on one structure, built in turn (the structure keeps
    them keyed by map and base stiffness), each equal the direct receptance
    B (K~ - w^2 M + i w C)^-1 B^T of their own."""
    n = 12
    M, K = chain(n)
    C = 0.002 * K
    s = LinearStructure(M, K, C, n_modes=n)
    maps = [np.array([[[3, -1, -1], [7, -1, -1]]]), np.array([[[2, -1, -1], [9, -1, -1]]])]
    k0 = np.array([30.0, 0, 0])
    for dofs in maps + maps:
        B = _contact_operator(dofs, n)
        Bd = B.toarray()
        Kb = K + Bd.T @ np.diag(k0) @ Bd
        Gd = Bd @ np.linalg.solve(Kb - 0.8 * M + 1j * np.sqrt(0.8) * C, Bd.T)
        G = s.receptance(B, k0).matrix(1, np.sqrt(0.8))
        assert np.abs(G - Gd).max() <= 1e-9 * np.abs(Gd).max()



def test_receptances_are_kept_per_base_stiffness():
    """A structure hands out one receptance per contact map and base stiffness (equal inputs,
    not the same arrays), the last RECEPTANCES_KEPT of them; a solver on a kept one gives the
    response of a fresh one."""
    n = 12
    M, K = chain(n)
    s = LinearStructure(M, K, 0.002 * K, n_modes=4)
    dofs = np.array([[[3, -1, -1], [7, -1, -1]], [[5, -1, -1], [-1, -1, -1]]])
    B = _contact_operator(dofs, n)
    k0 = np.array([30.0, 0, 0, 0, 0, 0])
    G = s.receptance(B, k0)
    assert s.receptance(_contact_operator(dofs.copy(), n), k0.copy()) is G
    other = s.receptance(B, 2 * k0)
    assert other is not G and abs(other.matrix(1, 2.0)[0, 0] - G.matrix(1, 2.0)[0, 0]) > 1e-6
    for j in range(1, s.RECEPTANCES_KEPT):       # G falls out after RECEPTANCES_KEPT others
        s.receptance(B, (2 + j) * k0)
    assert s.receptance(B, k0) is not G
    fresh = Receptance(s, B, k0)
    assert np.abs(s.receptance(B, k0).matrix(1, 2.0) - fresh.matrix(1, 2.0)).max() == 0.0


def test_receptances_kept_within_their_byte_budget(monkeypatch):
    """The kept receptances fit in RECEPTANCE_BYTES together: with room for two, the third
    newest falls out; the newest is kept even when it alone exceeds the budget."""
    n = 12
    M, K = chain(n)
    s = LinearStructure(M, K, 0.002 * K, n_modes=4)
    B = _contact_operator(np.array([[[3, -1, -1], [7, -1, -1]]]), n)
    k0 = np.array([30.0, 0, 0])
    G1 = s.receptance(B, k0)
    assert G1.nbytes == sum(a.nbytes for a in (G1.Kb, G1.Phi, G1.Psi, G1.R, G1.lam, G1.Cm,
                                               G1._factor[0]))
    monkeypatch.setattr(LinearStructure, "RECEPTANCE_BYTES", 2.5 * G1.nbytes)
    G2 = s.receptance(B, 2 * k0)
    assert s.receptance(B, k0) is G1                   # two fit: G1 still kept (now newest)
    G3 = s.receptance(B, 3 * k0)                        # G2 is the oldest of three: out
    assert s.receptance(B, 3 * k0) is G3 and s.receptance(B, k0) is G1
    assert s.receptance(B, 2 * k0) is not G2
    monkeypatch.setattr(LinearStructure, "RECEPTANCE_BYTES", 1.0)
    G4 = s.receptance(B, 4 * k0)
    assert s.receptance(B, 4 * k0) is G4 and s.receptance(B, k0) is not G1


def test_krylov_path_matches_direct():
    n = 30
    M, K = chain(n, free=True)
    rng = np.random.default_rng(0)
    ne = 12
    a = rng.choice(n, size=ne, replace=False)
    b = (a + 7) % n
    dofs = np.full((ne, 2, 3), -1)
    dofs[:, 0, 0], dofs[:, 1, 0] = a, b
    c = FrictionContacts(dofs, kt=50.0, kn=100.0, mu=0.3, n0=rng.uniform(0.2, 2.0, ne))
    s = LinearStructure(M, K, damping_ratio=0.01, n_modes=10)
    f = np.zeros(n)
    f[0] = 3.0
    direct = HarmonicBalance(s, c, harmonics=3, samples=64)
    krylov = HarmonicBalance(s, c, harmonics=3, samples=64, dense_limit=0)
    w = 2.0
    s1 = direct.solve(w, f)
    s2 = krylov.solve(w, f)
    assert s1.n_nonlinear >= 3
    assert krylov.stats["gmres_iterations"] > 0
    assert np.abs(s1.coefficients - s2.coefficients).max() <= 1e-7 * np.abs(s1.coefficients).max()
    # a GMRES that stalls falls back to the dense LU of the same reduced system: same solution
    stalled = HarmonicBalance(s, c, harmonics=3, samples=64, dense_limit=0)

    def stall(*_):
        raise ConvergenceError("GMRES stalled (test)", 1.0)
    stalled._krylov = stall
    s3 = stalled.solve(w, f)
    assert stalled.stats["dense_fallbacks"] >= 1 and stalled.stats["gmres_iterations"] == 0
    assert np.abs(s1.coefficients - s3.coefficients).max() <= 1e-9 * np.abs(s1.coefficients).max()
    # where GMRES failed twice in a row, the next DENSE_AFTER_FALLBACK systems of about that size
    # go to the LU directly, then GMRES is tried again; an isolated failure changes nothing
    from hbm.harmonic_balance import DENSE_AFTER_FALLBACK
    for fails, direct_after in (((1,), 0), ((1, 2), DENSE_AFTER_FALLBACK)):
        hb = HarmonicBalance(s, c, harmonics=3, samples=64, dense_limit=0)
        calls, krylov_solve = [], hb._krylov

        def failing(*a, hb=hb, calls=calls, krylov_solve=krylov_solve, fails=fails):
            calls.append(hb.stats["linear_solves"])
            if len(calls) in fails:
                raise ConvergenceError("GMRES stalled (test)", 1.0)
            return krylov_solve(*a)
        hb._krylov = failing
        sols = [hb.solve(ww, f) for ww in (w, 1.02 * w, 1.04 * w)]
        n = len(fails)
        assert hb.stats["linear_solves"] > DENSE_AFTER_FALLBACK + n + 1
        assert calls[:n + 1] == list(range(1, n + 1)) + [n + 1 + direct_after]
        assert hb.stats["dense_fallbacks"] == n
        assert hb.stats["dense_after_fallback"] == direct_after
        for ww, sol in zip((w, 1.02 * w, 1.04 * w), sols):
            ref = direct.solve(ww, f)
            assert np.abs(ref.coefficients - sol.coefficients).max() <= 1e-9 * np.abs(ref.coefficients).max()


def test_gmres_keeps_its_krylov_space_beyond_150_vectors():
    # GMRES on a cyclic shift of n unknowns makes no progress before its n-th iteration (the
    # Krylov space of b = e_0 reaches the solution e_{n-1} only then), and a restarted GMRES with
    # a shorter space never converges: a stiff joint's Newton systems, restarted at 150, lost
    # their convergence so and went to the dense LU (``GMRES_RESTART``)
    from hbm.harmonic_balance import GMRES_MAXITER, GMRES_RESTART
    M, K, C = free_free_pair()
    hb = HarmonicBalance(LinearStructure(M, K, C), contact(0.3), harmonics=1, dense_limit=0)
    n = 200
    assert GMRES_RESTART >= n and GMRES_RESTART * GMRES_MAXITER >= 600
    b = np.zeros((n, 1))
    b[0] = 1.0
    x = hb._krylov(lambda v: np.roll(v, 1), lambda v: v, b, n)
    assert hb.stats["gmres_iterations"] == n
    assert np.abs(x[:, 0] - np.eye(n)[n - 1]).max() <= 1e-10


def test_newton_failure_raises_with_residual():
    M, K, C = free_free_pair()
    hb = HarmonicBalance(LinearStructure(M, K, C), contact(0.2), harmonics=3, max_iter=1)
    with pytest.raises(ConvergenceError) as e:
        hb.solve(8.0, 5.0 * F)
    assert e.value.residual > 0


@pytest.mark.parametrize("scale", [0.0, 0.03])
def test_newton_stops_on_a_stall_and_gives_its_best_iterate(monkeypatch, scale):
    """Newton gives up on a stall near the solution, not after max_iter. From the solution moved
    by 1e-7 (relative residual below STALL_BELOW) with an unreachable tolerance: with a zero
    direction every line search fails (10 trials each) and it stops after STALL_LINE_SEARCHES of
    them, carrying the start as its best iterate; with 3 % of the Newton step the residual falls
    ≈ 3 % per iteration, every first trial is accepted, and it stops when the residual has not
    halved in STALL_ITERATIONS, carrying its last (best) iterate. Far from the solution (the
    linear start, residual ≈ 1) the same zero direction runs to max_iter."""
    from types import SimpleNamespace
    from hbm.harmonic_balance import STALL_BELOW, STALL_ITERATIONS, STALL_LINE_SEARCHES
    M, K, C = free_free_pair()
    hb = HarmonicBalance(LinearStructure(M, K, C), contact(0.2), harmonics=3, max_iter=40)
    sol = hb.solve(8.0, 5.0 * F)
    U0 = sol.contact * (1 + 1e-7)
    hb.tol = 1e-15                               # unreachable: only a stall ends it
    linsolve = hb.linsolve
    monkeypatch.setattr(hb, "linsolve", lambda *a, **k: [scale * x for x in linsolve(*a, **k)])
    before = hb.stats["residuals"]
    with pytest.raises(ConvergenceError, match="stalled") as e:
        hb.solve(8.0, 5.0 * F, guess=SimpleNamespace(contact=U0))
    best = e.value.best
    assert best.residual == e.value.residual
    assert hb.tol < best.residual <= STALL_BELOW
    assert max(STALL_ITERATIONS, STALL_LINE_SEARCHES) < hb.max_iter
    if scale == 0.0:
        assert hb.stats["residuals"] - before == 1 + 10 * STALL_LINE_SEARCHES
        assert np.array_equal(best.contact, U0)
    else:
        assert hb.stats["residuals"] - before == 1 + STALL_ITERATIONS
        assert best.iterations == STALL_ITERATIONS
        assert not np.array_equal(best.contact, U0)
        return
    before = hb.stats["residuals"]
    with pytest.raises(ConvergenceError, match="in 40 iterations"):
        hb.solve(8.0, 5.0 * F)                   # from the linear start: far, no stall exit
    assert hb.stats["residuals"] - before == 1 + 10 * hb.max_iter


@pytest.mark.parametrize("kw, msg", [
    (dict(kt=-1.0), "kt"), (dict(mu=-0.1), "mu"), (dict(n0=np.nan), "n0"),
    (dict(kn=np.ones(3)), "kn"), (dict(dofs=np.zeros((2, 3))), "dofs"),
])
def test_contact_validation(kw, msg):
    args = dict(dofs=np.array([[[0, 1, 2], [3, 4, 5]]]), kt=1.0, kn=1.0, mu=0.1, n0=1.0)
    args.update(kw)
    with pytest.raises(ValueError, match=msg):
        FrictionContacts(**args)


def test_structure_and_solver_validation():
    M, K, C = free_free_pair()
    with pytest.raises(ValueError, match="M"):
        LinearStructure(M * np.nan, K)
    with pytest.raises(ValueError, match="K"):
        LinearStructure(M, K[:3, :3])
    with pytest.raises(ValueError, match="damping_ratio"):
        LinearStructure(M, K, damping_ratio=-0.1)
    hb = HarmonicBalance(LinearStructure(M, K, C), contact(0.2))
    with pytest.raises(ValueError, match="omega"):
        hb.solve(-1.0, F)
    with pytest.raises(ValueError, match="force"):
        hb.solve(1.0, F[:3])
    with pytest.raises(ValueError, match="dofs"):
        HarmonicBalance(LinearStructure(M[:4, :4], K[:4, :4]), contact(0.2))


def test_truncated_modes_response_recovery():
    """Free-free chain, 6 of 30 modes + residual flexibility, joint stuck (mu huge): the recovered
    structure response matches the direct linear solve at low frequency; the per-DOF path used by
    sol.amplitude equals the full recovery."""
    n = 30
    M, K = chain(n, free=True)
    C = 0.001 * K
    dofs = np.full((2, 2, 3), -1)
    dofs[0, 0, 0], dofs[0, 1, 0] = 4, 20
    dofs[1, 0, 0] = 11
    c = FrictionContacts(dofs, kt=80.0, kn=100.0, mu=1e6, n0=1.0)
    hb = HarmonicBalance(LinearStructure(M, K, C, n_modes=6), c, harmonics=3, samples=64)
    f = np.zeros(n)
    f[0] = 1.0
    w = 1.0
    sol = hb.solve(w, f)
    amp7 = sol.amplitude(7)                                # per-DOF recovery (before the full one)
    Ks = K.copy()
    Ks[np.ix_([4, 20], [4, 20])] += 80.0 * np.array([[1, -1], [-1, 1]])
    Ks[11, 11] += 80.0
    q = linear_response(M, Ks, C, f, w)
    z = sol.coefficients[1] - 1j * sol.coefficients[2]
    assert np.abs(z - q).max() <= 1e-3 * np.abs(q).max()
    assert abs(amp7 - abs(z[7])) <= 1e-12 * abs(z[7])
