"""Like-for-like comparisons (issue 13, items 8 and 2): levels in the paper's ratios, the damping
scaling of the level rule, and when an element open at rest closes — against closed forms."""
from __future__ import annotations

import numpy as np
import pytest

from fe_joint.model.joint import JointModel, closure_onset, slip_onset, stuck_modes, stuck_stiffness
from fe_joint.study.configurations import (PAPER_LEVELS, damping_for_level, joint_on_element_set,
                                           joint_v2_keep, light_contact_kn, paper_ratio_levels)

M1, M2 = 2e-3, 3e-3


def _two_blocks():
    """Two point masses, 3 DOFs each (A = 0..2, B = 3..5: x, y, z), coupled only by the joint."""
    return np.diag([M1] * 3 + [M2] * 3), np.zeros((6, 6)), np.array([[[0, 1, 2], [3, 4, 5]]] * 2)


def test_paper_ratio_levels_are_1_2_4_anchored_at_the_top() -> None:
    top = 101.37
    lv = paper_ratio_levels(top)
    assert lv[-1] == top                                   # anchored at our top level
    assert lv[1] / lv[0] == pytest.approx(2.0, rel=1e-15)
    assert lv[2] / lv[1] == pytest.approx(2.0, rel=1e-15)
    # the paper's own levels in the same ratios
    assert np.allclose(np.array(lv) / top, np.array(PAPER_LEVELS) / PAPER_LEVELS[-1], rtol=1e-15)


@pytest.mark.parametrize("zeta", [1e-3, 4e-3])
def test_macroslip_scales_with_damping_two_dof(zeta) -> None:
    """Two elements on one 2-DOF relative mode: the macroslip estimate is
    μΣN0 · 2ζω² / (|φ_e| Σ k_t A |Δφ_x|) (closed form); a paper level P sits at our level L's ratio
    to it at ζ' = ζ P / L (``damping_for_level``)."""
    M, K, pd = _two_blocks()
    kt, area, n0, mu = np.array([4e4, 1e4]), np.array([1.0, 2.0]), np.array([60.0, 30.0]), 0.6
    j = JointModel("t", n0=n0, gap=np.zeros(2), kn=2 * kt, kt=kt, area=area)
    w = np.sqrt(np.sum(kt * area) * (1 / M1 + 1 / M2))       # the x relative mode (kt < kn)
    c = 1 / np.sqrt(1 / M1 + 1 / M2)                         # φ_A = c/m1, φ_B = −c/m2
    ref = mu * n0.sum() * 2 * zeta * w * w / ((c / M1) * np.sum(kt * area) * c * (1 / M1 + 1 / M2))
    est = slip_onset(K, M, pd, j, excitation_dof=0, damping_ratio=zeta, mu=mu)
    assert est["macroslip"] == pytest.approx(ref, rel=1e-9)
    L, P = 0.37 * ref, 2000.0
    zp = damping_for_level(zeta, L, P)
    est_p = slip_onset(K, M, pd, j, excitation_dof=0, damping_ratio=zp, mu=mu)
    assert P / est_p["macroslip"] == pytest.approx(L / est["macroslip"], rel=1e-9)
    assert est_p["first_slip"] / est["first_slip"] == pytest.approx(zp / zeta, rel=1e-9)


def _closing_pair(gap: float):
    """Element 0 loaded (its z stiffness makes the lowest elastic mode the z relative mode),
    element 1 on the same DOFs open at rest with ``gap``."""
    kn, kt, A = 1e4, 4e4, 1.0
    return JointModel("t", n0=np.array([500.0, 0.0]), gap=np.array([0.0, gap]),
                      kn=np.array([kn, kn]), kt=np.array([kt, kt]), area=np.array([A, A]))


def test_closure_onset_closed_form() -> None:
    """Stuck z mode φ_A = c/m1, φ_B = −c/m2: the open element touches at X_A = g m2/(m1 + m2)."""
    M, K, pd = _two_blocks()
    g = 3e-3
    j = _closing_pair(g)
    lin = stuck_modes(K, M, pd, j, n_modes=6)
    x = closure_onset(lin, pd, j, excitation_dof=2)
    assert np.isinf(x[0])                                    # loaded: never "closes"
    assert x[1] == pytest.approx(g * M2 / (M1 + M2), rel=1e-10)


