"""The joint configurations of the study (paper Table 1) as JointModels, and the excitation levels.

============  ==========================  ==============================  ==========================
name          N0, gap                     k_n                             k_t
============  ==========================  ==============================  ==========================
baseline      smooth FE preload           k_ref                           k_ref
smooth-ms     smooth FE preload           BEM patches, Rq = smooth_rq     = k_n
v1            BEM, rough (Rq = v_rq)      k_ref                           k_ref
v2            BEM, rough                  BEM patches at N0               Mindlin ratio · k_n
v3            BEM, rough                  BEM patches at cycle-mean N     BEM loop at resonance
============  ==========================  ==============================  ==========================

v3 is a fixed point: it starts from v2, computes the FRF at the chosen level, takes every element's
cycle-mean normal load and tangential force amplitude at resonance, recomputes k_n and k_t on the
element's patch (k_t = slope of the hysteresis loop at load reversal, paper Fig. 4) and repeats
until the resonance frequency and the peak change by less than ``contact.kt_tol`` (the paper did
one pass). Elements without real contact in their cell get k_n = 0, as in the paper: they carry no
force and are left out of the dynamics (model only what the analysis needs).
"""
from __future__ import annotations

import numpy as np

from ..model.joint import JointModel, slip_onset
from .contact import InterfaceSetup, SurfaceContact

#: the level quantiles of the auto rule: where 10 % and 50 % of the loaded area would slip
LEVEL_QUANTILES = (0.1, 0.5)
#: the top level as a fraction of the linear macroslip estimate
TOP_LEVEL_OF_MACROSLIP = 0.5
#: the paper's excitation levels on its rig, N, and their ratios (1 : 2 : 4)
PAPER_LEVELS = (500.0, 1000.0, 2000.0)
PAPER_LEVEL_RATIOS = tuple(x / PAPER_LEVELS[-1] for x in PAPER_LEVELS)
#: the like-for-like joints of v1 → v2 (issue 13, item 8): name → the configuration it varies
LIKE_FOR_LIKE = {"v1-v2set": "v1", "v2-keep": "v2"}
#: v2-keep: the open elements get the area-weighted mean k_n of this lightest-loaded share
#: (by pressure N0/A) of the loaded elements
KEEP_KN_SHARE = 0.1


def joint_baseline(setup: InterfaceSetup, k_ref: float) -> JointModel:
    """FE loads and gaps; k_n = k_t = k_ref (the paper's reference joint)."""
    ne = len(setup.area)
    return JointModel("baseline", n0=setup.n0_fe, gap=setup.gap_fe, kn=np.full(ne, k_ref),
                      kt=np.full(ne, k_ref), area=setup.area)


def joint_v1(setup: InterfaceSetup, sc: SurfaceContact, k_ref: float) -> JointModel:
    """BEM loads and gaps of the rough surface; k_n = k_t = k_ref."""
    ne = len(setup.area)
    return JointModel("v1", n0=sc.n0, gap=sc.gap_el, kn=np.full(ne, k_ref), kt=np.full(ne, k_ref),
                      area=setup.area, rq_um=sc.rq_um)


def joint_v2(setup: InterfaceSetup, sc: SurfaceContact, name: str = "v2") -> JointModel:
    """BEM loads, gaps and patch k_n at N0; k_t by Mindlin's ratio (the start of v3)."""
    return JointModel(name, n0=sc.n0, gap=sc.gap_el, kn=sc.kn, kt=sc.kt_mindlin, area=setup.area,
                      rq_um=sc.rq_um)


def fixed_joints(setup: InterfaceSetup, surfaces: dict, kn_smooth: np.ndarray, case) -> dict:
    """baseline, smooth-ms, v1, v2 (and the v2 start of every Rq's v3) as JointModels."""
    r, k_ref = case.roughness, case.contact.k_ref
    sv = surfaces[r.v_rq_um]
    joints = {
        "baseline": joint_baseline(setup, k_ref),
        "smooth-ms": JointModel("smooth-ms", n0=setup.n0_fe, gap=setup.gap_fe, kn=kn_smooth,
                                kt=kn_smooth.copy(), area=setup.area, rq_um=r.smooth_rq_um),
        "v1": joint_v1(setup, sv, k_ref),
        "v2": joint_v2(setup, sv),
    }
    return joints


