"""The stages of ``fe-joint run``: thin functions that call the packages and write artifacts.

Each function takes a :class:`~fe_joint.pipeline.runner.StageContext`, runs on every MPI rank,
writes its artifacts on rank 0 and returns a small JSON-able summary (kept in the stage manifest
and read by the report). Only ``mesh`` and ``fe`` touch the FE package (dolfinx), and they import
it when they run, so the other stages — and ``fe-joint report`` — work without dolfinx.
"""
from __future__ import annotations

import json
import time

import numpy as np

from ..model.joint import remember_stuck_modes, stuck_modes
from ..model.reduced_model import ReducedModel
from ..study import contact as ms
from ..study import stiffness_definitions as stiff_defs
from ..study import variants
from ..study import jobs as study
from ..study.artifacts import (CurveKey, load_artifact, load_backbones, load_curves, read_json_artifact,
                               rq_label)
from ..study.configurations import (choose_levels, fixed_joints, joint_baseline,
                                    like_for_like_joints)
from ..study.frf import SweepSettings
from ..study.queue import map_ranks, run_jobs
from . import guards
from .runner import StageContext


def stage_mesh(ctx: StageContext) -> dict:
    """Build the gmsh resonator, load it into dolfinx, write mesh.xdmf, pairs.csv, geometry.png."""
    from ..fe.mesh import load_resonator
    from ..fe.output import write_mesh_artifacts
    fe = load_resonator(ctx.case.geometry, ctx.comm)
    stats = write_mesh_artifacts(fe, ctx.path("mesh"))
    ctx.print(f"[fe-joint] mesh: {stats.get('n_nodes')} nodes, {stats.get('n_cells')} cells, "
              f"{stats.get('n_pairs')} interface pairs")
    return stats


def stage_fe(ctx: StageContext) -> dict:
    """Bolt preload with smooth interface contact, free–free modes and Craig–Bampton → ReducedModel,
    on the mesh the mesh stage wrote (``mesh/resonator.npz``: not meshed again, so a rerun of this
    stage gives the same bits)."""
    from mpi4py import MPI

    from ..fe.mesh import load_resonator_file
    from ..fe.reduction import build_reduced_model_from_fe
    c = ctx.case
    comm = MPI.COMM_WORLD if ctx.comm is None else ctx.comm
    fe = load_artifact(ctx.path("mesh", "resonator.npz"),
                       lambda p: load_resonator_file(p, c.geometry, comm))
    rm = build_reduced_model_from_fe(fe, c.material, c.preload.bolt_force, c.reduction.damping_ratio,
                                     c.reduction.cutoff_hz, out_dir=str(ctx.path("fe")),
                                     n_full_elastic=c.reduction.n_check_modes + 2)
    full = np.asarray(rm.full_frequencies)
    red = np.asarray(rm.reduced_frequencies)
    fe_el = full[full > 1.0][: c.reduction.n_check_modes]
    rd_el = red[red > 1.0][: len(fe_el)]
    err = np.abs(rd_el - fe_el) / fe_el
    summary = {
        "n_reduced_dofs": int(rm.n_dofs), "n_pairs": int(rm.n_pairs), "n_boundary": int(rm.n_boundary),
        "bolt_force": float(np.sum(rm.preload_normal_force)),
        "closed_pairs": int(np.sum(rm.preload_status != 0)),
        "full_elastic_hz": fe_el.tolist(), "reduced_elastic_hz": rd_el.tolist(),
        "max_rel_freq_error": float(err.max()) if len(err) else None,
        "timings": {k: v for k, v in rm.metadata.get("timings", {}).items()},
        "ranks": int(comm.size),
    }
    ctx.print(f"[fe-joint] fe: {rm.n_dofs} reduced DOFs, {rm.n_pairs} pairs "
              f"({summary['closed_pairs']} closed), first elastic f = {fe_el[0]:.2f} Hz, "
              f"reduced vs full ≤ {summary['max_rel_freq_error']:.1e}")
    return summary


def _reduced_model(ctx: StageContext) -> ReducedModel:
    return load_artifact(ctx.path("fe", "reduced_model.h5"), lambda p: ReducedModel.load(str(p)))


