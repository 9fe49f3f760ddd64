#!/usr/bin/env python3
"""Run one case on 1 and on N ranks and compare what the dynamics made of the two FE models.

    python scripts/check_ranks.py [CASE.toml] [--preset quick] [--out DIR] [--np 2] [--small]

Runs ``fe-joint run`` serially into ``DIR/np1`` and under ``mpirun -n N`` into ``DIR/npN`` (a
finished folder is reused: the stages are cached), then prints

* the reduced model's largest relative differences (K, M, C: max |A1 - AN| / max |A1|) and the
  preload forces';
* per FRF curve: the peak frequency's and amplitude's relative differences and both point counts;
* per backbone: the largest relative difference of its frequencies and damping ratios, and both
  point counts;
* the largest difference of any other number of ``summary.json`` (``report.compare``).

Exit status 1 when a peak differs by more than ``--f-tol`` (1e-7) in frequency or ``--a-tol``
(1e-6) in amplitude, or a point count by more than ``--n-tol`` (5 %) — the tolerances of the
README's "In parallel" section; 2 when a run fails.

``--small``: the case of the MPI test (tests/test_workflow.py, ``MPI_CASE``): the quick preset
with one configuration (baseline, and the Rq sweep's v3 on its one surface, one pass), one level.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: the small case: quick preset, one configuration (baseline; the Rq sweep's v3 fixed point on
#: its one surface always runs, here with one pass), one level where the joint slips
SMALL_CASE = """name = "ranks-small"
[roughness]
rq_um = [15.0]
v_rq_um = 15.0
seeds = 1
material_hardness = 0.0
[dynamics]
configurations = ["baseline"]
levels = [15.0]
[contact]
kt_max_passes = 1
"""


def run(case: str | None, preset: str | None, out: Path, n: int) -> None:
    """``fe-joint run`` into ``out`` on ``n`` ranks (serial without mpirun when n == 1)."""
    cmd = [str(ROOT / ".venv" / "bin" / "fe-joint"), "run"] + ([case] if case else [])
    cmd += (["--preset", preset] if preset else []) + ["--out", str(out), "--no-progress"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    if n > 1:
        cmd = ["mpirun", "-q", "-n", str(n)] + cmd
    print("$", " ".join(cmd), flush=True)
    if subprocess.run(cmd, env=env).returncode != 0:
        raise SystemExit(2)


def rel(a, b) -> float:
    """max |a - b| / max |a| over arrays (0 when both are zero)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return float("inf")
    scale = np.max(np.abs(a)) if a.size else 0.0
    return float(np.max(np.abs(a - b)) / scale) if scale > 0 else float(np.any(a != b))


def model_rows(d1: Path, d2: Path) -> list[tuple[str, float]]:
    """The reduced models' relative differences (K, M, C, preload forces)."""
    from fe_joint.model.reduced_model import ReducedModel
    a = ReducedModel.load(str(d1 / "fe" / "reduced_model.h5"))
    b = ReducedModel.load(str(d2 / "fe" / "reduced_model.h5"))
    return [(name, rel(getattr(a, name), getattr(b, name)))
            for name in ("K", "M", "C", "preload_normal_force")]


def count_rel(n1: int, n2: int) -> float:
    """Relative difference of two point counts (of the larger)."""
    return abs(n1 - n2) / max(n1, n2, 1)


