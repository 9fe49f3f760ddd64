"""``summary.json``: the run's numbers in one JSON dict (what ``scripts/compare_summaries.py`` reads),
and ``timings.json``: its wall times.

The summary holds no wall time, so the same case on the same number of ranks writes the same
bytes (README, "In parallel"); every time — per stage, per FE part, per surface, per curve, per v3
pass, per backbone, and the speed-against-error tables — is in ``timings.json``, which the
report's cost table reads."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..study.contact import contact_area
from .damping import damping_by_curve, slip_onsets
from .joint_state import interface_motions, joint_shear, stuck_modes_by_configuration
from ..study.artifacts import rq_label, v3_job_name
from ..study.frf import CurveResult
from . import like_for_like
from .backbones import backbones_section
from .stiffness_definitions import section as stiffness_definitions_section
from .data import STAGES_READ, ReportData
from .findings import findings, findings_summary
from .provenance import provenance
from .stiffness import configuration_joints, k_eq_table, rq_joints

#: the mesh statistics copied from the mesh stage
MESH_KEYS = ("n_nodes", "n_cells", "n_dofs", "n_pairs")


def curve_peak(cr: CurveResult) -> dict:
    """The peak of one FRF.

    Args:
        cr: the curve.
    Returns:
        level N, peak_hz Hz, peak_amplitude mm, dissipated N·mm per cycle, n_nonlinear and
        n_active elements, n_points (its wall time is in :func:`build_timings`), sweep_tol (the
        Newton tolerance its sweep ended at) and handover_hz (where it went on at a tighter one
        after thrashing at a fold, Hz), each None when unknown or none.
    """
    def known(v: float):
        return None if not np.isfinite(v) else float(v)
    return {"level": cr.level, "peak_hz": cr.peak_hz, "peak_amplitude": cr.peak_amplitude,
            "dissipated": cr.dissipated, "n_nonlinear": cr.n_nonlinear,
            "n_points": cr.n_points, "n_active": cr.n_active,
            "sweep_tol": known(cr.sweep_tol), "handover_hz": known(cr.handover_hz)}


def v3_section(data: ReportData) -> dict:
    """Per v3 fixed point (keyed by its record's file stem): converged, passes, per-pass history
    (without the passes' wall times: :func:`build_timings`)."""
    return {v3_job_name(rq): {"converged": r.get("converged"), "passes": len(r.get("history", [])),
                              "history": None if r.get("history") is None else
                              [{k: v for k, v in x.items() if k != "seconds"} for x in r["history"]]}
            for rq, r in sorted(data.v3_records.items())}


def run_warnings(data: ReportData) -> list[dict]:
    """The warnings the stages recorded in their manifests (``pipeline.guards.RunWarning`` as
    dicts: kind, subject, message, value, limit), in stage order."""
    return [dict(w) for s in STAGES_READ for w in (data.summaries.get(s) or {}).get("warnings", [])]


def build_timings(data: ReportData) -> dict:
    """``timings.json``: every wall time of the run, s.

    Returns:
        {"stages": per stage, "fe": the FE stage's parts, "contact": per surface its solves,
        "curves": per FRF curve, "v3": per fixed point the seconds of each pass, "backbones":
        per backbone, "queues": per stage with a job queue its {"seconds", "busy": each rank's
        share}, and "speed_vs_error": the speed-against-error tables (when the run has them)}.
    """
    fe, ct = data.summaries["fe"], data.summaries["contact"]
    out = {"stages": dict(data.stage_seconds), "fe": fe.get("timings", {}),
           "contact": {k: v.get("seconds") for k, v in ct.get("surfaces", {}).items()},
           "curves": {k.name: cr.seconds for k, cr in data.curves.items()},
           "v3": {v3_job_name(rq): [x.get("seconds") for x in r.get("history") or []]
                  for rq, r in sorted(data.v3_records.items())},
           "backbones": {k.name: br.seconds
                         for k, br in sorted(data.backbones.items(), key=lambda kv: kv[0].name)}}
    queues = {k: v["queue"] for k, v in data.summaries.items() if isinstance(v, dict) and v.get("queue")}
    if queues:      # the job queues' wall time and each rank's busy share
        out["queues"] = queues
    if data.speed:
        out["speed_vs_error"] = data.speed
    # commit, versions, ranks and dates: the same inputs at another time are the same numbers
    out["provenance"] = provenance(data)
    return out


def contact_areas(data: ReportData) -> dict:
    """Per Rq: the real contact area and its fractions of the usable overlap (ours), the whole
    overlap (the paper's) and the FE-loaded region (study.contact.ContactArea), and the peak
    pressure (MPa)."""
    mask, p_s = data.extra["mask"].astype(bool), data.extra["p_s"]
    out = {}
    for rq in data.rqs:
        sc = data.surfaces[rq]
        ca = contact_area(mask, data.cell_area, sc.pressure, p_s)
        out[rq_label(rq)] = {"real_mm2": ca.real, "usable_mm2": ca.usable, "overlap_mm2": ca.overlap,
                             "fe_loaded_mm2": ca.fe_loaded,
                             **{f"fraction_{k}": v for k, v in ca.fractions().items()},
                             "peak_pressure_MPa": float(sc.pressure.max())}
    return out


def seed_statistics(data: ReportData) -> dict:
    """Per Rq: mean/std/min/max over the realizations of the contact stage (contact/seeds.json)."""
    return {k: {"seeds": v["seeds"], **v["stats"]} for k, v in (data.seeds or {}).items()}


def build_summary(data: ReportData) -> dict:
    """The summary of a run.

    Args:
        data: the run's artifacts.
    Returns:
        JSON-able dict: frequencies in Hz, forces in N, stiffness in N/mm³, amplitudes in mm,
        contact fractions as fractions of the usable nominal area, times in s.
    """
    fe, ct, dyn = data.summaries["fe"], data.summaries["contact"], data.dynamics
    kn_smooth = data.extra["kn_smooth"]
    stuck = stuck_modes_by_configuration(data)
    motions = interface_motions(data, stuck)
    damping = damping_by_curve(data, stuck)
    peaks = {k.name: {**curve_peak(cr), **damping.get(k.name, {})} for k, cr in data.curves.items()}
    summary = {
        "case": data.case.name,
        "warnings": run_warnings(data),
        "mesh": {k: data.summaries["mesh"].get(k) for k in MESH_KEYS},
        "first_elastic_hz_full_free": (fe.get("full_elastic_hz") or [None])[0],
        "reduced_vs_full_max_rel_error": fe.get("max_rel_freq_error"),
        "stuck_frequency_hz": {**dyn["f_lin"], **({"v3": motions["v3"]["frequency_hz"]}
                                                  if "v3" in motions else {})},
        "levels_N": data.levels, "macroslip_estimate_N": data.macroslip,
        "levels_over_macroslip": [lv / data.macroslip for lv in data.levels],
        "contact_fraction": {rq_label(rq): data.surfaces[rq].contact_fraction for rq in data.rqs},
        "kn_smooth_mean": float(np.mean(kn_smooth)), "kn_smooth_max": float(np.max(kn_smooth)),
        "k_eq": k_eq_table(configuration_joints(data)),
        "k_eq_vs_rq": {rq_label(q): v for q, v in k_eq_table(rq_joints(data)).items()},
        "peaks": peaks,
        "structural_damping_ratio": data.rm.damping_ratio,
        "slip_onset_response_mm": slip_onsets(data, stuck),
        "contact_area": contact_areas(data),
        "material_hardness_MPa": data.case.roughness.material_hardness,
        "v3": v3_section(data),
        "joint_shear_top_level": joint_shear(data),
        "interface_motion": motions,
        "coupling_rel_error": ct.get("coupling_rel_error"),
        "linear_peak_rel_error": dyn.get("linear_peak_rel_error"),
    }
    if data.seeds:
        summary["seeds"] = seed_statistics(data)
    if data.hardness:
        summary["hardness_variant"] = data.hardness
    if data.backbones:
        summary["backbones"] = backbones_section(data)
    summary["like_for_like"] = like_for_like.section(data)
    summary["warnings"] += like_for_like.warnings(summary)
    summary["stiffness_definitions"] = stiffness_definitions_section(data)
    # last: the findings read the numbers above
    summary["findings"] = findings_summary(findings(data, summary))
    return summary


def write_summary(summary: dict, path: Path) -> Path:
    """Write ``summary`` (or the timings) as indented JSON (numpy scalars as floats); returns
    ``path``."""
    Path(path).write_text(json.dumps(summary, indent=1, default=float))
    return Path(path)