def _surfaces(ctx: StageContext) -> tuple[dict, dict]:
    return load_artifact(ctx.path("contact", "surfaces.npz"), ms.load_surfaces)


def _surface_summary(s: ms.SurfaceContact) -> dict:
    return {"rq_um": s.rq_um, "contact_fraction": s.contact_fraction, "iterations": s.iterations,
            "kn_mean": float(np.mean(s.kn)), "kn_max": float(np.max(s.kn)),
            "load_scale": s.load_scale, "loaded_elements": int(np.sum(s.n0 > 0)), "seconds": s.seconds}


def stage_contact(ctx: StageContext) -> dict:
    """Rough contact: FE → BEM coupling check, global solve and element k_n for every surface."""
    c = ctx.case
    r = c.roughness
    rm = _reduced_model(ctx)
    setup = ms.interface_setup(rm, c.geometry, c.material, r)
    # zero roughness must give back the smooth FE pressure (equivalent macro gap)
    flat = ms.rough_contact(setup, 0.0, r.corr_length, r.seed, comm=ctx.comm, stiffness=False, tol=1e-12)
    coupling_err = float(np.abs(flat.pressure - setup.p_s).max() / setup.p_s.max())
    surfaces = {}
    for rq in sorted(set(r.rq_um) | {r.v_rq_um}):
        surfaces[rq] = ms.rough_contact(setup, rq, r.corr_length, r.seed, hardness=r.hardness,
                                        comm=ctx.comm)
        ctx.print(f"[fe-joint] contact: Rq = {rq_label(rq)} µm: contact fraction "
                  f"{100 * surfaces[rq].contact_fraction:.2f} %, {surfaces[rq].iterations} iterations, "
                  f"k_n mean {np.mean(surfaces[rq].kn):.3g} N/mm³")
    # smooth-ms: FE loads, k_n on patches of the nearly smooth realization
    t0 = time.perf_counter()
    z_smooth = ms.surface(setup, r.smooth_rq_um, r.corr_length, r.seed)
    kn_smooth = ms.element_normal_stiffness(setup, z_smooth, setup.n0_fe, comm=ctx.comm)
    t_smooth = time.perf_counter() - t0
    # seed statistics and the hardness-capped sweep (no FRFs; study/variants.py)
    t0 = time.perf_counter()
    own = variants.own_numbers(setup, rm, r, surfaces, comm=ctx.comm)
    seeds = variants.seed_study(setup, rm, r, surfaces, comm=ctx.comm, own=own)
    t_seeds = time.perf_counter() - t0
    t0 = time.perf_counter()
    capped = variants.hardness_study(setup, rm, r, surfaces, comm=ctx.comm, own=own)
    t_capped = time.perf_counter() - t0
    t0 = time.perf_counter()
    definitions = stiff_defs.contact_study(setup, rm, surfaces, kn_smooth, comm=ctx.comm)
    t_defs = time.perf_counter() - t0
    if ctx.rank == 0:
        ctx.path("contact").mkdir(parents=True, exist_ok=True)
        ms.save_surfaces(ctx.path("contact", "surfaces.npz"), surfaces, extra={
            "kn_smooth": kn_smooth, "p_s": setup.p_s, "g_s": setup.g_s, "mask": setup.ig.mask,
            "flat_pressure": flat.pressure})
        variants.write_json(ctx.path("contact", "seeds.json"), seeds)
        variants.write_json(ctx.path("contact", "hardness.json"), capped)
        variants.write_json(ctx.path("contact", "stiffness_definitions.json"), definitions)
    ctx.print(f"[fe-joint] contact: {r.seeds} seeds per Rq in {t_seeds:.1f} s, hardness-capped "
              f"sweep in {t_capped:.1f} s")
    return {
        "seeds_seconds": t_seeds, "hardness_seconds": t_capped, "definitions_seconds": t_defs,
        "coupling_rel_error": coupling_err, "pressure_interpolation_scale": setup.pressure_scale,
        "grid": r.grid, "patch": r.patch, "patch_side_mm": setup.side,
        "surfaces": {rq_label(rq): _surface_summary(s) for rq, s in surfaces.items()},
        "smooth": {"rq_um": r.smooth_rq_um, "kn_mean": float(np.mean(kn_smooth)),
                   "kn_max": float(np.max(kn_smooth)), "seconds": t_smooth},
    }


