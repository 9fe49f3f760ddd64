"""The job queue (fe_joint.study.queue.run_jobs): dependencies, prepare, failures; the static
deal (map_ranks); serial and on 2 ranks."""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import pytest

from fe_joint.errors import EXIT_BUG, EXIT_CONVERGENCE, JobFailed
from fe_joint.study.queue import busy_fractions, map_ranks, run_jobs


@dataclass(frozen=True)
class _Job:
    name: str
    needs: tuple = ()
    seconds: float = 0.0
    key: str = ""


def _write(folder: Path, job: _Job, r: dict) -> None:
    (folder / f"{job.name}.json").write_text(json.dumps(r))


def _run_reading(folder: Path):
    """A job that reads the files of the jobs it needs (as a dynamics job does) and sums them;
    a needed job that wrote nothing (skipped by prepare) counts 0."""
    def run(job: _Job) -> dict:
        time.sleep(job.seconds)
        got = [json.loads((folder / f"{n}.json").read_text())["value"]
               for n in job.needs if (folder / f"{n}.json").exists()]
        return {"value": 1 + sum(got), "key": job.key}
    return run


def test_dependencies_order_prepare_and_skip(tmp_path) -> None:
    """A job is dealt only after the jobs it needs are written, whatever the list order; prepare
    sets a key from their results or skips a job (it counts as done, its dependants run); the
    values are those of the dependency tree."""
    jobs = [_Job("d", ("b", "c")), _Job("b", ("a",)), _Job("c", ("a", "skipped")),
            _Job("a"), _Job("skipped"), _Job("e")]
    order, seen = [], []

    def prepare(job):
        seen.append(job.name)
        if job.name == "skipped":
            return None
        if job.name == "d":                   # a key that needs b's and c's results
            vals = [json.loads((tmp_path / f"{n}.json").read_text())["value"] for n in ("b", "c")]
            return replace(job, key=f"k{sum(vals)}")
        return job

    run = _run_reading(tmp_path)

    def run_logged(job):
        order.append(job.name)
        return run(job)
    progress = []
    t0 = time.perf_counter()
    schedule = run_jobs(run_logged, _write, jobs, tmp_path, after=lambda j: j.needs,
                        prepare=prepare, progress=lambda j: progress.append(j.name),
                        skip_done=False)
    wall = time.perf_counter() - t0
    # in list order among the ready ones: d waits for b and c, which wait for a
    assert order == ["a", "b", "c", "d", "e"]
    # the schedule: every job run (not the skipped one) once, on rank 0, one after the other
    assert [r["job"] for r in schedule] == order and {r["rank"] for r in schedule} == {0}
    assert all(a["end"] <= b["start"] for a, b in zip(schedule, schedule[1:]))
    assert 0.0 < busy_fractions(schedule, 1, wall)[0] <= 1.0
    assert "skipped" in seen and sorted(progress) == sorted(j.name for j in jobs)
    val = {j.name: json.loads((tmp_path / f"{j.name}.json").read_text()) for j in jobs
           if j.name != "skipped"}
    assert not (tmp_path / "skipped.json").exists()
    assert {k: v["value"] for k, v in val.items()} == {"a": 1, "b": 2, "c": 2, "d": 5, "e": 1}
    assert val["d"]["key"] == "k4"


def test_missing_dependency_result_and_cycle_fail(tmp_path) -> None:
    """A job whose run fails stops the queue with its exit class; a dependency cycle is reported
    as unmet dependencies, not waited for forever."""
    jobs = [_Job("a"), _Job("b", ("a",))]

    def bad(job):
        raise ValueError("no")
    with pytest.raises(JobFailed) as e:
        run_jobs(bad, _write, jobs, tmp_path, after=lambda j: j.needs, skip_done=False)
    assert e.value.job == "a" and not (tmp_path / "b.json").exists()
    cyc = [_Job("x", ("y",)), _Job("y", ("x",))]
    with pytest.raises(JobFailed, match="unmet dependencies"):
        run_jobs(_run_reading(tmp_path), _write, cyc, tmp_path, after=lambda j: j.needs,
                 skip_done=False)


