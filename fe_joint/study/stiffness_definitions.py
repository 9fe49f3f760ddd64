"""The contact stiffness definitions the study uses, beside the alternatives (issue 13, items 3–4).

* **k_n: patch (default, the paper's) or layer.** The patch k_n is the flat-punch stiffness of the
  patch's contact set, bulk compliance included; the *layer* k_n removes the bulk of the patch
  (``contact_bem.layer_stiffness``, capped at ``LAYER_CAP`` × k_bulk in complete contact). The
  contact stage compares, per joint (smooth-ms, and v2 of every Rq): k_n mean / max over the
  loaded elements, k_n,eq, k_t,eq and the stuck breathing-mode frequency, written to
  ``contact/stiffness_definitions.json``. The layer joints keep their configuration's k_t rule
  (smooth-ms: k_t = k_n; v2: Mindlin's ratio × k_n).
* **k_t/k_n at reversal**: the stick (reversal) slope of every loaded element's patch at N0 over
  its k_n, per Rq, against Mindlin's 2(1−ν)/(2−ν): why v3 ≈ v2 (same file).
* **k_t from the loop at resonance** (dynamics stage, after the v3 fixed points): for every v3
  surface, at the converged joint's middle-level peak (cycle-mean N and tangential amplitude
  per element), k_t by the stick slope, the secant and the energy-equivalent Jenkins
  (``contact_bem.patch_loop_stiffness``) with their ratios to Mindlin's k_t at the same k_n →
  ``dynamics/stiffness_definitions/kt_definitions.json``.
* **Backbones of the alternative joints** (the cheap FRF comparison: SNMS peaks at the study's
  levels): ``smooth-ms-layer``, ``v2-layer`` (comparison surface), ``v3-secant`` and
  ``v3-energy`` (v3's converged k_n with that k_t, the comparison surface) →
  ``dynamics/stiffness_definitions/<name>.npz`` (:class:`~fe_joint.study.backbone.BackboneResult`).

The paper-literal definitions stay the study's: they are what the paper computes, and the
alternatives are reported beside them (one run shows both; the alternatives cost seconds).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from contact_bem import (LAYER_CAP, BulkStiffness, layer_stiffness, mindlin_ratio, patch_bulk_stiffness,
                         patch_loop_stiffness, patch_stiffness)

from ..model.joint import JointModel, stuck_modes
from .artifacts import BackboneKey, CurveKey, file_record, rq_label, v3_job_name
from .configurations import joint_v2
from .contact import InterfaceSetup, _gather_concat, _split, element_patches
from .queue import map_ranks
from .variants import statistics, stuck_frequency, write_json

#: the folder (under dynamics/) of the loop definitions and the alternative backbones
FOLDER = "stiffness_definitions"
#: caps of the layer stiffness (× k_bulk) whose smooth-ms stuck frequency is reported
CAP_SENSITIVITY = (10.0, 100.0, 1000.0)


def bulk_stiffness(setup: InterfaceSetup) -> BulkStiffness:
    """The bulk (whole patch in contact) stiffness of the element patches, N/mm³."""
    n = setup.patch
    return patch_bulk_stiffness((n, n), (setup.side / n,) * 2, setup.young, setup.poisson)


def layer_joint(joint: JointModel, bulk: BulkStiffness, kt_ratio: float, cap: float = LAYER_CAP,
                name: str | None = None) -> JointModel:
    """``joint`` with its k_n replaced by the layer stiffness and k_t = kt_ratio · k_n.

    Args:
        joint: a patch-k_n joint. bulk: the patches' bulk stiffness.
        kt_ratio: k_t/k_n of the configuration's rule (smooth-ms: 1; v2: Mindlin's ratio).
        cap: k_layer ≤ cap · k_bulk.
        name: the new joint's name (default ``<name>-layer``).
    """
    kn = layer_stiffness(joint.kn, bulk.k_n, cap)
    return JointModel(name or f"{joint.name}-layer", n0=joint.n0, gap=joint.gap, kn=kn,
                      kt=kt_ratio * kn, area=joint.area, rq_um=joint.rq_um)


def joint_numbers(joint: JointModel) -> dict:
    """k_n mean and max over the loaded elements, k_n,eq and k_t,eq of a joint (N/mm³)."""
    loaded = joint.kn > 0
    return {"kn_mean": float(joint.kn[loaded].mean()) if loaded.any() else 0.0,
            "kn_max": float(joint.kn.max()), "kn_eq": joint.k_eq("kn"), "kt_eq": joint.k_eq("kt"),
            "loaded_elements": int(loaded.sum())}


def reversal_ratio(setup: InterfaceSetup, sc, comm=None) -> np.ndarray:
    """k_t(reversal, along x)/k_n of every element's patch at N0 (NaN where k_n = 0)."""
    P = element_patches(setup, sc.z)
    sl = _split(len(sc.n0), comm)
    cell = (setup.side / setup.patch,) * 2
    loads = sc.n0 / setup.area * setup.side ** 2
    q = np.zeros((len(loads), 2))
    q[:, 0] = 1.0
    ps = patch_stiffness(P[sl], cell, setup.young, setup.poisson, 1.0, loads[sl], q[sl], secant=False)
    kn, kt = _gather_concat(ps.k_n, comm), _gather_concat(ps.k_t, comm)
    return np.where(kn > 0, kt / np.where(kn > 0, kn, 1.0), np.nan)