def _curve_summary(cr) -> dict:
    return {"config": cr.config, "level_index": cr.level_index, "rq_um": cr.key.rq_um,
            "level": cr.level, "peak_hz": cr.peak_hz, "peak_amplitude": cr.peak_amplitude,
            "dissipated": cr.dissipated, "n_active": cr.n_active, "n_nonlinear": cr.n_nonlinear,
            "n_points": cr.n_points, "seconds": cr.seconds,
            "status_counts": np.bincount(cr.status, minlength=5).tolist(),
            "unstable_points": int(np.sum(~cr.stable))}


def study_inputs(ctx: StageContext) -> tuple[study.StudyInputs, dict]:
    """What the dynamics stage's jobs read, from the fe and contact stages' artifacts: the
    reduced model, interface, surfaces, the fixed configurations' joints (and the like-for-like
    ones), their stuck frequencies and the excitation levels (``scripts/bench_preconditioner.py``
    uses it on a finished run). Collective (the stuck modes are shared out to the ranks).

    Returns:
        (StudyInputs, the level choice's information from :func:`choose_levels`).
    """
    c = ctx.case
    rm = _reduced_model(ctx)
    setup = ms.interface_setup(rm, c.geometry, c.material, c.roughness)
    surfaces, extra = _surfaces(ctx)
    joints = fixed_joints(setup, surfaces, extra["kn_smooth"], c)
    joints.update(like_for_like_joints(joints, c.material.poisson))   # backbones only (item 8)
    # one eigenproblem per joint (0.3 s at 2198 DOFs), dealt to the ranks and cached on every
    # rank (the jobs ask for them again)
    names = list(joints)
    lins = map_ranks(lambda n: stuck_modes(rm.K, rm.M, rm.pair_dofs, joints[n]), names, ctx.comm)
    for n, lin in zip(names, lins):
        remember_stuck_modes(rm.K, rm.M, rm.pair_dofs, joints[n], lin)
    f_lin = {n: lin.frequency for n, lin in zip(names, lins)}
    levels, level_info = choose_levels(rm, joints["baseline"], c)
    inp = study.StudyInputs(rm=rm, setup=setup, surfaces=surfaces, kn_smooth=extra["kn_smooth"],
                            joints=joints, levels=levels, f_lin=f_lin, case=c,
                            settings=SweepSettings.from_case(c))
    return inp, level_info


