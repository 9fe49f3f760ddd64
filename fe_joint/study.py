"""The dynamics of the study: configurations × excitation levels, the v3 fixed point, the Rq sweep.

Work is cut into *jobs* — one FRF of a fixed configuration at one level, or one v3 fixed point
(a sequence of FRFs, each followed by BEM loops on every element) — that are dealt round-robin
to the MPI ranks. A job's results are gathered to rank 0, which writes them to
``dynamics/<job>.npz`` at once: a killed run loses at most the jobs in flight and a rerun skips
every job whose file exists (the folder is cleared when the stage's inputs change).

Excitation levels: the paper's 500/1000/2000 N do not transfer to this resonator (DESIGN §4.6).
With ``levels = "auto"`` they are taken from the stuck-joint estimate of the baseline
(:func:`fe_joint.joint.slip_onset`): the excitations at which 10 % and 50 % of the loaded contact
area would slip if the joint stayed linear, and half the linear macroslip estimate (net tangential
force = μ·ΣN0). At the full estimate the quick model's rough configurations are in gross slip
(mass A moving ±9 mm, resonance 6 % down, outside any sensible band); at half of it the joint
slips extensively (resonance ≈ 2 % down) and the sweep stays affordable. Friction damping caps the real response, so
the nonlinear model slips less than that; the report gives, per level, the slipping fraction the
HBM finds at resonance and the ratio of the level to the macroslip estimate.
"""
from __future__ import annotations

import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import multiscale as ms
from .dynamics import CurveResult, frf
from .joint import JointModel, slip_onset, stuck_modes

LEVEL_QUANTILES = (0.1, 0.5)
TOP_LEVEL_OF_MACROSLIP = 0.5
V3_RELAXATION = 0.5


@dataclass
class Job:
    """One unit of work: a fixed-configuration FRF or a v3 fixed point."""
    name: str                    # file stem, e.g. "baseline@L1" or "v3-rq10"
    kind: str                    # "curve" | "v3"
    config: str
    level_index: int = 0
    rq_um: float | None = None


@dataclass
class StudyInputs:
    """What every job needs (identical on every rank)."""
    rm: object
    setup: ms.InterfaceSetup
    surfaces: dict
    kn_smooth: np.ndarray
    joints: dict                 # name → JointModel for the fixed configurations
    levels: list
    f_lin: dict                  # name → stuck linear frequency, Hz
    case: object


