"""Mean (0th-harmonic) tangential force of friction elements and of a bolted joint (issue 12).

A zero-mean excitation can leave a static shear in the joint. These tests pin down where the
element law puts it, against forces integrated by hand:

* an element that opens during the cycle re-sticks where it re-closes (its slider is reset), so
  its mean tangential force is set by the orbit alone: independent of the mean tangential
  displacement and of the phase at which the AFT march starts (a ratchet, unique);
* an element that stays closed and stuck keeps the memory of its rest state (slider w = 0 at
  preload): its mean force is kt·u0 clipped to ±(μN − kt·b) (not shift invariant);
* in a two-mass "bolted joint" the bolt spring carries minus the joint's mean shear, which
  vanishes for symmetric closed loops and equals the hand-integrated ratchet force otherwise.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hbm import FrictionContacts, HarmonicBalance, LinearStructure
from hbm.fourier import Fourier


def _first_harmonic(u: tuple[float, float, float]):
    """u(θ) = u0 + a cos θ + b sin θ, its derivative and its antiderivative."""
    u0, a, b = u
    return (lambda t: u0 + a * np.cos(t) + b * np.sin(t),
            lambda t: -a * np.sin(t) + b * np.cos(t),
            lambda t: u0 * t + a * np.sin(t) - b * np.cos(t))


def mean_force_opening(ut: tuple[float, float, float], un: tuple[float, float, float], kt: float,
                       kn: float, mu: float, n0: float) -> tuple[float, float]:
    """Cycle-mean tangential force of one element on a first-harmonic orbit that opens.

    The element law integrated by hand (no time march): with u_n = un0 + A cos(θ − α) the
    element is closed on (θc, θe) = (α − θo, α + θo), cos θo = −(n0/kn + un0)/A. It closes with
    its slider at u_t(θc) (reset while open), sticks, T = kt (u_t − u_t(θc)), until |T| reaches
    μN at θs (root by bisection), then slips with T = ±μN until it opens (the conditions of this
    sequence, stick at closure and no re-stick before opening, are asserted).

    Args:
        ut, un: (mean, cos, sin) coefficients of the tangential and normal relative displacement, mm.
        kt, kn: element stiffnesses, N/mm; mu: friction coefficient; n0: preload, N (gap 0).

    Returns:
        (mean T, N; the first-order bound of the sampled AFT's closure error per sample spacing,
        kt |u_t'(θc)| (θs − θc) / 2π, N per rad).
    """
    u, du, iu = _first_harmonic(ut)
    A, al = np.hypot(un[1], un[2]), np.arctan2(un[2], un[1])
    c0 = n0 / kn + un[0]
    assert abs(c0) < A, "the orbit must open during part of the cycle"
    th_o = np.arccos(-c0 / A)
    thc, the = al - th_o, al + th_o

    def N(t):
        return kn * (c0 + A * np.cos(t - al))

    def dN(t):
        return -kn * A * np.sin(t - al)

    def iN(t):
        return kn * (c0 * t + A * np.sin(t - al))

    assert kt * abs(du(thc)) < mu * dN(thc), "the reference assumes stick at closure"

    def excess(t):
        return np.abs(kt * (u(t) - u(thc))) - mu * N(t)

    grid = np.linspace(thc, the, 20001)[1:]
    k = int(np.argmax(excess(grid) >= 0.0))
    lo, hi = grid[k - 1], grid[k]
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if excess(mid) < 0.0 else (lo, mid)
    ths = 0.5 * (lo + hi)
    s = np.sign(u(ths) - u(thc))
    tail = np.linspace(ths, the, 20001)
    assert np.all(s * kt * du(tail) >= mu * dN(tail) - 1e-12 * kn * A), "re-sticks before opening"
    mean = (kt * (iu(ths) - iu(thc) - (ths - thc) * u(thc)) + s * mu * (iN(the) - iN(ths))) / (2 * np.pi)
    return float(mean), float(kt * abs(du(thc)) * (ths - thc) / (2 * np.pi))


def rotated(X: np.ndarray, phi: float) -> np.ndarray:
    """Harmonics (..., 2H+1) of x(θ + φ) for harmonics X of x(θ)."""
    Y = X.copy()
    for h in range(1, (X.shape[-1] - 1) // 2 + 1):
        a, b = X[..., 2 * h - 1], X[..., 2 * h]
        ch, sh = np.cos(h * phi), np.sin(h * phi)
        Y[..., 2 * h - 1], Y[..., 2 * h] = a * ch + b * sh, b * ch - a * sh
    return Y


def one_element(kt: float, kn: float, mu: float, n0: float, copies: int = 1) -> FrictionContacts:
    """One element against ground (DOFs 0, 1, 2); ``copies`` > 4 identical ones take numpy's
    vectorized march instead of the scalar one when the compiled march is off."""
    return FrictionContacts(np.array([[[0, 1, 2], [-1, -1, -1]]] * copies), kt=kt, kn=kn, mu=mu,
                            n0=n0)


# ---------------------------------------------------------------- one element, prescribed orbit
KT, KN, MU, N0 = 50.0, 100.0, 0.5, 10.0
#: u_n = 0.2 cos θ: N = 10 + 20 cos θ, open for |θ| > 2π/3 (a sample when 3 | n_t)
A_N, B_T = 0.2, 0.1


def test_opening_in_phase_closed_form():
    """u_n = a cos θ, u_t = u0 + b cos θ with kt b ≤ μ kn a: the element sticks from closure to
    opening, T = kt b (cos θ − cos θo), so mean T = kt b (sin θo − θo cos θo)/π, whatever u0."""
    th_o = np.arccos(-N0 / (KN * A_N))
    exact = KT * B_T * (np.sin(th_o) - th_o * np.cos(th_o)) / np.pi
    f = Fourier(1, 768)
    c = one_element(KT, KN, MU, N0)
    for u0 in (0.0, 0.3, -5.0):
        U = np.zeros((1, 3, 3))
        U[0, 0] = (u0, B_T, 0.0)
        U[0, 2] = (0.0, A_N, 0.0)
        F = c.evaluate(U, f, jacobian=False)[0]
        assert abs(F[0, 0, 0] - exact) <= 1e-5 * exact
    assert exact > 0.6 * MU * N0          # a large mean force from a zero-mean orbit


@pytest.mark.parametrize("copies", [1, 5])
@pytest.mark.parametrize("phi", [0.4, -0.4, 1.0, 2.5])
def test_opening_mean_force_orbit_set(phi, copies):
    """u_t = u0 + b cos(θ + φ): stick, slip, open. The AFT mean matches the hand integration,
    does not change with u0 (shift invariance) nor with the sample the march starts from."""
    nt = 768
    f = Fourier(1, nt)
    c = one_element(KT, KN, MU, N0, copies)
    ut = (0.3, B_T * np.cos(phi), -B_T * np.sin(phi))
    un = (0.0, A_N, 0.0)
    ref, _ = mean_force_opening(ut, un, KT, KN, MU, N0)
    U = np.zeros((copies, 3, 3))
    U[:, 0], U[:, 2] = ut, un
    F = c.evaluate(U, f, jacobian=False)[0]
    assert np.abs(F[:, 0, 0] - ref).max() <= 2e-5 * MU * N0
    # shift invariance: the whole force history is the same for another mean displacement
    V = U.copy()
    V[:, 0, 0] += 0.7
    assert np.abs(c.evaluate(V, f, jacobian=False)[0] - F).max() <= 1e-10 * MU * N0
    # the march starting 100 samples later gives the same periodic force
    dphi = 2 * np.pi * 100 / nt
    Fr = rotated(c.evaluate(rotated(U, dphi), f, jacobian=False)[0], -dphi)
    assert np.abs(Fr - F).max() <= 1e-10 * MU * N0


@pytest.mark.parametrize("u0", [0.0, 0.05, 0.3, -0.3, -2.0])
@pytest.mark.parametrize("k_phase", [0, 37, 200])
def test_closed_stuck_element_remembers_rest(u0, k_phase):
    """Always closed, N = n0, u_t = u0 + b cos(θ + φ), kt b < μN: the element shakes down to
    stick. Its slider starts at rest (w = 0) and moves only if kt|u0| + kt b > μN, so
    mean T = clip(kt u0, ±(μN − kt b)) for every start phase: a memory of the rest state."""
    nt = 512
    f = Fourier(1, nt)
    kt, mu, n0, b = 100.0, 0.5, 10.0, 0.02           # kt b = 2 N < μN = 5 N
    c = one_element(kt, 1e3, mu, n0)
    phi = 2 * np.pi * k_phase / nt                   # the extremes of u_t fall on samples
    U = np.zeros((1, 3, 3))
    U[0, 0] = (u0, b * np.cos(phi), -b * np.sin(phi))
    F = c.evaluate(U, f, jacobian=False)[0]
    lim = mu * n0 - kt * b
    assert abs(F[0, 0, 0] - np.clip(kt * u0, -lim, lim)) <= 1e-10 * mu * n0


# ---------------------------------------------------------------- two masses and a bolt
M_A, M_B = 1e-3, 2e-3                                 # t
KB = (500.0, 500.0, 200.0)                            # N/mm: the bolt's x, y, z stiffness


def two_masses(zeta: float = 0.02) -> LinearStructure:
    """Masses A (DOFs 0-2) and B (3-5), free–free, joined by the bolt springs KB."""
    M = np.diag([M_A] * 3 + [M_B] * 3)
    K = np.kron(np.array([[1.0, -1.0], [-1.0, 1.0]]), np.diag(KB))
    return LinearStructure(M, K, damping_ratio=zeta)


def omega_x(kt: float) -> float:
    """Relative x frequency with the elements stuck, rad/s."""
    return float(np.sqrt((KB[0] + kt) * (M_A + M_B) / (M_A * M_B)))


def test_symmetric_slip_no_mean_shear():
    """Constant normal loads, zero-mean x excitation, the elements slip both ways: the loops are
    symmetric, so the joint's mean shear and the bolt's mean force vanish, also when Newton
    starts from a joint shifted by 50 µm (the mean state is unique)."""
    kt, mu, n0 = 1e3, 0.5, np.array([10.0, 20.0])
    c = FrictionContacts(np.array([[[0, 1, 2], [3, 4, 5]]] * 2), kt=kt, kn=1e4, mu=mu, n0=n0)
    hb = HarmonicBalance(two_masses(), c, harmonics=3, samples=64)
    force = np.zeros(6)
    force[0] = 100.0
    w = 0.8 * omega_x(0.0)
    sol = hb.solve(w, force)
    guess = sol.contact.copy()
    guess[:, 0, 0] += 0.05
    for s in (sol, hb.solve(w, force, guess=SimpleNamespace(contact=guess))):
        er = hb.element_results(s)
        assert np.all(er.slip_fraction > 0.5)        # both elements slip most of the cycle
        F = c.evaluate(s.contact, hb.fourier, jacobian=False)[0]
        assert abs(F[:, 0, 0].sum()) <= 1e-9 * mu * n0.sum()
        amp = np.hypot(*s.contact[0, 0, 1:3])
        assert np.abs(s.contact[:, 0, 0]).max() <= 1e-9 * amp
        q0 = s.coefficients[0]
        assert abs(KB[0] * (q0[0] - q0[3])) <= 1e-9 * mu * n0.sum()


def test_opening_joint_ratchet_carried_by_bolt():
    """x and z excitation in phase, zero mean: the element opens once per cycle and sticks/slips
    while closed. The HBM's mean shear is the hand-integrated ratchet force of its own orbit (to
    the sampled AFT's first-order closure error), a third of μn0; the bolt carries exactly minus
    it, and Newton started 50 µm off returns to the same state (unique mean)."""
    kt, kn, mu, n0 = 20.0, 100.0, 0.5, 10.0
    c = FrictionContacts(np.array([[[0, 1, 2], [3, 4, 5]]]), kt=kt, kn=kn, mu=mu, n0=n0)
    nt = 1024
    hb = HarmonicBalance(two_masses(), c, harmonics=1, samples=nt)
    force = np.zeros(6)
    force[0], force[2] = 10.0, 80.0
    w = 0.95 * omega_x(kt)
    sol = hb.solve(w, force)
    U = sol.contact[0]
    F = c.evaluate(sol.contact, hb.fourier, jacobian=False)[0]
    T0 = F[0, 0, 0]
    ref, bound = mean_force_opening(tuple(U[0]), tuple(U[2]), kt, kn, mu, n0)
    assert abs(T0 - ref) <= 1.2 * bound * 2 * np.pi / nt + 1e-5 * mu * n0
    assert abs(ref) > 0.3 * mu * n0
    q0 = sol.coefficients[0]
    assert abs(KB[0] * (q0[0] - q0[3]) + T0) <= 1e-9 * mu * n0     # bolt = −mean shear
    guess = sol.contact.copy()
    guess[0, 0, 0] += 0.05
    again = hb.solve(w, force, guess=SimpleNamespace(contact=guess))
    assert np.abs(again.contact - sol.contact).max() <= 1e-9 * np.abs(sol.contact).max()
