"""The MPI job queue of the dynamics and speed stages: ranks take jobs from one queue, longest
first, each job once the jobs it needs are written; rank 0 serves it from a thread and writes
each result as it arrives (a killed run loses only the jobs in flight)."""
from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from ..errors import JobFailed, classify


def _attempt(run_job: Callable, job) -> tuple[dict | None, tuple | None]:
    """``run_job(job)``, with a failure turned into (job, exit code, message) that can cross ranks."""
    try:
        return run_job(job), None
    except Exception as e:  # noqa: BLE001 - reported on every rank by run_jobs
        code, msg = classify(e)
        return None, (job.name, code, msg, e)


def map_ranks(fn: Callable, items: list, comm=None) -> list:
    """``[fn(x) for x in items]``, item i computed on rank i % size, the results gathered on every
    rank in order (collective). For items of about equal cost, as a static deal (:func:`run_jobs`
    deals unequal ones); ``fn`` must not be collective. On several ranks a failure on any rank is
    raised on every rank as :class:`~fe_joint.errors.JobFailed` with the original's exit class
    (one rank: the failure itself).

    Args:
        fn: item → result (picklable).
        items: the work, the same list on every rank.
        comm: MPI communicator or None (serial).
    """
    if comm is None or comm.size == 1:
        return [fn(x) for x in items]
    mine, fail, own = {}, None, None
    for i in range(comm.rank, len(items), comm.size):
        try:
            mine[i] = fn(items[i])
        except Exception as e:  # noqa: BLE001 - raised on every rank below
            own, fail = e, (f"item {i} of {len(items)}",) + classify(e)
            break
    parts = comm.allgather((mine, fail))
    fails = [f for _, f in parts if f is not None]
    if fails:
        raise JobFailed(*fails[0]) from own
    out = {}
    for m, _ in parts:
        out.update(m)
    return [out[i] for i in range(len(items))]


_TAG = 77
#: how often rank 0's queue server looks for requests, s (jobs take 5–600 s)
POLL_SECONDS = 0.05
#: what the schedule answers when no job is ready yet but some are in flight
_WAIT = object()


class _Schedule:
    """The jobs still to deal, in order, each dealt once the jobs it needs are written (rank 0;
    the server thread and rank 0's own loop share it under ``lock``).

    ``after(job)``: names of the jobs that must be written first (names not in this queue count
    as written). ``prepare(job)``: called when the job is about to be dealt; returns the job to
    run (e.g. with a cache key that needed the earlier jobs' results) or None when there is
    nothing to run (it counts as written at once).
    """

    def __init__(self, todo: list, after: Callable | None, prepare: Callable | None,
                 progress: Callable | None) -> None:
        self.pending = list(todo)
        names = {j.name for j in todo}
        self.needs = {j.name: set(after(j)) & names if after is not None else set() for j in todo}
        self.prepare, self.progress = prepare, progress
        self.done: set[str] = set()
        self.flying: set[str] = set()
        self.failure = None
        self.lock = threading.Lock()
        self.t0 = time.perf_counter()
        self.trace: dict[str, dict] = {}       # job name -> {"rank", "start", "end"} (s from t0)

    def dealt(self, job, rank: int) -> None:
        """Note that ``job`` went to ``rank`` now (the schedule's record)."""
        with self.lock:
            self.trace[job.name] = {"job": job.name, "rank": rank,
                                    "start": time.perf_counter() - self.t0}

    def schedule(self) -> list[dict]:
        """Every finished job's rank and start and end, s from the queue's start, by start."""
        with self.lock:
            return sorted((dict(r) for r in self.trace.values() if "end" in r),
                          key=lambda r: r["start"])

    def next_job(self):
        """The first ready job (marked in flight), ``_WAIT`` when none is ready but some are in
        flight, or None when the queue is finished (or failed)."""
        with self.lock:
            while self.failure is None:
                ready = next((j for j in self.pending if self.needs[j.name] <= self.done), None)
                if ready is None:
                    if self.pending and not self.flying:
                        # nothing runs and nothing can start: a job needs one that never comes
                        self.failure = (self.pending[0].name, 1, "job queue: unmet dependencies "
                                        f"{sorted(self.needs[self.pending[0].name] - self.done)}",
                                        None)
                        return None
                    return _WAIT if self.pending else None
                self.pending.remove(ready)
                job = ready
                if self.prepare is not None:
                    try:
                        job = self.prepare(ready)
                    except Exception as e:  # noqa: BLE001 - reported on every rank
                        code, msg = classify(e)
                        self.failure = (ready.name, code, msg, e)
                        return None
                if job is None:
                    self.done.add(ready.name)
                    if self.progress is not None:
                        self.progress(ready)
                    continue
                self.flying.add(job.name)
                return job
            return None

    def finished(self, job, write_job: Callable, folder: Path, r, fail) -> None:
        """A job's outcome: written (and its dependants freed), or the queue's failure."""
        with self.lock:
            self.flying.discard(job.name)
            if job.name in self.trace:
                self.trace[job.name]["end"] = time.perf_counter() - self.t0
            if fail is not None:
                if self.failure is None:
                    self.failure = fail
                return
            write_job(folder, job, r)
            self.done.add(job.name)
            if self.progress is not None:
                self.progress(job)


