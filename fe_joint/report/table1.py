"""The counterpart of the paper's Table 1: the configurations this run actually computed.

Each row is read from the JointModel the report rebuilds from the artifacts
(:func:`~.stiffness.configuration_joints`, the same arrays the dynamics stage used), so the
element counts and sums are the run's, and the sources are stated as the study builds them
(README, "The multiscale study", item 3).
"""
from __future__ import annotations

import numpy as np

from ..study.artifacts import rq_label
from .data import ReportData
from .stiffness import configuration_joints

#: configuration → (normal load and gap, k_n, k_t): where each comes from, as the study builds it
SOURCES = {
    "baseline": ("FE preload (smooth contact)", "k_ref", "k_ref"),
    "smooth-ms": ("FE preload (smooth contact)", "patch BEM of the smooth-ms surface at N0", "= k_n"),
    "v1": ("global rough BEM", "k_ref (0 where N0 = 0)", "k_ref (0 where N0 = 0)"),
    "v2": ("global rough BEM", "patch BEM at N0", "Mindlin 2(1−ν)/(2−ν)·k_n"),
    "v3": ("global rough BEM", "patch BEM at the cycle-mean N (fixed point)",
           "patch BEM loop at resonance (fixed point)"),
}
#: the paper's Table 1 (normal load, k_n, k_t); smooth-ms is its Section 4 model (Fig. 8, 11)
PAPER_TABLE1 = {
    "baseline": ("from Abaqus", "6e4", "6e4"),
    "smooth-ms": ("from Abaqus", "from contact solver (smooth)", "= k_n"),
    "v1": ("from contact solver", "6e4", "6e4"),
    "v2": ("from contact solver", "from contact solver", "2(1−ν)/(2−ν)·k_n"),
    "v3": ("from contact solver", "from contact solver", "from contact solver"),
}


def table1_rows(data: ReportData) -> list[dict]:
    """One dict per configuration of the case that the report can rebuild.

    Args:
        data: the run's artifacts.
    Returns:
        [{"config", "surface" (Rq in µm or "smooth"), "load", "kn_source", "kt_source",
        "paper" (normal load, k_n, k_t), "loaded" (elements with N0 > 0), "active" (k_n, k_t > 0:
        the elements in the dynamics), "sum_n0" N, "kn_eq", "kt_eq" N/mm³, "ran" (curves found)}].
    """
    joints = configuration_joints(data)
    ran = {k.config for k in data.curves}
    rows = []
    for cfg in data.configs:
        j = joints.get(cfg)
        if j is None:
            continue
        load, kn_src, kt_src = SOURCES[cfg]
        rows.append({
            "config": cfg, "surface": "smooth" if j.rq_um is None else rq_label(j.rq_um),
            "load": load, "kn_source": kn_src, "kt_source": kt_src, "paper": PAPER_TABLE1[cfg],
            "loaded": int(np.sum(j.n0 > 0)), "active": int(np.sum((j.kn > 0) & (j.kt > 0))),
            "sum_n0": float(np.sum(j.n0)), "kn_eq": j.k_eq("kn"), "kt_eq": j.k_eq("kt"),
            "ran": cfg in ran})
    return rows


def table1_markdown(data: ReportData) -> list[str]:
    """Table 1 as Markdown lines."""
    rows = table1_rows(data)
    L = ["## Configurations (the paper's Table 1)", "",
         f"The joints this run computed, {len(data.area)} friction elements in all. \"loaded\": "
         "N0 > 0; \"in the dynamics\": k_n, k_t > 0 (the others carry no force and are left out). "
         "Paper columns: its Table 1 (smooth-ms is its Section 4 model).", "",
         "| configuration | surface Rq [µm] | normal load and gap | k_n | k_t | paper: load / k_n / k_t "
         "| loaded | in the dynamics | Σ N0 [N] | k_n,eq [N/mm³] | k_t,eq [N/mm³] | FRFs |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['config']} | {r['surface']} | {r['load']} | {r['kn_source']} | {r['kt_source']} "
                 f"| {' / '.join(r['paper'])} | {r['loaded']} | {r['active']} | {r['sum_n0']:.6g} "
                 f"| {r['kn_eq']:.4g} | {r['kt_eq']:.4g} | {'yes' if r['ran'] else 'no'} |")
    return L + [""]
