"""Differences between two runs' ``summary.json``: every number, key by key, timings skipped.

Used by ``scripts/compare_summaries.py`` and the reproducibility tests.
"""
from __future__ import annotations

import math
import re

#: a number as the report prints it inside a text (findings, verdict reasons)
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")

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
    elif isinstance(a, str) and isinstance(b, str) and a != b:
        out.append((_text_difference(a, b), path, a, b))
    elif a != b:
        out.append((math.inf, path, a, b))
    return out


def _text_difference(a: str, b: str) -> float:
    """Largest relative difference of the numbers printed in two texts that are otherwise the
    same (inf if the words differ): a peak 1.3e-4 apart prints as "602 µm" in one run and
    "601.9 µm" in the other."""
    if _NUMBER.sub("#", a) != _NUMBER.sub("#", b):
        return math.inf
    rel = 0.0
    for x, y in zip(map(float, _NUMBER.findall(a)), map(float, _NUMBER.findall(b))):
        scale = max(abs(x), abs(y))
        rel = max(rel, abs(x - y) / scale if scale else 0.0)
    return rel
