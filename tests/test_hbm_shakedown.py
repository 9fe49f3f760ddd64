"""The slider of an element that sticks all cycle after slipping (hbm.shakedown): the admissible
slider nearest rest, against brute-force minimization, closed forms (hbm.reference), central
differences, and the time origin."""
import numpy as np
import pytest
from scipy.optimize import minimize

from hbm import Fourier, FrictionContacts
from hbm import friction, shakedown
from hbm.reference import ramped_slider, shakedown_slider_1d, shakedown_slider_circle


def disks(k: int = 60, m: int = 48, seed: int = 0):
    """Sampled closed orbits with a mean shear (complex samples) and varying radii."""
    rng = np.random.default_rng(seed)
    t = 2 * np.pi * np.arange(m) / m
    mean = rng.normal(size=(k, 1)) + 1j * rng.normal(size=(k, 1))
    c = (mean + rng.uniform(0.2, 1.5, (k, 1)) * np.cos(t)
         + 1j * rng.uniform(0, 1, (k, 1)) * np.cos(t + rng.uniform(0, 6, (k, 1))) + 0.1 * np.cos(2 * t))
    rho = rng.uniform(1.0, 2.0, (k, 1)) * (1 + 0.3 * np.cos(t + rng.uniform(0, 6, (k, 1))))
    return c, rho


def test_sampled_projection_equals_a_constrained_minimization():
    """nearest_admissible gives the least-norm admissible slider (SLSQP from a nearby start agrees
    to 1e-7), and where it says the disks have no common point, none has a positive slack."""
    c, rho = disks()
    w, active, ok = shakedown.nearest_admissible(c, rho)
    assert 10 < ok.sum() < len(ok)                      # both kinds are exercised
    for i in range(len(w)):
        slack = lambda x, i=i: rho[i] - np.abs(x[0] + 1j * x[1] - c[i])
        if ok[i]:
            assert slack([w[i].real, w[i].imag]).min() >= -1e-9
            r = minimize(lambda x: x @ x, [w[i].real + 0.01, w[i].imag - 0.01], method="SLSQP",
                         constraints=[{"type": "ineq", "fun": slack}], options={"ftol": 1e-14})
            assert abs(np.sqrt(r.fun) - abs(w[i])) < 1e-7
        else:
            r = minimize(lambda x: -slack(x).min(), [c[i].mean().real, c[i].mean().imag],
                         method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-12})
            assert -r.fun < 1e-8


@pytest.mark.parametrize("mean, amp, rho", [(0.3, 0.1, 0.15), (-0.3, 0.1, 0.15), (0.02, 0.1, 0.15),
                                            (0.3, 0.149, 0.15)])
def test_a_line_orbit_takes_the_nearer_end_of_its_interval(mean, amp, rho):
    """u_t = m + a cos t at constant limit: the slider is the end of [m + a - rho, m - a + rho]
    nearer 0 (or 0 inside), hbm.reference.shakedown_slider_1d."""
    f = Fourier(3, 64)
    U = np.zeros((1, 3, f.nH))
    U[0, 0, 0], U[0, 0, 1] = mean, amp
    c = FrictionContacts(np.array([[[0, 1, 2], [-1, -1, -1]]]), kt=2.0, kn=5.0, mu=0.5, n0=rho * 2.0 / 0.5)
    c.shakedown = True
    u = f.to_time(U)
    _, stuck, w, _ = c._classify(u, U, np.arange(1))
    assert stuck[0]
    assert abs(w[0] - shakedown_slider_1d(mean, amp, rho)) < 1e-12


