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
