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

Exit status 1 when a peak differs by more than ``--f-tol`` (1e-6, the peak search's resolution
``frf.PEAK_XTOL``) in frequency or ``--a-tol`` (4e-6) in amplitude, or a point count by more than
``--n-tol`` (5 %) — the tolerances of the README's "In parallel" section; 2 when a run fails.
Backbones are compared with the same two (frequencies with ``--f-tol``, damping ratios with
``--a-tol``), looser than the MPI test's 1e-7 / 1e-5 for them.

``--perturb EPS --run DIR --curve NAME``: no runs on N ranks; instead the amplification of
round-off by the dynamics alone. The finished run ``DIR``'s reduced model gets a random
symmetric relative perturbation of K and M (A_ij (1 + EPS r_ij), r standard normal, one seed per
row of ``--seeds``), the curve NAME (e.g. ``baseline@L1``; a fixed configuration) is computed
again from it, and the table shows how far its stuck frequency, peak and point count moved from
the unperturbed model's. Exit 1 beyond the same tolerances.

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


def perturbed_model(rm, eps: float, seed: int):
    """A copy of the reduced model with K and M changed by a random symmetric relative ``eps``."""
    import copy
    out = copy.copy(rm)
    if eps == 0:
        return out
    g = np.random.default_rng(seed)
    for name in ("K", "M"):
        a = np.asarray(getattr(rm, name))
        r = g.standard_normal(a.shape)
        setattr(out, name, a * (1 + eps * 0.5 * (r + r.T)))
    return out


def perturb(run_dir: Path, curve: str, eps: float, seeds: int, f_tol: float, a_tol: float,
            n_tol: float) -> int:
    """The ``--perturb`` table (see the module docstring); returns the rows beyond tolerance."""
    from fe_joint.case import load_case
    from fe_joint.model.joint import stuck_modes
    from fe_joint.model.reduced_model import ReducedModel
    from fe_joint.study import contact as ms
    from fe_joint.study.configurations import choose_levels, fixed_joints
    from fe_joint.study.frf import SweepSettings, frf
    case = load_case(run_dir / "case.toml")
    rm = ReducedModel.load(str(run_dir / "fe" / "reduced_model.h5"))
    setup = ms.interface_setup(rm, case.geometry, case.material, case.roughness)
    surfaces, extra = ms.load_surfaces(run_dir / "contact" / "surfaces.npz")
    joints = fixed_joints(setup, surfaces, extra["kn_smooth"], case)
    levels, _ = choose_levels(rm, joints["baseline"], case)
    config, _, li = curve.partition("@L")
    joint, level = joints[config], levels[int(li)]
    print(f"{curve} ({level:.4g} N) of {run_dir}, K and M perturbed by {eps:g} (relative, random "
          "symmetric)")
    print(f"  {'seed':>4s} {'stuck f [Hz]':>14s} {'peak f [Hz]':>14s} {'peak A [mm]':>12s} "
          f"{'points':>6s} {'Δf_stuck':>9s} {'Δf':>9s} {'ΔA':>9s} {'Δn/n':>6s}")
    ref, bad = None, 0
    for seed in range(seeds + 1):
        m = perturbed_model(rm, eps if seed else 0.0, seed)
        f_lin = stuck_modes(m.K, m.M, m.pair_dofs, joint).frequency
        try:
            cr = frf(m, joint, level, f_lin, SweepSettings.from_case(case))
        except Exception as e:   # a failed sweep is a row of the table, and beyond tolerance
            print(f"  {seed:4d} {f_lin:14.8f} failed: {type(e).__name__}: {e}")
            bad += 1
            continue
        row = (f_lin, cr.peak_hz, cr.peak_amplitude, cr.n_points)
        if ref is None:
            ref = row
            print(f"  {seed:4d} {f_lin:14.8f} {cr.peak_hz:14.8f} {cr.peak_amplitude:12.8f} {cr.n_points:6d}")
            continue
        d = [abs(row[i] - ref[i]) / ref[i] for i in range(3)] + [count_rel(row[3], ref[3])]
        over = d[1] > f_tol or d[2] > a_tol or d[3] > n_tol
        bad += over
        print(f"  {seed:4d} {f_lin:14.8f} {cr.peak_hz:14.8f} {cr.peak_amplitude:12.8f} {cr.n_points:6d} "
              f"{d[0]:9.1e} {d[1]:9.1e} {d[2]:9.1e} {100 * d[3]:5.1f}%{'  <-- beyond' if over else ''}",
              flush=True)
    return bad


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("case", nargs="?", help="case file (default: the embedded case)")
    p.add_argument("--preset", default="quick", help="preset (default quick; 'none' for none)")
    p.add_argument("--out", default="results/check_ranks", help="folder of the two runs")
    p.add_argument("--np", type=int, default=2, help="ranks of the parallel run")
    p.add_argument("--small", action="store_true", help="the MPI test's small case")
    p.add_argument("--f-tol", type=float, default=1e-6)
    p.add_argument("--a-tol", type=float, default=4e-6)
    p.add_argument("--n-tol", type=float, default=0.05)
    p.add_argument("--compare-only", action="store_true", help="compare two finished runs")
    p.add_argument("--perturb", type=float, help="relative perturbation of K and M (no runs)")
    p.add_argument("--run", help="--perturb: a finished run's folder")
    p.add_argument("--curve", default="baseline@L1", help="--perturb: the curve to recompute")
    p.add_argument("--seeds", type=int, default=2, help="--perturb: perturbed models")
    a = p.parse_args(argv)
    if a.perturb is not None:
        if not a.run:
            p.error("--perturb needs --run DIR (a finished run)")
        bad = perturb(Path(a.run), a.curve, a.perturb, a.seeds, a.f_tol, a.a_tol, a.n_tol)
        print(f"\n{bad} rows beyond the tolerances" if bad else "\nall within the tolerances")
        return 1 if bad else 0
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
