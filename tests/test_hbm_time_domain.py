"""hbm.time_domain: the exact path law, the exact linear part, energy balance, HBM vs time domain."""
import numpy as np
import pytest

from hbm import FrictionContacts, HarmonicBalance, LinearStructure
from hbm.reference import StickSlipIntegrator
from hbm.time_domain import FrictionTimeIntegrator, friction_path_step

#: HBM (H = 7, 9, 11; n_t = 128, the default) vs the time integration (1024 steps per period),
#: relative difference of the first-harmonic amplitude on the 6-DOF case with 2D gross slip and
#: separation: measured 3.1e-5, 1.6e-5, 3.2e-6: the harmonic truncation, converging with H (the
#: first-order 2D update used before was 1.1e-2 off at 128 samples, 9.6e-4 at 512)
HBM_TD_AMPLITUDE = 1e-4


def random_elements(k, seed=0):
    """Random elements and straight paths: open, closing, opening, sticking and slipping ones."""
    rng = np.random.default_rng(seed)
    u0 = rng.normal(size=(k, 3)) * [1.0, 1.0, 0.3]
    u1 = u0 + rng.normal(size=(k, 3)) * [0.5, 0.5, 0.3]
    kt, kn = rng.uniform(0.5, 2.0, k), rng.uniform(0.5, 2.0, k)
    mu, n0 = rng.uniform(0.1, 1.0, k), rng.uniform(0.0, 1.0, k)
    gap = rng.uniform(0.0, 0.2, k) * (n0 < 0.3)
    # an admissible start: the force inside the disc, the slider on u_t when open
    w0 = u0[:, :2] + rng.normal(size=(k, 2)) * 0.3
    L = mu * np.maximum(n0 + kn * (u0[:, 2] - gap), 0.0)
    T = kt[:, None] * (u0[:, :2] - w0)
    nT = np.hypot(T[:, 0], T[:, 1])
    T *= np.where(nT > L, L / np.maximum(nT, 1e-300), 1.0)[:, None]
    w0 = u0[:, :2] - T / kt[:, None]
    return u0, u1, w0, dict(kt=kt, kn=kn, mu=mu, n0=n0, gap=gap)


def test_path_step_exact_along_straight_paths():
    u0, u1, w0, p = random_elements(400)
    one = friction_path_step(u0, u1, w0, **p)
    kinds = one.slipped.sum(), (~one.closed).sum()
    assert min(kinds) > 30                      # many slipping and many open elements
    # exact: the same path in 5 steps ends in the same state
    ua, w = u0, w0
    for j in range(1, 6):
        ub = u0 + (u1 - u0) * j / 5
        ps = friction_path_step(ua, ub, w, **p)
        ua, w = ub, ps.w
    assert np.abs(ps.T - one.T).max() <= 1e-12 and np.abs(ps.w - one.w).max() <= 1e-12
    # the scalar path (one element at a time) and the vectorized one agree
    sc = [friction_path_step(u0[i:i + 1], u1[i:i + 1], w0[i:i + 1], **{k: v[i] for k, v in p.items()})
          for i in range(0, 400, 7)]
    assert np.abs(np.concatenate([s.T for s in sc]) - one.T[::7]).max() <= 1e-13
    # independent reference: radial return on m sub-steps converges to it at first order
    err = {}
    for m in (400, 4000):
        w = w0.copy()
        for j in range(1, m + 1):
            u = u0 + (u1 - u0) * j / m
            N = np.maximum(0.0, p["n0"] + p["kn"] * (u[:, 2] - p["gap"]))
            Ts = p["kt"][:, None] * (u[:, :2] - w)
            nT = np.hypot(Ts[:, 0], Ts[:, 1])
            slip = nT > p["mu"] * N
            T = np.where(slip[:, None], Ts * (p["mu"] * N / np.maximum(nT, 1e-300))[:, None], Ts)
            w_slip = np.where(slip[:, None], u[:, :2] - T / p["kt"][:, None], w)
            w = np.where((N > 0)[:, None], w_slip, u[:, :2])
        T = np.where((N > 0)[:, None], T, 0.0)
        err[m] = np.abs(T - one.T).max()
    assert err[4000] <= 2e-4 and 7 <= err[400] / err[4000] <= 13


