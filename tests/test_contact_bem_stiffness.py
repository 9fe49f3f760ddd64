"""Contact stiffness: Hertz k_n, finite differences of the load–approach curve, Mindlin k_t/k_n,
loops (energy vs Mindlin–Deresiewicz), batched patches vs single solves."""
import numpy as np
import pytest

from contact_bem import (ElasticHalfSpace, Grid, gaussian_surface, load_approach_curve, mindlin_ratio,
                         normal_stiffness, patch_normal_stiffness, patch_stiffness,
                         patch_tangential_stiffness, solve_normal, tangential_loop,
                         tangential_stiffness)
from contact_bem import reference as ref

E, NU, MU = 198400.0, 0.3, 0.6


@pytest.fixture(scope="module")
def hertz96():
    es, gs = ref.composite_moduli(E, NU)
    hz = ref.hertz(100.0, 10.0, es)
    n = 96
    g = Grid((n, n), (2.6 * hz.radius,) * 2)
    X, Y = g.meshgrid()
    c = g.x[n // 2]
    hs = ElasticHalfSpace(g, E, NU)
    return hz, gs, g, hs, ((X - c) ** 2 + (Y - c) ** 2) / 20.0


def test_hertz_normal_stiffness(hertz96):
    hz, gs, g, hs, h = hertz96
    st = normal_stiffness(hs, h, 100.0)
    assert st.dn_ddelta == pytest.approx(hz.stiffness, rel=0.01)          # 2 a E*
    assert st.k_n == pytest.approx(st.dn_ddelta / g.area, rel=1e-12)
    # independent: central finite difference of the nonlinear load–approach curve
    d = load_approach_curve(hs, h, [99.5, 100.5])
    assert st.dn_ddelta == pytest.approx(1.0 / (d[1] - d[0]), rel=0.005)


def test_mindlin_ratio_and_hertz_kt_over_kn(hertz96):
    hz, gs, g, hs, h = hertz96
    assert mindlin_ratio(0.3) == pytest.approx(2 * 0.7 / 1.7)
    assert mindlin_ratio(0.0) == pytest.approx(1.0)
    kn = normal_stiffness(hs, h, 100.0)
    kt = tangential_stiffness(hs, kn.solution)
    assert kt.k_t / kn.k_n == pytest.approx(mindlin_ratio(NU), rel=0.01)
    assert kt.k_t * kt.area == pytest.approx(ref.mindlin_initial_stiffness(hz.radius, gs), rel=0.01)
    with pytest.raises(ValueError, match="poisson"):
        mindlin_ratio(0.6)


def test_tangential_loop_energy_and_secant(hertz96):
    hz, gs, g, hs, h = hertz96
    ns = solve_normal(hs, h, load=100.0)
    Qs = 0.5 * MU * 100.0
    lp = tangential_loop(hs, ns, MU, (Qs, 0.0), n_steps=6)
    W = ref.mindlin_dissipation(Qs, MU, 100.0, hz.radius, gs)
    assert lp.energy == pytest.approx(W, rel=0.05)   # trapezoidal rule on 24 increments
    d = ref.mindlin_displacement(Qs, MU, 100.0, hz.radius, gs)
    assert lp.k_t_secant * g.area == pytest.approx(Qs / d, rel=0.03)
    assert lp.k_t_first_step < lp.k_t          # the discrete reversal slope is a secant below it
    assert lp.force[0] == pytest.approx([0, 0]) and lp.force[-1] == pytest.approx([Qs, 0])
    # the loop closes: reloading to +Q* returns to the virgin tip
    assert lp.shift[-1][0] == pytest.approx(lp.shift[6][0], rel=0.01)


def _patches(npch=24, n=16, seed=3):
    gp = Grid((128, 128), (10.0, 10.0))
    z = gaussian_surface(gp, 0.005, 0.5, seed=seed)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, 128 - n, (npch, 2))
    P = np.stack([z[i:i + n, j:j + n] for i, j in idx])
    loads = rng.uniform(1.0, 100.0, npch)
    loads[0] = 0.0
    return gp, P, loads


def test_batched_patches_equal_single_solves():
    gp, P, loads = _patches()
    cell = (gp.dx, gp.dy)
    q = np.c_[0.4 * MU * loads, 0.1 * MU * loads]
    res = patch_stiffness(P, cell, E, NU, MU, loads, q)
    kn = patch_normal_stiffness(P, cell, E, NU, loads)
    kt, ks, clipped = patch_tangential_stiffness(P, cell, E, NU, MU, loads, q)
    assert np.allclose(res.k_n, kn, rtol=1e-12) and np.allclose(res.k_t, kt, rtol=1e-12)
    assert res.k_n[0] == 0 and res.k_t[0] == 0 and not clipped.any()
    g1 = Grid((16, 16), (16 * gp.dx, 16 * gp.dy))
    hs = ElasticHalfSpace(g1, E, NU)
    for i in (1, 5, 11):
        s = normal_stiffness(hs, P[i].max() - P[i], loads[i])
        assert kn[i] == pytest.approx(s.k_n, rel=1e-6)
        t = tangential_stiffness(hs, s.solution, MU, q[i])
        assert kt[i] == pytest.approx(t.k_t, rel=1e-6)
        assert ks[i] == pytest.approx(t.k_t_secant, rel=1e-3)
        assert 0 < ks[i] <= kt[i] * (1 + 1e-9)     # partial slip softens the secant
        assert res.contact_fraction[i] == pytest.approx(s.solution.contact_fraction)


def test_patch_kn_finite_difference_and_clipping():
    gp, P, loads = _patches(npch=6)
    cell = (gp.dx, gp.dy)
    k = patch_normal_stiffness(P, cell, E, NU, loads)
    g1 = Grid((16, 16), (16 * gp.dx, 16 * gp.dy))
    hs = ElasticHalfSpace(g1, E, NU)
    i = 2
    d = load_approach_curve(hs, P[i].max() - P[i], [loads[i] * 0.999, loads[i] * 1.001])
    # rough patches: the curve is piecewise smooth, the FD straddles few contact changes
    assert k[i] * g1.area == pytest.approx(0.002 * loads[i] / (d[1] - d[0]), rel=0.05)
    q = np.c_[2.0 * MU * loads, 0 * loads]
    kt, ks, clipped = patch_tangential_stiffness(P, cell, E, NU, MU, loads, q)
    assert clipped[1:].all() and not clipped[0]
    assert np.all(ks[1:] < kt[1:])


@pytest.mark.parametrize("kw, name", [
    (dict(patches=np.zeros((2, 16))), "patches"),
    (dict(loads=np.ones(3)), "loads"),
    (dict(loads=-np.ones(2)), "loads"),
    (dict(cell_size=(0.1, 0.0)), "cell_size"),
    (dict(q_amplitudes=np.ones((2, 3))), "q_amplitudes"),
    (dict(mu=float("nan")), "mu"),
])
def test_patch_bad_input(kw, name):
    args = dict(patches=np.zeros((2, 16, 16)), cell_size=(0.1, 0.1), young=E, poisson=NU, mu=MU,
                loads=np.ones(2), q_amplitudes=np.zeros((2, 2)))
    args.update(kw)
    with pytest.raises(ValueError, match=name):
        patch_tangential_stiffness(**args)
