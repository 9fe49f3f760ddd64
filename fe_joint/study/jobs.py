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
from .artifacts import CurveKey, v3_job_name
from .contact import InterfaceSetup
from .fixed_point import run_v3
from .frf import SweepSettings, frf


@dataclass
class Job:
    """One unit of work: a fixed-configuration FRF (``kind = "curve"``) or a v3 fixed point.

    Attributes:
        kind: "curve" or "v3".
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
        """File stem of the job's record (e.g. ``baseline@L1``, ``v3-rq10``)."""
        if self.kind == "v3":
            return v3_job_name(self.rq_um)
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
