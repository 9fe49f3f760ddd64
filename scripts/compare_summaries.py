#!/usr/bin/env python3
"""Compare two runs' ``summary.json``: every number, key by key, ignoring timings.

    python scripts/compare_summaries.py A/summary.json B/summary.json [--rtol 1e-9]

Prints the largest relative differences and exits 1 if any number differs by more than
``--rtol`` (or a key exists on one side only). Keys that hold wall times (``seconds``,
``timings_s``, ``wall_time``) are skipped: they differ between any two runs.
"""
from __future__ import annotations

import argparse
import json
import sys

from fe_joint.report.compare import differences


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--rtol", type=float, default=1e-9)
    p.add_argument("--show", type=int, default=15, help="rows to print")
    args = p.parse_args(argv)
    with open(args.a) as fa, open(args.b) as fb:
        diffs = differences(json.load(fa), json.load(fb))
    diffs.sort(key=lambda d: -d[0])
    bad = [d for d in diffs if d[0] > args.rtol]
    for rel, path, x, y in diffs[: args.show]:
        print(f"{rel:10.3g}  {path}: {x!r} vs {y!r}")
    print(f"{len(diffs)} numbers differ, {len(bad)} by more than {args.rtol:g} (timings skipped)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
