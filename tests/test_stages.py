"""Stage cache, resume after a kill, and the stage log (issue 2/6 'robust runs')."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fe_joint.case import load_case
from fe_joint.pipeline.runner import STAGES, read_stage_log, run_stages, stage_keys


class Killed(Exception):
    pass


def _registry(calls: list, kill_at: str | None = None) -> dict:
    def make(name):
        def f(ctx):
            if name == kill_at:
                raise Killed(name)
            calls.append(name)
            return {"n": len(calls)}
        return f
    return {s: make(s) for s in STAGES}


def test_rerun_skips_finished_stages(tmp_path: Path) -> None:
    case = load_case(preset="quick")
    calls: list = []
    # a run killed in 'contact': mesh and fe are finished and logged
    with pytest.raises(Killed):
        run_stages(case, tmp_path, ("dynamics",), _registry(calls, kill_at="contact"))
    assert calls == ["mesh", "fe"]
    calls.clear()
    run_stages(case, tmp_path, ("dynamics",), _registry(calls))
    assert calls == ["contact", "dynamics"]          # resumed where it stopped
    log = read_stage_log(tmp_path)
    assert [(e["stage"], e["action"]) for e in log] == [
        ("mesh", "ran"), ("fe", "ran"), ("mesh", "cached"), ("fe", "cached"),
        ("contact", "ran"), ("dynamics", "ran")]


def test_changed_section_reruns_downstream_only(tmp_path: Path) -> None:
    case = load_case(preset="quick")
    calls: list = []
    run_stages(case, tmp_path, STAGES, _registry(calls))
    assert calls == list(STAGES)
    # friction coefficient: the BEM (contact) does not read it; dynamics onwards must rerun
    case2 = dataclasses.replace(case, contact=dataclasses.replace(case.contact, mu=0.3))
    k1, k2 = stage_keys(case), stage_keys(case2)
    assert [s for s in STAGES if k1[s] != k2[s]] == ["dynamics", "speed", "report"]
    calls.clear()
    run_stages(case2, tmp_path, STAGES, _registry(calls))
    assert calls == ["dynamics", "speed", "report"]
    calls.clear()
    run_stages(case2, tmp_path, STAGES, _registry(calls), force=False)
    assert calls == []


def test_speed_study_switch_keeps_the_curves() -> None:
    """dynamics.speed_study is read by the speed stage only: toggling it keeps every dynamics
    curve (the dynamics key) and reruns speed and report."""
    case = load_case(preset="quick")
    case2 = dataclasses.replace(case, dynamics=dataclasses.replace(case.dynamics, speed_study=True))
    k1, k2 = stage_keys(case), stage_keys(case2)
    assert [s for s in STAGES if k1[s] != k2[s]] == ["speed", "report"]


def test_forced_stage_reruns_everything_after_it(tmp_path: Path) -> None:
    case = load_case(preset="quick")
    calls: list = []
    run_stages(case, tmp_path, STAGES, _registry(calls))
    calls.clear()
    run_stages(case, tmp_path, ("contact",), _registry(calls), force=True)
    assert calls == ["contact"]
    calls.clear()
    # dynamics and report read contact's new output: they must not come from the cache
    run_stages(case, tmp_path, STAGES, _registry(calls))
    assert calls == ["dynamics", "speed", "report"]
    calls.clear()
    run_stages(case, tmp_path, STAGES, _registry(calls))
    assert calls == []
    (tmp_path / "stages" / "fe.json").unlink()
    run_stages(case, tmp_path, STAGES, _registry(calls))
    assert calls == ["fe", "contact", "dynamics", "speed", "report"]


def test_changed_artifact_or_unrecorded_manifest_reruns_the_stage(tmp_path: Path, capsys) -> None:
    """A file edited in place (same size, other bytes) reruns the stage that wrote it, with one
    line naming it; a manifest without a file record (an older run) is not trusted either."""
    import json
    case = load_case(preset="quick")
    calls: list = []

    def writer(name):
        def f(ctx):
            calls.append(name)
            ctx.path(name).mkdir(exist_ok=True)
            ctx.path(name, "a.bin").write_bytes(b"x" * 64)
            return {}
        return f
    reg = {s: writer(s) for s in STAGES}
    run_stages(case, tmp_path, ("contact",), reg)
    f = tmp_path / "fe" / "a.bin"
    f.write_bytes(b"y" * 64)
    calls.clear()
    capsys.readouterr()
    run_stages(case, tmp_path, ("contact",), reg)
    assert calls == ["fe", "contact"]
    out = capsys.readouterr().out
    assert [l for l in out.splitlines() if "a.bin" in l] == [
        "[fe-joint] fe: fe/a.bin changed (sha256 differs): rerunning fe"]
    m = tmp_path / "stages" / "contact.json"
    man = json.loads(m.read_text())
    del man["files"]
    m.write_text(json.dumps(man))
    calls.clear()
    run_stages(case, tmp_path, ("contact",), reg)
    assert calls == ["contact"]


def _tiny_model() -> "ReducedModel":
    """A reduced model that round-trips through its h5 file (K, M only shaped right)."""
    from fe_joint.model.reduced_model import ReducedModel
    n, ne = 9, 1
    return ReducedModel(
        K=np.diag(np.arange(1.0, n + 1)), M=np.eye(n), C=np.zeros((n, n)), damping_ratio=1e-3,
        dof_labels=[f"dof{i}" for i in range(n)], pair_xyz=np.zeros((ne, 3)), pair_area=np.ones(ne),
        pair_frame=np.eye(3)[None], pair_dofs=np.arange(6).reshape(ne, 2, 3),
        preload_normal_force=np.ones(ne), preload_pressure=np.ones(ne), preload_gap=np.zeros(ne),
        preload_status=np.ones(ne, int), excitation_dof=6, response_dof=6,
        full_frequencies=np.array([0.0, 250.0]), reduced_frequencies=np.zeros(n), n_boundary=6)


def test_coarser_models_built_ahead_are_read_back_only_with_their_key(tmp_path: Path, monkeypatch) -> None:
    """The speed stage's coarser FE models built ahead (``prepare_speed``, one task each) are
    read back by the stage while their record's key (the fe stage's and the lap mesh size) and
    the h5's bytes match; another fe key or a damaged file makes them missing again."""
    import dataclasses

    from fe_joint.pipeline import stages
    from fe_joint.pipeline.runner import StageContext, stage_keys
    from fe_joint.study.speed_error import lap_mesh_sizes
    built: list = []

    def build(c, size):
        built.append(size)
        return _tiny_model(), 1.5 + size
    monkeypatch.setattr(stages, "_coarser_reduced_model", build)
    monkeypatch.setattr(stages, "_coarser_tuple", lambda c, size, rm, sec: (size, rm, sec, None))
    case = load_case(preset="quick")
    case = dataclasses.replace(case, dynamics=dataclasses.replace(case.dynamics, speed_study=True))
    ctx = StageContext(case=case, out=tmp_path, comm=None, keys=stage_keys(case))
    sizes = lap_mesh_sizes(case.geometry.lap_mesh_size)
    assert stages._prebuilt_model(ctx, 0, sizes[0]) is None
    tasks = stages.prepare_speed(ctx)
    assert len(tasks) == len(sizes) == 2
    for t in tasks:
        t()
    assert built == sizes and stages.prepare_speed(ctx) == []
    size, rm, sec, _ = stages._prebuilt_model(ctx, 1, sizes[1])
    assert (size, sec) == (sizes[1], 1.5 + sizes[1])
    assert np.array_equal(rm.K, _tiny_model().K)
    # another fe stage's models are not this run's
    other = StageContext(case=case, out=tmp_path, comm=None, keys={**ctx.keys, "fe": "0" * 16})
    assert stages._prebuilt_model(other, 1, sizes[1]) is None and len(stages.prepare_speed(other)) == 2
    # a damaged h5 is not read (the stage builds that model itself)
    with open(tmp_path / "speed" / "models" / "coarser-1.h5", "ab") as f:
        f.write(b"\0")
    assert stages._prebuilt_model(ctx, 1, sizes[1]) is None
    assert stages._prebuilt_model(ctx, 0, sizes[0])[2] == 1.5 + sizes[0]
    # nothing to prepare without the speed study
    off = dataclasses.replace(case, dynamics=dataclasses.replace(case.dynamics, speed_study=False))
    assert stages.prepare_speed(StageContext(case=off, out=tmp_path, comm=None, keys=ctx.keys)) == []


