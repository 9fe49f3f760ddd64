#!/usr/bin/env python3
"""Benchmark of the hbm package: speed against error, scaling with the number of elements, pyHarm.

Prints markdown tables:
1. 1-DOF Jenkins oscillator: first-harmonic amplitude error at a fixed frequency near the peak
   against the exact event-driven stick-slip integration, for H x n_t, with the time per point of
   a whole FRF curve (continuation).
2. pyHarm (pyharm-os) on the same oscillator, side by side, if a pyHarm interpreter is given
   (--pyharm-python, default /tmp/pyharm/bin/python when it exists); it runs in a subprocess.
3. Scaling: synthetic dense reduced structure (random orthogonal modes, a few low modes, n ~ 2100
   DOFs) with n_e friction elements, H = 3: setup, time per Newton iteration, per FRF curve through
   resonance, number of points, largest fraction of elements modeled nonlinearly.
4. Backbones (EPMC, issue 15) on the synthetic structure (600 DOFs, 40 kept modes, 40 elements):
   the cost of one backbone against the forced FRFs it replaces (one per level), with the
   synthesized peaks' error against each FRF's peak; and speed against error of the backbone
   over H x n_t (max relative error of omega and zeta at the same amplitudes against H = 7,
   n_t = 512).

Usage: OMP_NUM_THREADS=1 python scripts/bench_hbm.py [--quick] [--elements 10 40 160 340 680]
       [--skip-jenkins] [--skip-scaling] [--skip-backbone] [--backbone-levels 80 300 1000]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from hbm import FrictionContacts, HarmonicBalance, LinearStructure  # noqa: E402
from hbm.reference import StickSlipIntegrator, jenkins_frf_h1  # noqa: E402

try:  # rank-0 printing when launched under MPI (the benchmark itself is serial)
    from mpi4py import MPI
    RANK = MPI.COMM_WORLD.rank
except Exception:  # pragma: no cover
    RANK = 0

M1, K1, C1, KT1, FS1, F1, W_PEAK = 1.0, 1.0, 0.02, 1.0, 0.1, 0.3, 1.2

PYHARM_SCRIPT = r'''
import json, sys, time, numpy as np, pyHarm
def run(H, nt, w0, w1, ds):
    inp = {"system": {"type": "Base", "nh": H, "nti": nt},
           "substructures": {"sub": {"type": "onlydofs", "nnodes": 1, "ndofs": 1, "matching": [0]}},
           "connectors": {
             "mass": {"type": "GOElement", "connect": {"sub": [0]}, "dirs": [0], "dto": 2, "xo": 1, "k": %(m)r},
             "spring": {"type": "LinearSpring", "connect": {"sub": [0]}, "dirs": [0], "k": %(k)r},
             "damper": {"type": "LinearDamper", "connect": {"sub": [0]}, "dirs": [0], "k": %(c)r},
             "jenkins": {"type": "Jenkins", "connect": {"sub": [0]}, "dirs": [0], "mu": %(fs)r, "N0": 1.0, "k": %(kt)r},
             "force": {"type": "CosinusForcing", "connect": {"sub": [0]}, "dirs": [0], "amp": %(F)r}},
           "analysis": {"frf": {"study": "frf", "puls_inf": w0, "puls_sup": w1, "ds0": ds, "ds_max": ds,
                                "ds_min": 1e-8, "verbose": False}}}
    ma = pyHarm.Maestro(inp)
    t = time.perf_counter(); ma.operate(); dt = time.perf_counter() - t
    sols = [s for s in ma.nls["frf"].SolList if s.flag_accepted]
    return dt, [s.x[-1] for s in sols], [float(np.hypot(s.x[1], s.x[2])) for s in sols]
a = json.loads(sys.argv[1])
run(a["H"], a["nt"], 1.15, 1.25, 0.05)                       # warm-up: numba compilation
dt, om, amp = run(a["H"], a["nt"], 0.8, 1.8, a["ds"])
_, om1, amp1 = run(a["H"], a["nt"], %(wpk)r, %(wpk)r + 0.05, 0.05)   # first point at the check frequency
print(json.dumps({"time": dt, "points": len(om), "omega": om, "amp": amp, "amp_check": amp1[0]}))
''' % dict(m=M1, k=K1, c=C1, fs=FS1, kt=KT1, F=F1, wpk=W_PEAK)


def say(*a):
    if RANK == 0:
        print(*a, flush=True)


def jenkins_solver(H, nt):
    s = LinearStructure([[M1]], [[K1]], [[C1]])
    c = FrictionContacts(np.array([[[0, -1, -1], [-1, -1, -1]]]), kt=KT1, kn=1.0, mu=FS1, n0=1.0)
    return HarmonicBalance(s, c, harmonics=H, samples=nt)


def bench_jenkins(Hs, nts, pyharm_python):
    ig = StickSlipIntegrator([[M1]], [[C1]], [[K1]], [(0, -1, KT1, FS1)], [F1], W_PEAK)
    X = ig.harmonics(ig.steady_state(), 0, H=1)
    A_exact = float(np.hypot(X[1], X[2]))
    say(f"\n### 1-DOF Jenkins oscillator (m={M1}, k={K1}, c={C1}, kt={KT1}, fs={FS1}, F={F1})\n")
    say(f"Exact stick-slip integration at w = {W_PEAK} rad/s: first-harmonic amplitude {A_exact:.8f}. "
        "Curve: continuation over w in [0.8, 1.8] rad/s.\n")
    say("| code | H | n_t | error at w_check | FRF points | time / point (ms) |")
    say("|---|---|---|---|---|---|")
    for H in Hs:
        for nt in nts:
            hb = jenkins_solver(H, nt)
            A = hb.solve(W_PEAK, np.array([F1])).amplitude(0)
            hb.frf(0.8, 1.8, np.array([F1]), dof=0)             # warm-up
            t = time.perf_counter()
            frf = hb.frf(0.8, 1.8, np.array([F1]), dof=0)
            dt = time.perf_counter() - t
            say(f"| hbm | {H} | {nt} | {abs(A - A_exact) / A_exact:.2e} | {len(frf.omega)} | "
                f"{1e3 * dt / len(frf.omega):.2f} |")
    if pyharm_python and os.path.exists(pyharm_python):
        for H, nt in [(1, 128), (3, 128)]:
            try:
                out = subprocess.run([pyharm_python, "-c", PYHARM_SCRIPT, json.dumps(dict(H=H, nt=nt, ds=0.05))],
                                     capture_output=True, text=True, timeout=600, cwd="/tmp")
                r = json.loads(out.stdout.strip().splitlines()[-1])
                err = abs(r["amp_check"] - A_exact) / A_exact
                say(f"| pyHarm {'' if H else ''}| {H} | {nt} | {err:.2e} | {r['points']} | "
                    f"{1e3 * r['time'] / r['points']:.2f} |")
            except Exception as e:  # pragma: no cover - optional peer
                say(f"| pyHarm | {H} | {nt} | failed: {type(e).__name__} | | |")
    else:
        say("| pyHarm | - | - | not installed (give --pyharm-python) | | |")
    # the H = 1 closed form along the hbm curve (accuracy of the continuation itself)
    hb = jenkins_solver(1, 1024)
    frf = hb.frf(0.8, 1.8, np.array([F1]), dof=0)
    ref = np.array([jenkins_frf_h1(w, M1, K1, C1, KT1, FS1, F1)[0] for w in frf.omega])
    say(f"\nH = 1, n_t = 1024 curve vs the closed-form describing-function FRF: max relative error "
        f"{np.max(np.abs(frf.amplitude - ref) / ref):.1e} over {len(frf.omega)} points.")


def synthetic(ne, n, seed=0):
    """Dense synthetic reduced structure: random orthogonal mode shapes, 5 low modes (250-1700 Hz)
    and a stiff remainder, elements grounding DOF triples (the interface flexibility is dense)."""
    rng = np.random.default_rng(seed)
    m = 1e-4                                                        # tonne per DOF
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    w = np.concatenate([2 * np.pi * np.array([250., 540., 800., 1200., 1700.]),
                        2 * np.pi * np.geomspace(3e3, 1e5, n - 5)])
    K = (Q * (m * w**2)) @ Q.T
    K = 0.5 * (K + K.T)
    dofs = np.full((ne, 2, 3), -1)
    dofs[:, 0, :] = (np.arange(3 * ne) + 10).reshape(ne, 3)
    c = FrictionContacts(dofs, kt=200.0, kn=400.0, mu=0.6, n0=rng.uniform(1.0, 20.0, ne))
    s = LinearStructure(m * np.eye(n), K, damping_ratio=0.005, n_modes=40)
    f = np.zeros(n)
    f[0] = 1.0
    return s, c, f


def bench_scaling(elements, n, force, ds_max):
    say(f"\n### Scaling: synthetic dense reduced structure, n = {n} DOFs, 40 kept modes, H = 3, n_t = 128, "
        f"force {force:g} N, curve 0.8-1.1 x first base frequency\n")
    say("| n_e | setup (s) | FRF points | Newton iterations | time / iteration (ms) | curve (s) | "
        "max nonlinear elements | Krylov iterations |")
    say("|---|---|---|---|---|---|---|---|")
    for ne in elements:
        s, c, f = synthetic(ne, n)
        t = time.perf_counter()
        hb = HarmonicBalance(s, c, harmonics=3, samples=128)
        setup = time.perf_counter() - t
        w1 = np.sqrt(hb.G.lam[0])
        t = time.perf_counter()
        kw = {} if ds_max is None else {"ds_max": ds_max}
        frf = hb.frf(0.8 * w1, 1.1 * w1, force * f, dof=0, max_points=2000, **kw)
        dt = time.perf_counter() - t
        nnl = max(s_.n_nonlinear for s_ in frf.solutions)
        say(f"| {ne} | {setup:.1f} | {len(frf.omega)} | {frf.newton_iterations} | "
            f"{1e3 * dt / max(frf.newton_iterations, 1):.0f} | {dt:.1f} | {nnl} ({100 * nnl / ne:.0f} %) | "
            f"{hb.stats['gmres_iterations']} |")


def _frf_peak(hb, force, w_lo, w_hi):
    """Largest point of a forced FRF, polished by Brent on the amplitude: (omega, amplitude, s)."""
    from scipy.optimize import minimize_scalar
    t = time.perf_counter()
    fr = hb.frf(w_lo, w_hi, force, dof=0, max_points=2000)
    k = int(np.argmax(fr.amplitude))
    last = [fr.solutions[k]]

    def neg(om):
        last[0] = hb.solve(om, force, guess=last[0])
        return -last[0].amplitude(0)
    r = minimize_scalar(neg, bounds=(fr.omega[max(k - 1, 0)], fr.omega[min(k + 1, len(fr.omega) - 1)]),
                        method="bounded", options={"xatol": 1e-9 * fr.omega[k]})
    return r.x, -r.fun, time.perf_counter() - t, len(fr.omega)


def bench_backbone(levels, Hs, nts, n=600, ne=40, n_points=40):
    """Backbone cost vs the forced FRFs it replaces, and H x n_t speed against error."""
    from hbm import synthesize
    from hbm.nonlinear_mode import NonlinearModeProblem
    s, c, f = synthetic(ne, n)
    hb = HarmonicBalance(s, c, harmonics=3, samples=128)
    w1 = np.sqrt(hb.G.lam[0])
    on = NonlinearModeProblem(hb, 0).onset_amplitude()
    amps = (0.3 * on, 300 * on)
    say(f"\n### Backbone vs forced FRFs: synthetic structure, n = {n} DOFs, 40 kept modes, {ne} elements, "
        f"H = 3, n_t = 128, response and force at DOF 0\n")
    t = time.perf_counter()
    bb = hb.nonlinear_mode(0, amps, dof=0, n_points=n_points)
    t_bb = time.perf_counter() - t
    say(f"Backbone: {bb.omega.size} points from 0.3x to 300x the slip onset ({bb.modal_amplitude[0]:.3g} to "
        f"{bb.modal_amplitude[-1]:.3g} mm·t^0.5), {t_bb:.1f} s, {int(bb.iterations.sum())} Newton iterations.\n")
    say("| level (N) | FRF points | FRF + polish (s) | FRF peak (rad/s) | FRF peak amp (mm) | "
        "SNMS error f | SNMS error amp | mode-only error f | mode-only error amp | SNMS (ms) |")
    say("|---|---|---|---|---|---|---|---|---|---|")
    total = 0.0
    for F in levels:
        w, a, dt, npts = _frf_peak(hb, F * f, 0.9 * w1, 1.05 * w1)
        total += dt
        t = time.perf_counter()
        sr = synthesize(bb, F * f)
        ts = time.perf_counter() - t
        s0 = synthesize(bb, F * f, background=False)
        say(f"| {F:g} | {npts} | {dt:.1f} | {w:.4f} | {a:.5g} | {sr.peak_omega / w - 1:.1e} | "
            f"{sr.peak_amplitude / a - 1:.1e} | {s0.peak_omega / w - 1:.1e} | {s0.peak_amplitude / a - 1:.1e} | "
            f"{1e3 * ts:.0f} |")
    say(f"\nOne backbone {t_bb:.1f} s against {len(levels)} FRFs {total:.1f} s.")
    say(f"\n### Backbone speed against error (same structure; reference H = 7, n_t = 512; "
        f"{n_points} points, 0.3x-300x onset)\n")
    ref = HarmonicBalance(s, c, harmonics=7, samples=512).nonlinear_mode(0, amps, dof=0, n_points=n_points)
    say("| H | n_t | backbone (s) | max error omega | max error zeta |")
    say("|---|---|---|---|---|")
    for H in Hs:
        for nt in nts:
            if nt < 2 * (2 * H + 1):
                continue
            t = time.perf_counter()
            b = HarmonicBalance(s, c, harmonics=H, samples=nt).nonlinear_mode(0, amps, dof=0, n_points=n_points)
            dt = time.perf_counter() - t
            say(f"| {H} | {nt} | {dt:.1f} | {np.max(np.abs(b.omega / ref.omega - 1)):.1e} | "
                f"{np.max(np.abs(b.zeta / ref.zeta - 1)):.1e} |")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="small tables (H in 1,3; n_t in 64,128; n_e in 10,40)")
    p.add_argument("--elements", type=int, nargs="+", default=[10, 40, 160, 340, 680])
    p.add_argument("--dofs", type=int, default=2100, help="synthetic structure size")
    p.add_argument("--force", type=float, default=3000.0, help="synthetic excitation amplitude, N")
    p.add_argument("--ds-max", type=float, default=None, help="largest arc-length step (relative; solver default 0.1)")
    p.add_argument("--pyharm-python", default="/tmp/pyharm/bin/python",
                   help="interpreter with pyharm-os installed (skipped if missing)")
    p.add_argument("--skip-jenkins", action="store_true")
    p.add_argument("--skip-scaling", action="store_true")
    p.add_argument("--skip-backbone", action="store_true")
    p.add_argument("--backbone-levels", type=float, nargs="+", default=[80.0, 300.0, 1000.0],
                   help="synthetic structure's levels for the backbone vs FRF table, N")
    a = p.parse_args(argv)
    Hs, nts = ([1, 3], [64, 128]) if a.quick else ([1, 3, 5, 7], [32, 64, 128, 256])
    elements = [10, 40] if a.quick else a.elements
    if not a.skip_jenkins:
        bench_jenkins(Hs, nts, a.pyharm_python)
    if not a.skip_scaling:
        bench_scaling(elements, max(a.dofs, 3 * max(elements) + 20), a.force, a.ds_max)
    if not a.skip_backbone:
        bench_backbone(a.backbone_levels, [1, 3] if a.quick else [1, 3, 5],
                       [64, 128] if a.quick else [32, 64, 128, 256])


if __name__ == "__main__":
    main()
