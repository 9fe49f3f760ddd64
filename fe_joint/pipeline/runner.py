"""Stage runner: input-hash caching, verified artifacts, resumable runs and the stage log.

A run is a fixed sequence of stages. Each stage depends on some case sections and on the stages
before it; its *key* is the hash of those sections, the upstream keys and the stage's code
version. When a stage finishes, it writes ``DIR/stages/<stage>.json`` (key, seconds, summary,
warnings, and the files it wrote with their size and sha256) — after its artifacts, so a killed
run never leaves a manifest for half-written output. A rerun skips a stage only if its manifest
key matches, it was computed from the current output of the stage before it, and every file it
recorded is still there with the same size and content (``cached`` in the log); otherwise it
says which file is missing, truncated or changed and reruns the stage (and so everything after
it). Every action is appended to ``DIR/stage_log.jsonl``, which is also how the tests check that
finished stages are not recomputed.

All MPI ranks call :func:`run_stages`; only rank 0 checks files, writes manifests and the log.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..case import Case, case_to_toml
from ..study.artifacts import check_files, file_record
from .environment import run_environment
from .guards import RunWarning

#: the dynamics settings the study's curves depend on (not ``speed_study``: the speed stage's switch)
_DYNAMICS_CURVES = tuple(f"dynamics.{k}" for k in
                         ("harmonics", "samples", "levels", "band", "max_points", "configurations"))

#: stage name → (the case inputs it reads: "section" or "section.key", code version; bump the
#: version when a stage's output changes). A stage's key also chains the key of the stage before.
STAGE_INPUTS: dict[str, tuple[tuple[str, ...], str]] = {
    # 2: writes mesh/resonator.npz, the mesh the fe stage reads
    "mesh": (("geometry",), "2"),
    # preload and Craig–Bampton share the interface condensation (one factorization), so they
    # are one stage: splitting them would factorize the 60k-DOF stiffness twice
    "fe": (("geometry", "material", "preload", "reduction"), "1"),
    # the BEM grid spans the overlap (geometry) and uses the elastic constants (material)
    "contact": (("geometry", "material", "roughness"), "4"),
    "dynamics": (("geometry", "material", "roughness", "contact") + _DYNAMICS_CURVES, "8"),
    "speed": (("geometry", "material", "roughness", "contact", "dynamics"), "4"),
    # the report reads every section (titles, tables, the paper comparison)
    "report": (("geometry", "material", "preload", "reduction", "roughness", "contact",
                "dynamics"), "3"),
}
STAGES: tuple[str, ...] = tuple(STAGE_INPUTS)
#: what each stage writes, relative to the run folder (folders are walked); a stage may list its
#: files itself instead (``StageContext.files``: the dynamics stage lists its study's jobs only)
STAGE_OUTPUTS: dict[str, tuple[str, ...]] = {
    "mesh": ("mesh",), "fe": ("fe",), "contact": ("contact",), "dynamics": ("dynamics",),
    "speed": ("speed",), "report": ("report.md", "summary.json", "timings.json", "figures",
                                    "paraview"),
}
#: the effective case of a run, written into its folder (``fe-joint report DIR`` reads it)
CASE_FILE = "case.toml"
#: stages that gain little from a second rank (default model, serially / on 2 ranks: mesh 5.2 /
#: 7.3 s, fe 42.1 / 33.9 s, contact 20.0 / 15.5 s; issue 16, session 26). When they run and a
#: later stage has work that needs only the case (``run_stages``' ``prepare``: the speed stage's
#: coarser FE models, 63 s on one rank), rank 0 runs them alone while the other ranks do that work
SOLO_STAGES = ("mesh", "fe", "contact")


@dataclass
class StageContext:
    """What a stage function gets: the case, the output folder, MPI, earlier stages' summaries."""
    case: Case
    out: Path
    comm: object
    summaries: dict = field(default_factory=dict)
    progress: bool = True
    keys: dict = field(default_factory=dict)      # stage → cache key (for stage-internal caches)
    runs: dict = field(default_factory=dict)      # stage → run id of its current output
    files: dict = field(default_factory=dict)     # stage → the paths it wrote (overrides STAGE_OUTPUTS)
    pending: list = field(default_factory=list)   # warnings of the stage being run

    @property
    def rank(self) -> int:
        return self.comm.rank if self.comm is not None else 0

    def path(self, *parts: str) -> Path:
        p = self.out.joinpath(*parts)
        return p

    def print(self, *a, **kw) -> None:
        if self.rank == 0:
            print(*a, **kw, flush=True)

    def warn(self, warnings: list[RunWarning]) -> None:
        """Record warnings of the running stage (kept in its manifest) and print them (rank 0)."""
        for w in warnings:
            self.pending.append(w)
            self.print(f"[fe-joint] warning: {w.message}")

    @property
    def warnings(self) -> list[RunWarning]:
        """Every warning of the stages run or loaded from the cache, in stage order."""
        return [RunWarning.from_dict(w) for s in STAGES
                for w in (self.summaries.get(s) or {}).get("warnings", [])]