def fixed_joints(setup: ms.InterfaceSetup, surfaces: dict, kn_smooth: np.ndarray, case) -> dict:
    """baseline, smooth-ms, v1, v2 (and the v2 start of every Rq's v3) as JointModels."""
    r, k_ref = case.roughness, case.contact.k_ref
    sv = surfaces[r.v_rq_um]
    joints = {
        "baseline": ms.joint_baseline(setup, k_ref),
        "smooth-ms": JointModel("smooth-ms", n0=setup.n0_fe, gap=setup.gap_fe, kn=kn_smooth,
                                kt=kn_smooth.copy(), area=setup.area, rq_um=r.smooth_rq_um),
        "v1": ms.joint_v1(setup, sv, k_ref),
        "v2": ms.joint_v2(setup, sv),
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


def jobs_for(case, levels: list) -> list[Job]:
    """All jobs of the study, v3 fixed points first (they are the longest)."""
    d, r = case.dynamics, case.roughness
    mid = len(levels) // 2
    jobs: list[Job] = []
    rqs = sorted(set(r.rq_um) | ({r.v_rq_um} if "v3" in d.configurations else set()))
    for rq in rqs:
        jobs.append(Job(name=f"v3-rq{rq:g}", kind="v3", config="v3", level_index=mid, rq_um=rq))
    for cfg in d.configurations:
        if cfg == "v3":
            continue
        for i in range(len(levels)):
            jobs.append(Job(name=f"{cfg}@L{i}", kind="curve", config=cfg, level_index=i))
    return jobs


def _frf(inp: StudyInputs, joint: JointModel, level: float, f_lin: float) -> CurveResult:
    d = inp.case.dynamics
    return frf(inp.rm, joint, level, inp.case.contact.mu, f_lin, tuple(d.band), d.harmonics,
               d.samples, d.max_points)


def run_v3(inp: StudyInputs, rq: float, level: float) -> dict:
    """The v3 fixed point on the surface of Rq = ``rq``: FRF → loads → BEM k_n, k_t → FRF …

    Pass 0 is v2 (k_t by Mindlin). Each further pass recomputes every loaded element's k_n at its
    cycle-mean normal load and k_t as the slope at load reversal of its patch's hysteresis loop
    under the tangential force amplitude at resonance (from the second update on, the new
    stiffnesses are averaged with the previous ones: under-relaxation). It stops when the peak
    frequency and amplitude change by less than ``contact.kt_tol``.

    Returns:
        dict with the final ``curve`` (CurveResult), ``joint`` arrays, per-pass history and
        ``converged``.
    """
    c = inp.case
    sc = inp.surfaces[rq]
    joint = ms.joint_v2(inp.setup, sc, name=f"v3-rq{rq:g}")
    history = []
    prev = None
    converged = False
    curve = None
    for p in range(c.contact.kt_max_passes + 1):
        t0 = time.perf_counter()
        lin = stuck_modes(inp.rm.K, inp.rm.M, inp.rm.pair_dofs, joint)
        curve = _frf(inp, joint, level, lin.frequency)
        change = (None if prev is None else
                  max(abs(curve.peak_hz - prev.peak_hz) / prev.peak_hz,
                      abs(curve.peak_amplitude - prev.peak_amplitude) / prev.peak_amplitude))
        history.append({"pass": p, "peak_hz": curve.peak_hz, "peak_amplitude": curve.peak_amplitude,
                        "f_lin": lin.frequency, "kn_eq": joint.k_eq("kn"), "kt_eq": joint.k_eq("kt"),
                        "change": change, "seconds": time.perf_counter() - t0})
        if change is not None and change < c.contact.kt_tol:
            converged = True
            break
        if p == c.contact.kt_max_passes:
            break
        prev = curve
        loaded = sc.n0 > 0
        n_mean = np.where(loaded, np.maximum(curve.mean_normal, 0.0), 0.0)
        kn, kt = ms.element_loop_stiffness(inp.setup, sc.z, n_mean, curve.q_amp, c.contact.mu)
        kn = np.where(loaded, kn, 0.0)
        kt = np.where(loaded, kt, 0.0)
        if p >= 1:
            # under-relaxation from the second update on: the plain iteration was seen to
            # oscillate (±1.5 % in peak amplitude on Rq = 15 µm), the averaged one settles
            kn = V3_RELAXATION * kn + (1 - V3_RELAXATION) * joint.kn
            kt = V3_RELAXATION * kt + (1 - V3_RELAXATION) * joint.kt
        joint = JointModel(joint.name, n0=sc.n0, gap=sc.gap_el, kn=kn, kt=kt, area=inp.setup.area,
                           rq_um=rq)
    return {"curve": curve, "kn": joint.kn, "kt": joint.kt, "history": history,
            "converged": converged, "f_lin": history[-1]["f_lin"]}


def run_job(inp: StudyInputs, job: Job) -> dict:
    """Run one job; returns {"curves": {name: CurveResult}, "meta": {...}, "arrays": {...}}."""
    level = inp.levels[job.level_index]
    if job.kind == "curve":
        cr = _frf(inp, inp.joints[job.config], level, inp.f_lin[job.config])
        return {"curves": {job.name: cr}, "meta": {}, "arrays": {}}
    out = run_v3(inp, job.rq_um, level)
    cr = out["curve"]
    curves = {f"{job.name}@L{job.level_index}": cr}
    meta = {"history": out["history"], "converged": out["converged"], "rq_um": job.rq_um,
            "f_lin": out["f_lin"]}
    # the v3 surface of the comparison also gets the other levels with its converged k
    if job.rq_um == inp.case.roughness.v_rq_um:
        sc = inp.surfaces[job.rq_um]
        j3 = JointModel("v3", n0=sc.n0, gap=sc.gap_el, kn=out["kn"], kt=out["kt"],
                        area=inp.setup.area, rq_um=job.rq_um)
        for i, lv in enumerate(inp.levels):
            if i != job.level_index:
                curves[f"{job.name}@L{i}"] = _frf(inp, j3, lv, out["f_lin"])
    return {"curves": curves, "meta": meta, "arrays": {"kn": out["kn"], "kt": out["kt"]}}


def run_jobs(inp: StudyInputs, jobs: list[Job], folder: Path, comm=None, progress=None) -> None:
    """Deal the jobs not yet on disk to the ranks; rank 0 writes each job's files as it arrives."""
    rank = comm.rank if comm is not None else 0
    size = comm.size if comm is not None else 1
    todo = [j for j in jobs if not (folder / f"{j.name}.json").exists()] if rank == 0 else None
    if comm is not None:
        todo = comm.bcast(todo, root=0)
    for start in range(0, len(todo), size):
        batch = todo[start:start + size]
        mine = batch[rank] if rank < len(batch) else None
        res = run_job(inp, mine) if mine is not None else None
        results = comm.gather(res, root=0) if comm is not None else [res]
        if rank == 0:
            for job, r in zip(batch, results):
                for name, cr in r["curves"].items():
                    cr.save(folder / f"{name}.npz")
                if r["arrays"]:
                    np.savez(folder / f"{job.name}.arrays.npz", **r["arrays"])
                # the .json marks the job done: written last
                (folder / f"{job.name}.json").write_text(json.dumps(
                    {"job": job.__dict__, "curves": list(r["curves"]), **r["meta"]}, default=float))
                if progress is not None:
                    progress(job)
        if comm is not None:
            comm.barrier()


def prepare_folder(folder: Path, key: str, rank: int, comm=None) -> None:
    """Make ``folder``; clear it if it holds results of other inputs (key mismatch)."""
    if rank == 0:
        kf = folder / "KEY"
        if folder.exists() and (not kf.exists() or kf.read_text() != key):
            shutil.rmtree(folder)
        folder.mkdir(parents=True, exist_ok=True)
        kf.write_text(key)
    if comm is not None:
        comm.barrier()
