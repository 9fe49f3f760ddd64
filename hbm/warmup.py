"""Compile the friction march's numba kernels into their on-disk cache before a study needs them.

numba compiles a kernel for each argument signature on its first call and caches the machine
code next to the source (``hbm/__pycache__``). A fresh checkout's first default study compiled
six kernels on each rank in its first dynamics job (the plain repetition of neutral elements,
the period map of 2D orbits, a second signature of the row sensitivities and their helpers):
the first sweep took 19.8 s instead of 11.7 s (issue 16, session 27). ``scripts/setup`` runs
this module once per source version of the compiled code (a stamp in ``.venv``), so the study
meets a warm cache.

The problem is small but exercises what the study's joints do: two bodies on springs held by
twelve friction elements of graded preload (some open part of the cycle, some slip in 2D as
the x and y motions are out of phase), swept through the first resonance at a level where all
slip; the peak's motion marched by plain repetition (the neutral elements' path, with and
without the Jacobian); then its nonlinear mode over a few amplitudes (the backbones' shakedown
path).

Run: ``python -m hbm.warmup`` (prints the seconds it took).
"""
from __future__ import annotations

import time

import numpy as np

from . import FrictionContacts, HarmonicBalance, LinearStructure


def problem() -> tuple[HarmonicBalance, np.ndarray, float]:
    """The warm-up's harmonic balance, force amplitude (N) and first resonance (rad/s)."""
    m = np.array([1.0, 1.0, 1.0, 1.2, 1.2, 1.2]) * 1e-3          # t
    k = np.array([2.0e5, 3.1e5, 6.0e5, 3.0e5, 2.6e5, 7.5e5])     # N/mm, to ground
    K, M = np.diag(k), np.diag(m)
    ne = 12
    dofs = np.tile(np.array([[0, 1, 2], [3, 4, 5]]), (ne, 1, 1))
    n0 = np.geomspace(0.5, 60.0, ne)                              # N: light ones open
    c = FrictionContacts(dofs, kt=np.full(ne, 4e3), kn=np.full(ne, 8e3), mu=0.5, n0=n0,
                         gap=np.zeros(ne))
    hb = HarmonicBalance(LinearStructure(M, K, damping_ratio=0.01), c, harmonics=3, samples=128)
    lam = np.linalg.eigvalsh(np.linalg.solve(np.sqrt(M), np.linalg.solve(np.sqrt(M), hb.G.Kb).T))
    f = np.zeros(6)
    f[0], f[1], f[2] = 100.0, 60.0, 200.0
    return hb, f, float(np.sqrt(lam[0]))


def warm() -> float:
    """Run the warm-up; returns its seconds."""
    t0 = time.perf_counter()
    hb, force, w0 = problem()
    res = hb.frf(0.8 * w0, 1.2 * w0, force, dof=0, max_points=60)
    # the plain repetition (neutral elements, and the Jacobian it propagates) on the peak's motion
    u = res.solutions[int(np.argmax(res.amplitude))].contact @ hb.fourier.E.T    # (ne, 3, nt)
    for jacobian in (False, True):
        hb.c.march(u, np.arange(hb.c.ne), hb.fourier, jacobian=jacobian, newton=False)
    try:
        hb.nonlinear_mode(0, (1e-6, 1e-3), dof=0, n_points=6, partial=True)
    except Exception:           # noqa: BLE001 - the warm-up only has to call the kernels
        pass
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"[warmup] numba kernels ready ({warm():.1f} s)")
