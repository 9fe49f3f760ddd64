"""Tangential partial slip: Cattaneo–Mindlin, Mindlin–Deresiewicz loop, limits μ → 0 / ∞, gross slip."""
import numpy as np
import pytest

from contact_bem import (ConvergenceError, ElasticHalfSpace, GrossSlipError, Grid, solve_normal,
                         solve_tangential, tangential_stiffness)
from contact_bem import reference as ref

E, NU, MU, P, RS = 198400.0, 0.3, 0.6, 100.0, 10.0


@pytest.fixture(scope="module")
def hertz128():
    es, gs = ref.composite_moduli(E, NU)
    hz = ref.hertz(P, RS, es)
    n = 128
    L = 2.6 * hz.radius
    g = Grid((n, n), (L, L))
    X, Y = g.meshgrid()
    c = g.x[n // 2]
    h = ((X - c) ** 2 + (Y - c) ** 2) / (2 * RS)
    hs = ElasticHalfSpace(g, E, NU)
    ns = solve_normal(hs, h, load=P)
    return hz, gs, g, hs, ns


@pytest.mark.parametrize("ratio", [0.25, 0.5, 0.75])
def test_cattaneo_mindlin_loading(hertz128, ratio):
    hz, gs, g, hs, ns = hertz128
    Q = ratio * MU * P
    st = solve_tangential(hs, ns, MU, [(Q, 0.0)])[0]
    c_num = np.sqrt(st.stick.sum() * g.cell_area / np.pi)
    assert c_num == pytest.approx(ref.cattaneo_stick_radius(Q, MU, P, hz.radius), rel=0.02)
    assert st.shift[0] == pytest.approx(ref.mindlin_displacement(Q, MU, P, hz.radius, gs), rel=0.03)
    assert abs(st.shift[1]) < 1e-6 * st.shift[0]
    assert st.force == pytest.approx([Q, 0.0], abs=1e-6 * Q)
    # Coulomb: |q| ≤ μp everywhere, = μp on the slip annulus
    qn = np.hypot(*st.traction)
    assert np.all(qn <= MU * ns.pressure * (1 + 1e-9) + 1e-12)
    assert np.allclose(qn[st.slip], MU * ns.pressure[st.slip], rtol=1e-9)


def test_mindlin_deresiewicz_unloading_and_reversal_slope(hertz128):
    hz, gs, g, hs, ns = hertz128
    a = hz.radius
    Qs = 0.75 * MU * P
    path = [(Qs, 0.0), (0.98 * Qs, 0.0), (0.5 * Qs, 0.0), (0.0, 0.0), (-0.5 * Qs, 0.0), (-Qs, 0.0)]
    sts = solve_tangential(hs, ns, MU, path)
    d_star = ref.mindlin_displacement(Qs, MU, P, a, gs)
    for st, (Q, _) in zip(sts[1:], path[1:]):
        d_ref = ref.mindlin_deresiewicz(Q, Qs, MU, P, a, gs, "unloading")
        assert abs(st.shift[0] - d_ref) <= 0.03 * d_star
    # slope at reversal: first small unloading increment, and the exact stuck-contact tangent
    slope = (path[0][0] - path[1][0]) / (sts[0].shift[0] - sts[1].shift[0])
    k0 = ref.mindlin_initial_stiffness(a, gs)
    assert slope == pytest.approx(k0, rel=0.03)
    ts = tangential_stiffness(hs, ns)
    assert ts.k_t * ts.area == pytest.approx(k0, rel=0.03)
    # at −Q* the loop closes onto the mirror of the virgin curve: the stick zone is the virgin one
    assert sts[-1].shift[0] == pytest.approx(-d_star, rel=0.03)


def test_mu_very_large_all_stick(hertz128):
    hz, gs, g, hs, ns = hertz128
    Q = 10.0
    st = solve_tangential(hs, ns, 1e6, [(Q, 0.0)])[0]
    assert st.stick.sum() == ns.contact.sum()
    ts = tangential_stiffness(hs, ns)
    assert st.shift[0] == pytest.approx(Q / (ts.k_t * ts.area), rel=1e-4)


def test_mu_tiny_and_gross_slip(hertz128):
    hz, gs, g, hs, ns = hertz128
    mu = 1e-6
    st = solve_tangential(hs, ns, mu, [(0.5 * mu * P, 0.0)])[0]
    assert st.force[0] == pytest.approx(0.5 * mu * P, rel=1e-6)
    c_num = np.sqrt(st.stick.sum() * g.cell_area / np.pi)
    assert c_num == pytest.approx(ref.cattaneo_stick_radius(0.5 * mu * P, mu, P, hz.radius), rel=0.02)
    with pytest.raises(GrossSlipError, match="Coulomb limit"):
        solve_tangential(hs, ns, mu, [(1.01 * mu * P, 0.0)])
    with pytest.raises(GrossSlipError):
        solve_tangential(hs, ns, 0.0, [(1.0, 0.0)])


def test_gross_slip_full_slip_state(hertz128):
    hz, gs, g, hs, ns = hertz128
    Q = np.array([0.6, 0.8]) * 1.5 * MU * P
    sts = solve_tangential(hs, ns, MU, [(10.0, 0.0), tuple(Q), (10.0, 0.0)], on_gross_slip="full_slip")
    fs = sts[1]
    assert fs.gross_slip and np.all(np.isnan(fs.shift)) and not fs.stick.any()
    # sliding state: q = μp along Q, total force μP along Q
    assert fs.force == pytest.approx(MU * P * np.array([0.6, 0.8]), rel=1e-10)
    assert np.allclose(np.hypot(*fs.traction), MU * ns.pressure)
    # the path continues after gross slip with a finite, converged state
    assert np.all(np.isfinite(sts[2].shift)) and sts[2].force == pytest.approx([10.0, 0.0], abs=1e-5)


def test_two_dimensional_path_is_history_dependent(hertz128):
    hz, gs, g, hs, ns = hertz128
    # same final force reached by two paths gives different tractions (friction memory)
    F = 0.4 * MU * P
    a = solve_tangential(hs, ns, MU, [(F, 0.0), (F, F)])[-1]
    b = solve_tangential(hs, ns, MU, [(0.0, F), (F, F)])[-1]
    assert a.force == pytest.approx(b.force, abs=1e-6 * F)
    assert np.abs(a.traction - b.traction).max() > 0.01 * MU * ns.pressure.max()


def test_non_convergence_and_bad_input(hertz128):
    hz, gs, g, hs, ns = hertz128
    with pytest.raises(ConvergenceError, match="residual reached"):
        solve_tangential(hs, ns, MU, [(0.5 * MU * P, 0.0)], max_iter=2)
    with pytest.raises(ValueError, match="forces"):
        solve_tangential(hs, ns, MU, [(np.nan, 0.0)])
    with pytest.raises(ValueError, match="forces"):
        solve_tangential(hs, ns, MU, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="mu"):
        solve_tangential(hs, ns, -0.1, [(1.0, 0.0)])
    with pytest.raises(ValueError, match="on_gross_slip"):
        solve_tangential(hs, ns, MU, [(1.0, 0.0)], on_gross_slip="ignore")


def test_cg_and_fista_fallback_agree():
    # the two increment solvers are independent algorithms; on a 2D load they must agree
    from contact_bem.tangential import fista_tangential_batch, pk_tangential_batch
    es, gs = ref.composite_moduli(E, NU)
    hz = ref.hertz(P, RS, es)
    g = Grid((48, 48), (2.6 * hz.radius,) * 2)
    X, Y = g.meshgrid()
    c = g.x[24]
    hs = ElasticHalfSpace(g, E, NU)
    ns = solve_normal(hs, ((X - c) ** 2 + (Y - c) ** 2) / (2 * RS), load=P)
    R = (MU * ns.pressure)[None]
    zero = np.zeros((1, 2) + g.shape)
    Q = np.array([[0.5, 0.6]]) * MU * P
    a = pk_tangential_batch(hs._apply_tangential, R, zero, zero, Q, g.cell_area, tol=1e-7, max_iter=5000)
    b = fista_tangential_batch(hs._apply_tangential, hs.tangential_lipschitz, R, zero, zero, Q, g.cell_area,
                               tol=1e-7, max_iter=20000)
    assert np.allclose(a["shift"], b["shift"], rtol=1e-4)
    assert np.abs(a["traction"] - b["traction"]).max() < 1e-3 * R.max()


def test_flat_patch_near_gross_slip_in_2d_converges():
    # the smooth-surface case of the study: full contact, |Q| = 0.99 μP at an angle
    from contact_bem import patch_tangential_stiffness
    rng = np.random.default_rng(0)
    z = 1e-8 * rng.standard_normal((6, 16, 16))
    loads = np.linspace(20.0, 200.0, 6)
    ang = np.linspace(0.0, 2.5, 6)
    q = np.c_[np.cos(ang), np.sin(ang)] * (1.2 * MU * loads)[:, None]
    kt, ks, clipped = patch_tangential_stiffness(z, (0.08, 0.08), E, NU, MU, loads, q)
    assert clipped.all()
    assert np.all(ks > 0) and np.all(ks < kt)
    # the reversal slope of a full-contact flat square patch is load independent
    assert np.allclose(kt, kt[0], rtol=1e-6)