@pytest.mark.parametrize("centre", [0.5 + 0.2j, -0.1 + 0.45j, 0.05 + 0.02j])
def test_a_circular_orbit_takes_the_nearest_point_of_its_disk(centre):
    """u_t on a circle of radius r about a centre, constant limit rho: the admissible set is the
    disk of radius rho - r about the centre, and the slider its point nearest 0 — exactly (the
    refinement on the motion, not the samples' polygon-like set)."""
    f = Fourier(3, 32)
    r, rho = 0.1, 0.3
    U = np.zeros((1, 3, f.nH))
    U[0, 0, 0], U[0, 1, 0] = centre.real, centre.imag
    U[0, 0, 1], U[0, 1, 2] = r, r
    c = FrictionContacts(np.array([[[0, 1, 2], [-1, -1, -1]]]), kt=2.0, kn=5.0, mu=0.5, n0=rho * 2.0 / 0.5)
    c.shakedown = True
    _, stuck, w, _ = c._classify(f.to_time(U), U, np.arange(1))
    assert stuck[0]
    assert abs(w[0] - shakedown_slider_circle(centre, r, rho)) < 1e-12


def shaken_contacts(ne: int = 40, seed: int = 1):
    """Elements with a mean shear and 2D vibration (with normal load variation): some stick from
    rest, some after slipping (one or two active instants), the rest slip."""
    rng = np.random.default_rng(seed)
    f = Fourier(3, 64)
    dofs = np.stack([np.stack([np.arange(3) + 3 * e, -np.ones(3, int)]) for e in range(ne)])
    c = FrictionContacts(dofs, kt=10.0, kn=20.0, mu=0.3, n0=1.0)
    c.shakedown = True
    U = np.zeros((ne, 3, f.nH))
    U[:, 0:2, 0] = rng.normal(0, 0.08, (ne, 2))
    U[:, 0:2, 1:3] = rng.normal(0, 0.03, (ne, 2, 2))
    U[:, 2, 1:3] = rng.normal(0, 0.01, (ne, 2))
    U[:, 0, 3:5] = rng.normal(0, 0.005, (ne, 2))
    return c, U, f


def test_the_slider_is_admissible_on_the_motion_and_nearest_rest():
    """Against a dense sampling of the same motion (8192 samples): the refined slider keeps the
    stuck force inside the limit everywhere (to 1e-7 of the limit), and is at most 1e-4 farther
    from rest than the dense samples' projection (which can only be nearer: fewer constraints)."""
    c, U, f = shaken_contacts()
    _, stuck, w, times = c._classify(f.to_time(U), U, np.arange(c.ne))
    sh = np.nonzero(np.isfinite(times[:, 0]))[0]
    assert sh.size >= 4 and np.isfinite(times[sh, 1]).sum() >= 2     # one and two active instants
    fd = Fourier(3, 8192)
    ud = fd.to_time(U[sh])
    cd = ud[:, 0] + 1j * ud[:, 1]
    rho = c.mu[sh, None] * (c.n0[sh, None] + c.kn[sh, None] * ud[:, 2]) / c.kt[sh, None]
    assert ((np.abs(w[sh, None] - cd) - rho).max(axis=1) <= 1e-7 * rho.max(axis=1)).all()
    wd, _, okd = shakedown.nearest_admissible(cd, rho)
    assert okd.all()
    assert (np.abs(wd) <= np.abs(w[sh]) * (1 + 1e-9)).all()
    assert (np.abs(wd - w[sh]) <= 1e-4 * np.abs(w[sh])).all()


def test_force_jacobian_of_shaken_elements_equals_central_differences():
    """evaluate's Jacobian of the elements that stick after slipping (the slider's derivative,
    the active instants moving) against central differences of the force harmonics, to 1e-6."""
    c, U, f = shaken_contacts()
    _, _, _, times = c._classify(f.to_time(U), U, np.arange(c.ne))
    sh = np.nonzero(np.isfinite(times[:, 0]))[0]
    F, nl, DF = c.evaluate(U, f)
    pos = {e: i for i, e in enumerate(nl)}
    h = 1e-7
    for e in sh:
        J = np.zeros((3 * f.nH, 3 * f.nH))
        for d in range(3):
            for k in range(f.nH):
                Up, Um = U.copy(), U.copy()
                Up[e, d, k] += h
                Um[e, d, k] -= h
                J[:, d * f.nH + k] = ((c.evaluate(Up, f, jacobian=False)[0][e]
                                       - c.evaluate(Um, f, jacobian=False)[0][e]) / (2 * h)).ravel()
        assert np.abs(DF[pos[e]] - J).max() <= 1e-6 * np.abs(J).max(), e


