"""3D friction element and AFT: describing function, circular orbit, separation, Jacobian."""
import numpy as np
import pytest

from hbm import FrictionContacts, HarmonicBalance, LinearStructure, Solution
from hbm.fourier import Fourier
from hbm.reference import jenkins_describing_function

KT, FS = 100.0, 1.0                       # N/mm, N  (mu = 0.1, n0 = 10 N)


def one_element(mu=0.1, n0=10.0, kn=1e3, gap=0.0):
    return FrictionContacts(np.array([[[0, 1, 2], [-1, -1, -1]]]), kt=KT, kn=kn, mu=mu, n0=n0, gap=gap)


def element_results(c, U, nt, H=1):
    """Per-element results through the public HarmonicBalance API for given contact harmonics."""
    s = LinearStructure(np.eye(3), np.eye(3) * 1e3)
    hb = HarmonicBalance(s, c, harmonics=H, samples=nt)
    sol = Solution(1.0, np.zeros((2 * H + 1, 3)), U, 0.0, 0, 0)
    return hb.element_results(sol)


@pytest.mark.parametrize("A", [0.005, 0.011, 0.02, 0.05])
def test_describing_function_and_energy(A):
    f = Fourier(1, 4096)
    c = one_element()
    U = np.zeros((1, 3, 3))
    U[0, 0, 1] = A
    F, _, _ = c.evaluate(U, f, jacobian=False)
    a1, b1, W = jenkins_describing_function(A, KT, FS)
    assert abs(F[0, 0, 1] - a1) <= 1e-6 * abs(a1)
    if W > 0:
        assert abs(F[0, 0, 2] - b1) <= 1e-6 * abs(b1)
        er = element_results(c, U, 4096)
        assert abs(er.energy[0] - W) <= 1e-6 * W
        assert er.status[0] == 1                       # stick-slip
    else:
        assert abs(F[0, 0, 2]) <= 1e-12 * KT * A
        assert element_results(c, U, 4096).status[0] == 0


def test_describing_function_large_amplitude():
    """Strong slip (A = 50 fs/kt): the off-sample stick->slip kink limits the sampled AFT (trapezoidal rule on a C0 force with a kink)."""
    A = 0.5
    c = one_element()
    U = np.zeros((1, 3, 3))
    U[0, 0, 1] = A
    a1, b1, _ = jenkins_describing_function(A, KT, FS)
    errs = []
    for nt in (1024, 4096):
        F = c.evaluate(U, Fourier(1, nt), jacobian=False)[0]
        errs.append(np.hypot(F[0, 0, 1] - a1, F[0, 0, 2] - b1) / np.hypot(a1, b1))
    assert errs[1] <= 1e-5
    assert errs[1] < errs[0]


def test_circular_orbit_coupled_limit():
    A = 0.1                                            # mm, >> fs/kt = 0.01
    U = np.zeros((1, 3, 3))
    U[0, 0, 1] = A                                     # u1 = A cos
    U[0, 1, 2] = A                                     # u2 = A sin
    c = one_element()
    er = element_results(c, U, 2048)
    W_exact = 2 * np.pi * FS * np.sqrt(A**2 - (FS / KT) ** 2)
    assert abs(er.energy[0] - W_exact) <= 1e-3 * W_exact
    # the circular limit: |T| = mu N at every sample once the cycle has closed
    assert np.allclose(np.hypot(er.T[0, 0], er.T[0, 1]), FS, rtol=1e-9)
    assert er.status[0] == 2                           # gross slip
    # two independent 1D sliders would dissipate 2 * 4 fs (A - fs/kt): 15 % more here
    W_indep = 2 * jenkins_describing_function(A, KT, FS)[2]
    assert abs(W_indep - W_exact) > 0.1 * W_exact


def test_separation_zero_force_and_slider_reset():
    nt = 256
    f = Fourier(2, nt)
    c = one_element(mu=0.3, n0=10.0, kn=1e3)
    U = np.zeros((1, 3, 5))
    U[0, 0, 1] = 0.05                                  # tangential A cos
    U[0, 0, 3] = 0.02                                  # + second harmonic
    U[0, 2, 1] = -0.02                                 # normal: opens when cos > 0.5
    h = c.histories(U, f)
    u = f.to_time(U[0])
    N_exp = np.maximum(0.0, 10.0 + 1e3 * u[2])
    assert np.allclose(h["N"][0], N_exp, rtol=0, atol=1e-12)
    open_ = N_exp == 0
    assert open_.any() and (~open_).any()
    assert np.all(h["T"][0][:, open_] == 0.0)          # zero force while open
    assert h["status"][0] == 3                         # partly open
    # slider reset: at the first closed sample after an open one the trial force starts from
    # the tangential position at the last open sample (zero force there)
    j = np.nonzero(open_[:-1] & ~open_[1:])[0][0] + 1
    trial = KT * (u[0:2, j] - u[0:2, j - 1])
    lim = 0.3 * N_exp[j]
    expect = trial if np.hypot(*trial) <= lim else trial * lim / np.hypot(*trial)
    assert np.allclose(h["T"][0][:, j], expect, rtol=1e-12, atol=1e-12)


