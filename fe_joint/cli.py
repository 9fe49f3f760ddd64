"""Command line: ``fe-joint run [CASE.toml] [--out DIR] [--preset P] [--stages ...] [--force]``,
``fe-joint check CASE.toml`` and ``fe-joint report DIR``.

Bad input (case file, options) ends with one line ``fe-joint: error: …`` naming the key and
exit status 2, before anything is written; a solver that does not converge ends with its residual
and exit status 3; anything else is a bug: exit 1, "internal error: …" (``fe_joint.errors``).
``--debug`` (before or after the subcommand) shows the traceback instead. Under ``mpirun`` every
rank runs the stages and only rank 0 prints and writes.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .case import PRESETS, load_case
from .errors import EXIT_INPUT, CaseError
from .logs import configure_logging
from .pipeline.runner import STAGES


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse's own default is a usage dump)
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
                   help="quick: coarse (tests, demos); default: the case as written; paper: paper resolution")
    r.add_argument("--stages", default="all",
                   help=f"comma-separated subset of {','.join(STAGES)} (earlier stages come from the cache "
                        "or are run), or 'all'")
    r.add_argument("--force", action="store_true", help="rerun the requested stages even when cached")
    r.add_argument("--no-progress", action="store_true", help="no progress bars")
    r.add_argument("--debug", **dbg)
    c = sub.add_parser("check", help="validate a case file and print it with all defaults filled in")
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


def _rank() -> int:
    mpi = sys.modules.get("mpi4py.MPI")
    return mpi.COMM_WORLD.rank if mpi is not None else 0


def _fail(msg: str, code: int) -> int:
    if _rank() == 0:
        print(f"fe-joint: error: {msg}", file=sys.stderr, flush=True)
    return code


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``fe-joint`` console script; returns the exit status."""
    args = _parser().parse_args(argv)
    configure_logging(args.debug)
    try:
        return _dispatch(args)
    except Exception as e:  # turned into one line unless --debug
        if args.debug:
            raise
        from .errors import classify
        code, msg = classify(e)
        return _fail(msg, code)


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "report":
        return _report(Path(args.out))
    if args.command == "check":
        from .case import case_to_toml
        case = load_case(args.case, preset=args.preset)
        print(case_to_toml(case), end="")
        print(f"# {args.case}: valid", file=sys.stderr)
        return 0
    stages = _parse_stages(args.stages)
    case = load_case(args.case, preset=args.preset)   # validated before anything is written
    out = Path(args.out) if args.out else Path("results") / case.name
    from mpi4py import MPI

    from .pipeline.runner import run_stages
    from .pipeline.stages import REGISTRY
    ctx = run_stages(case, out, stages, REGISTRY, comm=MPI.COMM_WORLD, force=args.force,
                     progress=not args.no_progress)
    if MPI.COMM_WORLD.rank == 0:   # the last line names the run's warnings (pipeline.guards)
        from .pipeline.guards import done_line
        print(done_line(out, ctx.warnings, report="report" in ctx.summaries), flush=True)
    del ctx
    return 0


def _report(out: Path) -> int:
    """``fe-joint report DIR``: the report of a finished run, from its artifacts and its case."""
    from .case import load_case
    from .pipeline.runner import CASE_FILE
    from .report import write_report
    case_file = out / CASE_FILE
    if not case_file.is_file():
        raise CaseError(f"report: {str(out)!r} is not a finished run's folder (no {CASE_FILE})")
    write_report(out, load_case(case_file))
    print(f"[fe-joint] report: {out / 'report.md'}", flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
