"""The jobs of the dynamics stage: configurations × excitation levels, the v3 fixed points, the Rq sweep.

Work is cut into *jobs* — one FRF of a fixed configuration at one level, or one v3 fixed point
(a full FRF, then short peak searches each followed by BEM loops on every element, then the full
FRF of the converged joint) — that the MPI ranks take from a shared queue, longest first
(:func:`fe_joint.study.queue.run_jobs`). Two follow-up kinds need a finished v3 fixed point and
are dealt once it is written (:class:`DynamicsQueue`): the comparison surface's v3 joint at the
other levels (``v3-level``), and its pass-0 FRF kept as the v2 curve at the middle level
(``v2-pass0``, no solve).

Each job has a cache *key*, the digest of everything it reads (:func:`job_key`): the reduced
model's matrices, the joint's arrays (loads, gaps, k_n, k_t), the level in N, the stuck
frequency, the sweep settings and μ; a v3 fixed point also its surface, the BEM interface and the
fixed-point settings. Rank 0 writes each finished job to ``dynamics/`` at once — its curves, then
``<job>.json`` (the key and the size and sha256 of every file) as the marker. A rerun keeps a job
whose marker has its key and whose files are intact, takes a job whose key is found under another
name (the levels were renumbered) by relabelling its curves, and reruns the rest, saying which
file was missing, truncated or changed (:func:`plan_jobs`). So adding a level or a configuration
runs only the new curves, and changing μ reruns every curve (all depend on it) but not the
contact stage.

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
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..model.joint import JointModel
from .configurations import LIKE_FOR_LIKE
from .artifacts import (BACKBONE_DIR, BackboneKey, CurveKey, check_files, digest, file_record,
                        load_artifact, load_curves, v3_job_name, v3_pass0_file)
from .contact import InterfaceSetup
from .fixed_point import run_v3
from .frf import CurveResult, SweepSettings, frf

#: bump when a job's result changes for the same inputs (its key changes with it); 2: a curve
#: keeps its contact harmonics at the peak (``CurveResult.peak_contact``, the speed stage's warm start)
JOB_VERSION = "2"
#: job kinds that need a finished v3 fixed point (dealt once it is written: DynamicsQueue.after)
FOLLOW_UP = ("v3-level", "v2-pass0")


@dataclass
class Job:
    """One unit of work.

    Attributes:
        kind: "curve" (a fixed configuration's FRF), "v3" (a fixed point), "v3-level" (the
            converged v3 joint of ``rq_um`` at another level) or "v2-pass0" (the pass-0 FRF of
            the v3 fixed point on ``rq_um``, kept as the v2 curve) or "backbone" (the nonlinear
            mode of a fixed configuration, or of v3 on surface ``rq_um``).
        config: configuration name.
        level_index: index into the study's levels (None: the small-excitation check).
        rq_um: the surface of a v3 fixed point, µm.
        key: cache key (:func:`job_key`; "" until set).
    """
    kind: str
    config: str
    level_index: int | None = 0
    rq_um: float | None = None
    key: str = ""

    @property
    def name(self) -> str:
        """File stem of the job's record (e.g. ``baseline@L1``, ``v3-rq10``, ``v3-rq10@L0``)."""
        if self.kind == "v3":
            return v3_job_name(self.rq_um)
        if self.kind == "backbone":
            return f"{BACKBONE_DIR}/{BackboneKey(self.config, self.rq_um).name}"
        return self.curve_keys[0].name

    @property
    def curve_keys(self) -> list[CurveKey]:
        """The study curves this job writes (none for a backbone)."""
        if self.kind == "backbone":
            return []
        if self.kind in ("v3", "v3-level"):
            return [CurveKey("v3", self.level_index, self.rq_um)]
        return [CurveKey(self.config, self.level_index)]

    @property
    def files(self) -> list[str]:
        """Every file the job writes into the dynamics folder, its marker ``<name>.json`` last."""
        if self.kind == "backbone":
            return [f"{self.name}.npz", f"{self.name}.csv", f"{self.name}.json"]
        out = [f"{k.name}.npz" for k in self.curve_keys]
        if self.kind == "v3":
            out += [f"{self.name}.arrays.npz", v3_pass0_file(self.rq_um)]
        return out + [f"{self.name}.json"]


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
    v3_out: dict = field(default_factory=dict)   # Rq → finished v3 fixed point (follow-up jobs)


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