def stage_dynamics(ctx: StageContext) -> dict:
    """FRFs of every configuration and level, the v3 fixed point and the Rq sweep (HBM).

    Every job is cached on its own (:mod:`fe_joint.study.jobs`): only the jobs whose inputs
    changed, or whose files are missing or damaged, run. Warns where a result is suspect
    (:mod:`.guards`) and rejects a level absurdly beyond gross slip (exit 2) before any job runs.
    """
    c = ctx.case
    inp, level_info = study_inputs(ctx)
    rm, levels, f_lin = inp.rm, inp.levels, inp.f_lin
    # before any work: a level absurdly beyond gross slip is an input error, one beyond it a warning
    ctx.warn(guards.gross_slip_guard(levels, level_info["macroslip"], c.contact.mu,
                                     float(np.sum(inp.joints["baseline"].n0))))
    fe = ctx.summaries.get("fe") or {}
    if fe.get("full_elastic_hz"):
        ctx.warn(guards.cutoff_guard(fe["full_elastic_hz"], fe["reduced_elastic_hz"],
                                     c.reduction.cutoff_hz, c.dynamics.band[1] * max(f_lin.values())))
    folder = ctx.path("dynamics")
    # the small-excitation check: far below first slip the FRF peak is the stuck linear mode
    inp_tiny = study.StudyInputs(**{**inp.__dict__, "levels": [level_info["first_slip"] * 1e-3]})
    rm_key = study.rm_digest(rm)
    tiny = study.with_keys(inp_tiny, [study.Job(kind="curve", config="baseline", level_index=None)],
                           rm_key)
    first = study.with_keys(inp, study.jobs_for(c, levels), rm_key)
    v3_keys = {j.rq_um: j.key for j in first if j.kind == "v3"}
    later = study.with_keys(inp, study.follow_up_jobs(c, levels), rm_key, v3_keys)
    every = tiny + first + later
    todo = study.plan_jobs(folder, every, say=ctx.print) if ctx.rank == 0 else []
    if ctx.comm is not None:
        todo = ctx.comm.bcast(todo, root=0)
    names = {j.name for j in todo}
    ctx.print(f"[fe-joint] dynamics: levels {', '.join(f'{x:.3g}' for x in levels)} N "
              f"(macroslip estimate {level_info['macroslip']:.3g} N), {len(todo)} of "
              f"{len(every)} jobs to run ({len(every) - len(todo)} cached)")
    # one queue for every FRF, v3 and backbone job, each dealt once the jobs it reads are
    # written: the follow-up jobs after their v3 fixed point, a backbone after its joint's
    # forced curves (its cache key needs their peaks: keyed, or skipped when cached, just before
    # it is dealt), the layer joints' backbones (issue 13) after their parent's curves; longest
    # first among the ready ones (``jobs.dealing_order``)
    bb_jobs = study.backbone_jobs(c)
    alts = stiff_defs.layer_joints(inp, stiff_defs.bulk_stiffness(inp.setup))
    queue = study.dealing_order([j for j in every if j.name in names], list(alts), len(levels),
                                bb_jobs)
    bar = None
    if ctx.rank == 0 and ctx.progress and queue:
        from tqdm import tqdm
        bar = tqdm(total=len(queue), desc="dynamics", unit="job")
    tick = (lambda job: bar.update(1)) if bar is not None else None
    sched = study.DynamicsQueue(inp, inp_tiny, folder, every, alts, rm_key)
    t0 = time.perf_counter()
    schedule = run_jobs(sched.run, sched.write, queue, folder, ctx.comm, tick, skip_done=False,
                        after=sched.after, prepare=sched.prepare)
    queue_info = _queue_record(ctx, "dynamics", schedule, time.perf_counter() - t0)
    # the k_t definitions at the v3 peaks and the alternative joints' backbones (issue 13)
    t0 = time.perf_counter()
    defs = stiff_defs.dynamics_study(inp, folder, ctx.comm)
    defs["seconds"] = time.perf_counter() - t0
    if bar is not None:
        bar.close()
    ctx.files["dynamics"] = ([folder / f for j in every + bb_jobs for f in j.files]
                             + stiff_defs.files(folder, defs))
    summary: dict = {"levels": levels, "level_info": level_info, "f_lin": f_lin, "curves": {},
                     "v3": {}, "stiffness_definitions": defs, "queue": queue_info}
    if ctx.rank == 0:
        curves = load_curves(folder, sorted(k.name for j in every for k in j.curve_keys))
        summary["curves"] = {k.name: _curve_summary(cr) for k, cr in curves.items()}
        for j in first:
            if j.kind == "v3":
                summary["v3"][j.name] = read_json_artifact(folder / f"{j.name}.json")
        summary["backbones"] = {k.name: {"seconds": br.seconds, "points": int(br.omega.size),
                                         "snms_hz": br.snms_hz.tolist(),
                                         "snms_amplitude": br.snms_amplitude.tolist()}
                                for k, br in load_backbones(folder).items()}
        t = curves[CurveKey("baseline", None)]
        summary["linear_peak_rel_error"] = abs(t.peak_hz - f_lin["baseline"]) / f_lin["baseline"]
        warn = []
        for name, rec in summary["v3"].items():
            warn += guards.v3_guard(name, rec, c.contact.kt_tol)
        for k, cr in curves.items():
            warn += guards.unstable_guard(k.name, cr.omega_hz, cr.stable)
        for k, br in load_backbones(folder).items():
            warn += guards.backbone_guard(k.name, br.complete, float(br.displacement_amplitude[-1]),
                                          br.stop_reason)
        summary["warnings"] = [w.to_dict() for w in warn]
    if ctx.comm is not None:
        summary = ctx.comm.bcast(summary, root=0)
    ctx.warn([guards.RunWarning.from_dict(w) for w in summary.pop("warnings")])
    return summary


def _coarser_model(c, size: float) -> tuple:
    """The case's reduced model at lap mesh size ``size`` (mm), built by this rank alone (a row
    of the element-count table, a job of the speed stage's queue):
    (size, ReducedModel, FE seconds, baseline JointModel on it)."""
    return _coarser_tuple(c, size, *_coarser_reduced_model(c, size))


