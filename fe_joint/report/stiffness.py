"""The equivalent stiffness of the report's configurations (paper Figs. 15, 19).

Every k_eq is :meth:`JointModel.k_eq` (Σ k_i A_i / Σ A_i) of a JointModel built from the run's
artifacts, so the report and the study share one definition.
"""
from __future__ import annotations

import numpy as np

from ..model.joint import JointModel
from .data import ReportData


def _v3_joint(data: ReportData, rq: float) -> JointModel:
    """The converged v3 joint on the surface of Rq ``rq`` (µm), from its stiffness arrays."""
    sc, k = data.surfaces[rq], data.v3_arrays[rq]
    return JointModel("v3", n0=sc.n0, gap=sc.gap_el, kn=k["kn"], kt=k["kt"], area=data.area,
                      rq_um=rq)


def _v2_joint(data: ReportData, rq: float, name: str = "v2") -> JointModel:
    """The v2 joint (patch k_n at N0, Mindlin k_t) on the surface of Rq ``rq`` (µm)."""
    sc = data.surfaces[rq]
    return JointModel(name, n0=sc.n0, gap=sc.gap_el, kn=sc.kn, kt=sc.kt_mindlin, area=data.area,
                      rq_um=rq)


def configuration_joints(data: ReportData) -> dict[str, JointModel]:
    """baseline, smooth-ms, v1, v2 and (when its fixed point finished) v3 on the comparison surface.

    Args:
        data: the run's artifacts.
    Returns:
        name → JointModel (k_n, k_t in N/mm³, areas in mm²), in the report's order.
    """
    rm, area, k_ref = data.rm, data.area, data.case.contact.k_ref
    full = np.full(len(area), k_ref)
    kn_smooth = data.extra["kn_smooth"]
    sv = data.surfaces[data.v_rq]
    # unloaded elements count 0 for v1 (as the figure says): they carry no preload, so no stiffness
    k_v1 = np.where(sv.n0 > 0, k_ref, 0.0)
    joints = {
        "baseline": JointModel("baseline", n0=rm.preload_normal_force, gap=rm.preload_gap,
                               kn=full, kt=full, area=area),
        "smooth-ms": JointModel("smooth-ms", n0=rm.preload_normal_force, gap=rm.preload_gap,
                                kn=kn_smooth, kt=kn_smooth, area=area),
        "v1": JointModel("v1", n0=sv.n0, gap=sv.gap_el, kn=k_v1, kt=k_v1, area=area, rq_um=data.v_rq),
        "v2": _v2_joint(data, data.v_rq),
    }
    if data.v_rq in data.v3_arrays:
        joints["v3"] = _v3_joint(data, data.v_rq)
    return joints


def rq_joints(data: ReportData) -> dict[float, JointModel]:
    """Per surface, the v3 joint when its fixed point finished, else its v2 start.

    Args:
        data: the run's artifacts.
    Returns:
        Rq in µm (ascending) → JointModel.
    """
    return {rq: _v3_joint(data, rq) if rq in data.v3_arrays else _v2_joint(data, rq, "v3")
            for rq in data.rqs}


def k_eq_table(joints: dict) -> dict:
    """{name: {"kn": k_n,eq, "kt": k_t,eq}} in N/mm³ for a dict of JointModels (same keys)."""
    return {name: {"kn": j.k_eq("kn"), "kt": j.k_eq("kt")} for name, j in joints.items()}