def test_path_step_circular_orbit_closed_form():
    """Steady circular orbit u_t = R e^{i theta}, constant N: |T| = mu N, the slider on the circle
    r = sqrt(R^2 - (mu N / kt)^2) with T perpendicular to it (the polygon converges as 1/n^2)."""
    kt, kn, mu, n0, R = 2.0, 5.0, 0.5, 1.0, 0.6
    L = mu * n0
    r = np.sqrt(R ** 2 - (L / kt) ** 2)
    err = {}
    for n in (64, 128):
        th = 2 * np.pi * np.arange(6 * n + 1) / n
        u = np.stack([R * np.cos(th), R * np.sin(th), np.zeros_like(th)], axis=1)
        w = np.zeros((1, 2))
        for j in range(6 * n):
            ps = friction_path_step(u[j:j + 1], u[j + 1:j + 2], w, kt, kn, mu, n0)
            w = ps.w
        T, wv = ps.T[0], w[0]
        assert abs(np.hypot(*T) - L) <= 1e-14 * L
        err[n] = (abs(np.hypot(*wv) - r) / r, abs(T @ wv) / (np.hypot(*T) * np.hypot(*wv)))
    assert err[128][0] <= 3e-4 and err[128][1] <= 6e-4
    assert 3.5 <= err[64][0] / err[128][0] <= 4.5


# 1-DOF Jenkins oscillator m x'' + c x' + k x + f_J(x) = F cos(w t) (heavily damped: the march
# from rest settles in ~30 periods)
M1, K1, C1, KT1, FS1, F1, W1 = 1.0, 1.0, 0.2, 1.0, 0.1, 0.3, 1.2


def jenkins_integrator(mu=FS1):
    # tangential t1 on DOF 0, t2 and n grounded: constant normal load n0 = 1, slip force mu
    return FrictionTimeIntegrator([[M1]], [[K1]], np.array([[[0, -1, -1], [-1, -1, -1]]]), kt=KT1,
                                  kn=1.0, mu=mu, n0=1.0, C=[[C1]])


def test_jenkins_oscillator_vs_exact_event_driven_integration():
    ig = StickSlipIntegrator([[M1]], [[C1]], [[K1]], [(0, -1, KT1, FS1)], [F1], W1)
    X = ig.harmonics(ig.steady_state(), 0, H=1)
    exact = np.hypot(X[1], X[2])
    td = jenkins_integrator()
    res = {n: td.run(W1, np.array([F1]), 0, steps_per_period=n, rtol=1e-10) for n in (64, 128)}
    err = {n: abs(r.amplitude - exact) / exact for n, r in res.items()}
    # measured 2.0e-3 and 4.1e-4: second order in the step (events inside steps)
    assert err[128] <= 6e-4 and err[64] / err[128] >= 3.0
    r = res[128]
    assert r.converged and r.status[0] == 1             # stick-slip
    # energy balance of the periodic state: excitation = viscous + friction work, per cycle
    assert abs(r.input_work - r.viscous_work - r.friction_work) <= 1e-6 * r.input_work
    assert r.friction_work > 0.3 * r.input_work
    # the input work is pi F b1 of the response's first harmonic
    assert abs(r.input_work - np.pi * F1 * r.harmonics[2]) <= 1e-4 * r.input_work


def test_stuck_limit_is_the_exact_linear_frf():
    """mu huge: exactly linear (g = 0), any step; free-free with rigid-body modes and a 3D element."""
    m1, m2, k = 2.0, 1.0, 50.0
    M = np.diag([m1] * 3 + [m2] * 3)
    K = np.zeros((6, 6))
    for d in range(3):
        K[np.ix_([d, d + 3], [d, d + 3])] += k * np.array([[1, -1], [-1, 1]])
    kc = np.array([40.0, 30.0, 100.0])
    zeta = 0.05
    td = FrictionTimeIntegrator(M, K, np.array([[[0, 1, 2], [3, 4, 5]]]), kt=kc[0], kn=kc[2], mu=1e9,
                                n0=5.0, damping_ratio=zeta)
    # the linear base and its modal damping, from scratch
    Ks = K.copy()
    for d, kk in enumerate([kc[0], kc[0], kc[2]]):
        Ks[np.ix_([d, d + 3], [d, d + 3])] += kk * np.array([[1, -1], [-1, 1]])
    lam, phi = np.linalg.eigh(np.linalg.solve(np.sqrt(M), np.linalg.solve(np.sqrt(M), Ks).T))
    phi = np.linalg.solve(np.sqrt(M), phi)
    lam = np.where(lam < 1e-9 * lam.max(), 0.0, lam)     # rigid-body modes: exactly 0, undamped
    F = np.array([1.0, 0.3, 0.2, 0.0, 0.0, 0.0])
    for w in (4.0, 9.0):
        ref = phi @ ((phi.T @ F) / (lam - w ** 2 + 2j * zeta * np.sqrt(lam) * w))
        r = td.run(w, F, 0, steps_per_period=16, rtol=1e-11)
        assert abs(r.amplitude - abs(ref[0])) <= 1e-9 * abs(ref[0])
        assert np.all(r.status == 0) and abs(r.friction_work) <= 1e-9 * r.input_work
        assert abs(r.input_work - r.viscous_work) <= 1e-8 * r.input_work
        # started on the periodic state it stays there: periodic from the first period on
        r0 = td.run(w, F, 0, steps_per_period=16, rtol=1e-11, min_periods=2,
                    initial=(ref.real, (1j * w * ref).real, np.zeros((1, 2))))
        assert r0.periods <= 3 and abs(r0.amplitudes[0] - abs(ref[0])) <= 1e-9 * abs(ref[0])


