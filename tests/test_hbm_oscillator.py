"""1-DOF Jenkins oscillator: H = 1 vs the closed-form FRF, H = 3, 5 vs exact stick-slip integration."""
import numpy as np
import pytest

from hbm import FrictionContacts, HarmonicBalance, LinearStructure
from hbm.reference import StickSlipIntegrator, jenkins_frf_h1

# m x'' + c x' + k x + f_J(x) = F cos(w t); Jenkins: kt, fs = mu n0. Stuck resonance sqrt(2) rad/s,
# fully slipping resonance 1 rad/s; macroslip force 4 fs / pi = 0.127.
M, K, C, KT, FS = 1.0, 1.0, 0.02, 1.0, 0.1
LEVELS = [0.06, 0.1, 0.3]          # barely slipping, half slipping, mostly slipping
OMEGA = 1.2                        # between the stuck and the slipping resonance


def solver(H, nt):
    s = LinearStructure([[M]], [[K]], [[C]])
    # tangential t1 on DOF 0, t2 and n grounded (u_n = 0): constant normal load n0 = 1
    c = FrictionContacts(np.array([[[0, -1, -1], [-1, -1, -1]]]), kt=KT, kn=1.0, mu=FS, n0=1.0)
    return HarmonicBalance(s, c, harmonics=H, samples=nt)


@pytest.mark.parametrize("F", LEVELS)
def test_h1_matches_closed_form(F):
    # sampled AFT: the stick->slip kinks off the sample grid give an O(1/nt^2) error (2e-5 at
    # nt = 1024 here), so the 1e-5 check runs at nt = 4096
    hb = solver(1, 4096)
    for w in (1.1, OMEGA):
        ref = jenkins_frf_h1(w, M, K, C, KT, FS, F)
        assert ref.size == 1
        A = hb.solve(w, np.array([F])).amplitude(0)
        assert abs(A - ref[0]) <= 1e-5 * ref[0]
    # the barely slipping level really slips, the strongest one slips most of the cycle
    er = hb.element_results(hb.solve(OMEGA, np.array([F])))
    assert er.status[0] == 1 and 0 < er.slip_fraction[0] < 1


def test_higher_harmonics_vs_exact_time_integration():
    F = LEVELS[-1]
    ig = StickSlipIntegrator([[M]], [[C]], [[K]], [(0, -1, KT, FS)], [F], OMEGA)
    ss = ig.steady_state()
    X = ig.harmonics(ss, 0, H=1)
    A_exact = np.hypot(X[1], X[2])
    err = {}
    for H in (1, 3, 5):
        A = solver(H, 1024).solve(OMEGA, np.array([F])).amplitude(0)
        err[H] = abs(A - A_exact) / A_exact
    assert err[3] <= 1e-2 and err[5] <= 5e-3
    assert err[1] > err[3] and err[1] > err[5]
    # the truncation error is not monotone in H (1e-4 at H = 3 and 5 here) but vanishes: H = 13
    # reproduces the exact steady state to a few 1e-6
    A13 = solver(13, 2048).solve(OMEGA, np.array([F])).amplitude(0)
    assert abs(A13 - A_exact) <= 1e-5 * A_exact
    # the H = 1 closed form is an independent check of the integrator's first harmonic: H = 1
    # differs from the exact response by the higher-harmonic feedback only (~0.3 % here)
    assert abs(jenkins_frf_h1(OMEGA, M, K, C, KT, FS, F)[0] - A_exact) <= 1e-2 * A_exact


def test_exact_integrator_linear_limit():
    """Stuck (fs huge): the integrator reproduces the linear steady state with k + kt."""
    ig = StickSlipIntegrator([[M]], [[C]], [[K]], [(0, -1, KT, 1e9)], [0.1], OMEGA)
    X = ig.harmonics(ig.steady_state(), 0, H=1)
    ref = 0.1 / abs(K + KT - M * OMEGA**2 + 1j * C * OMEGA)
    assert abs(np.hypot(X[1], X[2]) - ref) <= 1e-8 * ref
