#!/usr/bin/env python3
"""Benchmark of the GMRES preconditioners on the study's own FRF curves (issue 16).

Runs chosen curves of a finished run (its fe and contact stages are read, nothing is written)
with each preconditioner of ``hbm.preconditioner`` in turn, in the same process, and prints a
markdown table: points, curve time, linear solves, GMRES iterations per solve, preconditioner
set-ups, dense LUs (for a determinant's sign, after a GMRES failure, and straight after two
failures), and the peak of each run against the first preconditioner's.

Usage: OMP_NUM_THREADS=1 python scripts/bench_preconditioner.py RUN_DIR
       [--curves baseline@L2 v2@L1 ...] [--preconditioners element averaged two-level]

A curve is ``<configuration>@L<level index>`` of that run's fixed configurations (baseline,
smooth-ms, v1, v2). The peers run one after the other on one core: compare them in the same run.
"""
from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from fe_joint.case import load_case  # noqa: E402
from fe_joint.pipeline import stages  # noqa: E402
from fe_joint.pipeline.runner import StageContext  # noqa: E402
from fe_joint.study import frf as frfm  # noqa: E402
from hbm import HarmonicBalance  # noqa: E402
from hbm.preconditioner import PRECONDITIONERS  # noqa: E402


def run_curve(inp, config: str, level: int, preconditioner: str):
    """One FRF (``frf.frf_with_peak``) with the given preconditioner; (CurveResult, stats, s)."""
    made = []

    def factory(*a, **k):
        hb = HarmonicBalance(*a, preconditioner=preconditioner, **k)
        made.append(hb)
        return hb
    frfm.HarmonicBalance = factory
    try:
        t = time.perf_counter()
        cr, _ = frfm.frf_with_peak(inp.rm, inp.joints[config], inp.levels[level],
                                   inp.f_lin[config], inp.settings)
        dt = time.perf_counter() - t
    finally:
        frfm.HarmonicBalance = HarmonicBalance
    stats = functools.reduce(lambda a, b: {k: a[k] + b[k] for k in a}, [h.stats for h in made])
    return cr, stats, dt


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", help="a finished run's output folder (its fe and contact stages)")
    p.add_argument("--curves", nargs="+", default=["baseline@L2", "v2@L2", "v2@L1"])
    p.add_argument("--preconditioners", nargs="+", default=list(PRECONDITIONERS),
                   choices=list(PRECONDITIONERS))
    a = p.parse_args(argv)
    out = Path(a.run)
    ctx = StageContext(case=load_case(out / "case.toml"), out=out, comm=None, progress=False)
    inp, _ = stages.study_inputs(ctx)
    for name in a.curves:       # one line naming the bad curve, exit 2, before any work
        config, _, level = name.partition("@L")
        if config not in inp.joints or not level.isdigit() or int(level) >= len(inp.levels):
            p.error(f"--curves {name!r}: must be <configuration>@L<level> with a configuration of "
                    f"{', '.join(sorted(inp.joints))} and a level index 0..{len(inp.levels) - 1}")
    print(f"\n### GMRES preconditioners on {out} (H = {inp.settings.harmonics}, "
          f"n_t = {inp.settings.samples}, levels {', '.join(f'{x:.3g}' for x in inp.levels)} N)\n")
    print("| curve | preconditioner | points | curve (s) | linear solves | GMRES iterations / solve "
          "| set-ups | dense LUs (signs / GMRES failed / after failures) | peak (Hz) | peak (mm) "
          "| peak vs first, rel. (Hz / mm) | time ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in a.curves:
        config, level = name.split("@L")
        first = None
        for pc in a.preconditioners:
            cr, st, dt = run_curve(inp, config, int(level), pc)
            first = first or (cr, dt)
            dhz = abs(cr.peak_hz - first[0].peak_hz) / first[0].peak_hz
            damp = abs(cr.peak_amplitude - first[0].peak_amplitude) / first[0].peak_amplitude
            gm = st["gmres_iterations"] / max(st["linear_solves"], 1)
            print(f"| {name} | {pc} | {cr.n_points} | {dt:.1f} | {st['linear_solves']} | {gm:.1f} | "
                  f"{st['preconditioners']} | {st['sign_factorizations']} / {st['dense_fallbacks']} / "
                  f"{st['dense_after_fallback']} | {cr.peak_hz:.6f} | {cr.peak_amplitude:.6f} | "
                  f"{dhz:.1e} / {damp:.1e} | {dt / first[1]:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