def run_jobs(run_job: Callable, write_job: Callable, jobs: list, folder: Path, comm=None,
             progress=None, skip_done: bool = True,
             after: Callable[[object], Iterable[str]] | None = None,
             prepare: Callable | None = None) -> list[dict] | None:
    """Run the jobs not yet on disk, dealt dynamically to the ranks, longest first.

    With ``skip_done`` a job whose ``<name>.json`` marker exists is skipped; without it rank 0's
    ``jobs`` are run as given (the caller decided, e.g. :func:`fe_joint.study.jobs.plan_jobs`).

    Jobs differ in cost by 50× (a v3 fixed point vs a low-level FRF), so a static deal leaves
    ranks idle. Rank 0 works through the queue too; a server thread on rank 0 (MPI_THREAD_MULTIPLE)
    hands the next job to any rank that asks and writes each result as it arrives, so a killed
    run loses only the jobs in flight. Jobs are deterministic: which rank runs one does not change
    its result. A failed job stops the handing out; every rank then raises
    :class:`~fe_joint.errors.JobFailed` with the original's exit class.

    Args:
        run_job: job → result (any rank; it may read the files of the jobs it needs).
        write_job: (folder, job, result) → None, on rank 0 as each result arrives.
        jobs: rank 0's jobs in dealing order (other ranks' are ignored).
        folder: where the ``<name>.json`` markers are (``skip_done``).
        comm: MPI communicator or None (serial).
        progress: optional callable(job) after each job written or found cached.
        after: job → names of the jobs whose results it reads: it is dealt only once they are
            written (a rank that asks meanwhile waits). So a job that needs another starts as
            soon as that one is done, not after a whole round.
        prepare: job → the job to run, or None if nothing needs running (rank 0, when the job
            is about to be dealt, its needs written): for jobs whose cache key depends on
            earlier results.
    Returns:
        rank 0: the schedule, one {"job", "rank", "start", "end"} per job run (s from the
        queue's start; a job on another rank from when it was sent to when its result came
        back); other ranks: None.
    """
    rank = comm.rank if comm is not None else 0
    size = comm.size if comm is not None else 1
    todo = None
    if rank == 0:
        todo = [j for j in jobs if not (skip_done and (folder / f"{j.name}.json").exists())]
    sched = _Schedule(todo, after, prepare, progress) if rank == 0 else None
    failure = None
    if size == 1:
        while (job := sched.next_job()) is not None:
            sched.dealt(job, 0)
            r, fail = _attempt(run_job, job)      # one rank: nothing in flight to wait for
            sched.finished(job, write_job, folder, r, fail)
        failure = sched.failure
    elif rank == 0:
        failure = _serve_and_work(run_job, write_job, sched, folder, comm)
    else:
        msg = ("ask", None, None, None)
        while True:
            comm.send(msg, dest=0, tag=_TAG)
            job = comm.recv(source=0, tag=_TAG)
            if job is None:
                break
            r, fail = _attempt(run_job, job)
            msg = ("result", job, r, None) if fail is None else ("failed", job, None, fail[:3])
    if comm is not None:
        info = comm.bcast(None if failure is None else failure[:3], root=0)
        comm.barrier()
    else:
        info = None if failure is None else failure[:3]
    if info is not None:
        own = failure[3] if failure is not None and len(failure) > 3 else None
        raise JobFailed(*info) from own
    return sched.schedule() if sched is not None else None


