"""Stage runner: input-hash caching, resumable runs and the stage log.

A run is a fixed sequence of stages. Each stage depends on some case sections and on the stages
before it; its *key* is the hash of those sections, the upstream keys and the stage's code
version. When a stage finishes, it writes ``DIR/stages/<stage>.json`` (key, seconds, summary) —
after its artifacts, so a killed run never leaves a manifest for half-written output. A rerun
skips every stage whose manifest key matches and that was computed from the current output of
the stage before it (``cached`` in the log), and resumes at the first one that does not. Every action is appended to ``DIR/stage_log.jsonl``, which is also how the
tests check that finished stages are not recomputed.

All MPI ranks call :func:`run_stages`; only rank 0 writes manifests and the log.
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

#: the dynamics settings the study's curves depend on (not ``speed_study``: the speed stage's switch)
_DYNAMICS_CURVES = tuple(f"dynamics.{k}" for k in
                         ("harmonics", "samples", "levels", "band", "max_points", "configurations"))

#: stage name → (the case inputs it reads: "section" or "section.key", code version; bump the
#: version when a stage's output changes). A stage's key also chains the key of the stage before.
STAGE_INPUTS: dict[str, tuple[tuple[str, ...], str]] = {
    "mesh": (("geometry",), "1"),
    # preload and Craig–Bampton share the interface condensation (one factorization), so they
    # are one stage: splitting them would factorize the 60k-DOF stiffness twice
    "fe": (("geometry", "material", "preload", "reduction"), "1"),
    # the BEM grid spans the overlap (geometry) and uses the elastic constants (material)
    "contact": (("geometry", "material", "roughness"), "2"),
    "dynamics": (("geometry", "material", "roughness", "contact") + _DYNAMICS_CURVES, "7"),
    "speed": (("geometry", "material", "roughness", "contact", "dynamics"), "1"),
    # the report reads every section (titles, tables, the paper comparison)
    "report": (("geometry", "material", "preload", "reduction", "roughness", "contact",
                "dynamics"), "2"),
}
STAGES: tuple[str, ...] = tuple(STAGE_INPUTS)
#: the effective case of a run, written into its folder (``fe-joint report DIR`` reads it)
CASE_FILE = "case.toml"


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

    @property
    def rank(self) -> int:
        return self.comm.rank if self.comm is not None else 0

    def path(self, *parts: str) -> Path:
        p = self.out.joinpath(*parts)
        return p

    def print(self, *a, **kw) -> None:
        if self.rank == 0:
            print(*a, **kw, flush=True)


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


def read_stage_log(out: Path) -> list[dict]:
    """The stage log as a list of entries ``{stage, action: ran|cached, key, seconds, time}``."""
    p = Path(out) / "stage_log.jsonl"
    if not p.exists():
        return []
    return [json.loads(line) for line in p.read_text().splitlines() if line.strip()]


def run_stages(case: Case, out: Path, stages: tuple[str, ...], registry: dict[str, Callable],
               comm=None, force: bool = False, progress: bool = True) -> StageContext:
    """Run ``stages`` in pipeline order, skipping those whose cached key matches.

    Args:
        case: the validated case.
        out: output folder (created on rank 0).
        stages: names to run (a subset of :data:`STAGES`; earlier stages they need are run or
            loaded from the cache automatically).
        registry: stage name → function ``f(ctx) -> summary dict``.
        comm: mpi4py communicator (None: serial without MPI).
        force: rerun the requested stages even if cached.
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
    # a stage is cached only if its key matches and it was computed from the current output of
    # the stage before it (each manifest records that stage's run id)
    prev_run = None
    for s in needed:
        man = read_manifest(out, s)
        cached = (man is not None and man.get("key") == keys[s] and not (force and s in stages)
                  and man.get("upstream_run") == prev_run)
        if comm is not None:  # every rank takes the same branch
            cached = comm.bcast(cached, root=0)
            man = comm.bcast(man, root=0)
        if cached:
            prev_run = ctx.runs[s] = man.get("run_id")
            ctx.summaries[s] = man.get("summary", {})
            _log(out, rank, {"stage": s, "action": "cached", "key": keys[s], "seconds": 0.0})
            continue
        ctx.print(f"[fe-joint] stage {s} ...")
        t0 = time.perf_counter()
        summary = registry[s](ctx) or {}
        dt = time.perf_counter() - t0
        ctx.summaries[s] = summary
        run_id = uuid.uuid4().hex if rank == 0 else None
        if comm is not None:
            run_id = comm.bcast(run_id, root=0)
        if rank == 0:
            _write_json_atomic(out / "stages" / f"{s}.json",
                               {"stage": s, "key": keys[s], "seconds": dt, "summary": summary,
                                "run_id": run_id, "upstream_run": prev_run})
        prev_run = ctx.runs[s] = run_id
        _log(out, rank, {"stage": s, "action": "ran", "key": keys[s], "seconds": dt})
        ctx.print(f"[fe-joint] stage {s} done in {dt:.1f} s")
        if comm is not None:
            comm.barrier()
    return ctx


def _log(out: Path, rank: int, entry: dict) -> None:
    if rank != 0:
        return
    entry["time"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    with open(out / "stage_log.jsonl", "a") as f:
        f.write(json.dumps(entry) + "\n")
