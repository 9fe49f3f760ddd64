"""The dynamics of the study: configurations × excitation levels, the v3 fixed point, the Rq sweep.

Work is cut into *jobs* — one FRF of a fixed configuration at one level, or one v3 fixed point
(a full FRF, then short peak searches each followed by BEM loops on every element, then the full
FRF of the converged joint) — that the MPI ranks take from a shared queue, longest first
(:func:`run_jobs`). Rank 0 writes each finished job to ``dynamics/<job>.npz`` at once: a killed
run loses at most the jobs in flight and a rerun skips every job whose file exists (the folder
is cleared when the stage's inputs change).

Excitation levels: the paper's 500/1000/2000 N do not transfer to this resonator (DESIGN §4.6).
With ``levels = "auto"`` they are taken from the stuck-joint estimate of the baseline
(:func:`fe_joint.joint.slip_onset`): the excitations at which 10 % and 50 % of the loaded contact
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

import dataclasses
import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import multiscale as ms
from hbm import ConvergenceError

from .dynamics import CurveResult, frf, frf_with_peak, peak_near
from .joint import JointModel, slip_onset, stuck_modes

LEVEL_QUANTILES = (0.1, 0.5)
#: the top level as a fraction of the linear macroslip estimate
TOP_LEVEL_OF_MACROSLIP = 0.5
#: bounds of the Aitken relaxation factor of the v3 fixed point
V3_RELAX_MIN, V3_RELAX_MAX = 0.1, 1.5
#: the local peak search of a v3 pass starts this far (relative) above the predicted peak
PEAK_START_MARGIN = 1e-3


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
        jobs.append(Job(name=f"v3-rq{rq:g}", kind="v3", config="v3", level_index=mid, rq_um=rq))
    for i in reversed(range(len(levels))):
        for cfg in d.configurations:
            if cfg == "v3" or (cfg == "v2" and i == mid and "v3" in d.configurations):
                continue   # v2 at the middle level is pass 0 of the v3 job on the same surface
            jobs.append(Job(name=f"{cfg}@L{i}", kind="curve", config=cfg, level_index=i))
    return jobs


def _frf(inp: StudyInputs, joint: JointModel, level: float, f_lin: float) -> CurveResult:
    d = inp.case.dynamics
    return frf(inp.rm, joint, level, inp.case.contact.mu, f_lin, tuple(d.band), d.harmonics,
               d.samples, d.max_points)


def _aitken(x: np.ndarray, r: np.ndarray, r_prev: np.ndarray | None, w_prev: float) -> float:
    """Aitken's dynamic relaxation factor for the fixed point x ← x + ω r (r = F(x) − x).

    ω_k = −ω_{k−1} r_{k−1}·(r_k − r_{k−1}) / |r_k − r_{k−1}|², the secant estimate of the
    optimal step along the last two residuals (Irons–Tuck; Küttler & Wall 2008 for coupled
    problems): it damps an oscillating iteration and lengthens the steps of a creeping one.
    The first update is plain (ω = 1); ω is kept in [V3_RELAX_MIN, V3_RELAX_MAX].
    """
    if r_prev is None:
        return 1.0
    d = r - r_prev
    dd = float(d @ d)
    if dd == 0.0:
        return w_prev
    return float(np.clip(-w_prev * float(r_prev @ d) / dd, V3_RELAX_MIN, V3_RELAX_MAX))


def run_v3(inp: StudyInputs, rq: float, level: float) -> dict:
    """The v3 fixed point on the surface of Rq = ``rq``: FRF → loads → BEM k_n, k_t → FRF …

    Pass 0 is v2 (k_t by Mindlin), a full FRF. Each further pass recomputes every loaded
    element's k_n at its cycle-mean normal load and k_t as the slope at load reversal of its
    patch's hysteresis loop under the tangential force amplitude at resonance, relaxed by
    Aitken's factor (the plain iteration was seen to oscillate, ±1.5 % in peak amplitude on
    Rq = 15 µm, and a fixed factor 0.5 to creep, 5–6 passes), and finds the new peak by a short
    continuation from the previous one (:func:`~fe_joint.dynamics.peak_near`; a full sweep if
    that fails). It stops when the peak frequency and amplitude change by less than
    ``contact.kt_tol``; the converged joint then gets its full FRF (whose polished peak is the
    last pass's, recorded in the history as a check).

    Returns:
        dict with the final ``curve`` (CurveResult), the pass-0 curve ``first``, ``kn``, ``kt``,
        per-pass ``history``, ``converged`` and ``f_lin``.
    """
    c = inp.case
    d = c.dynamics
    sc = inp.surfaces[rq]
    loaded = sc.n0 > 0
    joint = ms.joint_v2(inp.setup, sc, name=f"v3-rq{rq:g}")
    history = []
    prev = first = None
    converged = False
    state = r_prev = None
    relax = 1.0
    for p in range(c.contact.kt_max_passes + 1):
        t0 = time.perf_counter()
        lin = stuck_modes(inp.rm.K, inp.rm.M, inp.rm.pair_dofs, joint)
        search, why = "sweep", None
        if p > 0:
            try:
                # the peak moves about as the stuck frequency does; start just above it
                f_start = (prev.peak_hz * lin.frequency / history[-1]["f_lin"]
                           * (1 + PEAK_START_MARGIN))
                curve, state = peak_near(inp.rm, joint, level, c.contact.mu, f_start, state,
                                         d.harmonics, d.samples)
                search = "local"
            except ConvergenceError as e:
                why = " ".join(str(e).split())
        if search == "sweep":
            curve, state = frf_with_peak(inp.rm, joint, level, c.contact.mu, lin.frequency,
                                         tuple(d.band), d.harmonics, d.samples, d.max_points)
        if p == 0:
            first = curve
        change = (None if prev is None else
                  max(abs(curve.peak_hz - prev.peak_hz) / prev.peak_hz,
                      abs(curve.peak_amplitude - prev.peak_amplitude) / prev.peak_amplitude))
        history.append({"pass": p, "peak_hz": curve.peak_hz, "peak_amplitude": curve.peak_amplitude,
                        "f_lin": lin.frequency, "kn_eq": joint.k_eq("kn"), "kt_eq": joint.k_eq("kt"),
                        "change": change, "search": search, "local_failed": why, "points": curve.n_points,
                        "seconds": time.perf_counter() - t0})
        if change is not None and change < c.contact.kt_tol:
            converged = True
            break
        if p == c.contact.kt_max_passes:
            break
        prev = curve
        n_mean = np.where(loaded, np.maximum(curve.mean_normal, 0.0), 0.0)
        kn_new, kt_new = ms.element_loop_stiffness(inp.setup, sc.z, n_mean, curve.q_amp, c.contact.mu)
        # Aitken-relaxed update on the elements in contact at the mean load; an element the
        # BEM finds out of contact leaves the joint (as the plain update would)
        keep = loaded & (kn_new > 0) & (kt_new > 0)
        x = np.concatenate([joint.kn[keep], joint.kt[keep]])
        r = np.concatenate([kn_new[keep], kt_new[keep]]) - x
        if r_prev is not None and r_prev.shape != r.shape:
            r_prev = None
        relax = _aitken(x, r, r_prev, relax)
        r_prev = r
        # a relaxed step keeps every stiffness positive (ω ≤ V3_RELAX_MAX may extrapolate)
        x = np.maximum(x + relax * r, 0.1 * x)
        history[-1]["relaxation"] = relax
        kn, kt = np.zeros_like(joint.kn), np.zeros_like(joint.kt)
        kn[keep], kt[keep] = x[:keep.sum()], x[keep.sum():]
        joint = JointModel(joint.name, n0=sc.n0, gap=sc.gap_el, kn=kn, kt=kt, area=inp.setup.area,
                           rq_um=rq)
    final = curve
    if search == "local":
        final = _frf(inp, joint, level, lin.frequency)
        history[-1]["sweep_peak_hz"] = final.peak_hz
        history[-1]["sweep_peak_amplitude"] = final.peak_amplitude
    return {"curve": final, "first": first, "kn": joint.kn, "kt": joint.kt, "history": history,
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
    if job.rq_um == inp.case.roughness.v_rq_um:
        # pass 0 on the comparison surface is the v2 FRF at this level: kept, not run twice
        if "v2" in inp.case.dynamics.configurations:
            curves[f"v2@L{job.level_index}"] = dataclasses.replace(out["first"], config="v2")
        # the v3 surface of the comparison also gets the other levels with its converged k
        sc = inp.surfaces[job.rq_um]
        j3 = JointModel("v3", n0=sc.n0, gap=sc.gap_el, kn=out["kn"], kt=out["kt"],
                        area=inp.setup.area, rq_um=job.rq_um)
        for i, lv in enumerate(inp.levels):
            if i != job.level_index:
                curves[f"{job.name}@L{i}"] = _frf(inp, j3, lv, out["f_lin"])
    return {"curves": curves, "meta": meta, "arrays": {"kn": out["kn"], "kt": out["kt"]}}


def _write_job(folder: Path, job: Job, r: dict) -> None:
    """Write one finished job's files (rank 0); the .json marks the job done and is written last."""
    for name, cr in r["curves"].items():
        cr.save(folder / f"{name}.npz")
    if r["arrays"]:
        np.savez(folder / f"{job.name}.arrays.npz", **r["arrays"])
    (folder / f"{job.name}.json").write_text(json.dumps(
        {"job": job.__dict__, "curves": list(r["curves"]), **r["meta"]}, default=float))


def _attempt(inp: StudyInputs, job: Job) -> tuple[dict | None, tuple | None]:
    """run_job, with a failure turned into (job, exit code, message) that can cross ranks."""
    from .errors import classify
    try:
        return run_job(inp, job), None
    except Exception as e:  # noqa: BLE001 - reported on every rank by run_jobs
        code, msg = classify(e)
        return None, (job.name, code, msg, e)


_TAG = 77
#: how often rank 0's queue server looks for requests, s (jobs take 5–600 s)
POLL_SECONDS = 0.05


def run_jobs(inp: StudyInputs, jobs: list[Job], folder: Path, comm=None, progress=None) -> None:
    """Run the jobs not yet on disk, dealt dynamically to the ranks, longest first.

    Jobs differ in cost by 50× (a v3 fixed point vs a low-level FRF), so a static deal leaves
    ranks idle. Rank 0 works through the queue too; a server thread on rank 0 (MPI_THREAD_MULTIPLE)
    hands the next job to any rank that asks and writes each result as it arrives, so a killed
    run loses only the jobs in flight. Jobs are deterministic: which rank runs one does not change
    its result. A failed job stops the handing out; every rank then raises
    :class:`~fe_joint.errors.JobFailed` with the original's exit class.
    """
    from .errors import JobFailed
    rank = comm.rank if comm is not None else 0
    size = comm.size if comm is not None else 1
    todo = [j for j in jobs if not (folder / f"{j.name}.json").exists()] if rank == 0 else None
    if comm is not None:
        todo = comm.bcast(todo, root=0)
    failure = None
    if size == 1:
        for job in todo:
            r, failure = _attempt(inp, job)
            if failure is not None:
                break
            _write_job(folder, job, r)
            if progress is not None:
                progress(job)
    elif rank == 0:
        failure = _serve_and_work(inp, todo, folder, comm, progress)
    else:
        msg = ("ask", None, None, None)
        while True:
            comm.send(msg, dest=0, tag=_TAG)
            job = comm.recv(source=0, tag=_TAG)
            if job is None:
                break
            r, fail = _attempt(inp, job)
            msg = ("result", job, r, None) if fail is None else ("failed", job, None, fail[:3])
    if comm is not None:
        if rank != 0:
            failure = None
        info = comm.bcast(None if failure is None else failure[:3], root=0)
        comm.barrier()
    else:
        info = None if failure is None else failure[:3]
    if info is not None:
        own = failure[3] if failure is not None and len(failure) > 3 else None
        raise JobFailed(*info) from own


def _serve_and_work(inp: StudyInputs, todo: list[Job], folder: Path, comm, progress):
    """Rank 0: hand out jobs from a thread while working through the same queue."""
    import threading
    from collections import deque
    queue = deque(todo)
    lock = threading.Lock()
    state = {"failure": None}

    def next_job():
        with lock:
            return queue.popleft() if queue and state["failure"] is None else None

    def finished(job, r, fail):
        with lock:
            if fail is not None:
                if state["failure"] is None:
                    state["failure"] = fail
                return
            _write_job(folder, job, r)
            if progress is not None:
                progress(job)

    def serve():
        from mpi4py import MPI
        working = comm.size - 1
        while working:
            st = MPI.Status()
            # Open MPI's blocking receive busy-polls: in this thread it would take a core from
            # the ranks' work (it halved their speed on 2 cores). Probe, and sleep in between.
            while not comm.Iprobe(source=MPI.ANY_SOURCE, tag=_TAG, status=st):
                time.sleep(POLL_SECONDS)
            kind, job, r, fail = comm.recv(source=st.Get_source(), tag=_TAG)
            if kind in ("result", "failed"):
                finished(job, r, fail)
            nxt = next_job()
            comm.send(nxt, dest=st.Get_source(), tag=_TAG)
            if nxt is None:
                working -= 1

    server = threading.Thread(target=serve, name="fe-joint-jobs", daemon=True)
    server.start()
    while (job := next_job()) is not None:
        r, fail = _attempt(inp, job)
        finished(job, r, fail)
    server.join()
    return state["failure"]


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
