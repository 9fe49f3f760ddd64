"""Exit statuses and messages of the command line, and its logging."""
from __future__ import annotations

import logging

import pytest

import contact_bem
import hbm
from fe_joint.cli import main
from fe_joint.errors import CaseError, ConvergenceError, JobFailed, classify


@pytest.mark.parametrize("error, code", [
    (CaseError("roughness.grid = 3: allowed range [16, 4096]"), 2),
    (ConvergenceError("active set cycled"), 3),
    (hbm.ConvergenceError("Newton did not converge", 1e-3), 3),
    (contact_bem.ConvergenceError("normal solve", 1e-4), 3),
    (JobFailed("baseline@L1", 3, "did not converge: x"), 3),
    (KeyError("1.23457"), 1),
    (ValueError("an internal inconsistency"), 1),
    (TypeError("unsupported operand"), 1),
])
def test_exit_status_by_error_class(error: BaseException, code: int) -> None:
    got, msg = classify(error)
    assert got == code
    assert "\n" not in msg
    if code == 1:   # a bug: says so, and how to see the traceback
        assert msg.startswith("internal error:") and "--debug" in msg


def _bad_case(tmp_path) -> str:
    p = tmp_path / "bad.toml"
    p.write_text("[roughness]\ngrid = 3\n")
    return str(p)


