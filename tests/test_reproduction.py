"""Issue 13: the numbers behind the reproduction claims (damping ratio, contact area definitions,
seed statistics, hardness cap), each against an independent reference or an invariant."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from contact_bem import ElasticHalfSpace, Grid, gaussian_surface, patch_normal_stiffness, solve_normal
from fe_joint.model.joint import JointModel, stuck_modes
from fe_joint.report.damping import (amplitude_damping_ratio, friction_damping_ratio,
                                     modal_amplitude)
from fe_joint.study.contact import contact_area
from fe_joint.study.variants import statistics, stuck_frequency

E, NU = 198400.0, 0.3


# --------------------------------------------------------------------------------- damping (item 1)
def _chain(n: int = 6, k: float = 1e4, m: float = 1e-3):
    """A fixed–free spring–mass chain (N/mm, t)."""
    K = np.zeros((n, n))
    for i in range(n):
        K[i, i] += k
        if i + 1 < n:
            K[i, i] += k
            K[i, i + 1] = K[i + 1, i] = -k
    return K, np.eye(n) * m


@pytest.mark.parametrize("zeta", [1e-3, 1e-2])
def test_damping_ratio_of_a_viscous_structure_is_given_back(zeta):
    """A pure viscous structure with modal ζ on every mode, driven at its first resonance: the
    energy its damper dissipates per cycle, put through ζ = E/(2π ω² a²) with a = X/|φ_e|, and the
    amplitude check F|φ_e|/(2ω²a) both give back the structural ζ (to O(ζ) from the other modes)."""
    K, M = _chain()
    w2, phi = sla.eigh(K, M)
    w = np.sqrt(w2)
    C = M @ phi @ np.diag(2 * zeta * w) @ phi.T @ M
    e, F = 0, 1.0
    f = np.zeros(len(K))
    f[e] = F
    # the peak of |q_e(ω)| near the first mode, by a fine scan
    om = w[0] * np.linspace(1 - 3 * zeta, 1 + 3 * zeta, 4001)
    amps = [abs(np.linalg.solve(K - o * o * M + 1j * o * C, f)[e]) for o in om]
    o = om[int(np.argmax(amps))]
    q = np.linalg.solve(K - o * o * M + 1j * o * C, f)
    energy = np.pi * o * np.real(q.conj() @ C @ q)          # viscous energy per cycle, N·mm
    a = modal_amplitude(abs(q[e]), phi[e, 0])
    assert friction_damping_ratio(energy, o, a) == pytest.approx(zeta, rel=3 * zeta)
    assert amplitude_damping_ratio(F, phi[e, 0], o, a) == pytest.approx(zeta, rel=3 * zeta)


def test_damping_ratio_definition_single_oscillator():
    """m ẍ + c ẋ + k x = F cos ωt at ω = ω_n: E = π c ω X², ζ = c/(2√(km)), φ = 1/√m."""
    m, k, zeta, X = 2e-3, 5e3, 0.004, 0.3
    wn = np.sqrt(k / m)
    c = 2 * zeta * np.sqrt(k * m)
    energy = np.pi * c * wn * X ** 2
    a = modal_amplitude(X, 1 / np.sqrt(m))
    assert friction_damping_ratio(energy, wn, a) == pytest.approx(zeta, rel=1e-12)


# ---------------------------------------------------------------------------- contact area (item 5)
def _square_with_hole(n: int, L: float = 20.0, d: float = 8.5):
    g = Grid((n, n), (L, L), origin=(-L / 2, -L / 2))
    x = (np.arange(n) + 0.5) * L / n - L / 2
    X, Y = np.meshgrid(x, x, indexing="ij")
    return g, np.hypot(X, Y) > d / 2


def test_contact_area_of_a_flat_punch_on_both_definitions():
    """A flat rigid punch over the overlap with the hole masked is in full contact: the fraction of
    the usable area and of the FE-loaded area is 1, that of the whole overlap is 1 − π r²/L²."""
    g, mask = _square_with_hole(128)
    hs = ElasticHalfSpace(g, E, NU)
    ns = solve_normal(hs, np.zeros(g.shape), load=30e3, mask=mask)
    p_fe = np.where(mask, 1.0, 0.0)                      # the clamped region = the usable overlap
    ca = contact_area(mask, g.cell_area, ns.pressure, p_fe)
    fr = ca.fractions()
    assert fr["usable"] == 1.0 and fr["fe_loaded"] == 1.0
    assert ca.overlap == pytest.approx(400.0, rel=1e-12)
    assert fr["overlap"] == pytest.approx(1 - np.pi * 4.25 ** 2 / 400.0, abs=2e-3)   # pixelized hole


def test_contact_area_ratio_of_the_two_definitions_is_the_area_ratio():
    """On a rough surface the paper's fraction is ours × usable/overlap, whatever the contact."""
    g, mask = _square_with_hole(64)
    z = gaussian_surface(g, 0.01, 0.5, seed=3)
    ns = solve_normal(ElasticHalfSpace(g, E, NU), z.max() - z, load=30e3, mask=mask)
    ca = contact_area(mask, g.cell_area, ns.pressure, np.where(mask, 1.0, 0.0))
    fr = ca.fractions()
    assert fr["usable"] == pytest.approx(ns.contact_fraction, rel=1e-12)   # the solver's own
    assert fr["overlap"] == pytest.approx(fr["usable"] * mask.sum() / mask.size, rel=1e-12)