@pytest.mark.mpi
def test_dependencies_on_two_ranks(tmp_path_factory) -> None:
    """On 2 ranks a job listed first but needing a slow one waits for it (the asking rank is
    answered once it is written) while the other ready jobs go on; results equal the serial
    run's."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    if comm.size == 1:
        pytest.skip("needs mpirun -n 2 (scripts/test runs it)")
    d = Path(comm.bcast(str(tmp_path_factory.mktemp("q")) if comm.rank == 0 else None, root=0))
    jobs = [_Job("slow", (), 0.6), _Job("late", ("slow",)), _Job("q1", (), 0.1), _Job("q2", ()),
            _Job("last", ("late", "q1"))]
    t0 = time.perf_counter()
    schedule = run_jobs(_run_reading(d), _write, jobs, d, comm=comm, after=lambda j: j.needs,
                        skip_done=False)
    wall = time.perf_counter() - t0
    if comm.rank == 0:
        val = {j.name: json.loads((d / f"{j.name}.json").read_text())["value"] for j in jobs}
        assert val == {"slow": 1, "late": 2, "q1": 1, "q2": 1, "last": 4}
        # the schedule: each job once; a rank runs one job at a time; "late" starts after
        # "slow" ends; the 0.6 s job keeps its rank busy that long
        at = {r["job"]: r for r in schedule}
        assert sorted(at) == sorted(j.name for j in jobs)
        for rank in range(comm.size):
            mine = [r for r in schedule if r["rank"] == rank]
            assert all(a["end"] <= b["start"] for a, b in zip(mine, mine[1:]))
        assert at["late"]["start"] >= at["slow"]["end"] >= at["slow"]["start"] + 0.6
        busy = busy_fractions(schedule, comm.size, wall)
        assert max(busy) <= 1.0 and busy[at["slow"]["rank"]] >= 0.6 / wall
    else:
        assert schedule is None


def _square_or_fail(x: int) -> int:
    if x == 3:
        raise ValueError("three")
    return x * x


@pytest.mark.mpi
def test_map_ranks_deals_items_and_gathers_them_in_order() -> None:
    """map_ranks on any number of ranks: every rank gets [x² for x in items] in order, each item
    computed by rank i % size; on several ranks a failure on one is raised on every rank with its
    exit class (a bug: 1; a ConvergenceError: 3), on one it is raised as it is."""
    from mpi4py import MPI

    from hbm import ConvergenceError
    comm = MPI.COMM_WORLD
    items = list(range(7))
    got = map_ranks(lambda x: (x * x, comm.rank), items, comm)
    assert [v for v, _ in got] == [x * x for x in items]
    assert [r for _, r in got] == [i % comm.size for i in items]
    assert comm.allgather(got) == [got] * comm.size
    assert map_ranks(lambda x: x + 1, items) == [x + 1 for x in items]       # serial
    # one rank: the failure itself; several: JobFailed on every rank, with its exit class
    with pytest.raises(ValueError if comm.size == 1 else JobFailed) as e:
        map_ranks(_square_or_fail, items, comm)
    assert "three" in str(e.value)
    if comm.size > 1:
        assert e.value.code == EXIT_BUG and "item 3 of 7" in str(e.value)

    def diverge(x):
        if x == 4:
            raise ConvergenceError("no", 1e-3)
        return x
    with pytest.raises(ConvergenceError if comm.size == 1 else JobFailed) as e:
        map_ranks(diverge, items, comm)
    if comm.size > 1:
        assert e.value.code == EXIT_CONVERGENCE


def test_dynamics_dealing_order_readies_the_layer_backbone_early() -> None:
    """The dynamics queue's order (jobs.dealing_order): v3 fixed points, their follow-ups, the
    layer joints' parents' curves (lower levels first), the layer joints' backbones, the other
    top-level curves, the other lower curves, the small-excitation check, the backbones; every
    job once. The queue deals the first ready job in this order, so the long stiff-layer
    backbone starts as soon as its parent's top-level curve is written."""
    from fe_joint.study.jobs import Job, dealing_order
    from fe_joint.study.stiffness_definitions import AltJob
    curves = [Job("curve", c, lv) for lv in (0, 1, 2) for c in ("baseline", "smooth-ms", "v1")]
    jobs = ([Job("v3", "v3", 1, rq) for rq in (1.0, 10.0)] + curves
            + [Job("curve", "baseline", None), Job("v3-level", "v3", 2, 10.0),
               Job("v2-pass0", "v2", 1, 10.0)])
    alts = [AltJob("smooth-ms-layer", None, "smooth-ms")]
    bbs = [Job("backbone", "baseline", None), Job("backbone", "smooth-ms", None)]
    names = [j.name for j in dealing_order(jobs, alts, 3, bbs)]
    assert sorted(names) == sorted([j.name for j in jobs + bbs] + ["smooth-ms-layer"])
    assert names[:4] == ["v3-rq1", "v3-rq10", "v3-rq10@L2", "v2@L1"]
    assert names[4:7] == ["smooth-ms@L1", "smooth-ms@L0", "smooth-ms@L2"]
    assert names[7] == "smooth-ms-layer"
    assert names[8:10] == ["baseline@L2", "v1@L2"]
    assert names[10:14] == ["baseline@L1", "v1@L1", "baseline@L0", "v1@L0"]
    assert names[14] == "check-linear@tiny" and names[15:] == [j.name for j in bbs]
    # without layer joints: the top-level curves first, then down the levels
    plain = [j.name for j in dealing_order(jobs, [], 3, bbs)]
    assert plain[4:7] == ["baseline@L2", "smooth-ms@L2", "v1@L2"]
    assert plain[7:13] == ["baseline@L1", "smooth-ms@L1", "v1@L1", "baseline@L0", "smooth-ms@L0",
                           "v1@L0"]