def follow_up_jobs(case, levels: list) -> list[Job]:
    """The jobs that need a finished v3 fixed point: the comparison surface's v3 joint at the
    other levels (highest first) and its pass-0 FRF as the v2 curve at the middle level."""
    d, r = case.dynamics, case.roughness
    if "v3" not in d.configurations:
        return []
    mid = len(levels) // 2
    jobs = [Job(kind="v3-level", config="v3", level_index=i, rq_um=r.v_rq_um)
            for i in reversed(range(len(levels))) if i != mid]
    if "v2" in d.configurations:
        jobs.append(Job(kind="v2-pass0", config="v2", level_index=mid, rq_um=r.v_rq_um))
    return jobs


def full_pass0(case, rq_um: float) -> bool:
    """Whether the v3 fixed point on ``rq_um`` starts with a full sweep: only where its pass 0 is
    kept as the study's v2 curve (``v2-pass0``); elsewhere pass 0 only gives a peak, found by a
    local search (``fixed_point.run_v3``)."""
    return "v2" in case.dynamics.configurations and float(rq_um) == float(case.roughness.v_rq_um)


def rm_digest(rm) -> str:
    """Digest of what the FRFs read from the reduced model (matrices, pairs, DOFs, damping)."""
    return digest(np.asarray(rm.K), np.asarray(rm.M), np.asarray(rm.pair_dofs),
                  float(rm.damping_ratio), int(rm.excitation_dof), int(rm.response_dof))


def _setup_digest(s: InterfaceSetup) -> str:
    """Digest of what the v3 patch loops read from the interface setup."""
    return digest(s.pair_xy, s.area, s.n0_fe, s.gap_fe, s.p_s, s.g_s, s.side, s.patch, s.young,
                  s.poisson, s.ig.mask, s.ig.owner, s.ig.xc, s.ig.yc)


def _surface_digest(sc) -> str:
    """Digest of what a v3 fixed point reads from its surface (not the timings)."""
    return digest(sc.rq_um, sc.z, sc.n0, sc.gap_el, sc.kn, sc.kt_mindlin)


def job_key(inp: "StudyInputs", job: Job, rm_key: str, v3_keys: dict | None = None) -> str:
    """The cache key of ``job``: the digest of everything its result depends on.

    Args:
        inp: the study's inputs (for the small-excitation check: those with its level).
        job: the job.
        rm_key: :func:`rm_digest` of ``inp.rm`` (computed once per stage).
        v3_keys: Rq → key of the v3 fixed point (needed by the follow-up kinds).
    """
    level = float(inp.levels[0 if job.level_index is None else job.level_index])
    common = (JOB_VERSION, job.kind, rm_key, inp.settings, level)
    if job.kind == "curve":
        return digest(common, job.config, inp.joints[job.config], float(inp.f_lin[job.config]))
    if job.kind == "v3":
        c = inp.case.contact
        return digest(common, _setup_digest(inp.setup), _surface_digest(inp.surfaces[job.rq_um]),
                      float(c.kt_tol), int(c.kt_max_passes), full_pass0(inp.case, job.rq_um))
    return digest(common, (v3_keys or {})[job.rq_um])


def with_keys(inp: "StudyInputs", jobs: list[Job], rm_key: str,
              v3_keys: dict | None = None) -> list[Job]:
    """``jobs`` with their cache keys set (:func:`job_key`)."""
    return [replace(j, key=job_key(inp, j, rm_key, v3_keys)) for j in jobs]