def test_forces_do_not_depend_on_the_time_origin():
    """The motion moved by half a period (odd harmonics negated: what a mode's other sign does)
    gives the same forces moved by half a period, to 1e-10; the march from rest at t = 0 for the
    elements that stick after slipping did not (shakedown False, forced responses' default: 10 %
    here)."""
    c, U, f = shaken_contacts()
    s = np.where(f.orders % 2 == 1, -1.0, 1.0)
    F = c.evaluate(U, f, jacobian=False)[0]
    assert np.abs(c.evaluate(U * s, f, jacobian=False)[0] * s - F).max() <= 1e-10 * np.abs(F).max()
    c.shakedown = False
    F0 = c.evaluate(U, f, jacobian=False)[0]
    F0s = c.evaluate(U * s, f, jacobian=False)[0]
    assert np.abs(F0s * s - F0).max() > 1e-2 * np.abs(F).max()


def test_histories_show_shaken_elements_stuck_inside_the_limit():
    """element histories: an element that sticks after slipping has status STUCK, no slip, and its
    force kt (u_t - w) inside the limit at every sample."""
    c, U, f = shaken_contacts()
    _, _, w, times = c._classify(f.to_time(U), U, np.arange(c.ne))
    sh = np.nonzero(np.isfinite(times[:, 0]))[0]
    hist = c.histories(U, f)
    assert (hist["status"][sh] == friction.STUCK).all()
    T = hist["T"][sh, 0] + 1j * hist["T"][sh, 1]
    assert (np.abs(T) <= c.mu[sh, None] * hist["N"][sh] * (1 + 1e-9)).all()
    assert np.allclose(T, c.kt[sh, None] * (hist["u_t"][sh, 0] + 1j * hist["u_t"][sh, 1] - w[sh, None]))


def test_the_slider_is_near_what_a_slow_growth_from_rest_leaves():
    """The whole motion grown slowly from rest (100 periods, then 10 held; hbm.reference's
    catching-up integration) leaves each element that sticks after slipping within 5 % of the
    slider nearest rest (|w| scale). The march from rest at t = 0 left sliders up to 22 % away
    from it (measured in session 19), hence the choice."""
    c, U, f = shaken_contacts()
    _, _, w, times = c._classify(f.to_time(U), U, np.arange(c.ne))
    sh = np.nonzero(np.isfinite(times[:, 0]))[0]
    wr = ramped_slider(U[sh], c.kt[sh], c.kn[sh], c.mu[sh], c.n0[sh], c.gap[sh], steps=2000)
    assert (np.abs(wr - w[sh]) <= 0.05 * np.abs(w[sh])).all(), np.abs(wr - w[sh]) / np.abs(w[sh])


def test_nonlinear_modes_use_the_nearest_rest_slider_and_forced_responses_the_march():
    """continue_backbone evaluates the friction with ``shakedown`` set (a mode has no time
    origin) and restores the contacts' setting after, also when it fails; a forced solve keeps
    the march (the excitation's t = 0)."""
    from test_hbm_nonlinear_mode import jenkins_1dof
    hb = jenkins_1dof(1, 64)
    seen = []
    orig = hb.c.evaluate

    def evaluate(*a, **k):
        seen.append(hb.c.shakedown)
        return orig(*a, **k)
    hb.c.evaluate = evaluate
    hb.nonlinear_mode(0, (0.05, 1.0), dof=0, n_points=4)
    assert seen and all(seen) and hb.c.shakedown is False
    seen.clear()
    with pytest.raises(ValueError):
        hb.nonlinear_mode(0, (0.05, 1.0), dof=0, n_points=4, max_iter=0)
    assert hb.c.shakedown is False
    hb.solve(1.0, np.array([0.1]))
    assert seen and not any(seen)