def stage_keys(case: Case, stages: tuple[str, ...] = STAGES) -> dict[str, str]:
    """Cache key of each stage: its sections, its code version and the key of the stage before."""
    keys: dict[str, str] = {}
    prev = ""
    for s in STAGES:
        sections, version = STAGE_INPUTS[s]
        h = hashlib.sha256(f"{s}|{version}|{prev}|{case.section_hash(*sections)}".encode())
        keys[s] = prev = h.hexdigest()[:16]
    return {s: keys[s] for s in stages}


def _write_json_atomic(path: Path, data: dict) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=1, default=str))
    os.replace(tmp, path)


def read_manifest(out: Path, stage: str) -> dict | None:
    p = out / "stages" / f"{stage}.json"
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


def stage_files(out: Path, stage: str, ctx: StageContext) -> dict[str, dict]:
    """The record of the files ``stage`` wrote: {relative path: {"size", "sha256"}} (rank 0)."""
    paths = ctx.files.get(stage)
    if paths is None:
        paths = [out / p for p in STAGE_OUTPUTS[stage]]
    return file_record(out, paths)


def cache_problem(out: Path, stage: str, man: dict | None, key: str, upstream_run) -> str | None:
    """Why the cached output of ``stage`` cannot be used, None if it can (rank 0).

    Returns:
        None when the manifest's key and upstream run match and every recorded file is intact;
        "" when there is no usable manifest (a plain rerun, nothing to say); otherwise one line
        naming the first missing, truncated or changed file.
    """
    if man is None or man.get("key") != key or man.get("upstream_run") != upstream_run:
        return ""
    if "files" not in man:   # a manifest from before files were recorded: cannot be checked
        return f"stages/{stage}.json has no file record (an older run)"
    return check_files(out, man["files"])


def read_stage_log(out: Path) -> list[dict]:
    """The stage log as a list of entries ``{stage, action: ran|cached, key, seconds, time}``."""
    p = Path(out) / "stage_log.jsonl"
    if not p.exists():
        return []
    return [json.loads(line) for line in p.read_text().splitlines() if line.strip()]


def run_stages(case: Case, out: Path, stages: tuple[str, ...], registry: dict[str, Callable],
               comm=None, force: bool = False, progress: bool = True,
               prepare: dict[str, Callable] | None = None) -> StageContext:
    """Run ``stages`` in pipeline order, skipping those whose cached key matches.

    Args:
        case: the validated case.
        out: output folder (created on rank 0).
        stages: names to run (a subset of :data:`STAGES`; earlier stages they need are run or
            loaded from the cache automatically).
        registry: stage name → function ``f(ctx) -> summary dict``.
        comm: mpi4py communicator (None: serial without MPI).
        force: rerun the requested stages even if cached.
        prepare: stage name → ``f(ctx) -> [task]``, the work of that stage that needs only the
            case (collective; every rank gets the same list of callables). On several ranks,
            when :data:`SOLO_STAGES` are to run before that stage, rank 0 runs them alone and
            the other ranks run the tasks meanwhile (:func:`_run_solo`); a task that fails is
            left to its stage.
    Returns:
        The context with every stage's summary.
    """
    out = Path(out)
    rank = comm.rank if comm is not None else 0
    if rank == 0:
        (out / "stages").mkdir(parents=True, exist_ok=True)
        (out / CASE_FILE).write_text(case_to_toml(case))
    if comm is not None:
        comm.barrier()
    keys = stage_keys(case)
    last = max(STAGES.index(s) for s in stages)
    needed = STAGES[: last + 1]
    ctx = StageContext(case=case, out=out, comm=comm, progress=progress, keys=keys)
    # a stage is cached only if its key matches, it was computed from the current output of the
    # stage before it (each manifest records that stage's run id) and its files are intact
    prev_run = None
    solo_done: set[str] = set()
    for s in needed:
        if s in solo_done:
            continue
        man = read_manifest(out, s)
        cached = False
        if rank == 0 and not (force and s in stages):
            why = cache_problem(out, s, man, keys[s], prev_run)
            cached = why is None
            if why:   # one line naming the file ("" = nothing cached: say nothing)
                ctx.print(f"[fe-joint] {s}: {why}: rerunning {s}")
        if comm is not None:  # every rank takes the same branch
            cached = comm.bcast(cached, root=0)
            man = comm.bcast(man, root=0)
        if cached:
            prev_run = ctx.runs[s] = man.get("run_id")
            ctx.summaries[s] = man.get("summary", {})
            _log(out, rank, {"stage": s, "action": "cached", "key": keys[s], "seconds": 0.0})
            continue
        # this stage runs, so every stage after it does (their upstream run changes)
        solo = [t for t in needed[needed.index(s):] if t in SOLO_STAGES]
        tasks = _side_tasks(ctx, needed, solo, prepare) if solo and solo[0] == s else []
        if tasks:
            prev_run = _run_solo(ctx, registry, solo, tasks, prev_run)
            solo_done.update(solo)
            continue
        prev_run = _run_stage(ctx, registry, s, prev_run)
    return ctx


