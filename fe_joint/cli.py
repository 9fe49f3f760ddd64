"""Command line: ``fe-joint run [CASE.toml] [--out DIR] [--preset P] [--stages ...] [--force]``,
``fe-joint check CASE.toml [--preset P]`` and ``fe-joint report DIR``.

Bad input (case file, options, an output folder that is a file or not writable, a folder
another run is writing) ends with one line ``fe-joint: error: …`` naming the key, file or folder,
and exit status 2, before anything is written; a solver that does not converge ends with its
residual and exit status 3; anything else is a bug: exit 1, "internal error: …"
(``fe_joint.errors``). Ctrl-C ends with "interrupted: …" and exit status 130 (SIGTERM, which
mpirun sends its ranks on Ctrl-C: 143); finished stages are kept. ``--debug`` (before or after
the subcommand) shows the traceback instead. Under ``mpirun`` every rank runs the stages; only
rank 0 prints, writes and holds the folder's lock, and every rank exits with the same status.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

# one BLAS thread per process (one rank per core, as scripts/run and scripts/test set it), unless
# the user chose otherwise; only effective before numpy loads OpenBLAS, hence here. Run serially
# with 2 BLAS threads on the 2 cores, the quick model's v2 top-level curve took 914 s instead of
# 31 s and rounded differently (its peak 6.6e-6 off the 1-thread value, which 1 and 2 ranks
# agree on to 2e-8)
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from .case import PRESETS, load_case, load_case_with_sources  # noqa: E402
from .errors import EXIT_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED, CaseError
from .logs import NumericWarnings, configure_logging
from .pipeline.runner import STAGES

INTERRUPTED = "interrupted: finished stages are kept; run again to resume"

#: environment variables an MPI launcher sets in every rank (Open MPI, MPICH/Hydra, PMIx)
_MPI_ENV = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse's own default is a usage dump)
        if _rank() == 0:
            print(f"fe-joint: error: {message}", file=sys.stderr)
        sys.exit(EXIT_INPUT)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="fe-joint", description="Multiscale nonlinear dynamics of a bolted lap joint "
                "with rough contact (dolfinx FE → FFT-BEM → harmonic balance).")
    p.add_argument("--debug", action="store_true", help="show tracebacks and fe-joint's debug log")
    # the subcommands' --debug must not reset a --debug given before them (argparse copies a
    # subparser's defaults over the namespace), hence SUPPRESS
    dbg = {"action": "store_true", "default": argparse.SUPPRESS, "help": "show tracebacks"}
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("run", help="run the pipeline on a case (default: the embedded resonator case)")
    r.add_argument("case", nargs="?", help="case file (TOML); default: the embedded resonator study")
    r.add_argument("--out", help="output folder (default: results/<case name>)")
    r.add_argument("--preset", choices=list(PRESETS), default=None,
                   help="quick: coarse (tests, demos); default: the case as written; paper: paper "
                        "resolution. Sets the keys the case file does not write.")
    r.add_argument("--stages", default="all",
                   help=f"comma-separated subset of {','.join(STAGES)} (earlier stages come from the cache "
                        "or are run), or 'all'")
    r.add_argument("--force", action="store_true",
                   help="rerun the requested stages even when cached (and so every stage after them)")
    r.add_argument("--no-progress", action="store_true", help="no progress bars")
    r.add_argument("--debug", **dbg)
    c = sub.add_parser("check", help="validate a case file and print every value with its source "
                       "(default, preset, file)")
    c.add_argument("case", help="case file (TOML)")
    c.add_argument("--preset", choices=list(PRESETS), default=None)
    c.add_argument("--debug", **dbg)
    rp = sub.add_parser("report", help="write the report of a finished run again from its artifacts "
                        "(no dolfinx needed)")
    rp.add_argument("out", help="the run's output folder")
    rp.add_argument("--debug", **dbg)
    return p


def _parse_stages(text: str) -> tuple[str, ...]:
    if text == "all":
        return STAGES
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    for n in names:
        if n not in STAGES:
            raise CaseError(f"--stages: unknown stage {n!r} (allowed: all or {', '.join(STAGES)})")
    if not names:
        raise CaseError(f"--stages: empty (allowed: all or {', '.join(STAGES)})")
    return names


def _comm():
    """MPI.COMM_WORLD if mpi4py is loaded, else None."""
    mpi = sys.modules.get("mpi4py.MPI")
    return mpi.COMM_WORLD if mpi is not None else None


def _rank() -> int:
    comm = _comm()
    return comm.rank if comm is not None else 0


def _init_mpi_if_launched() -> None:
    """Under mpirun, initialize MPI first, so that even an option or case-file error is printed
    by rank 0 alone (without MPI every rank would think it is rank 0)."""
    if any(v in os.environ for v in _MPI_ENV):
        from mpi4py import MPI  # noqa: F401


def _import_gmsh_keeping_sigint() -> None:
    """Import gmsh now, keeping Python's SIGINT handler: gmsh 4.8 sets SIGINT to SIG_DFL when
    its module is imported (until its first finalize), so Ctrl-C in the mesh stage would kill the
    process outright, without the message and leaving the lock. With Python's handler, Ctrl-C
    takes effect when the current gmsh call returns."""
    if "gmsh" in sys.modules:
        return
    try:
        prev = signal.getsignal(signal.SIGINT)
    except ValueError:
        return
    try:
        import gmsh  # noqa: F401
    except ImportError:   # `fe-joint report` and the non-FE stages need no gmsh
        return
    finally:
        if prev is not None:
            try:
                signal.signal(signal.SIGINT, prev)
            except ValueError:   # not the main thread
                pass


def _fail(msg: str, code: int) -> int:
    if _rank() == 0:
        print(f"fe-joint: error: {msg}", file=sys.stderr, flush=True)
    return code


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that the run ends like after Ctrl-C."""


