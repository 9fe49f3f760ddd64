"""Command line: ``fe-joint run [CASE.toml] [--out DIR] [--preset P] [--stages ...]`` and
``fe-joint check CASE.toml``.

Bad input (case file, options) ends with one line ``fe-joint: error: …`` naming the key and
exit status 2, before anything is written; ``--debug`` shows the traceback instead. A solver that
does not converge ends with its residual and exit status 3. Under ``mpirun`` every rank runs the
stages and only rank 0 prints and writes.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .case import PRESETS, load_case
from .errors import EXIT_INPUT, CaseError
from .pipeline.runner import STAGES


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse's own default is a usage dump)
        print(f"fe-joint: error: {message}", file=sys.stderr)
        sys.exit(EXIT_INPUT)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="fe-joint", description="Multiscale nonlinear dynamics of a bolted lap joint "
                "with rough contact (dolfinx FE → FFT-BEM → harmonic balance).")
    p.add_argument("--debug", action="store_true", help="show tracebacks")
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
    r.add_argument("--debug", action="store_true", help="show tracebacks")
    c = sub.add_parser("check", help="validate a case file and print it with all defaults filled in")
    c.add_argument("case", help="case file (TOML)")
    c.add_argument("--preset", choices=list(PRESETS), default=None)
    c.add_argument("--debug", action="store_true", help="show tracebacks")
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
    import logging
    logging.basicConfig(level=logging.WARNING)   # FFCx's JIT logs every compile at INFO otherwise
    args = _parser().parse_args(argv)
    try:
        return _dispatch(args)
    except Exception as e:  # turned into one line unless --debug
        if args.debug:
            raise
        from .errors import classify
        code, msg = classify(e)
        return _fail(msg, code)


def _dispatch(args: argparse.Namespace) -> int:
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
    ctx = run_stages(case, out, stages, REGISTRY, comm=MPI.COMM_WORLD,
                     progress=not args.no_progress)
    if MPI.COMM_WORLD.rank == 0:
        print(f"[fe-joint] done: {out}", flush=True)
    del ctx
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