def _frequencies(rm, joints: dict, comm=None) -> dict:
    """Stuck breathing-mode frequency (Hz) of each joint: the first exactly, the rest by one
    shift-and-invert solve near it (``variants.stuck_frequency``), dealt to the ranks."""
    names = list(joints)
    f0 = stuck_modes(rm.K, rm.M, rm.pair_dofs, joints[names[0]]).frequency
    rest = map_ranks(lambda n: stuck_frequency(rm.K, rm.M, rm.pair_dofs, joints[n], f0), names[1:], comm)
    return dict(zip(names, [f0] + rest))


def contact_study(setup: InterfaceSetup, rm, surfaces: dict, kn_smooth: np.ndarray, comm=None) -> dict:
    """The contact stage's comparison of the k_n definitions and the reversal k_t/k_n per Rq.

    Returns:
        {"bulk": {kn, kt (N/mm³), kt_over_kn, patch_side_mm, cells}, "cap": LAYER_CAP,
         "mindlin_ratio", "joints": {name: numbers + stuck_hz}, "smooth_complete_share",
         "cap_sensitivity_hz": {cap: smooth-ms-layer stuck Hz},
         "reversal_ratio": {rq label: {"rq_um", "stats"}}}.
    """
    bulk = bulk_stiffness(setup)
    nu = setup.poisson
    smooth = JointModel("smooth-ms", n0=setup.n0_fe, gap=setup.gap_fe, kn=kn_smooth, kt=kn_smooth.copy(),
                        area=setup.area)
    joints = {"smooth-ms": smooth, "smooth-ms-layer": layer_joint(smooth, bulk, 1.0)}
    for rq in sorted(surfaces):
        v2 = joint_v2(setup, surfaces[rq], f"v2-rq{rq_label(rq)}")
        joints[v2.name] = v2
        joints[f"{v2.name}-layer"] = layer_joint(v2, bulk, mindlin_ratio(nu))
    f = _frequencies(rm, joints, comm)
    capped = map_ranks(lambda c: stuck_frequency(rm.K, rm.M, rm.pair_dofs,
                                                 layer_joint(smooth, bulk, 1.0, c), f["smooth-ms"]),
                       CAP_SENSITIVITY, comm)
    caps = {f"{c:g}": fc for c, fc in zip(CAP_SENSITIVITY, capped)}
    ratio = {}
    for rq in sorted(surfaces):
        r = reversal_ratio(setup, surfaces[rq], comm)
        ratio[rq_label(rq)] = {"rq_um": rq, "stats": statistics(r[np.isfinite(r)])}
    loaded = kn_smooth > 0
    complete = np.isclose(kn_smooth[loaded], bulk.k_n, rtol=1e-6)
    return {"bulk": {"kn": bulk.k_n, "kt": bulk.k_t, "kt_over_kn": bulk.k_t / bulk.k_n,
                     "patch_side_mm": setup.side, "cells": setup.patch},
            "cap": LAYER_CAP, "mindlin_ratio": mindlin_ratio(nu),
            "joints": {k: {**joint_numbers(j), "stuck_hz": f[k], "rq_um": j.rq_um}
                       for k, j in joints.items()},
            "smooth_complete_share": float(complete.mean()) if loaded.any() else 0.0,
            "cap_sensitivity_hz": caps, "reversal_ratio": ratio}


