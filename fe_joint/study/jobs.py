"""The jobs of the dynamics stage: configurations × excitation levels, the v3 fixed points, the Rq sweep.

Work is cut into *jobs* — one FRF of a fixed configuration at one level, or one v3 fixed point
(a full FRF, then short peak searches each followed by BEM loops on every element, then the full
FRF of the converged joint) — that the MPI ranks take from a shared queue, longest first
(:func:`fe_joint.study.queue.run_jobs`). Rank 0 writes each finished job to ``dynamics/<job>.npz`` at once: a killed
run loses at most the jobs in flight and a rerun skips every job whose file exists (the folder
is cleared when the stage's inputs change).

Excitation levels: the paper's 500/1000/2000 N do not transfer to this resonator (docs/design.md, "Excitation levels").
With ``levels = "auto"`` they are taken from the stuck-joint estimate of the baseline
(:func:`fe_joint.model.joint.slip_onset`): the excitations at which 10 % and 50 % of the loaded contact
area would slip if the joint stayed linear, and half the linear macroslip estimate (net tangential
force = μ·ΣN0). At the full estimate the quick model's rough configurations are in gross slip
(mass A moving ±9 mm, resonance 6 % down, outside any sensible band); at half of it the joint
slips extensively (resonance ≈ 2 % down). Friction damping caps the real response, so the
nonlinear model slips less than that; the report gives, per level, the slipping fraction the HBM
finds at resonance and the ratio of the level to the macroslip estimate. (Twice the middle level,
the paper's 1000 → 2000 N step, was tried as the top level: it did not make the sweeps cheaper —
the v3 curve needed 299 continuation points there against ≈ 145 at half the macroslip estimate.)
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model.joint import JointModel
from .artifacts import BACKBONE_DIR, BackboneKey, CurveKey, load_curves, v3_job_name
from .contact import InterfaceSetup
from .fixed_point import run_v3
from .frf import SweepSettings, frf


@dataclass
class Job:
    """One unit of work: a fixed-configuration FRF (``kind = "curve"``), a v3 fixed point, or a
    backbone (``kind = "backbone"``: a fixed configuration, or v3 on surface ``rq_um``).

    Attributes:
        kind: "curve", "v3" or "backbone".
        config: configuration name.
        level_index: index into the study's levels (None: the small-excitation check).
        rq_um: the surface of a v3 fixed point, µm.
    """
    kind: str
    config: str
    level_index: int | None = 0
    rq_um: float | None = None

    @property
    def name(self) -> str:
        """File stem of the job's record (e.g. ``baseline@L1``, ``v3-rq10``,
        ``backbones/v3-rq10``)."""
        if self.kind == "v3":
            return v3_job_name(self.rq_um)
        if self.kind == "backbone":
            return f"{BACKBONE_DIR}/{BackboneKey(self.config, self.rq_um).name}"
        return CurveKey(self.config, self.level_index).name


@dataclass
class StudyInputs:
    """What every job needs (identical on every rank)."""
    rm: object
    setup: InterfaceSetup
    surfaces: dict               # Rq (µm) → SurfaceContact
    kn_smooth: np.ndarray
    joints: dict                 # name → JointModel for the fixed configurations
    levels: list
    f_lin: dict                  # name → stuck linear frequency, Hz
    case: object
    settings: SweepSettings


def jobs_for(case, levels: list) -> list[Job]:
    """All jobs of the study, roughly longest first (the order in which ranks take them).

    The v3 fixed points are the longest (the one on the comparison surface also runs the other
    levels), then the FRFs from the highest level down: the cost of a curve grows steeply with
    the number of slipping elements.
    """
    d, r = case.dynamics, case.roughness
    mid = len(levels) // 2
    jobs: list[Job] = []
    # the Rq sweep (v3 at the middle level); the comparison surface joins it when v3 is compared
    rqs = set(r.rq_um) | ({r.v_rq_um} if "v3" in d.configurations else set())
    for rq in sorted(rqs, key=lambda q: (q != r.v_rq_um, q)):
        jobs.append(Job(kind="v3", config="v3", level_index=mid, rq_um=rq))
    for i in reversed(range(len(levels))):
        for cfg in d.configurations:
            if cfg == "v3" or (cfg == "v2" and i == mid and "v3" in d.configurations):
                continue   # v2 at the middle level is pass 0 of the v3 job on the same surface
            jobs.append(Job(kind="curve", config=cfg, level_index=i))
    return jobs


def run_job(inp: StudyInputs, job: Job) -> dict:
    """Run one job; returns {"curves": {CurveKey: CurveResult}, "meta": {...}, "arrays": {...}}."""
    level = inp.levels[0 if job.level_index is None else job.level_index]
    if job.kind == "curve":
        key = CurveKey(job.config, job.level_index)
        cr = frf(inp.rm, inp.joints[job.config], level, inp.f_lin[job.config], inp.settings)
        return {"curves": {key: cr.with_key(key)}, "meta": {}, "arrays": {}}
    out = run_v3(inp, job.rq_um, level)
    key = CurveKey("v3", job.level_index, job.rq_um)
    curves = {key: out["curve"].with_key(key)}
    meta = {"history": out["history"], "converged": out["converged"], "rq_um": job.rq_um,
            "f_lin": out["f_lin"]}
    if job.rq_um == inp.case.roughness.v_rq_um:
        # pass 0 on the comparison surface is the v2 FRF at this level: kept, not run twice
        if "v2" in inp.case.dynamics.configurations:
            k2 = CurveKey("v2", job.level_index)
            curves[k2] = out["first"].with_key(k2)
        # the v3 surface of the comparison also gets the other levels with its converged k
        sc = inp.surfaces[job.rq_um]
        j3 = JointModel("v3", n0=sc.n0, gap=sc.gap_el, kn=out["kn"], kt=out["kt"],
                        area=inp.setup.area, rq_um=job.rq_um)
        for i, lv in enumerate(inp.levels):
            if i != job.level_index:
                ki = CurveKey("v3", i, job.rq_um)
                curves[ki] = frf(inp.rm, j3, lv, out["f_lin"], inp.settings).with_key(ki)
    return {"curves": curves, "meta": meta, "arrays": {"kn": out["kn"], "kt": out["kt"]}}


def write_job(folder: Path, job: Job, r: dict) -> None:
    """Write one finished job's files (rank 0); the .json marks the job done and is written last."""
    for key, cr in r["curves"].items():
        cr.save(folder / f"{key.name}.npz")
    if r["arrays"]:
        np.savez(folder / f"{job.name}.arrays.npz", **r["arrays"])
    (folder / f"{job.name}.json").write_text(json.dumps(
        {"job": {**job.__dict__, "name": job.name}, "curves": [k.name for k in r["curves"]],
         **r["meta"]}, default=float))