def run_job(inp: StudyInputs, job: Job) -> dict:
    """Run one job; returns {"curves": {CurveKey: CurveResult}, "meta": {...}, "arrays": {...}}
    (a v3 fixed point also "pass0", its pass-0 CurveResult)."""
    level = inp.levels[0 if job.level_index is None else job.level_index]
    key = job.curve_keys[0]
    if job.kind == "curve":
        cr = frf(inp.rm, inp.joints[job.config], level, inp.f_lin[job.config], inp.settings)
        return {"curves": {key: cr.with_key(key)}, "meta": {}, "arrays": {}}
    if job.kind == "v3-level":
        # the converged joint of the fixed point on this surface, at another level
        v = inp.v3_out[job.rq_um]
        sc = inp.surfaces[job.rq_um]
        j3 = JointModel("v3", n0=sc.n0, gap=sc.gap_el, kn=v["kn"], kt=v["kt"],
                        area=inp.setup.area, rq_um=job.rq_um)
        return {"curves": {key: frf(inp.rm, j3, level, v["f_lin"], inp.settings).with_key(key)},
                "meta": {}, "arrays": {}}
    if job.kind == "v2-pass0":
        # pass 0 of the v3 fixed point is the v2 FRF at this level: kept, not run twice
        return {"curves": {key: inp.v3_out[job.rq_um]["pass0"].with_key(key)}, "meta": {},
                "arrays": {}}
    out = run_v3(inp, job.rq_um, level, full_first=full_pass0(inp.case, job.rq_um))
    meta = {"history": out["history"], "converged": out["converged"], "rq_um": job.rq_um,
            "f_lin": out["f_lin"]}
    return {"curves": {key: out["curve"].with_key(key)}, "meta": meta,
            "arrays": {"kn": out["kn"], "kt": out["kt"]}, "pass0": out["first"]}


def write_job(folder: Path, job: Job, r: dict) -> None:
    """Write one finished job's files (rank 0); the .json marks the job done and is written last.

    The marker holds the job, its key, its curves' names, the size and sha256 of each file and
    the job's meta data (a v3 fixed point's history).
    """
    folder = Path(folder)
    for key, cr in r["curves"].items():
        cr.save(folder / f"{key.name}.npz")
    if r["arrays"]:
        tmp = folder / f"{job.name}.arrays.tmp.npz"
        np.savez(tmp, **r["arrays"])
        tmp.replace(folder / f"{job.name}.arrays.npz")
    if r.get("pass0") is not None:
        r["pass0"].save(folder / v3_pass0_file(job.rq_um))
    files = file_record(folder, [folder / f for f in job.files[:-1]])
    marker = {"job": {**job.__dict__, "name": job.name}, "key": job.key,
              "curves": [k.name for k in r["curves"]], "files": files, **r["meta"]}
    tmp = folder / f"{job.name}.json.tmp"
    tmp.write_text(json.dumps(marker, default=float))
    tmp.replace(folder / f"{job.name}.json")


def read_marker(folder: Path, name: str) -> dict | None:
    """A job's marker, None if it is missing or unreadable."""
    try:
        m = json.loads((Path(folder) / f"{name}.json").read_text())
    except (OSError, ValueError):
        return None
    return m if isinstance(m, dict) and "key" in m and "files" in m else None


def _read_kn_kt(path: Path) -> dict:
    """A v3 fixed point's converged {"kn", "kt"} (N/mm³) from its ``.arrays.npz``."""
    with np.load(path) as a:
        return {"kn": a["kn"], "kt": a["kt"]}


def _load_job(folder: Path, job: Job, marker: dict) -> dict:
    """A finished job's result read back from its files (to be written under another name)."""
    old = Job(**{k: v for k, v in marker["job"].items() if k != "name"})
    curves = {}
    for k_old, k_new in zip(old.curve_keys, job.curve_keys):
        cr = load_artifact(folder / f"{k_old.name}.npz", CurveResult.load)
        curves[k_new] = cr.with_key(k_new)
    r = {"curves": curves, "arrays": {}, "meta": {k: marker[k] for k in
                                                 ("history", "converged", "rq_um", "f_lin")
                                                 if k in marker}}
    if old.kind == "v3":
        r["arrays"] = load_artifact(folder / f"{old.name}.arrays.npz", _read_kn_kt)
        r["pass0"] = load_artifact(folder / v3_pass0_file(old.rq_um), CurveResult.load)
    return r


