#!/usr/bin/env python3
"""Benchmark of contact_bem: speed against error, peers side by side, rough contact, batched patches.

Sections (markdown tables on stdout):

1. Hertz sphere, non-periodic, n² = 128² … 1024²: CG iterations, solve time, errors vs Hertz.
2. Peers, same problem and same tolerance, when their interpreter is available (``--peer-python``):
   * ContactMechanics (``contactmechanics``, non-periodic FreeFFTElasticHalfSpace, Polonsky–Keer CG):
     Hertz 512² at pentol 1e-7 and 1e-8 mm, ours at tolerances of about equal (1e-6: peak error 7.0e-5
     vs 6.0e-5) or better accuracy (1e-7, 1e-8).
   * Tamaas (``tamaas``, periodic, PolonskyKeerRey): rough 256²/512² periodic surface, both with the
     continuous 2/(E*|k|) kernel (``periodic_kernel='continuous'``) and tol = 1e-8.
   The peers live in a throwaway venv, never in the project's::

       /usr/bin/python3 -m venv /tmp/peer && /tmp/peer/bin/pip install tamaas contactmechanics

   (installed fine here: tamaas 2.9.0, ContactMechanics 1.8.3 with SurfaceTopography 1.27.1; note that
   ContactMechanics' ``make_system`` takes ``surface`` first). They run in a subprocess.
3. Rough 256² on a 20 mm square at 30 kN, Rq = 1, 5, 10, 15 µm, λ = 0.5 mm (paper: 22.1 % … 2.7 %
   (10 µm) … 2.0 %): contact fraction, iterations, time.
4. 340 patches of 16² (the study's element count): k_n for all and one tangential cycle ±Q each
   (k_t at reversal + secant), batched along the leading axis; total time.

Timings are the median of ``--repeat`` runs (default 3); the peer and ours alternate in the same
run so that machine load hits both alike. ``--sections`` picks sections (default all).

Usage: ``.venv/bin/python scripts/bench_contact.py [--sizes 128 256 512 1024] [--threads 1]
[--peer-python /tmp/peer/bin/python] [--skip-peers] [--repeat 3] [--sections 1 2 3 4]``
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from contact_bem import (ElasticHalfSpace, Grid, extract_patches, gaussian_surface,  # noqa: E402
                         patch_stiffness, solve_normal)
from contact_bem import reference as ref  # noqa: E402

E, NU = 198400.0, 0.3
ES = E / (2 * (1 - NU ** 2))

CM_SCRIPT = r"""
import sys, time, json, numpy as np
from ContactMechanics import FreeFFTElasticHalfSpace
from ContactMechanics.Factory import make_system
from SurfaceTopography import Topography
h = np.load(sys.argv[1]); L = float(sys.argv[2]); es = float(sys.argv[3]); W = float(sys.argv[4])
n = h.shape[0]
t0 = time.perf_counter()
sub = FreeFFTElasticHalfSpace((n, n), es, (L, L))
system = make_system(substrate=sub, surface=Topography(-h, physical_sizes=(L, L)))
t1 = time.perf_counter()
res = system.minimize_proxy(external_force=W, pentol=float(sys.argv[6]))
t2 = time.perf_counter()
f = np.asarray(res.jac)
np.save(sys.argv[5], f / (L / n) ** 2)
print(json.dumps({"setup": t1 - t0, "solve": t2 - t1, "nit": int(res.nit)}))
"""

TM_SCRIPT = r"""
import sys, time, json, numpy as np, tamaas as tm
z = np.load(sys.argv[1]); L = float(sys.argv[2]); es = float(sys.argv[3]); W = float(sys.argv[4])
tol = float(sys.argv[5]); n = z.shape[0]
model = tm.ModelFactory.createModel(tm.model_type.basic_2d, [L, L], [n, n])
model.E = es; model.nu = 0.0
t0 = time.perf_counter()
solver = tm.PolonskyKeerRey(model, z, tol, tm.PolonskyKeerRey.pressure, tm.PolonskyKeerRey.pressure)
solver.setMaxIterations(20000)
t1 = time.perf_counter()
solver.solve(W / (L * L))
t2 = time.perf_counter()
np.save(sys.argv[6], np.asarray(model.traction).reshape(n, n))
print(json.dumps({"setup": t1 - t0, "solve": t2 - t1}))
"""


def table(header, rows):
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join("---" for _ in header) + "|")
    for r in rows:
        print("| " + " | ".join(str(c) for c in r) + " |")
    print()


def hertz_case(n, load=100.0, radius=10.0):
    hz = ref.hertz(load, radius, ES)
    L = 3.0 * hz.radius
    g = Grid((n, n), (L, L))
    X, Y = g.meshgrid()
    c = g.x[n // 2]
    return hz, g, ((X - c) ** 2 + (Y - c) ** 2) / (2 * radius)


def run_peer(python, script, args):
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(script)
    env = dict(os.environ, OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "1"))
    out = subprocess.run([python, f.name] + [str(a) for a in args], capture_output=True, text=True,
                         env=env, timeout=900)
    os.unlink(f.name)
    if out.returncode != 0:
        raise RuntimeError(out.stderr.strip().splitlines()[-1] if out.stderr else "peer failed")
    import json
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512, 1024])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--tol", type=float, default=1e-8)
    ap.add_argument("--peer-python", default="/tmp/peer/bin/python")
    ap.add_argument("--skip-peers", action="store_true")
    ap.add_argument("--patches", type=int, default=340)
    ap.add_argument("--repeat", type=int, default=3, help="timings are the median of this many runs")
    ap.add_argument("--sections", type=int, nargs="+", default=[1, 2, 3, 4], choices=[1, 2, 3, 4])
    a = ap.parse_args(argv)
    print(f"# contact_bem benchmark (threads={a.threads}, tol={a.tol:g}, {os.cpu_count()} cores, "
          f"median of {a.repeat})\n")

    def timed(fn):
        """(median wall time s, last result) of ``a.repeat`` calls of fn()."""
        ts, res = [], None
        for _ in range(max(a.repeat, 1)):
            t = time.perf_counter()
            res = fn()
            ts.append(time.perf_counter() - t)
        return float(np.median(ts)), res

    # 1 ---------------------------------------------------------------- Hertz, speed vs error
    if 1 in a.sections:
        print("## Hertz sphere, non-periodic (R = 10 mm, P = 100 N, domain 3a)\n")
    rows = []
    for n in (a.sizes if 1 in a.sections else []):
        hz, g, h = hertz_case(n)
        t0 = time.perf_counter()
        hs = ElasticHalfSpace(g, E, NU, threads=a.threads)
        hs.displacement(h)  # plans
        t1 = time.perf_counter()
        dt, ns = timed(lambda: solve_normal(hs, h, load=100.0, tol=a.tol))
        a_num = np.sqrt(ns.contact.sum() * g.cell_area / np.pi)
        rows.append([f"{n}²", ns.iterations, f"{t1 - t0:.2f}", f"{dt:.3f}",
                     f"{ns.pressure.max() / hz.peak_pressure - 1:+.1e}", f"{(a_num - hz.radius) / g.dx:+.2f}",
                     f"{ns.approach / hz.approach - 1:+.1e}", f"{ns.load / 100 - 1:+.0e}"])
    if rows:
        table(["grid", "iterations", "setup s", "solve s", "peak p err", "radius err (cells)",
               "approach err", "load err"], rows)

    # 2 ---------------------------------------------------------------- peers
    if not a.skip_peers and 2 in a.sections:
        print("## Peers, side by side\n")
        have = Path(a.peer_python).exists()
        rows = []
        tmp = Path(tempfile.mkdtemp())
        if not have:
            print(f"(peer interpreter {a.peer_python} not found: peers skipped)\n")
        else:
            # ContactMechanics: Hertz 512² non-periodic
            n = 512
            hz, g, h = hertz_case(n)
            np.save(tmp / "h.npy", h)
            try:
                hs = ElasticHalfSpace(g, E, NU, threads=a.threads)
                hs.displacement(h)
                # pairs of (peer penetration tolerance in mm, our relative tolerance): peak-pressure
                # errors 6.0e-5 vs 7.0e-5 (the closest to equal), 3.5e-5 vs 3.5e-6 and vs 1.2e-6
                for pentol, tol in ((1e-7, 1e-6), (1e-8, 1e-7), (1e-8, 1e-8)):
                    t_cm, t_us = [], []
                    for _ in range(max(a.repeat, 1)):  # alternate, so that machine load hits both
                        r = run_peer(a.peer_python, CM_SCRIPT,
                                     [tmp / "h.npy", g.size[0], ES, 100.0, tmp / "p_cm.npy", pentol])
                        t_cm.append(r["solve"])
                        t = time.perf_counter()
                        ns = solve_normal(hs, h, load=100.0, tol=tol)
                        t_us.append(time.perf_counter() - t)
                    r["solve"], dt = float(np.median(t_cm)), float(np.median(t_us))
                    p_cm = np.load(tmp / "p_cm.npy")
                    err_cm = abs(p_cm.max() / hz.peak_pressure - 1)
                    err = abs(ns.pressure.max() / hz.peak_pressure - 1)
                    dA = ns.contact.sum() / max((p_cm > 0).sum(), 1) - 1
                    rows.append([f"Hertz {n}² non-periodic", f"ContactMechanics (pentol {pentol:g} mm)",
                                 f"{r['solve']:.2f} ({r['nit']} it, peak err {err_cm:.1e})",
                                 f"{dt:.2f} (tol {tol:g}, {ns.iterations} it, peak err {err:.1e})",
                                 f"{r['solve'] / dt:.1f}×", f"{100 * dA:+.3f} %"])
            except Exception as exc:  # noqa: BLE001 - report, don't fail the benchmark
                rows.append([f"Hertz {n}²", "ContactMechanics", f"failed: {exc}", "", "", ""])
            # Tamaas: rough periodic
            for n in (256, 512):
                g = Grid((n, n), (20.0, 20.0))
                z = gaussian_surface(g, 0.010, 0.5, seed=0)
                np.save(tmp / "z.npy", z)
                try:
                    r = run_peer(a.peer_python, TM_SCRIPT, [tmp / "z.npy", 20.0, ES, 30e3, a.tol, tmp / "p_tm.npy"])
                    p_tm = np.load(tmp / "p_tm.npy")
                    hs = ElasticHalfSpace(g, E, NU, periodic=True, periodic_kernel="continuous", threads=a.threads)
                    hs.displacement(z)
                    dt, ns = timed(lambda: solve_normal(hs, z.max() - z, load=30e3, tol=a.tol))
                    dA = ns.contact.sum() / max((p_tm > 0).sum(), 1) - 1
                    rows.append([f"rough {n}² periodic, Rq 10 µm, 30 kN", "Tamaas PolonskyKeerRey",
                                 f"{r['solve']:.3f}", f"{dt:.3f} ({ns.iterations} it)", f"{r['solve'] / dt:.1f}×",
                                 f"{100 * dA:+.3f} %"])
                except Exception as exc:  # noqa: BLE001
                    rows.append([f"rough {n}²", "Tamaas", f"failed: {exc}", "", "", ""])
        if rows:
            table(["problem", "peer", "peer solve s", "contact_bem solve s", "speed-up", "contact area diff"], rows)

    if not {3, 4} & set(a.sections):
        return
    # 3 ---------------------------------------------------------------- rough, paper case
    g = Grid((256, 256), (20.0, 20.0), origin=(-10.0, -10.0))
    hs = ElasticHalfSpace(g, E, NU, threads=a.threads)
    z0 = gaussian_surface(g, 1.0, 0.5, seed=0)
    hs.displacement(z0)
    if 3 in a.sections:
        print("## Rough 256², 20 mm square, 30 kN, λ = 0.5 mm, non-periodic "
              "(paper: 22.1 % → 2.7 % (10 µm) → 2.0 %)\n")
        rows = []
        for rq_um in (1, 5, 10, 15):
            z = z0 * rq_um * 1e-3
            dt, ns = timed(lambda: solve_normal(hs, z.max() - z, load=30e3, tol=a.tol))
            rows.append([rq_um, f"{100 * ns.contact_fraction:.2f} %", ns.iterations, f"{dt:.3f}",
                         f"{ns.pressure.max():.0f}"])
        table(["Rq µm", "contact fraction", "iterations", "solve s", "max pressure MPa"], rows)
    if 4 not in a.sections:
        return

    # 4 ---------------------------------------------------------------- batched patches
    print(f"## {a.patches} patches of 16² (Rq 10 µm surface above), k_n + one tangential cycle each\n")
    rng = np.random.default_rng(0)
    z = z0 * 0.010
    centers = rng.uniform(-9.0, 9.0, (a.patches, 2))
    P = extract_patches(z, g, centers, (16, 16))
    loads = rng.uniform(0.0, 200.0, a.patches)
    ratio = rng.uniform(0.1, 0.9, a.patches)
    q = np.c_[ratio * 0.6 * loads, 0.2 * ratio * 0.6 * loads]
    from contact_bem import patch_normal_stiffness
    t = time.perf_counter()
    kn = patch_normal_stiffness(P, g.cell_size, E, NU, loads, threads=a.threads)
    t_n = time.perf_counter() - t
    t = time.perf_counter()
    res = patch_stiffness(P, g.cell_size, E, NU, 0.6, loads, q, threads=a.threads)
    t_all = time.perf_counter() - t
    ok = res.k_t > 0
    table(["patches", "k_n only s", "k_n + k_t (reversal + secant) s", "median k_n N/mm³",
           "median k_t/k_n", "median secant/k_t", "Mindlin k_t/k_n"],
          [[a.patches, f"{t_n:.2f}", f"{t_all:.2f}", f"{np.median(kn[kn > 0]):.3g}",
            f"{np.median(res.k_t[ok] / res.k_n[ok]):.3f}", f"{np.median(res.k_t_secant[ok] / res.k_t[ok]):.3f}",
            f"{2 * (1 - NU) / (2 - NU):.3f}"]])


if __name__ == "__main__":
    main()
