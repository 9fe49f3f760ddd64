"""The MPI job queue of the dynamics stage: ranks take jobs from one queue, longest first; rank 0
serves it from a thread and writes each result as it arrives (a killed run loses only the jobs
in flight)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

from ..errors import JobFailed, classify

def _attempt(run_job: Callable, job) -> tuple[dict | None, tuple | None]:
    """``run_job(job)``, with a failure turned into (job, exit code, message) that can cross ranks."""
    try:
        return run_job(job), None
    except Exception as e:  # noqa: BLE001 - reported on every rank by run_jobs
        code, msg = classify(e)
        return None, (job.name, code, msg, e)


_TAG = 77
#: how often rank 0's queue server looks for requests, s (jobs take 5–600 s)
POLL_SECONDS = 0.05


def run_jobs(run_job: Callable, write_job: Callable, jobs: list, folder: Path, comm=None,
             progress=None, skip_done: bool = True) -> None:
    """Run the jobs not yet on disk, dealt dynamically to the ranks, longest first.

    With ``skip_done`` a job whose ``<name>.json`` marker exists is skipped; without it rank 0's
    ``jobs`` are run as given (the caller decided, e.g. :func:`fe_joint.study.jobs.plan_jobs`).

    Jobs differ in cost by 50× (a v3 fixed point vs a low-level FRF), so a static deal leaves
    ranks idle. Rank 0 works through the queue too; a server thread on rank 0 (MPI_THREAD_MULTIPLE)
    hands the next job to any rank that asks and writes each result as it arrives, so a killed
    run loses only the jobs in flight. Jobs are deterministic: which rank runs one does not change
    its result. A failed job stops the handing out; every rank then raises
    :class:`~fe_joint.errors.JobFailed` with the original's exit class.
    """
    rank = comm.rank if comm is not None else 0
    size = comm.size if comm is not None else 1
    todo = None
    if rank == 0:
        todo = [j for j in jobs if not (skip_done and (folder / f"{j.name}.json").exists())]
    if comm is not None:
        todo = comm.bcast(todo, root=0)
    failure = None
    if size == 1:
        for job in todo:
            r, failure = _attempt(run_job, job)
            if failure is not None:
                break
            write_job(folder, job, r)
            if progress is not None:
                progress(job)
    elif rank == 0:
        failure = _serve_and_work(run_job, write_job, todo, folder, comm, progress)
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
        if rank != 0:
            failure = None
        info = comm.bcast(None if failure is None else failure[:3], root=0)
        comm.barrier()
    else:
        info = None if failure is None else failure[:3]
    if info is not None:
        own = failure[3] if failure is not None and len(failure) > 3 else None
        raise JobFailed(*info) from own


def _serve_and_work(run_job: Callable, write_job: Callable, todo: list, folder: Path, comm,
                    progress):
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
            write_job(folder, job, r)
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
        r, fail = _attempt(run_job, job)
        finished(job, r, fail)
    server.join()
    return state["failure"]