def _run_stage(ctx: StageContext, registry: dict[str, Callable], s: str, prev_run) -> str:
    """Run stage ``s`` on ``ctx.comm``: its summary, manifest (rank 0) and log line; returns
    its run id."""
    comm, rank, out = ctx.comm, ctx.rank, ctx.out
    ctx.print(f"[fe-joint] stage {s} ...")
    t0 = time.perf_counter()
    ctx.pending = []
    summary = registry[s](ctx) or {}
    dt = time.perf_counter() - t0
    if ctx.pending:
        summary["warnings"] = [w.to_dict() for w in ctx.pending]
    ctx.summaries[s] = summary
    run_id = uuid.uuid4().hex if rank == 0 else None
    if comm is not None:
        run_id = comm.bcast(run_id, root=0)
    if rank == 0:
        _write_json_atomic(out / "stages" / f"{s}.json",
                           {"stage": s, "key": ctx.keys[s], "seconds": dt, "summary": summary,
                            "run_id": run_id, "upstream_run": prev_run,
                            "files": stage_files(out, s, ctx),
                            # what it ran on (after the stage: its imports are loaded)
                            "environment": run_environment(comm)})
    ctx.runs[s] = run_id
    _log(out, rank, {"stage": s, "action": "ran", "key": ctx.keys[s], "seconds": dt})
    ctx.print(f"[fe-joint] stage {s} done in {dt:.1f} s")
    if comm is not None:
        comm.barrier()
    return run_id


def _side_tasks(ctx: StageContext, needed: tuple[str, ...], solo: list[str],
                prepare: dict[str, Callable] | None) -> list[Callable]:
    """The tasks the ranks other than 0 run while rank 0 runs the ``solo`` stages alone: the
    preparations of the stages after them (collective; [] on one rank)."""
    if ctx.comm is None or ctx.comm.size < 2 or not prepare:
        return []
    return [task for t in needed[needed.index(solo[-1]) + 1:] if t in prepare
            for task in prepare[t](ctx)]


def _run_solo(ctx: StageContext, registry: dict[str, Callable], solo: list[str],
              tasks: list[Callable], prev_run) -> str:
    """Rank 0 runs the ``solo`` stages on a communicator of its own while the other ranks run
    ``tasks`` (dealt round-robin); then every rank gets the stages' summaries and run ids, or
    the exception that stopped rank 0 (raised on every rank, as a collective stage's would be).
    Returns the last stage's run id."""
    comm = ctx.comm
    sub = comm.Split(0 if comm.rank == 0 else 1, comm.rank)
    outcome = None
    try:
        if comm.rank == 0:
            mine = StageContext(case=ctx.case, out=ctx.out, comm=sub, summaries=ctx.summaries,
                                progress=ctx.progress, keys=ctx.keys, runs=ctx.runs, files=ctx.files)
            try:
                for s in solo:
                    prev_run = _run_stage(mine, registry, s, prev_run)
            except BaseException as e:       # the other ranks raise it too, then rank 0 does
                outcome = ("error", _portable(e))
                comm.bcast(outcome, root=0)
                raise
            outcome = ("done", {s: ctx.summaries[s] for s in solo}, {s: ctx.runs[s] for s in solo})
        else:
            for i, task in enumerate(tasks):
                if i % sub.size == sub.rank:
                    try:
                        task()
                    except Exception:      # noqa: BLE001 - the stage does that work itself then
                        pass
        outcome = comm.bcast(outcome, root=0)
    finally:
        sub.Free()
    if outcome[0] == "error":
        raise outcome[1]
    ctx.summaries.update(outcome[1])
    ctx.runs.update(outcome[2])
    return outcome[2][solo[-1]]


def _portable(e: BaseException) -> BaseException:
    """``e`` if it survives pickling (to be sent to the other ranks), else a RuntimeError with
    its message."""
    import pickle
    try:
        pickle.loads(pickle.dumps(e))
        return e
    except Exception:   # noqa: BLE001
        return RuntimeError(str(e))


def _log(out: Path, rank: int, entry: dict) -> None:
    if rank != 0:
        return
    entry["time"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    with open(out / "stage_log.jsonl", "a") as f:
        f.write(json.dumps(entry) + "\n")