def reference_march(ut, un, kt, kn, mu, n0, cycles=4):
    """Independent straightforward time march (Python loop, 2D radial return)."""
    nt = ut.shape[1]
    w = np.zeros(2)
    T = np.zeros((2, nt))
    for _ in range(cycles):
        for j in range(nt):
            N = max(0.0, n0 + kn * un[j])
            if N == 0.0:
                w = ut[:, j].copy()
                T[:, j] = 0
                continue
            tr = kt * (ut[:, j] - w)
            nrm = np.hypot(*tr)
            if nrm > mu * N:
                tr *= mu * N / nrm
                w = ut[:, j] - tr / kt
            T[:, j] = tr
    return T


def test_in_phase_normal_tangential_vs_fine_march():
    H, nt, fine = 3, 1024, 2**15
    c = one_element(mu=0.5, n0=10.0, kn=500.0)
    U = np.zeros((1, 3, 2 * H + 1))
    U[0, 0, 1] = 0.1                                    # u_t = 0.1 cos
    U[0, 2, 1] = 0.015                                  # u_n = 0.015 cos: N in [2.5, 17.5] N, in phase
    F, _, _ = c.evaluate(U, Fourier(H, nt), jacobian=False)
    ff = Fourier(H, fine)
    u = ff.to_time(U[0])
    T = reference_march(u[0:2], u[2], KT, 500.0, 0.5, 10.0)
    Fref = ff.to_freq(T)
    assert np.max(np.abs(F[0, 0] - Fref[0])) <= 2e-3 * np.max(np.abs(Fref[0]))


def fd_check(c, U, f, eps=1e-7):
    F, nl, DF = c.evaluate(U, f)
    ne = U.shape[0]
    J = np.zeros_like(DF)
    flat = U.reshape(ne, -1)
    for x in range(flat.shape[1]):
        Up, Um = flat.copy(), flat.copy()
        Up[:, x] += eps
        Um[:, x] -= eps
        Fp = c.evaluate(Up.reshape(U.shape), f, False)[0].reshape(ne, -1)
        Fm = c.evaluate(Um.reshape(U.shape), f, False)[0].reshape(ne, -1)
        J[:, :, x] = ((Fp - Fm) / (2 * eps))[nl]
    return nl, DF, J


@pytest.mark.parametrize("n_copies", [1, 3])   # 6, 18 elements (numpy march: scalar, vectorized; test_hbm_aft2d compares the marches)
def test_jacobian_vs_finite_differences_all_regimes(n_copies):
    H, nt = 3, 64
    f = Fourier(H, nt)
    rng = np.random.default_rng(3)
    # regimes: stuck (interference gap, linear), 1D stick-slip, 2D slip, partly open with
    # normal-load variation, open-at-rest closing, gross slip with mean offset
    n0 = np.array([10.0, 10.0, 10.0, 2.0, 0.0, 1.0] * n_copies)
    gap = np.array([-0.001, 0, 0, 0, 0.002, 0] * n_copies)
    ne = n0.size
    c = FrictionContacts(np.tile([[0, 1, 2], [-1, -1, -1]], (ne, 1, 1)), kt=KT, kn=1e3, mu=0.3,
                         n0=n0, gap=gap)
    U = np.zeros((ne, 3, 2 * H + 1))
    U[:, :, 1:] = rng.normal(size=(ne, 3, 2 * H)) * 0.01
    U[1::6, 1] = 0.0                                   # 1D tangential motion
    U[1::6, 0] *= 5.0
    U[0::6, 0:2] *= 0.05                               # small: stuck
    U[5::6, 0, 0] = 0.2                                # mean offset, gross slip
    U[:, 2] *= 0.3
    nl, DF, J = fd_check(c, U, f)
    assert set(range(1, ne, 6)) <= set(nl) and nl.size == 5 * n_copies
    # the stuck elements are exactly linear: T = kt u_t, N - n0 = kn (u_n - g)
    F = c.evaluate(U, f, False)[0]
    assert np.allclose(F[0::6, 0:2], KT * U[0::6, 0:2], rtol=1e-12, atol=0)
    err = np.abs(DF - J).max() / np.abs(DF).max()
    assert err <= 1e-6