# -------------------------------------------------------------------------- seed statistics (item 6)
def test_statistics_of_identical_seeds_have_no_spread():
    st = statistics([0.123] * 5)
    assert st == {"mean": 0.123, "std": 0.0, "min": 0.123, "max": 0.123, "n": 5}
    st = statistics([1.0, 2.0, 3.0])
    assert st["std"] == pytest.approx(1.0) and st["mean"] == 2.0


def test_mean_contact_fraction_over_seeds_is_near_the_single_seed_value():
    """Five realizations of the same Gaussian surface (λ = 0.5 mm on 20 mm: ≈ 1600 correlation
    areas) give contact fractions within ±15 % of their mean, and the mean within 10 % of seed 0."""
    g, mask = _square_with_hole(64)
    hs = ElasticHalfSpace(g, E, NU)
    fr = []
    for s in range(5):
        z = gaussian_surface(g, 0.01, 0.5, seed=s)
        fr.append(solve_normal(hs, z.max() - z, load=30e3, mask=mask).contact_fraction)
    st = statistics(fr)
    assert st["max"] < 1.15 * st["mean"] and st["min"] > 0.85 * st["mean"]
    assert st["mean"] == pytest.approx(fr[0], rel=0.10)
    assert st["std"] > 0


def test_shift_invert_stuck_frequency_equals_stuck_modes():
    """The one-LU shifted solve finds the same breathing mode as the dense eigensolve."""
    rng = np.random.default_rng(0)
    # two 3-DOF bodies (free–free chains) joined by two pairs: one rigid-body mode set + elastic
    n = 12
    K = np.zeros((n, n))
    for body in (0, 6):
        for i in range(5):
            a, b = body + i, body + i + 1
            k = 1e4 * (1 + rng.random())
            K[[a, b], [a, b]] += k
            K[a, b] -= k
            K[b, a] -= k
    M = np.diag(1e-3 * (1 + rng.random(n)))
    pair_dofs = np.array([[[3, 4, 5], [6, 7, 8]], [[0, 1, 2], [9, 10, 11]]])
    joint = JointModel("t", n0=np.array([10.0, 5.0]), gap=np.zeros(2), kn=np.array([3e3, 2e3]),
                       kt=np.array([2e3, 1e3]), area=np.ones(2))
    exact = stuck_modes(K, M, pair_dofs, joint, n_modes=n).frequency
    assert stuck_frequency(K, M, pair_dofs, joint, 1.02 * exact) == pytest.approx(exact, rel=1e-10)


# ----------------------------------------------------------------------------- hardness cap (item 7)
def test_hardness_cap_bounds_the_pressure_and_keeps_the_load():
    """Global solve: with a cap the largest pressure is the cap, the load is unchanged and the
    contact grows (the solver's invariants)."""
    g, mask = _square_with_hole(64)
    hs = ElasticHalfSpace(g, E, NU)
    z = gaussian_surface(g, 0.010, 0.5, seed=0)
    el = solve_normal(hs, z.max() - z, load=30e3, mask=mask)
    H = 2000.0
    assert el.pressure.max() > H
    cap = solve_normal(hs, z.max() - z, load=30e3, mask=mask, hardness=H)
    assert cap.pressure.max() == pytest.approx(H, rel=1e-12)
    assert cap.load == pytest.approx(30e3, rel=1e-7)
    assert cap.contact.sum() > el.contact.sum()


def test_capped_patches_carry_their_loads_at_the_cap():
    """Patches with a cap: each carries its load, no pressure exceeds H, and the stiffness is the
    unloading one of the (larger) contact set, so it is above the elastic patch's."""
    g = Grid((8, 8), (1.3, 1.3))
    z = np.stack([gaussian_surface(g, 0.015, 0.5, seed=s) for s in range(6)])
    W = np.array([50.0, 120.0, 200.0, 270.0, 310.0, 90.0])
    H = 2000.0
    cell = (1.3 / 8, 1.3 / 8)
    k_el, p_el = patch_normal_stiffness(z, cell, E, NU, W, return_pressure=True)
    k_cap, p_cap = patch_normal_stiffness(z, cell, E, NU, W, hardness=H, return_pressure=True)
    assert np.all(p_cap.max(axis=(1, 2)) <= H * (1 + 1e-12))
    assert np.allclose(p_cap.sum(axis=(1, 2)) * g.cell_area, W, rtol=1e-5)
    capped = p_el.max(axis=(1, 2)) > H
    assert capped.any()
    assert np.all(k_cap[capped] >= k_el[capped] * (1 - 1e-9))
    assert np.allclose(k_cap[~capped], k_el[~capped], rtol=1e-6)