# ------------------------------------------------------------------------- dynamics stage part
def loop_definitions(setup: InterfaceSetup, sc, curve, mu: float, comm=None) -> dict:
    """k_t of every element by the three loop definitions at a peak's loads (collective).

    Args:
        setup: the interface. sc: the surface's SurfaceContact.
        curve: the CurveResult whose peak gives the cycle-mean N and the tangential amplitudes.
        mu: friction coefficient.
    Returns:
        {"kn", "kt_mindlin", "stick", "secant", "energy", "dissipation" (N·mm), "q" (N),
        "clipped"}: (ne,) arrays, k in N/mm³ (0 for elements without contact).
    """
    loaded = sc.n0 > 0
    n_mean = np.where(loaded, np.maximum(curve.mean_normal, 0.0), 0.0)
    scale = setup.side ** 2 / setup.area
    P = element_patches(setup, sc.z)
    sl = _split(len(n_mean), comm)
    cell = (setup.side / setup.patch,) * 2
    L = patch_loop_stiffness(P[sl], cell, setup.young, setup.poisson, mu, (n_mean * scale)[sl],
                             (curve.q_amp * scale[:, None])[sl])
    out = {k: _gather_concat(getattr(L, k), comm) for k in
           ("k_n", "stick", "secant", "energy", "dissipation", "force", "clipped")}
    out["kn"] = out.pop("k_n")
    out["q"] = out.pop("force") / scale       # back to the element's force
    out["dissipation"] = out["dissipation"] / scale
    out["kt_mindlin"] = mindlin_ratio(setup.poisson) * out["kn"]
    return out


def loop_statistics(d: dict, area: np.ndarray) -> dict:
    """Per definition: k_t/(Mindlin k_t) over the loaded elements (statistics) and k_t,eq."""
    live = d["kn"] > 0
    mind = d["kt_mindlin"]
    out = {"kt_eq_mindlin": float(np.sum(mind * area) / np.sum(area)),
           "kn_eq": float(np.sum(d["kn"] * area) / np.sum(area)),
           "clipped": int(np.sum(d["clipped"] & live))}
    for k in ("stick", "secant", "energy"):
        out[k] = {"kt_eq": float(np.sum(d[k] * area) / np.sum(area)),
                  "over_mindlin": statistics(d[k][live] / mind[live]),
                  "over_kn": statistics(d[k][live] / d["kn"][live])}
    return out


@dataclass(frozen=True)
class AltJob:
    """One alternative joint's backbone (``name`` = its BackboneKey's name; ``parent`` the
    configuration whose forced curves set its amplitude range)."""
    config: str
    rq_um: float | None
    parent: str

    @property
    def key(self) -> BackboneKey:
        return BackboneKey(self.config, self.rq_um)

    @property
    def name(self) -> str:
        return self.key.name


def layer_joints(inp, bulk: BulkStiffness) -> dict:
    """{AltJob: JointModel} of the layer alternatives whose parent configuration the study runs:
    they need only the parent's joint, not the v3 loops (the dynamics stage runs their backbones
    beside the FRFs, :func:`alt_task`)."""
    c = inp.case
    cfgs = c.dynamics.configurations
    out = {}
    if "smooth-ms" in cfgs:
        out[AltJob("smooth-ms-layer", None, "smooth-ms")] = layer_joint(
            inp.joints["smooth-ms"], bulk, 1.0, name="smooth-ms-layer")
    if "v2" in cfgs:
        out[AltJob("v2-layer", None, "v2")] = layer_joint(
            inp.joints["v2"], bulk, mindlin_ratio(c.material.poisson), name="v2-layer")
    return out