def _on_sigterm(signum, frame) -> None:
    raise _Terminated()


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``fe-joint`` console script; returns the exit status."""
    _init_mpi_if_launched()
    args = _parser().parse_args(argv)
    configure_logging(args.debug)
    try:
        old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:   # not the main thread (an embedding application): leave signals alone
        old_term = None
    numeric = NumericWarnings()
    try:
        if args.debug:
            return _dispatch(args)
        with numeric:
            code = _dispatch(args)
        if numeric.count and _rank() == 0:   # one line, however many there were
            print(f"fe-joint: note: {numeric.summary()}", file=sys.stderr, flush=True)
        return code
    except (KeyboardInterrupt, _Terminated) as e:
        if _rank() == 0:
            print(f"fe-joint: {INTERRUPTED}", file=sys.stderr, flush=True)
        return EXIT_TERMINATED if isinstance(e, _Terminated) else EXIT_INTERRUPTED
    except Exception as e:  # turned into one line unless --debug
        if args.debug:
            raise
        from .errors import classify
        code, msg = classify(e)
        if numeric.count:   # the warnings may explain the failure: in the same line
            msg += f" (after {numeric.summary()})"
        return _fail(msg, code)
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "report":
        return _report(Path(args.out))
    if args.command == "check":
        from .case import case_to_toml
        case, sources = load_case_with_sources(args.case, preset=args.preset)
        if _rank() == 0:
            print(case_to_toml(case, sources), end="")
            print(f"# {args.case}: valid", file=sys.stderr)
        return 0
    stages = _parse_stages(args.stages)
    case = load_case(args.case, preset=args.preset)   # validated before anything is written
    if args.out:
        out, option = Path(args.out), "--out"
    else:
        out, option = Path("results") / case.name, "output folder (default; set --out)"
    from mpi4py import MPI

    _import_gmsh_keeping_sigint()
    from .pipeline.runner import run_stages
    from .pipeline.stages import PREPARATIONS, REGISTRY
    comm = MPI.COMM_WORLD
    lock = _claim(out, option, comm)
    try:
        ctx = run_stages(case, out, stages, REGISTRY, comm=comm, force=args.force,
                         progress=not args.no_progress, prepare=PREPARATIONS)
    finally:
        if lock is not None:
            lock.release()
    if comm.rank == 0:   # the last line names the run's warnings (pipeline.guards)
        from .pipeline.guards import done_line
        print(done_line(out, ctx.warnings, report="report" in ctx.summaries), flush=True)
    del ctx
    return 0


def _claim(out: Path, option: str, comm=None):
    """Make the output folder and take its lock on rank 0; every rank learns the outcome.

    Returns:
        the lock on rank 0 (None on the other ranks).
    Raises:
        CaseError: on every rank, when rank 0 could not (the folder is a file, not writable,
            or another run holds it).
    """
    from . import runlock
    rank = comm.rank if comm is not None else 0
    lock, outcome = None, None
    if rank == 0:
        try:
            runlock.prepare_out(out, option)
            lock, note = runlock.acquire(out, option)
            outcome = ("ok", note)
        except CaseError as e:
            outcome = ("input", str(e))
        except Exception as e:   # a bug: the other ranks must not wait for a broadcast forever
            outcome = ("bug", f"{type(e).__name__}: {e}")
    if comm is not None and comm.size > 1:
        outcome = comm.bcast(outcome, root=0)
    kind, text = outcome
    if kind == "input":
        raise CaseError(text)
    if kind == "bug":
        raise RuntimeError(f"output folder {str(out)!r}: {text}")
    if rank == 0 and text:
        print(f"fe-joint: {text}", file=sys.stderr, flush=True)
    return lock


def _report(out: Path) -> int:
    """``fe-joint report DIR``: the report of a finished run, from its artifacts and its case."""
    from .pipeline.runner import CASE_FILE
    from .report import write_report
    case_file = out / CASE_FILE
    if not case_file.is_file():
        raise CaseError(f"report: {str(out)!r} is not a finished run's folder (no {CASE_FILE})")
    case = load_case(case_file)
    lock = _claim(out, "report folder", _comm())
    try:
        if _rank() == 0:
            write_report(out, case)
            print(f"[fe-joint] report: {out / 'report.md'}", flush=True)
    finally:
        if lock is not None:
            lock.release()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