def test_bad_case_exits_2_with_one_line(tmp_path, capsys) -> None:
    assert main(["check", _bad_case(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["fe-joint: error: roughness.grid = 3: allowed range [16, 4096]"]


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_is_honoured_before_and_after_the_subcommand(tmp_path, where: str) -> None:
    args = ["check", _bad_case(tmp_path)]
    args = ["--debug"] + args if where == "before" else args + ["--debug"]
    with pytest.raises(CaseError):      # the traceback, not the one-line message
        main(args)


def test_report_of_a_folder_that_is_not_a_run_is_bad_input(tmp_path, capsys) -> None:
    assert main(["report", str(tmp_path)]) == 2
    assert "not a finished run's folder" in capsys.readouterr().err


def test_library_info_logs_are_silenced_unless_debug(capsys) -> None:
    from fe_joint.logs import configure_logging
    root = logging.getLogger()
    saved = root.level, list(root.handlers)
    try:
        configure_logging(debug=False)
        root.setLevel(logging.INFO)            # as distutils' set_verbosity does while compiling
        logging.getLogger().info("x86_64-linux-gnu-gcc -c form.c")
        logging.getLogger("fe_joint.study").info("own progress")
        logging.getLogger("ffcx").warning("a real warning")
        err = capsys.readouterr().err
        assert "gcc" not in err and "own progress" in err and "a real warning" in err
        configure_logging(debug=True)
        logging.getLogger().info("x86_64-linux-gnu-gcc -c form.c")
        assert "gcc" in capsys.readouterr().err
    finally:
        for h in list(root.handlers):
            if h not in saved[1]:
                root.removeHandler(h)
        root.setLevel(saved[0])


# --- runs with stand-in stages: --force, the folder lock, Ctrl-C, numpy warnings (issue 14) ---

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from fe_joint.pipeline.runner import STAGES, read_stage_log
from fe_joint.runlock import LOCK_FILE, _proc_start


class _Stages:
    """The stand-in stages' record: names in the order they ran, and per-stage behaviour."""

    def __init__(self) -> None:
        self.log: list[str] = []
        self.stage: dict = {}       # name → function(ctx) run before the name is recorded

    def take(self) -> list[str]:
        out, self.log = self.log, []
        return out


@pytest.fixture
def calls(monkeypatch) -> _Stages:
    """Replace every stage by a stand-in that records its name (the pipeline's order and cache
    logic stay real)."""
    from fe_joint.pipeline import stages
    rec = _Stages()

    def make(name):
        def f(ctx):
            if name in rec.stage:
                rec.stage[name](ctx)
            rec.log.append(name)
            return {"n": len(rec.log)}
        return f
    for name in STAGES:
        monkeypatch.setitem(stages.REGISTRY, name, make(name))
    return rec


def _run(out: Path, *extra: str) -> int:
    return main(["run", "--preset", "quick", "--out", str(out), "--no-progress", *extra])


def test_force_reruns_the_requested_stages_and_those_after_them(tmp_path: Path, calls) -> None:
    out = tmp_path / "out"
    assert _run(out) == 0 and calls.take() == list(STAGES)
    assert _run(out) == 0 and calls.take() == []                 # all cached
    assert _run(out, "--stages", "fe", "--force") == 0
    assert calls.take() == ["fe"]                                 # mesh stays cached
    assert _run(out) == 0                                         # fe's output is new: the rest follows
    assert calls.take() == ["contact", "dynamics", "speed", "report"]
    assert _run(out, "--stages", "mesh,dynamics", "--force") == 0
    assert calls.take() == ["mesh", "fe", "contact", "dynamics"]  # forced mesh → fe, contact too
    assert _run(out, "--force") == 0 and calls.take() == list(STAGES)
    actions = [(e["stage"], e["action"]) for e in read_stage_log(out)]
    assert actions.count(("fe", "ran")) == 4 and actions.count(("mesh", "cached")) == 3


def _lock(out: Path, pid: int, start: int | None, host: str | None = None) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    p = out / LOCK_FILE
    p.write_text(json.dumps({"host": host or socket.gethostname(), "pid": pid, "start": start,
                             "started": "2024-01-01T00:00:00", "token": "other"}))
    return p


def test_second_run_is_refused_naming_the_holder(tmp_path: Path, capsys, calls) -> None:
    out = tmp_path / "out"
    holder = subprocess.Popen(["sleep", "60"])
    try:
        lock = _lock(out, holder.pid, _proc_start(holder.pid))
        text = lock.read_text()
        assert _run(out) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"pid {holder.pid}" in err[0] and socket.gethostname() in err[0]
        assert "--out" in err[0] and str(lock) in err[0]
        assert calls.take() == [] and sorted(p.name for p in out.iterdir()) == [LOCK_FILE]
        assert lock.read_text() == text                       # the holder's lock is untouched
        # a holder on another host cannot be checked: refused too
        _lock(out, 1, None, host="elsewhere.example")
        assert _run(out) == 2 and "host elsewhere.example" in capsys.readouterr().err
    finally:
        holder.kill()
        holder.wait()


@pytest.mark.parametrize("how", ["dead", "reused-pid"])
def test_stale_lock_is_taken_over_with_one_line(tmp_path: Path, capsys, calls, how: str) -> None:
    out = tmp_path / "out"
    proc = subprocess.Popen(["sleep", "60"] if how == "reused-pid" else ["true"])
    try:
        if how == "dead":
            proc.wait()
            _lock(out, proc.pid, 12345)
        else:   # the pid is alive but started later than the run that wrote the lock
            _lock(out, proc.pid, _proc_start(proc.pid) - 1)
        assert _run(out) == 0
        err = [l for l in capsys.readouterr().err.splitlines() if l.startswith("fe-joint:")]
        assert err == [f"fe-joint: taking over the lock of a run that is no longer running (host "
                       f"{socket.gethostname()}, pid {proc.pid}, since 2024-01-01T00:00:00)"]
        assert calls.take() == list(STAGES)
        assert not (out / LOCK_FILE).exists()                 # released at the end
    finally:
        proc.kill()
        proc.wait()


def test_lock_is_released_after_a_failure(tmp_path: Path, capsys, calls) -> None:
    out = tmp_path / "out"

    def boom(ctx):
        raise RuntimeError("a bug")
    calls.stage["contact"] = boom
    assert _run(out) == 1
    assert "internal error" in capsys.readouterr().err
    assert not (out / LOCK_FILE).exists()


def test_ctrl_c_keeps_finished_stages_and_exits_130(tmp_path: Path, capsys, calls) -> None:
    out = tmp_path / "out"

    def interrupt(ctx):
        raise KeyboardInterrupt
    calls.stage["contact"] = interrupt
    assert _run(out) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["fe-joint: interrupted: finished stages are kept; run again to resume"]
    assert not (out / LOCK_FILE).exists()
    assert calls.take() == ["mesh", "fe"]
    del calls.stage["contact"]
    assert _run(out) == 0
    assert calls.take() == ["contact", "dynamics", "speed", "report"]   # resumed


def test_numpy_warnings_are_one_line(tmp_path: Path, capsys, calls) -> None:
    import numpy as np

    def overflow(ctx):
        np.float64(1e300) * np.float64(1e300)
        np.log(np.zeros(3))
    calls.stage["contact"] = overflow
    assert _run(tmp_path / "a") == 0
    err = capsys.readouterr().err
    assert "RuntimeWarning" not in err
    notes = [l for l in err.splitlines() if l.startswith("fe-joint:")]
    assert len(notes) == 1 and notes[0].startswith("fe-joint: note: 2 numerical warnings from numpy")
    assert "overflow" in notes[0]

    def overflow_then_fail(ctx):
        overflow(ctx)
        raise hbm.ConvergenceError("Newton did not converge", 1e3)
    calls.stage["contact"] = overflow_then_fail
    assert _run(tmp_path / "b") == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "did not converge" in err[0] and "numerical warning" in err[0]


_SLOW_RUN = """
import sys, time
from fe_joint.pipeline import stages
def slow(ctx):
    print("slow stage started", flush=True)
    time.sleep(60)
stages.REGISTRY.update({k: (lambda ctx: {}) for k in stages.REGISTRY})
stages.REGISTRY["fe"] = slow
from fe_joint.cli import main
sys.exit(main(["run", "--preset", "quick", "--out", sys.argv[1], "--no-progress"]))
"""


def test_concurrent_run_refused_then_ctrl_c_ends_the_first(tmp_path: Path, capsys, calls) -> None:
    """A real second process: refused while the first runs; SIGINT ends the first with the
    one-line message, exit 130, no traceback, and frees the folder."""
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    first = subprocess.Popen([sys.executable, "-c", _SLOW_RUN, str(out)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert first.stdout.readline().strip().endswith("stage mesh ...")
        while "slow stage started" not in first.stdout.readline():
            pass
        assert _run(out) == 2
        err = capsys.readouterr().err
        assert f"pid {first.pid}" in err and len(err.strip().splitlines()) == 1
        first.send_signal(signal.SIGINT)
        _, stderr = first.communicate(timeout=30)
    finally:
        first.kill()
    assert first.returncode == 130
    assert "Traceback" not in stderr
    assert stderr.strip().splitlines() == ["fe-joint: interrupted: finished stages are kept; run again to resume"]
    assert not (out / LOCK_FILE).exists()
    assert _run(out) == 0 and calls.take() == ["fe", "contact", "dynamics", "speed", "report"]


def test_errors_are_printed_once_under_mpirun(tmp_path: Path) -> None:
    mpirun = subprocess.run(["which", "mpirun"], capture_output=True, text=True).stdout.strip()
    assert mpirun, "mpirun is part of the stack (python3-mpi4py's Open MPI)"
    bad = tmp_path / "bad.toml"
    bad.write_text("[roughness]\ngrid = 3\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path),
           "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    for args in (["check", str(bad)], ["run", str(bad), "--out", str(tmp_path / "o")]):
        r = subprocess.run([mpirun, "-q", "-n", "2", sys.executable, "-m", "fe_joint.cli", *args],
                           capture_output=True, text=True, env=env, timeout=120)
        lines = [l for l in (r.stdout + r.stderr).splitlines() if "fe-joint" in l]
        assert r.returncode == 2 and len(lines) == 1, (args, r.stdout, r.stderr)
    assert not (tmp_path / "o").exists()


@pytest.mark.mpi
def test_lock_outcome_is_shared_by_every_rank(tmp_path_factory, capsys, calls) -> None:
    """Under mpirun only rank 0 reads and takes the lock; every rank exits with its outcome and
    only rank 0 prints."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    d = Path(comm.bcast(str(tmp_path_factory.mktemp("lock")) if comm.rank == 0 else None, root=0))
    out = d / "out"
    holder = subprocess.Popen(["sleep", "60"]) if comm.rank == 0 else None
    try:
        if comm.rank == 0:
            _lock(out, holder.pid, _proc_start(holder.pid))
        comm.barrier()
        assert _run(out) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == (1 if comm.rank == 0 else 0)
        comm.barrier()
        if comm.rank == 0:
            holder.kill()
            holder.wait()
        comm.barrier()
        assert _run(out) == 0                                  # stale now: taken over
        err = capsys.readouterr().err
        assert ("taking over the lock" in err) == (comm.rank == 0)
    finally:
        if holder is not None:
            holder.kill()
            holder.wait()


def test_gmsh_import_keeps_the_ctrl_c_handler() -> None:
    """gmsh 4.8 sets SIGINT to SIG_DFL on import (Ctrl-C would kill the mesh stage without the
    message, leaving the lock); the CLI imports it keeping Python's handler."""
    code = ("import signal, sys\n"
            "from fe_joint.cli import _import_gmsh_keeping_sigint\n"
            "if sys.argv[1] == 'plain':\n    import gmsh\n"
            "else:\n    _import_gmsh_keeping_sigint()\n"
            "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    got = {how: subprocess.run([sys.executable, "-c", code, how], capture_output=True, text=True,
                               env=env).stdout.strip() for how in ("plain", "cli")}
    assert got == {"plain": "False", "cli": "True"}


def test_scripts_run_on_two_ranks_prints_one_line_for_bad_input(tmp_path):
    """The user's command on 2 ranks: a bad case file → exit 2, one line on stderr (no mpirun
    banner, not once per rank), nothing on stdout, nothing written."""
    import os
    import subprocess
    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "out"
    env = dict(os.environ, FE_JOINT_NP="2")
    r = subprocess.run([str(root / "scripts" / "run"), str(tmp_path / "missing.toml"), "--out", str(out)],
                       capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 2, r.stderr
    assert r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "missing.toml" in lines[0], r.stderr
    assert not out.exists()


def test_one_blas_thread_unless_the_user_sets_it() -> None:
    """Importing the command line sets one BLAS thread per process where the user set none
    (scripts/run's and scripts/test's choice, now also for fe-joint run alone), and keeps a
    value the user set."""
    import subprocess
    code = ("import os, sys\nimport fe_joint.cli\n"
            "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])")
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["1", "1"]
    env["OPENBLAS_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["2", "1"]


def test_run_script_counts_cores_without_omp_num_threads() -> None:
    """scripts/run's default rank count is the cores this process may use, also when
    OMP_NUM_THREADS=1 is exported (GNU nproc reports that variable instead: a one-rank run)."""
    line = next(x for x in (Path(__file__).parents[1] / "scripts" / "run").read_text().splitlines()
                if x.startswith("np="))
    env = {k: v for k, v in os.environ.items() if k != "FE_JOINT_NP"}
    env["OMP_NUM_THREADS"] = "1"
    out = subprocess.run(["bash", "-c", f'{line}\necho "$np"'], env=env, capture_output=True,
                         text=True, check=True).stdout
    assert int(out) == len(os.sched_getaffinity(0))