def alternative_joints(inp, loops: dict, v3: dict, bulk: BulkStiffness) -> dict:
    """{AltJob: JointModel} of the alternatives whose parent configuration the study runs."""
    c = inp.case
    cfgs, v_rq = c.dynamics.configurations, c.roughness.v_rq_um
    out = layer_joints(inp, bulk)
    if "v3" in cfgs and v_rq in loops and v_rq in v3:
        sc, v = inp.surfaces[v_rq], v3[v_rq]
        for k in ("secant", "energy"):
            # an element the loop found without load keeps v3's own k_t (never a zero spring)
            kt = np.where(v["kn"] > 0, np.where(loops[v_rq][k] > 0, loops[v_rq][k], v["kt"]), 0.0)
            out[AltJob(f"v3-{k}", v_rq, "v3")] = JointModel(
                f"v3-{k}", n0=sc.n0, gap=sc.gap_el, kn=v["kn"], kt=kt, area=inp.setup.area, rq_um=v_rq)
    return out


def top_peak(curves: dict, parent: str, rq_um: float | None, top_level: float) -> float:
    """The parent joint's forced peak amplitude (mm) at its highest swept level, scaled linearly
    to ``top_level`` (N): where the alternative backbone ends (as ``jobs.backbone_plan``). Without
    a curve of the parent, the largest such amplitude of any configuration (a wider range)."""
    forced = [(k, cr) for k, cr in curves.items() if k.level_index is not None]
    mine = [cr for k, cr in forced if k.config == parent and (parent != "v3" or k.rq_um == rq_um)]
    if not mine and not forced:
        raise ValueError(f"no forced curve for the alternative backbone of {parent}")
    if mine:
        hi = max(mine, key=lambda cr: cr.level)
        return hi.peak_amplitude * top_level / hi.level
    return max(cr.peak_amplitude * top_level / cr.level for _, cr in forced)


def _v3_arrays(folder: Path, case, comm) -> dict:
    """Rq → the finished v3 fixed point's converged {"kn", "kt"} (rank 0 reads, all get them)."""
    from .jobs import v3_surfaces
    out = None
    if comm is None or comm.rank == 0:
        out = {}
        for rq in v3_surfaces(case):
            f = Path(folder) / f"{v3_job_name(rq)}.arrays.npz"
            if f.exists():
                with np.load(f) as a:
                    out[rq] = {"kn": a["kn"], "kt": a["kt"]}
    return comm.bcast(out, root=0) if comm is not None else out


def dynamics_study(inp, folder: Path, comm=None, progress=None) -> dict:
    """The loop definitions on every v3 surface and the alternative joints' backbones (collective;
    the backbones run on the stage's job queue, rank 0 writes). A backbone whose cache key
    (:func:`.backbone.backbone_key`: reduced model, joint, stuck frequency, amplitude range, levels,
    settings) and file match what is on disk is kept, so a rerun computes only what changed.

    Args:
        inp: the dynamics stage's StudyInputs (after the v3 and FRF jobs have finished).
        folder: the dynamics folder (writes ``folder/FOLDER/``).
        comm: MPI communicator or None.
        progress: optional callable(job) after each backbone.
    Returns:
        {"surfaces": {rq label: :func:`loop_statistics`}, "backbones": [names], "joints": {name:
        parent, rq_um, kn_eq, kt_eq (N/mm³), stuck_hz}}.
    """
    from .artifacts import load_curves
    sub = Path(folder) / FOLDER
    mid = len(inp.levels) // 2
    curves = load_curves(folder) if (comm is None or comm.rank == 0) else None
    if comm is not None:
        curves = comm.bcast(curves, root=0)
    v3 = _v3_arrays(folder, inp.case, comm)
    loops = {rq: loop_definitions(inp.setup, inp.surfaces[rq], curves[CurveKey("v3", mid, rq)],
                                  inp.case.contact.mu, comm)
             for rq in sorted(v3) if CurveKey("v3", mid, rq) in curves}
    stats = {rq_label(rq): {"rq_um": rq, **loop_statistics(d, inp.setup.area)} for rq, d in loops.items()}
    alts = alternative_joints(inp, loops, v3, bulk_stiffness(inp.setup))
    if comm is None or comm.rank == 0:
        sub.mkdir(parents=True, exist_ok=True)
    # the layer joints' backbones are usually done already (the stage ran them beside the FRFs)
    plan = _run_backbones(inp, folder, alts, curves, comm, progress)
    joints = {job.name: {"parent": job.parent, "rq_um": job.rq_um, "kn_eq": j.k_eq("kn"),
                         "kt_eq": j.k_eq("kt"), "stuck_hz": plan[job.name][1]}
              for job, j in alts.items()}
    summary = {"surfaces": stats, "backbones": [j.name for j in alts], "joints": joints}
    if comm is None or comm.rank == 0:
        arrays = {rq_label(rq): {"rq_um": rq, **{k: np.asarray(v).tolist() for k, v in d.items()}}
                  for rq, d in loops.items()}
        write_json(sub / "kt_definitions.json", {"summary": summary, "arrays": arrays})
    return summary