def plan_jobs(folder: Path, jobs: list[Job], say=print) -> list[Job]:
    """Which keyed jobs must run; reuse finished ones, relabelled if the levels were renumbered.

    Rank 0 only. A job is kept when its marker has its key and every file it recorded is
    intact. A job whose key is found in another job's marker (the same curve under another
    level index) is written under its own name from those files. Every other job is to run;
    when a marker with the right key is there but a file is not, ``say`` gets one line naming
    it. Files of jobs no longer in the study are removed, so the folder holds this study only.

    Args:
        folder: the dynamics folder (created if missing).
        jobs: every job of the study, keys set.
        say: where the one-line messages go.
    Returns:
        the jobs to run, in the given order.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    markers = {}
    for f in sorted(folder.glob("*.json")):
        m = read_marker(folder, f.stem)
        if m is not None:
            markers[f.stem] = m
    by_key: dict[str, str] = {}
    for name, m in markers.items():
        by_key.setdefault(m["key"], name)
    todo, reuse = [], []
    for job in jobs:
        m = markers.get(job.name)
        # in place: same key and the same curve names (a v3 fixed point keeps its name when the
        # middle level is renumbered, its curve does not)
        if m is not None and m["key"] == job.key and m.get("curves") == [
                k.name for k in job.curve_keys]:
            why = check_files(folder, m["files"])
            if why is None:
                continue
            say(f"[fe-joint] dynamics: dynamics/{why}: recomputing {job.name}")
            todo.append(job)
            continue
        src = by_key.get(job.key)
        if src is not None and check_files(folder, markers[src]["files"]) is None:
            reuse.append((job, markers[src]))
        else:
            todo.append(job)
    # read every reused result before writing any: a new name may be an old job's
    loaded = [(job, _load_job(folder, job, m)) for job, m in reuse]
    keep = {f for job in jobs for f in job.files}
    for f in folder.iterdir():
        if f.is_file() and f.name not in keep:
            f.unlink()
    for job, r in loaded:
        write_job(folder, job, r)
    return todo


def v3_surfaces(case) -> list[float]:
    """The Rq (µm) of every v3 fixed point of the study (the sweep, and the comparison surface
    when v3 is compared), ascending."""
    d, r = case.dynamics, case.roughness
    return sorted(set(r.rq_um) | ({r.v_rq_um} if "v3" in d.configurations else set()))


def backbone_jobs(case) -> list[Job]:
    """One backbone per fixed configuration and per v3 surface, v3 first, and one per
    like-for-like joint when v1 and v2 are compared (they need the v3 fixed
    points' converged stiffnesses, so they run after the FRF jobs: :func:`run_backbone_job`)."""
    out = [Job(kind="backbone", config="v3", level_index=None, rq_um=rq) for rq in v3_surfaces(case)]
    out += [Job(kind="backbone", config=c, level_index=None)
            for c in case.dynamics.configurations if c != "v3"]
    # the like-for-like joints of v1 → v2 (issue 13, item 8): backbones only, no forced FRF
    if {"v1", "v2"} <= set(case.dynamics.configurations):
        out += [Job(kind="backbone", config=c, level_index=None) for c in LIKE_FOR_LIKE]
    return out


def dealing_order(jobs: list[Job], alts: list, n_levels: int, backbones: list[Job]) -> list:
    """The dynamics queue's jobs in the order it deals the ready ones: the v3 fixed points, their
    follow-ups (the v3 joint's top-level curve is long), the curves of the layer joints'
    parents (their lower levels first: short), the layer joints' backbones, the other top-level
    curves, the other curves from the top level down, the small-excitation check, the backbones.

    A layer joint's backbone is ready once its parent's curves at every level are written, and
    the stiff one is the longest job after the top-level curves (65-100 s on the default model).
    Dealt after every top-level curve and their parent's lower curves, it started at 234-239 s
    of 316-341 s queues (studies 21a-c, session 21) and once ended last, one rank idle for 20 s
    (21b: 99 s). Listed before the other top-level curves, it starts as soon as its parent's
    top-level curve is done (the queue deals the first ready job in this order; 21d: at 193 s),
    and the short jobs fill the queue's end.

    Args:
        jobs: the jobs to run (curves, v3 and follow-ups); alts: the layer joints' ``AltJob``s
            (``parent``: the configuration whose curves they need); n_levels: the study's levels;
            backbones: :func:`backbone_jobs`.
    """
    curves = sorted((j for j in jobs if j.kind == "curve"),
                    key=lambda j: -1 if j.level_index is None else j.level_index, reverse=True)
    parents = {a.parent for a in alts}
    check = [j for j in curves if j.level_index is None]
    top = [j for j in curves if j.level_index == n_levels - 1]
    lower = [j for j in curves if j not in top and j not in check]
    return ([j for j in jobs if j.kind == "v3"] + [j for j in jobs if j.kind in FOLLOW_UP]
            + [j for j in lower if j.config in parents] + [j for j in top if j.config in parents]
            + list(alts) + [j for j in top if j.config not in parents]
            + [j for j in lower if j.config not in parents] + check + list(backbones))


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
    # a like-for-like joint has no forced curve: its range covers the joints it lies between
    # (v1 and v2), since removing or adding closing elements moves its peak towards either
    configs = set(LIKE_FOR_LIKE.values()) if job.config in LIKE_FOR_LIKE else {job.config}
    curves = [cr for k, cr in load_curves(folder).items()
              if k.config in configs and k.level_index is not None
              and (k.rq_um == job.rq_um if job.config == "v3" else True)]
    if not curves:
        raise ValueError(f"backbone of {job.name}: no forced curve of that joint in {folder}")
    amp = {}
    for cr in curves:      # per joint, its curve at the highest level it was swept at
        if cr.config not in amp or cr.level > amp[cr.config][0]:
            amp[cr.config] = (cr.level, cr.peak_amplitude)
    return joint, f_lin, max(a * top / lv for lv, a in amp.values())


def plan_backbones(inp: StudyInputs, folder: Path, jobs: list[Job], rm_key: str) -> list[Job]:
    """Which backbone jobs must run (rank 0, after the FRF and v3 jobs have finished): a backbone
    whose record has the key of its inputs (:func:`.backbone.backbone_key` of
    :func:`backbone_plan`) and intact files is kept, as a curve is.

    Args:
        inp: the study's inputs.
        folder: the dynamics folder.
        jobs: the backbone jobs (:func:`backbone_jobs`).
        rm_key: :func:`rm_digest` of ``inp.rm``.
    Returns:
        the jobs to run, their keys set, in the given order.
    """
    from .backbone import backbone_key, is_cached
    todo = []
    for job in jobs:
        job = replace(job, key=backbone_key(rm_key, *backbone_plan(inp, folder, job), inp.levels,
                                            inp.settings))
        if not is_cached(folder, job.name, job.key):
            todo.append(job)
    return todo


def run_backbone_job(inp: StudyInputs, folder: Path, job: Job) -> dict:
    """Run one backbone job; returns {"backbone": BackboneResult}."""
    from .backbone import compute_backbone
    joint, f_lin, a_top = backbone_plan(inp, folder, job)
    key = BackboneKey(job.config, job.rq_um)
    return {"backbone": compute_backbone(key, inp.rm, joint, f_lin, a_top, inp.levels,
                                         inp.settings)}


def write_backbone_job(folder: Path, job: Job, r: dict) -> None:
    """Write a finished backbone (rank 0): ``backbones/<name>.npz``, ``.csv`` and the ``.json``
    record last (it marks the job done: its cache key and the size and sha256 of each file)."""
    br = r["backbone"]
    folder = Path(folder)
    sub = folder / BACKBONE_DIR
    sub.mkdir(exist_ok=True)
    br.save(folder / f"{job.name}.npz")
    br.write_csv(folder / f"{job.name}.csv")
    tmp = folder / f"{job.name}.json.tmp"
    tmp.write_text(json.dumps(
        {"job": {**job.__dict__, "name": job.name}, "key": job.key,
         "files": file_record(folder, [folder / f for f in job.files[:-1]]), "seconds": br.seconds,
         "points": int(br.omega.size), "newton_iterations": br.newton_iterations}, default=float))
    tmp.replace(folder / f"{job.name}.json")


def read_v3_output(folder: Path, rq: float) -> dict:
    """A finished v3 fixed point as its follow-up jobs read it: converged "kn", "kt", "f_lin" and
    the pass-0 curve "pass0" (any rank; the files are written before the job counts as done)."""
    name = v3_job_name(rq)
    rec = json.loads((Path(folder) / f"{name}.json").read_text())
    return {**load_artifact(Path(folder) / f"{name}.arrays.npz", _read_kn_kt), "f_lin": rec["f_lin"],
            "pass0": load_artifact(Path(folder) / v3_pass0_file(rq), CurveResult.load)}


class DynamicsQueue:
    """The dynamics stage's one job queue (:func:`~fe_joint.study.queue.run_jobs` callbacks):
    which jobs a job reads (:meth:`after`), its cache key where that needs their results
    (:meth:`prepare`), how it runs and how rank 0 writes it.

    Jobs: the FRF and v3 jobs (:class:`Job`, the small-excitation check with its own inputs), the
    backbones (:class:`Job` of kind "backbone", keyed once their forced curves exist, as
    :func:`plan_backbones` does) and the layer joints' backbones of the stiffness-definition
    study (``stiffness_definitions.AltJob``, planned into an ``AltTask``). Before session 8 these
    ran in five rounds, each waiting for the last job of the one before: on the default case
    one rank idled for about 55 s after the FRFs (the v3 joint's top-level curve ran alone) and
    for about 100 s at the end (the stiff layer joint's backbone).

    Args:
        inp, inp_tiny: the study's inputs, and those of the small-excitation check.
        folder: the dynamics folder.
        frf_jobs: every FRF and v3 job of the study, keyed (the cached ones too: they say which
            job writes which curve).
        alts: {AltJob: JointModel} of the layer joints (``stiffness_definitions.layer_joints``).
        rm_key: :func:`rm_digest` of the reduced model.
    """

    def __init__(self, inp: StudyInputs, inp_tiny: StudyInputs, folder: Path, frf_jobs: list,
                 alts: dict, rm_key: str) -> None:
        self.inp, self.inp_tiny, self.folder = inp, inp_tiny, Path(folder)
        self.alts, self.rm_key = alts, rm_key
        self.writers = [(k, j.name) for j in frf_jobs for k in j.curve_keys]

    def _writers(self, configs: set, rq_um: float | None = None) -> set:
        """Names of the jobs that write a forced curve of ``configs`` (v3: of surface rq_um)."""
        return {n for k, n in self.writers if k.config in configs and k.level_index is not None
                and (k.config != "v3" or k.rq_um == rq_um)}

    def after(self, job) -> set:
        """Names of the jobs whose files ``job`` reads."""
        from .stiffness_definitions import AltJob
        if isinstance(job, AltJob):
            return self._writers({job.parent}, job.rq_um)
        if job.kind in FOLLOW_UP:
            return {v3_job_name(job.rq_um)}
        if job.kind == "backbone":
            configs = set(LIKE_FOR_LIKE.values()) if job.config in LIKE_FOR_LIKE else {job.config}
            return self._writers(configs, job.rq_um)
        return set()

    def prepare(self, job):
        """Rank 0, its needs written: a backbone keyed (None when cached, as plan_backbones), a
        layer joint's backbone planned into an AltTask (None when cached); others as they are."""
        from . import stiffness_definitions as sd
        if isinstance(job, sd.AltJob):
            task = sd.alt_task(self.inp, load_curves(self.folder), job, self.alts[job], self.rm_key)
            return None if sd.alt_cached(self.folder, task) else task
        if job.kind == "backbone":
            return (plan_backbones(self.inp, self.folder, [job], self.rm_key) or [None])[0]
        return job

    def run(self, job) -> dict:
        """Run one job (any rank)."""
        from . import stiffness_definitions as sd
        if isinstance(job, sd.AltTask):
            return sd.run_alt(self.inp, job)
        if job.kind == "backbone":
            return run_backbone_job(self.inp, self.folder, job)
        if job.level_index is None:
            return run_job(self.inp_tiny, job)
        if job.kind in FOLLOW_UP and job.rq_um not in self.inp.v3_out:
            self.inp.v3_out[job.rq_um] = read_v3_output(self.folder, job.rq_um)
        return run_job(self.inp, job)

    def write(self, folder: Path, job, r: dict) -> None:
        """Write a finished job (rank 0)."""
        from . import stiffness_definitions as sd
        if isinstance(job, sd.AltTask):
            sd.write_alt(folder, job, r)
        elif job.kind == "backbone":
            write_backbone_job(folder, job, r)
        else:
            write_job(folder, job, r)