def test_preparations_are_ignored_on_one_rank(tmp_path: Path) -> None:
    """Serially the stages run in order on the one rank and no preparation's task runs."""
    case = load_case(preset="quick")
    calls: list = []
    tasks_run: list = []
    run_stages(case, tmp_path, STAGES, _registry(calls),
               prepare={"speed": lambda ctx: [lambda: tasks_run.append(1)]})
    assert calls == list(STAGES) and tasks_run == []


@pytest.mark.mpi
def test_solo_stages_run_on_rank_0_while_the_other_rank_prepares(tmp_path_factory) -> None:
    """On 2 ranks, with a preparation for a later stage: mesh, fe and contact run on rank 0
    alone (a communicator of size 1) while rank 1 runs the preparation's tasks; the later
    stages run on both, every rank ends with the same summaries, and an error of rank 0's
    stages is raised on both ranks."""
    from mpi4py import MPI

    from fe_joint.pipeline.runner import SOLO_STAGES
    comm = MPI.COMM_WORLD
    if comm.size == 1:
        pytest.skip("MPI-only: needs mpirun -n 2 (scripts/test runs it)")
    d = Path(comm.bcast(str(tmp_path_factory.mktemp("solo")) if comm.rank == 0 else None, root=0))
    case = load_case(preset="quick")
    seen: list = []

    def make(name, fail=False):
        def f(ctx):
            if fail and ctx.rank == 0:
                raise Killed(name)
            seen.append((name, ctx.comm.size))
            return {"stage": name, "ranks": ctx.comm.size}
        return f
    side = d / f"side-{comm.rank}"
    prepare = {"speed": lambda ctx: [lambda: side.write_text("built")]}
    ctx = run_stages(case, d / "run", STAGES, {s: make(s) for s in STAGES}, comm=comm, prepare=prepare)
    expected = [(s, 1) for s in SOLO_STAGES] if comm.rank == 0 else []
    assert seen == expected + [(s, 2) for s in STAGES if s not in SOLO_STAGES]
    assert side.exists() == (comm.rank == 1)
    summaries = comm.allgather({s: ctx.summaries[s] for s in STAGES})
    assert summaries[0] == summaries[1] and summaries[0]["fe"] == {"stage": "fe", "ranks": 1}
    if comm.rank == 0:
        assert [(e["stage"], e["action"]) for e in read_stage_log(d / "run")] == [(s, "ran") for s in STAGES]
    # a rerun: everything cached, no preparation, nothing run
    seen.clear()
    run_stages(case, d / "run", STAGES, {s: make(s) for s in STAGES}, comm=comm, prepare=prepare)
    assert seen == []
    # rank 0's error in fe reaches rank 1 (which would otherwise wait for it)
    registry = {s: make(s, fail=(s == "fe")) for s in STAGES}
    with pytest.raises(Killed):
        run_stages(case, d / "failing", STAGES, registry, comm=comm, prepare=prepare)