@dataclass(frozen=True)
class AltTask:
    """An alternative backbone to compute: the job, its plan (joint, stuck frequency Hz, top
    amplitude mm) and its cache key (:func:`~.backbone.backbone_key`). ``name`` is the job's (the
    queue's bookkeeping; the files are ``stiffness_definitions/<name>.*`` under the dynamics
    folder)."""
    job: AltJob
    plan: tuple
    cache_key: str

    @property
    def name(self) -> str:
        return self.job.name


def alt_task(inp, curves: dict, job: AltJob, joint: JointModel, rm_key: str) -> AltTask:
    """The task of ``job``'s backbone, planned from the finished forced ``curves``."""
    from .backbone import backbone_key
    plan = (joint, stuck_modes(inp.rm.K, inp.rm.M, inp.rm.pair_dofs, joint).frequency,
            top_peak(curves, job.parent, job.rq_um, inp.levels[-1]))
    return AltTask(job, plan, backbone_key(rm_key, *plan, inp.levels, inp.settings))


def alt_cached(folder: Path, task: AltTask) -> bool:
    """Whether the task's backbone is on disk with its key (rank 0; ``folder`` the dynamics one)."""
    from .backbone import is_cached
    return is_cached(Path(folder) / FOLDER, task.job.name, task.cache_key)


def run_alt(inp, task: AltTask) -> dict:
    """Compute an alternative backbone: {"backbone": BackboneResult}."""
    from .backbone import compute_backbone
    joint, f_lin, a_top = task.plan
    return {"backbone": compute_backbone(task.job.key, inp.rm, joint, f_lin, a_top, inp.levels,
                                         inp.settings)}


def write_alt(folder: Path, task: AltTask, r: dict) -> None:
    """Write an alternative backbone (rank 0): ``<FOLDER>/<name>.npz`` and its ``.json`` record
    (key and file record) last; ``folder`` the dynamics one."""
    sub = Path(folder) / FOLDER
    sub.mkdir(parents=True, exist_ok=True)
    name = task.job.name
    r["backbone"].save(sub / f"{name}.npz")
    (sub / f"{name}.json").write_text(json.dumps(
        {"job": name, "parent": task.job.parent, "seconds": r["backbone"].seconds,
         "key": task.cache_key, "files": file_record(sub, [sub / f"{name}.npz"])}, default=float))


def _run_backbones(inp, folder: Path, alts: dict, curves: dict, comm, progress) -> dict:
    """Run the backbones of ``alts`` ({AltJob: JointModel}) not cached on the job queue; rank 0
    writes each (:func:`write_alt`). Returns {name: (joint, stuck Hz, top amplitude mm)}."""
    from .jobs import rm_digest
    from .queue import run_jobs
    rm_key = rm_digest(inp.rm)
    tasks = [alt_task(inp, curves, job, joint, rm_key) for job, joint in alts.items()]
    todo = [t for t in tasks if not alt_cached(folder, t)] if comm is None or comm.rank == 0 else []
    run_jobs(lambda t: run_alt(inp, t), write_alt, todo, Path(folder), comm, progress,
             skip_done=False)
    return {t.job.name: t.plan for t in tasks}


def files(folder: Path, summary: dict) -> list[Path]:
    """The files :func:`dynamics_study` wrote (for the stage manifest)."""
    sub = Path(folder) / FOLDER
    out = [sub / "kt_definitions.json"]
    for name in summary.get("backbones", []):
        out += [sub / f"{name}.npz", sub / f"{name}.json"]
    return out