def choose_levels(inputs_rm, baseline: JointModel, case) -> tuple[list, dict]:
    """Excitation levels (N) and the stuck-joint slip estimate behind them."""
    rm = inputs_rm
    est = slip_onset(rm.K, rm.M, rm.pair_dofs, baseline, rm.excitation_dof, rm.damping_ratio,
                     case.contact.mu)
    lv = case.dynamics.levels
    levels = ([est["quantile"](q) for q in LEVEL_QUANTILES]
              + [TOP_LEVEL_OF_MACROSLIP * est["macroslip"]] if lv == "auto" else list(lv))
    info = {"first_slip": est["first_slip"], "macroslip": est["macroslip"],
            "stuck_frequency": est["frequency"],
            "quantiles": {f"{q:g}": est["quantile"](q) for q in LEVEL_QUANTILES},
            "auto": lv == "auto"}
    return [float(x) for x in levels], info


def paper_ratio_levels(top: float, ratios: tuple = PAPER_LEVEL_RATIOS) -> list[float]:
    """Levels in the paper's ratios (500 : 1000 : 2000 N = 1 : 2 : 4), anchored at ``top`` (N).

    Anchored at the top: the study's top level is the one the auto rule places at a physical
    point (half the linear macroslip estimate), the paper's top level is its 2000 N.
    """
    return [float(top * r) for r in ratios]


def damping_for_level(zeta: float, level: float, paper_level: float) -> float:
    """The modal damping ratio at which ``paper_level`` (N) drives the resonator as ``level`` (N)
    does at ``zeta``.

    The stuck resonant response to a force F is φ (φ_e F) / (2ζω²), so every force the linear
    estimate derives from it (first slip, the slip quantiles, macroslip: the interface shear
    reaching μΣN0) is proportional to ζ: F(ζ') = F(ζ) ζ'/ζ. ``paper_level`` sits at ``level``'s
    ratio to macroslip when ζ' = ζ · paper_level / level.
    """
    return float(zeta * paper_level / level)


def joint_on_element_set(joint: JointModel, keep: np.ndarray, name: str) -> JointModel:
    """``joint`` with only the elements ``keep`` (the others get k_n = k_t = 0: not modelled).

    Used for v1 on v2's element set (v1'): v1's loads, gaps and k_ref, without the elements v2
    removes, so v1 → v1' is the element-set change alone and v1' → v2 the stiffness change.
    """
    k = np.asarray(keep, bool)
    return JointModel(name, n0=joint.n0, gap=joint.gap, kn=np.where(k, joint.kn, 0.0),
                      kt=np.where(k, joint.kt, 0.0), area=joint.area, rq_um=joint.rq_um)


def light_contact_kn(joint: JointModel, share: float = KEEP_KN_SHARE) -> float:
    """The k_n (N/mm³) of a lightly loaded contact of ``joint``'s surface: the area-weighted mean
    k_n of the loaded elements in the lightest ``share`` of them by pressure N0/A."""
    c = joint.closed & (joint.kn > 0)
    p = joint.n0[c] / joint.area[c]
    light = p <= np.quantile(p, share)
    return float(np.sum((joint.kn * joint.area)[c][light]) / np.sum(joint.area[c][light]))


def joint_v2_keep(v2: JointModel, kt_over_kn: float, kn_open: float,
                  name: str = "v2-keep") -> JointModel:
    """v2 whose elements open at rest keep existing, as in v1: k_n = ``kn_open`` (N/mm³), k_t by
    ``kt_over_kn`` (Mindlin, as v2), their N0 = 0 and gaps unchanged; the loaded elements are v2's."""
    o = ~v2.closed
    return JointModel(name, n0=v2.n0, gap=v2.gap, kn=np.where(o, kn_open, v2.kn),
                      kt=np.where(o, kt_over_kn * kn_open, v2.kt), area=v2.area, rq_um=v2.rq_um)


def like_for_like_joints(joints: dict, poisson: float) -> dict:
    """v1 on v2's element set (``v1-v2set``) and v2 with its open elements kept (``v2-keep``).

    Args:
        joints: the fixed configurations (``fixed_joints``; needs "v1" and "v2").
        poisson: Poisson's ratio (Mindlin's k_t / k_n of v2).
    Returns:
        name → JointModel (``LIKE_FOR_LIKE``'s names).
    """
    from contact_bem import mindlin_ratio
    v1, v2 = joints["v1"], joints["v2"]
    active = (v2.kn > 0) & (v2.kt > 0)
    return {"v1-v2set": joint_on_element_set(v1, active, "v1-v2set"),
            "v2-keep": joint_v2_keep(v2, mindlin_ratio(poisson), light_contact_kn(v2))}