def _coarser_reduced_model(c, size: float) -> tuple:
    """:func:`_coarser_model`'s FE build: (ReducedModel, seconds).

    On this rank's own communicator, so that the two coarser models are built at once, one per
    rank, beside the stage's other rows: a 4.0 mm model took 29.9 s alone against 20.2 s on 2
    ranks, and the ranks had built the two one after the other (48 s of the 85 s stage). On one
    rank or two the model is the same serial build. On several ranks they are usually built
    ahead, while rank 0 runs the mesh, fe and contact stages alone (:func:`prepare_speed`).
    """
    import dataclasses

    from mpi4py import MPI

    from ..fe.mesh import load_resonator
    from ..fe.reduction import build_reduced_model_from_fe
    t0 = time.perf_counter()
    fe = load_resonator(dataclasses.replace(c.geometry, lap_mesh_size=size), MPI.COMM_SELF)
    rm = build_reduced_model_from_fe(fe, c.material, c.preload.bolt_force, c.reduction.damping_ratio,
                                     c.reduction.cutoff_hz, n_full_elastic=0)
    return rm, time.perf_counter() - t0


def _coarser_tuple(c, size: float, rm: ReducedModel, seconds: float) -> tuple:
    """(size, rm, FE seconds, the baseline joint on rm): what a row of the element-count table
    needs of its model."""
    return size, rm, seconds, joint_baseline(ms.interface_setup(rm, c.geometry, c.material, c.roughness),
                                             c.contact.k_ref)


#: the folder (under speed/) of the coarser FE models built ahead of the speed stage, and the
#: version of their build (bump it when ``_coarser_model`` changes)
COARSER_DIR, COARSER_VERSION = "models", "1"


def _coarser_files(ctx: StageContext, index: int, size: float) -> tuple:
    """The files of the ``index``-th coarser model (h5, json record) and the key of its inputs
    (the fe stage's key, which chains the mesh's, and the lap mesh size)."""
    import hashlib
    key = hashlib.sha256(f"{COARSER_VERSION}|{ctx.keys.get('fe', '')}|{size!r}".encode()).hexdigest()[:16]
    base = ctx.path("speed", COARSER_DIR, f"coarser-{index}")
    return base.with_suffix(".h5"), base.with_suffix(".json"), key


def _coarser_record(ctx: StageContext, index: int, size: float) -> dict | None:
    """The record of the ``index``-th coarser model when it names this run's key (else None)."""
    _, record, key = _coarser_files(ctx, index, size)
    try:
        rec = json.loads(record.read_text())
    except (OSError, ValueError):
        return None
    return rec if rec.get("key") == key else None


def _prebuilt_model(ctx: StageContext, index: int, size: float) -> tuple | None:
    """The ``index``-th coarser model as :func:`_coarser_model` returns it, from its files when
    they are there with this run's key and intact (else None)."""
    from ..study.artifacts import check_files
    rec = _coarser_record(ctx, index, size)
    if rec is None or check_files(ctx.out, rec.get("files", {"?": {}})) is not None:
        return None
    h5 = _coarser_files(ctx, index, size)[0]
    return _coarser_tuple(ctx.case, size, ReducedModel.load(str(h5)), float(rec["fe_seconds"]))


def _build_coarser(ctx: StageContext, index: int, size: float) -> None:
    """Build the ``index``-th coarser model on this rank alone and write its files (the h5, then
    the record naming its key, FE seconds and the h5's size and sha256)."""
    import os

    from ..study.artifacts import file_record
    h5, record, key = _coarser_files(ctx, index, size)
    rm, seconds = _coarser_reduced_model(ctx.case, size)
    h5.parent.mkdir(parents=True, exist_ok=True)
    tmp = h5.with_name(h5.name + ".tmp")
    rm.save(str(tmp))
    os.replace(tmp, h5)
    tmp = record.with_name(record.name + ".tmp")
    tmp.write_text(json.dumps({"key": key, "lap_mesh_size": size, "fe_seconds": seconds,
                               "files": file_record(ctx.out, [h5])}, indent=1))
    os.replace(tmp, record)


