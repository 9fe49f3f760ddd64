#!/usr/bin/env python3
"""Benchmark of the AFT march of the friction element: 2D slip accuracy and cost, old vs new.

"old" is hbm/friction.py at git revision --old (default 38d152c: backward-Euler radial return
at each sample), loaded from git into this run; "new" is the working tree (piecewise-cubic path,
Magnus/Möbius slip steps, switches located inside the steps). Prints markdown tables:

1. Error against n_t (H = 2, kt = 100 N/mm, kn = 1000 N/mm, mu = 0.3, n0 = 10 N):
   - 1D Jenkins, u = 0.05 cos(theta): first harmonic against the describing function;
   - 1D with separation (two elements): harmonics against ``coulomb_element_reference``;
   - circular orbit, kt R = 2 mu N: phase of the force against ``circular_orbit_force``;
   - six elliptic orbits with separation: harmonics against ``coulomb_element_reference``,
     and the floor = the same error for the DFT of the reference's own samples (aliasing of
     the force's kinks, which no update can remove).
   Harmonic errors are max over elements of max |F - F_ref| / max |F_ref|.
2. Cost per evaluation (min of interleaved repeats): synthetic joint of 300 elements (random 2D
   orbits, normal oscillation, n0 in [1, 20] N; H = 3, n_t = 128), and one element (1D, 2D).

3. With ``--march`` (only): the working tree's numpy march and Jacobian against the compiled
   march (hbm.friction_jit) with the numpy Jacobian and with the compiled one, same cases as 2.

Usage: OMP_NUM_THREADS=1 python scripts/bench_aft2d.py [--old REV] [--repeat 5] [--quick] [--march [--cpu]]

Measured here (shared 2-core machine, old vs new in the same run, --repeat 7; the cost ratios
drifted between 2.0 and 2.4 (F) and 1.6 and 2.2 (F + J) over four runs with the machine's load):

| case | n_t | old | new | floor (exact samples) |
|---|---|---|---|---|
| 1D Jenkins (describing function) | 32 | 2.5e-03 | 2.5e-03 |  |
| 1D Jenkins (describing function) | 64 | 5.1e-04 | 5.1e-04 |  |
| 1D Jenkins (describing function) | 128 | 8.1e-05 | 8.1e-05 |  |
| 1D Jenkins (describing function) | 256 | 1.2e-06 | 1.2e-06 |  |
| 1D Jenkins (describing function) | 512 | 5.0e-06 | 5.0e-06 |  |
| 1D with separation | 32 | 1.2e-03 | 8.9e-04 | 8.9e-04 |
| 1D with separation | 64 | 5.0e-04 | 2.0e-04 | 2.0e-04 |
| 1D with separation | 128 | 8.3e-05 | 3.8e-05 | 3.8e-05 |
| 1D with separation | 256 | 1.5e-05 | 9.9e-06 | 9.9e-06 |
| 1D with separation | 512 | 5.2e-06 | 3.4e-06 | 3.4e-06 |
| circular orbit (phase, rad) | 32 | 9.5e-02 | 5.2e-05 |  |
| circular orbit (phase, rad) | 64 | 4.8e-02 | 3.3e-06 |  |
| circular orbit (phase, rad) | 128 | 2.4e-02 | 2.0e-07 |  |
| circular orbit (phase, rad) | 256 | 1.2e-02 | 1.3e-08 |  |
| circular orbit (phase, rad) | 512 | 6.1e-03 | 8.0e-10 |  |
| ellipses with separation | 32 | 2.0e-02 | 6.4e-04 | 6.4e-04 |
| ellipses with separation | 64 | 1.0e-02 | 2.3e-04 | 2.3e-04 |
| ellipses with separation | 128 | 5.2e-03 | 7.6e-05 | 7.6e-05 |
| ellipses with separation | 256 | 2.6e-03 | 1.7e-05 | 1.7e-05 |
| ellipses with separation | 512 | 1.3e-03 | 3.2e-06 | 3.2e-06 |

| evaluate (ms) | old F | old F + J | new F | new F + J | new/old F | new/old F + J |
|---|---|---|---|---|---|---|
| 300 elements, H = 3, n_t = 128 | 86.65 | 180.08 | 204.52 | 387.13 | 2.36 | 2.15 |
| 1 element, 1D slip | 0.27 | 0.98 | 1.00 | 3.63 | 3.65 | 3.71 |
| 1 element, 2D slip | 0.29 | 1.19 | 0.91 | 1.83 | 3.13 | 1.54 |
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
import hbm  # noqa: E402
from hbm.fourier import Fourier  # noqa: E402
from hbm.reference import (circular_orbit_force, coulomb_element_reference,  # noqa: E402
                           elliptic_orbits_with_separation as ellipses,
                           jenkins_describing_function)

KT, KN, MU, N0 = 100.0, 1000.0, 0.3, 10.0
NTS = (32, 64, 128, 256, 512)


def load_old(rev: str):
    """hbm/friction.py at git revision rev as a module of the hbm package (None if unavailable)."""
    try:
        src = subprocess.run(["git", "-C", ROOT, "show", f"{rev}:hbm/friction.py"], check=True,
                             capture_output=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as fh:
        fh.write(src)
    spec = importlib.util.spec_from_file_location("hbm._friction_old", fh.name)
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = "hbm"
    spec.loader.exec_module(mod)
    os.unlink(fh.name)
    return mod


def contacts(mod, ne: int, **kw):
    par = dict(kt=KT, kn=KN, mu=MU, n0=N0)
    par.update(kw)
    return mod.FrictionContacts(np.tile([[0, 1, 2], [-1, -1, -1]], (ne, 1, 1)), **par)


def separation_1d(H: int = 2) -> np.ndarray:
    U = np.zeros((2, 3, 2 * H + 1))
    U[0, 0, 1], U[0, 0, 3], U[0, 2, 1] = 0.05, 0.02, -0.012
    U[1, 0, 2], U[1, 2, 1], U[1, 2, 2] = 0.08, 0.011, 0.004
    return U


def rel_err(F, Fr) -> float:
    return max(np.abs(F[e] - Fr[e]).max() / np.abs(Fr[e]).max() for e in range(len(F)))


def harmonic_rows(mods, name: str, U: np.ndarray, nts):
    """Rows (case, n_t, error per module, floor) against the reference integration."""
    H = (U.shape[-1] - 1) // 2
    fine = 2 * np.pi * np.arange(max(nts)) / max(nts)          # every grid is a subgrid of it
    ref = coulomb_element_reference(U, KT, KN, MU, N0, theta=fine)
    rows = []
    for nt in nts:
        f = Fourier(H, nt)
        sub = slice(None, None, max(nts) // nt)
        floor = rel_err(np.concatenate([f.to_freq(ref["T"][..., sub]),
                                        f.to_freq(ref["N"][..., sub] - N0)[:, None]], axis=1), ref["F"])
        errs = [rel_err(contacts(m, len(U)).evaluate(U, f, False)[0], ref["F"]) for m in mods]
        rows.append((name, nt, errs, floor))
    return rows


def jenkins_rows(mods, nts):
    A = 0.05
    U = np.zeros((1, 3, 5))
    U[0, 0, 1] = A
    a1, b1, _ = jenkins_describing_function(A, KT, MU * N0)
    rows = []
    for nt in nts:
        f = Fourier(2, nt)
        errs = []
        for m in mods:
            F = contacts(m, 1).evaluate(U, f, False)[0]
            errs.append(np.hypot(F[0, 0, 1] - a1, F[0, 0, 2] - b1) / np.hypot(a1, b1))
        rows.append(("1D Jenkins (describing function)", nt, errs, None))
    return rows


def circle_rows(mods, nts):
    R = 2.0 * MU * N0 / KT
    U = np.zeros((1, 3, 3))
    U[0, 0, 1] = U[0, 1, 2] = R
    _, phi = circular_orbit_force(0.0, R, KT, MU * N0)
    rows = []
    for nt in nts:
        f = Fourier(1, nt)
        errs = []
        for m in mods:
            F = contacts(m, 1).evaluate(U, f, False)[0]
            errs.append(abs(np.arctan2(-F[0, 0, 2], F[0, 0, 1]) - phi))
        rows.append(("circular orbit (phase, rad)", nt, errs, None))
    return rows


def synthetic(mod, ne: int = 300, H: int = 3, seed: int = 0):
    """Synthetic joint: random 2D orbits and normal oscillation (some elements separate)."""
    rng = np.random.default_rng(seed)
    c = mod.FrictionContacts(np.tile([[0, 1, 2], [-1, -1, -1]], (ne, 1, 1)), kt=200.0, kn=400.0,
                             mu=0.6, n0=rng.uniform(1.0, 20.0, ne))
    U = np.zeros((ne, 3, 2 * H + 1))
    U[:, :, 1:] = rng.normal(size=(ne, 3, 2 * H)) * np.array([0.05, 0.05, 0.01])[None, :, None] \
        / np.arange(1, 2 * H + 1)
    return c, U


def one_element(mod, twod: bool, H: int = 3):
    c = mod.FrictionContacts(np.array([[[0, 1, 2], [-1, -1, -1]]]), kt=KT, kn=KN, mu=0.1, n0=N0)
    U = np.zeros((1, 3, 2 * H + 1))
    U[0, 0, 1], U[0, 0, 2] = 0.05, 0.02
    if twod:
        U[0, 1, 2], U[0, 1, 3] = 0.03, 0.01
    return c, U


def cost_rows(mods, names, repeat: int):
    """(case, {(name, jacobian): seconds}) from interleaved repeats (min)."""
    f = Fourier(3, 128)
    cases = [("300 elements, H = 3, n_t = 128", synthetic, {}),
             ("1 element, 1D slip", one_element, {"twod": False}),
             ("1 element, 2D slip", one_element, {"twod": True})]
    out = []
    for label, make, kw in cases:
        objs = [make(m, **kw) for m in mods]
        n = 1 if make is synthetic else 20
        best = {}
        for _ in range(repeat):
            for name, (c, U) in zip(names, objs):
                for jac in (False, True):
                    c.evaluate(U, f, jac)
                    t = time.perf_counter()
                    for _ in range(n):
                        c.evaluate(U, f, jac)
                    best[name, jac] = min(best.get((name, jac), np.inf), (time.perf_counter() - t) / n)
        out.append((label, best))
    return out


#: the marches of march_rows: (label, USE_JIT, JIT_JACOBIAN) of hbm.friction
MARCHES = (("numpy", False, False), ("compiled march", True, False), ("compiled", True, True))


def march_rows(repeat: int, clock=time.perf_counter):
    """(case, {(march, jacobian): seconds}): the working tree's numpy march and Jacobian, its
    compiled march with the numpy Jacobian, and both compiled (hbm.friction_jit); interleaved
    repeats (min) timed by clock. The forward-only cost of the last two is the same march:
    measured once."""
    import hbm.friction as fr
    f = Fourier(3, 128)
    # (label, maker, its arguments, evaluations per timing: enough to time above the clock noise)
    cases = [("300 elements, H = 3, n_t = 128", synthetic, {}, 1),
             ("30 elements, H = 3, n_t = 128", synthetic, {"ne": 30}, 5),
             ("1 element, 2D slip", one_element, {"twod": True}, 20)]
    out = []
    for label, make, kw, n in cases:
        c, U = make(hbm, **kw)
        best = {}
        for _ in range(repeat):
            for name, jit, jit_jac in MARCHES:
                fr.USE_JIT, fr.JIT_JACOBIAN = jit, jit_jac
                for jac in ((False, True) if name != "compiled march" else (True,)):
                    c.evaluate(U, f, jac)
                    t = clock()
                    for _ in range(n):
                        c.evaluate(U, f, jac)
                    best[name, jac] = min(best.get((name, jac), np.inf), (clock() - t) / n)
        fr.USE_JIT, fr.JIT_JACOBIAN = True, True
        out.append((label, best))
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", default="38d152c", help="git revision of the old friction.py")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="n_t up to 256, 2 repeats")
    ap.add_argument("--march", action="store_true",
                    help="only the cost of the numpy march against the compiled one")
    ap.add_argument("--cpu", action="store_true",
                    help="--march timed in CPU time of this process (steadier on a shared machine)")
    a = ap.parse_args(argv)
    if a.march:
        print("| evaluate (ms) | numpy F | numpy F + J | compiled F | compiled F + numpy J "
              "| compiled F + J | numpy/compiled F | numpy/compiled F + J |")
        print("|---|---|---|---|---|---|---|---|")
        clock = time.process_time if a.cpu else time.perf_counter
        for label, b in march_rows(2 if a.quick else a.repeat, clock):
            print(f"| {label} | {b['numpy', False] * 1e3:.2f} | {b['numpy', True] * 1e3:.2f} | "
                  f"{b['compiled', False] * 1e3:.2f} | {b['compiled march', True] * 1e3:.2f} | "
                  f"{b['compiled', True] * 1e3:.2f} | {b['numpy', False] / b['compiled', False]:.1f} | "
                  f"{b['numpy', True] / b['compiled', True]:.1f} |")
        return
    nts = NTS[:-1] if a.quick else NTS
    old = load_old(a.old)
    mods, names = ([old, hbm] if old else [hbm]), (["old", "new"] if old else ["new"])
    if old is None:
        print(f"(git revision {a.old} not available: new only)")
    rows = (jenkins_rows(mods, nts) + harmonic_rows(mods, "1D with separation", separation_1d(), nts)
            + circle_rows(mods, nts) + harmonic_rows(mods, "ellipses with separation", ellipses(), nts))
    print("| case | n_t | " + " | ".join(names) + " | floor (exact samples) |")
    print("|---|---|" + "---|" * len(names) + "---|")
    for case, nt, errs, floor in rows:
        fl = "" if floor is None else f"{floor:.1e}"
        print(f"| {case} | {nt} | " + " | ".join(f"{e:.1e}" for e in errs) + f" | {fl} |")
    print()
    print("| evaluate (ms) | " + " | ".join(f"{n} {j}" for n in names for j in ("F", "F + J")) + " |"
          + (" new/old F | new/old F + J |" if old else ""))
    print("|---|" + "---|" * (2 * len(names) + (2 if old else 0)))
    for label, best in cost_rows(mods, names, 2 if a.quick else a.repeat):
        cells = [f"{best[n, j] * 1e3:.2f}" for n in names for j in (False, True)]
        if old:
            cells += [f"{best['new', j] / best['old', j]:.2f}" for j in (False, True)]
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