def busy_fractions(schedule: list[dict], ranks: int, wall: float) -> list[float]:
    """Each rank's share of ``wall`` seconds spent in jobs (the schedule of :func:`run_jobs`)."""
    busy = np.zeros(ranks)
    for r in schedule:
        busy[r["rank"]] += r["end"] - r["start"]
    return (busy / wall).tolist() if wall > 0 else [0.0] * ranks


def _serve_and_work(run_job: Callable, write_job: Callable, sched: _Schedule, folder: Path,
                    comm):
    """Rank 0: hand out jobs from a thread while working through the same queue."""

    from mpi4py import MPI
    working = comm.size - 1
    waiting: list[int] = []            # ranks that asked and have no answer yet

    def serve_jobs():
        nonlocal working
        while working:
            st = MPI.Status()
            # Open MPI's blocking receive busy-polls: in this thread it would take a core from
            # the ranks' work (it halved their speed on 2 cores). Probe, and sleep in between.
            while not comm.Iprobe(source=MPI.ANY_SOURCE, tag=_TAG, status=st):
                if waiting:
                    break
                time.sleep(POLL_SECONDS)
            else:
                kind, job, r, fail = comm.recv(source=st.Get_source(), tag=_TAG)
                if kind in ("result", "failed"):
                    sched.finished(job, write_job, folder, r, fail)
                waiting.append(st.Get_source())
            for src in list(waiting):
                nxt = sched.next_job()
                if nxt is _WAIT:
                    continue
                if nxt is not None:
                    sched.dealt(nxt, src)
                comm.send(nxt, dest=src, tag=_TAG)
                waiting.remove(src)
                if nxt is None:
                    working -= 1
            if waiting:
                time.sleep(POLL_SECONDS)

    def serve():
        """Serve the jobs; if serving itself fails (e.g. a job that does not pickle), the queue
        fails and every rank is told to stop, rather than waiting for ever."""
        nonlocal working
        try:
            serve_jobs()
        except Exception as e:  # noqa: BLE001 - raised on every rank by run_jobs
            with sched.lock:
                if sched.failure is None:
                    sched.failure = ("job queue", 1, f"{type(e).__name__}: {e}", e)
            for src in waiting:
                comm.send(None, dest=src, tag=_TAG)
                working -= 1
            while working:          # the others stop at their next request; results are dropped
                st = MPI.Status()
                comm.recv(source=MPI.ANY_SOURCE, tag=_TAG, status=st)
                comm.send(None, dest=st.Get_source(), tag=_TAG)
                working -= 1

    server = threading.Thread(target=serve, name="fe-joint-jobs", daemon=True)
    server.start()
    while (job := sched.next_job()) is not None:
        if job is _WAIT:
            time.sleep(POLL_SECONDS)
            continue
        sched.dealt(job, 0)
        r, fail = _attempt(run_job, job)
        sched.finished(job, write_job, folder, r, fail)
    server.join()
    return sched.failure