def prepare_speed(ctx: StageContext) -> list:
    """The speed stage's work that needs only the case, for ranks that would otherwise wait
    (``runner.SOLO_STAGES``): its coarser FE models not yet on disk, one task each
    (:func:`_build_coarser`; the stage reads them back, :func:`_prebuilt_model`). Collective:
    rank 0 looks at the files, every rank gets the same tasks."""
    c = ctx.case
    if not c.dynamics.speed_study:
        return []
    from ..study import speed_error as se
    sizes = se.lap_mesh_sizes(c.geometry.lap_mesh_size)
    todo = None
    if ctx.rank == 0:     # (the bytes are checked when the stage reads them)
        todo = [i for i, size in enumerate(sizes) if _coarser_record(ctx, i, size) is None
                or not _coarser_files(ctx, i, size)[0].exists()]
    todo = ctx.comm.bcast(todo, root=0) if ctx.comm is not None else todo
    if todo:
        # PETSc and SLEPc initialize collectively on COMM_WORLD: every rank imports the FE
        # package before the ranks part (rank 0 for its fe stage, the others for these builds)
        from ..fe import mesh, modal  # noqa: F401
    return [lambda i=i: _build_coarser(ctx, i, sizes[i]) for i in todo]


def _queue_record(ctx: StageContext, folder: str, schedule: list | None, wall: float) -> dict:
    """A stage's job queue: ``<folder>/schedule.json`` (each job's rank, start and end, s; rank
    0 writes it), a line on how busy the ranks were, and {"seconds", "busy"} for the summary
    (the same on every rank)."""
    from ..study.queue import busy_fractions
    ranks = 1 if ctx.comm is None else ctx.comm.size
    info = None
    if ctx.rank == 0:
        info = {"seconds": wall, "busy": busy_fractions(schedule, ranks, wall)}
        ctx.path(folder).mkdir(parents=True, exist_ok=True)
        tmp = ctx.path(folder, "schedule.json.tmp")
        tmp.write_text(json.dumps({**info, "jobs": schedule}, indent=1))
        tmp.replace(ctx.path(folder, "schedule.json"))
        ctx.print(f"[fe-joint] {folder}: job queue {wall:.1f} s, ranks busy "
                  + " / ".join(f"{100 * b:.0f} %" for b in info["busy"]))
    return ctx.comm.bcast(info, root=0) if ctx.comm is not None else info


def stage_speed(ctx: StageContext) -> dict:
    """Speed against error: BEM grid, HBM harmonics and samples, element count (skipped unless
    dynamics.speed_study).

    Every row is a job of the dynamics stage's MPI queue (both ranks busy; a killed stage keeps
    its finished rows in ``speed/rows``). Writes ``speed/speed_error.json`` ({table title:
    [rows]}); it never touches the study's curves.
    """
    c = ctx.case
    tables, queue_info = _speed_tables(ctx) if c.dynamics.speed_study else ({}, None)
    if ctx.rank == 0:
        ctx.path("speed").mkdir(parents=True, exist_ok=True)
        tmp = ctx.path("speed", "speed_error.json.tmp")
        tmp.write_text(json.dumps(tables, indent=1, default=float))
        tmp.replace(ctx.path("speed", "speed_error.json"))
    return {"tables": sorted(tables), "skipped": not c.dynamics.speed_study, "queue": queue_info}