def v3_surfaces(case) -> list[float]:
    """The Rq (µm) of every v3 fixed point of the study (the sweep, and the comparison surface
    when v3 is compared), ascending."""
    d, r = case.dynamics, case.roughness
    return sorted(set(r.rq_um) | ({r.v_rq_um} if "v3" in d.configurations else set()))


def backbone_jobs(case) -> list[Job]:
    """One backbone per fixed configuration and per v3 surface, v3 first (they need the v3 fixed
    points' converged stiffnesses, so they run after the FRF jobs: :func:`run_backbone_job`)."""
    out = [Job(kind="backbone", config="v3", level_index=None, rq_um=rq) for rq in v3_surfaces(case)]
    out += [Job(kind="backbone", config=c, level_index=None)
            for c in case.dynamics.configurations if c != "v3"]
    return out


def backbone_plan(inp: StudyInputs, folder: Path, job: Job):
    """The joint, its stuck frequency (Hz) and the top-level peak amplitude (mm) a backbone job
    needs, from the finished FRF and v3 jobs in ``folder``.

    The amplitude is the peak of the joint's forced curve at the highest level it was swept at,
    scaled linearly to the top level (a v3 surface off the comparison has only its middle-level
    curve): friction damping makes the real growth slower, so this covers the top level's peak.
    """
    top = inp.levels[-1]
    if job.config == "v3":
        rec = json.loads((folder / f"{v3_job_name(job.rq_um)}.json").read_text())
        with np.load(folder / f"{v3_job_name(job.rq_um)}.arrays.npz") as a:
            kn, kt = a["kn"], a["kt"]
        sc = inp.surfaces[job.rq_um]
        joint = JointModel("v3", n0=sc.n0, gap=sc.gap_el, kn=kn, kt=kt, area=inp.setup.area,
                           rq_um=job.rq_um)
        f_lin = float(rec["f_lin"])
    else:
        joint, f_lin = inp.joints[job.config], float(inp.f_lin[job.config])
    curves = [cr for k, cr in load_curves(folder).items()
              if k.config == job.config and k.level_index is not None
              and (k.rq_um == job.rq_um if job.config == "v3" else True)]
    if not curves:
        raise ValueError(f"backbone of {job.name}: no forced curve of that joint in {folder}")
    hi = max(curves, key=lambda cr: cr.level)
    return joint, f_lin, hi.peak_amplitude * top / hi.level


def run_backbone_job(inp: StudyInputs, folder: Path, job: Job) -> dict:
    """Run one backbone job; returns {"backbone": BackboneResult}."""
    from .backbone import compute_backbone
    joint, f_lin, a_top = backbone_plan(inp, folder, job)
    key = BackboneKey(job.config, job.rq_um)
    return {"backbone": compute_backbone(key, inp.rm, joint, f_lin, a_top, inp.levels,
                                         inp.settings)}


def write_backbone_job(folder: Path, job: Job, r: dict) -> None:
    """Write a finished backbone (rank 0): ``backbones/<name>.npz``, ``.csv`` and the ``.json``
    record last (it marks the job done)."""
    br = r["backbone"]
    sub = folder / BACKBONE_DIR
    sub.mkdir(exist_ok=True)
    br.save(folder / f"{job.name}.npz")
    br.write_csv(folder / f"{job.name}.csv")
    (folder / f"{job.name}.json").write_text(json.dumps(
        {"job": {**job.__dict__, "name": job.name}, "seconds": br.seconds,
         "points": int(br.omega.size), "newton_iterations": br.newton_iterations}, default=float))