def six_dof_case():
    """Two 3-DOF masses on inclined springs; three elements: A-B loaded (2D gross slip on an
    ellipse), A-B lightly loaded (separates), B-ground with a gap (closes)."""
    M = np.diag([1.0, 1.0, 1.0, 0.6, 0.6, 0.6])
    K = np.zeros((6, 6))
    A, B = [0, 1, 2], [3, 4, 5]
    for body, k, d in ((A, 100.0, [1, 0, 0.5]), (A, 115.0, [0, 1, 0]), (A, 300.0, [0, 0, 1]),
                       (B, 150.0, [1, 0, -0.2]), (B, 110.0, [0, 1, 0.1]), (B, 400.0, [0, 0, 1])):
        d = np.asarray(d, float) / np.linalg.norm(d)
        K[np.ix_(body, body)] += k * np.outer(d, d)
    dofs = np.array([[A, B], [A, B], [B, [-1, -1, -1]]])
    c = FrictionContacts(dofs, kt=[60.0, 40.0, 30.0], kn=[150.0, 100.0, 80.0], mu=0.5,
                         n0=[4.0, 0.3, 0.0], gap=[0.0, 0.0, 0.001])
    F = 4.0 * np.array([1.5, 1.5, 0.0, 0.0, 0.5, 0.0])
    return LinearStructure(M, K, damping_ratio=0.08), c, F


def test_multi_dof_hbm_vs_time_domain():
    s, c, F = six_dof_case()
    w = 9.0                                             # the resonance peak (H = 3)
    td = FrictionTimeIntegrator.from_problem(s, c)
    r = td.run(w, F, 0, steps_per_period=1024, rtol=1e-10)
    assert r.converged and list(r.status) == [2, 3, 3]  # gross slip, partly open, partly open
    u = r.u[0, :2] - r.u[0, :2].mean(axis=1, keepdims=True)
    sv = np.linalg.svd(u, compute_uv=False)
    assert sv[1] > 0.1 * sv[0]                          # the slip orbit is an ellipse, not a line
    assert abs(r.energy_balance) <= 1e-6
    diff = {}
    for H in (7, 9, 11):
        hb = HarmonicBalance(s, c, harmonics=H)           # the default 128 samples
        sol = hb.solve(w, F)
        assert list(hb.element_results(sol).status) == [2, 3, 3]
        diff[H] = abs(sol.amplitude(0) - r.amplitude) / r.amplitude
        assert diff[H] <= HBM_TD_AMPLITUDE
    # what is left is the harmonic truncation: it falls with H (the AFT's own error is below it)
    assert diff[11] <= 1e-5 and diff[11] < diff[7] / 4
    er = hb.element_results(sol)
    # dissipated energy (total and per element) and the cycle-mean state: normal loads, joint shear
    assert abs(er.energy.sum() - r.friction_work) <= 2e-4 * r.friction_work
    assert np.abs(er.energy - r.element_work).max() <= 2e-4 * r.friction_work
    assert np.abs(er.mean_normal - r.mean_force[:, 2]).max() <= 2e-4 * c.n0.max()
    assert abs(er.T[:, 0].sum(axis=0).mean() - r.joint_shear[0]) <= 5e-4 * np.abs(er.T[:, 0]).max()


def test_input_validation():
    with pytest.raises(ValueError, match="dofs"):
        FrictionTimeIntegrator(np.eye(3), np.eye(3), np.zeros((1, 3)), kt=1, kn=1, mu=0.1, n0=1)
    with pytest.raises(ValueError, match="kt"):
        FrictionTimeIntegrator(np.eye(3), np.eye(3), [[[0, 1, 2], [-1, -1, -1]]], kt=0, kn=1, mu=0.1, n0=1)
    with pytest.raises(ValueError, match="diagonal"):
        C = np.array([[1.0, 0.5, 0], [0.5, 1.0, 0], [0, 0, 1.0]])
        FrictionTimeIntegrator(np.eye(3), np.diag([1.0, 2.0, 3.0]), [[[0, 1, 2], [-1, -1, -1]]], kt=1,
                               kn=1, mu=0.1, n0=1, C=C)
    td = jenkins_integrator()
    with pytest.raises(ValueError, match="omega"):
        td.run(0.0, np.array([1.0]), 0)