def _speed_tables(ctx: StageContext) -> tuple[dict, dict]:
    """The speed stage's tables (rank 0; {} on the others), its rows computed by the job queue
    on every rank, and the queue's record (:func:`_queue_record`)."""
    from ..study import speed_error as se
    c = ctx.case
    rm = _reduced_model(ctx)
    settings = SweepSettings.from_case(c)
    levels = (ctx.summaries.get("dynamics") or {}).get("levels", [])
    grids = (64, 128, 256, 512) if c.roughness.grid >= 256 else (32, 64, c.roughness.grid * 2)
    key = CurveKey("baseline", len(levels) // 2)
    # the HBM and element-count tables compare against the study's baseline curve at the middle
    # level; without it (not in the study, or missing) only the BEM table is made, and the
    # coarser FE models are not built (every rank sees the same files)
    cr = (load_curves(ctx.path("dynamics"), [key.name])[key]
          if levels and ctx.path("dynamics", f"{key.name}.npz").exists() else None)
    hs = (1, 3, 5) if c.dynamics.harmonics <= 3 else (1, 3, 5, 7)
    knobs = se.knob_grid(hs) if cr is not None else None
    # the element-count table's models, the case's own last; the coarser ones are built by
    # their rows' jobs (None here)
    models: list = []
    if cr is not None:
        fe_s = float(((ctx.summaries.get("fe") or {}).get("timings") or {}).get("total_s", float("nan")))
        su = ms.interface_setup(rm, c.geometry, c.material, c.roughness)
        models = [None] * len(se.lap_mesh_sizes(c.geometry.lap_mesh_size)) + [
            (c.geometry.lap_mesh_size, rm, fe_s, joint_baseline(su, c.contact.k_ref))]
    jobs = se.speed_jobs(grids, knobs, len(models), (settings.harmonics, settings.samples))
    ref: dict = {}     # the reference peak, read from disk by the first row that needs it

    ranks = 1 if ctx.comm is None else ctx.comm.size

    def run(job: se.SpeedJob) -> dict:
        if job.peak_of:     # the case mesh's row: its FE model is the fe stage's
            fe_ranks = (ctx.summaries.get("fe") or {}).get("ranks", ranks)
            return {**se.own_fields(job, models), **({"FE ranks": fe_ranks} if job.table == "mesh" else {})}
        if job.table == "bem":
            return se.bem_row(rm, c, job.grid)
        if job.table == "mesh":     # a coarser mesh: its FE model built by one rank alone,
            size = se.lap_mesh_sizes(c.geometry.lap_mesh_size)[job.model]   # maybe ahead
            model = _prebuilt_model(ctx, job.model, size) or _coarser_model(c, size)
            return {**se.mesh_row(model, cr.level, settings), "FE ranks": 1}
        if job.table == "reference":
            return se.curve_reference(cr)
        if not ref:        # written before any row that needs it is dealt (after=)
            ref.update(se.read_reference(folder, se.read_rows(folder, jobs, stage_key)))
        return se.hbm_row(rm, models[-1][3], cr.level, settings, ref, job.harmonics, job.samples)

    folder, stage_key = ctx.path("speed", "rows"), ctx.keys.get("speed", "")
    if ctx.rank == 0:       # rows of another key (an earlier case) are not this stage's
        keep = se.read_rows(folder, jobs, stage_key)
        if se.REFERENCE in keep and se.read_reference(folder, keep)["guess"] is None \
                and "note" not in keep[se.REFERENCE]:
            keep.pop(se.REFERENCE)          # its guess is missing: run it again
        for f in folder.glob("*.json") if folder.exists() else []:
            if f.stem not in keep:
                f.unlink()
    # the harmonics and samples rows start from the reference's peak: dealt once it is written
    t0 = time.perf_counter()
    schedule = run_jobs(run, lambda fold, job, row: se.write_row(fold, job, row, stage_key), jobs,
                        folder, comm=ctx.comm,
                        after=lambda j: {se.REFERENCE} if j.needs_reference else set())
    queue_info = _queue_record(ctx, "speed", schedule, time.perf_counter() - t0)
    if ctx.rank != 0:
        return {}, queue_info
    out = se.assemble_tables(jobs, se.read_rows(folder, jobs, stage_key), hs[-1])
    return {f"global BEM grid (Rq = {rq_label(c.roughness.v_rq_um)} µm)": out.pop("bem"), **out}, queue_info


def stage_report(ctx: StageContext) -> dict:
    """Figures, report.md, summary.json, timings.json from the artifacts of the earlier stages
    (written by rank 0; the eigenproblems of the stuck joints shared by every rank)."""
    from ..report import write_report
    write_report(ctx.out, ctx.case, ctx.comm)
    ctx.print(f"[fe-joint] report: {ctx.path('report.md')}")
    return {"written": ["report.md", "summary.json", "timings.json", "figures"]}


REGISTRY = {"mesh": stage_mesh, "fe": stage_fe, "contact": stage_contact,
            "dynamics": stage_dynamics, "speed": stage_speed, "report": stage_report}
#: the stages' work that needs only the case (``runner.run_stages``' ``prepare``)
PREPARATIONS = {"speed": prepare_speed}