def compare(d1: Path, d2: Path, f_tol: float, a_tol: float, n_tol: float, label: str) -> int:
    """Print the tables; returns the number of rows beyond the tolerances."""
    from fe_joint.report.compare import differences
    s1 = json.loads((d1 / "summary.json").read_text())
    s2 = json.loads((d2 / "summary.json").read_text())
    bad = 0
    print(f"\nreduced model, 1 vs {label} ranks (max |ΔA| / max |A|)")
    for name, r in model_rows(d1, d2):
        print(f"  {name:22s} {r:9.2e}")
    print(f"\nFRF peaks, 1 vs {label} ranks (tolerances: f {f_tol:g}, amplitude {a_tol:g}, "
          f"points {100 * n_tol:g} %)")
    print(f"  {'curve':20s} {'peak f [Hz]':>14s} {'Δf/f':>9s} {'ΔA/A':>9s} {'points':>11s} {'Δn/n':>7s}")
    for name in sorted(set(s1["peaks"]) | set(s2["peaks"])):
        p, q = s1["peaks"].get(name), s2["peaks"].get(name)
        if p is None or q is None:
            print(f"  {name:20s} only in one run")
            bad += 1
            continue
        df = abs(p["peak_hz"] - q["peak_hz"]) / p["peak_hz"]
        da = abs(p["peak_amplitude"] - q["peak_amplitude"]) / p["peak_amplitude"]
        dn = count_rel(p["n_points"], q["n_points"])
        over = df > f_tol or da > a_tol or dn > n_tol
        bad += over
        print(f"  {name:20s} {p['peak_hz']:14.7f} {df:9.1e} {da:9.1e} "
              f"{p['n_points']:5d}/{q['n_points']:<5d} {100 * dn:6.1f}%{'  <-- beyond' if over else ''}")
    bbs1, bbs2 = s1.get("backbones") or {}, s2.get("backbones") or {}
    if bbs1 or bbs2:
        print(f"\nbackbones, 1 vs {label} ranks")
        print(f"  {'backbone':20s} {'Δf/f':>9s} {'Δζ/ζ':>9s} {'points':>11s}")
        for name in sorted(set(bbs1) | set(bbs2)):
            p, q = bbs1.get(name), bbs2.get(name)
            if p is None or q is None:
                print(f"  {name:20s} only in one run")
                bad += 1
                continue
            n = min(len(p["frequency_hz"]), len(q["frequency_hz"]))
            df = rel(p["frequency_hz"][:n], q["frequency_hz"][:n])
            dz = rel(p["zeta"][:n], q["zeta"][:n])
            over = df > f_tol or dz > a_tol or p["points"] != q["points"]
            bad += over
            print(f"  {name:20s} {df:9.1e} {dz:9.1e} {p['points']:5d}/{q['points']:<5d}"
                  f"{'  <-- beyond' if over else ''}")
    # everything else: counts and round-off diagnostics are shown, not judged
    rest = [d for d in differences(s1, s2) if not d[1].startswith(("/peaks/", "/backbones/"))]
    rest.sort(key=lambda d: -d[0])
    print(f"\nother numbers of summary.json: {len(rest)} differ" +
          (f", the largest {rest[0][0]:.1e} ({rest[0][1]})" if rest else ""))
    for r_, path, x, y in rest[1:6]:
        print(f"  {r_:9.1e}  {path}")
    return bad


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("case", nargs="?", help="case file (default: the embedded case)")
    p.add_argument("--preset", default="quick", help="preset (default quick; 'none' for none)")
    p.add_argument("--out", default="results/check_ranks", help="folder of the two runs")
    p.add_argument("--np", type=int, default=2, help="ranks of the parallel run")
    p.add_argument("--small", action="store_true", help="the MPI test's small case")
    p.add_argument("--f-tol", type=float, default=1e-7)
    p.add_argument("--a-tol", type=float, default=1e-6)
    p.add_argument("--n-tol", type=float, default=0.05)
    p.add_argument("--compare-only", action="store_true", help="compare two finished runs")
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    case = a.case
    if a.small:
        case = str(out / "small.toml")
        Path(case).write_text(SMALL_CASE)
    preset = None if a.preset == "none" else a.preset
    d1, d2 = out / "np1", out / f"np{a.np}"
    if not a.compare_only:
        run(case, preset, d1, 1)
        run(case, preset, d2, a.np)
    bad = compare(d1, d2, a.f_tol, a.a_tol, a.n_tol, str(a.np))
    print(f"\n{bad} rows beyond the tolerances" if bad else "\nall within the tolerances")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