@pytest.mark.parametrize("ratio,closes", [(0.9, False), (1.1, True)])
def test_open_element_closes_at_the_known_amplitude(ratio, closes) -> None:
    """The harmonic balance of the same pair, forced in z below resonance with the force that
    gives a linear relative amplitude of ``ratio`` × gap: the open element stays open all cycle
    below the gap and is partly closed above it (the measured v1 check on the resonator)."""
    from hbm import FrictionContacts, HarmonicBalance, LinearStructure
    M, K, pd = _two_blocks()
    g = 3e-3
    j = _closing_pair(g)
    w = 0.5 * 2 * np.pi * stuck_modes(K, M, pd, j, n_modes=6).frequency
    Ks = stuck_stiffness(K, pd, j)
    e = np.zeros(6)
    e[2] = 1.0
    x1 = np.linalg.solve(Ks - w * w * M, e)                  # linear response to 1 N (undamped)
    force = ratio * g / abs(x1[2] - x1[5]) * e
    c = FrictionContacts(pd, kt=j.kt * j.area, kn=j.kn * j.area, mu=0.6, n0=j.n0, gap=j.gap)
    hb = HarmonicBalance(LinearStructure(M, K, damping_ratio=1e-3), c, harmonics=3, samples=64)
    er = hb.element_results(hb.solve(w, force))
    assert er.status[0] == 0                                 # the loaded element stays stuck
    assert (er.status[1] != 4) == closes                     # 4 = open all cycle
    assert (er.N[1].max() > 0) == closes


def test_like_for_like_joints() -> None:
    """v1' keeps v1's stuck stiffness exactly (the stuck model holds only loaded elements) and
    drops the chosen ones from the dynamics; v2-keep gives open elements the light-load k_n."""
    M, K, pd = _two_blocks()
    pd3 = np.concatenate([pd, pd[:1]])
    n0 = np.array([10.0, 0.0, 40.0])
    area = np.array([1.0, 2.0, 3.0])
    v1 = JointModel("v1", n0=n0, gap=np.array([0, 1e-3, 0]), kn=np.full(3, 6e4),
                    kt=np.full(3, 6e4), area=area)
    v1s = joint_on_element_set(v1, n0 > 0, "v1-v2set")
    assert np.array_equal(stuck_stiffness(K, pd3, v1s), stuck_stiffness(K, pd3, v1))
    assert v1s.kn[1] == 0 and v1s.kt[1] == 0 and v1s.kn[0] == 6e4
    # k_n of the lightest 10 % by pressure N0/A (10 and 13.3 MPa): the lightest one alone
    v2 = JointModel("v2", n0=n0, gap=v1.gap, kn=np.array([2e3, 0.0, 5e3]),
                    kt=np.array([1.6e3, 0.0, 4e3]), area=area)
    assert light_contact_kn(v2) == 2e3
    assert light_contact_kn(v2, share=1.0) == pytest.approx((2e3 * 1 + 5e3 * 3) / 4, rel=1e-15)
    keep = joint_v2_keep(v2, 0.8, 2e3)
    assert keep.kn.tolist() == [2e3, 2e3, 5e3] and keep.kt[1] == pytest.approx(1.6e3)
    assert keep.n0[1] == 0 and keep.gap[1] == 1e-3


def test_like_for_like_jobs_leave_the_curve_keys_alone() -> None:
    """Adding the like-for-like joints to the study adds two backbone jobs and changes no FRF
    job's cache key (a rerun of a finished run computes only the new backbones)."""
    import dataclasses
    from fe_joint.study import jobs as study
    from fe_joint.study.configurations import LIKE_FOR_LIKE, like_for_like_joints
    from test_artifacts import _inputs, _keyed
    inp = _inputs([1.0, 2.0, 4.0])
    for j in inp.joints.values():
        j.n0[:2] = 0.0                     # two elements open at rest (v2 removes them)
    inp.joints["v2"].kn[:2] = 0.0
    before = {j.name: j.key for j in _keyed(inp)}
    joints = {**inp.joints, **like_for_like_joints(inp.joints, 0.3)}
    after = {j.name: j.key for j in _keyed(dataclasses.replace(inp, joints=joints))}
    assert after == before
    names = [j.config for j in study.backbone_jobs(inp.case)]
    assert [n for n in names if n in LIKE_FOR_LIKE] == list(LIKE_FOR_LIKE)
    assert joints["v1-v2set"].kn[:2].tolist() == [0.0, 0.0]
    assert joints["v2-keep"].kn[:2].min() > 0


def test_off_backbone_peak_is_nan_and_element_set_warning() -> None:
    from types import SimpleNamespace
    from fe_joint.report.like_for_like import _checked, warnings
    br = SimpleNamespace(displacement_amplitude=np.array([1e-3, 1.0]),
                         frequency_hz=np.array([245.0, 240.0]), zeta=np.array([1e-3, 3e-3]))
    assert np.isnan(_checked(br, 17.36, 0.5)["hz"])          # a spurious maximum far off the band
    assert np.isnan(_checked(br, 242.0, 5.0)["amplitude"])   # beyond the backbone's end
    ok = _checked(br, 242.0, 0.1)
    assert ok["hz"] == 242.0 and 1e-3 < ok["zeta"] < 3e-3
    lv = {"level": 1.0, "closing": 0, "max_mean_normal_N": 0.0, "energy_share": 0.0}
    s = {"like_for_like": {"element_set": {"removed": 5, "levels": {"L0": lv}}, "split": {}}}
    assert warnings(s) == []                                  # nothing closes: like for like
    s["like_for_like"]["element_set"]["levels"]["L1"] = {**lv, "closing": 2}
    w = warnings(s)
    assert len(w) == 1 and w[0]["kind"] == "element-set" and w[0]["value"] == 2
