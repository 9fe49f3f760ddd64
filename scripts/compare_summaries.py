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
import math
import sys

#: keys whose values are wall-clock times
TIMING_KEYS = frozenset({"seconds", "timings_s", "wall_time", "time [s]", "cost"})


def differences(a, b, path: str = "") -> list[tuple[float, str, object, object]]:
    """(relative difference, path, a, b) for every leaf that differs (inf: structure differs)."""
    out = []
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k in TIMING_KEYS:
                continue
            if k not in a or k not in b:
                out.append((math.inf, f"{path}/{k}", a.get(k, "<missing>"), b.get(k, "<missing>")))
                continue
            out += differences(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [(math.inf, f"{path} (length)", len(a), len(b))]
        for i, (x, y) in enumerate(zip(a, b)):
            out += differences(x, y, f"{path}[{i}]")
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        if a != b and not (math.isnan(a) and math.isnan(b)):
            scale = max(abs(a), abs(b))
            out.append((abs(a - b) / scale if scale else math.inf, path, a, b))
    elif a != b:
        out.append((math.inf, path, a, b))
    return out


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
