#!/usr/bin/env python3
"""Demo 4 — friction damping by harmonic balance, checked against exact solutions.

The smallest friction oscillator: a mass on a spring, with a Jenkins element (a spring k_t in
series with a Coulomb slider that slips at f_s = μN) to the ground, driven by F cos ωt. The HBM
writes the response as a truncated Fourier series, evaluates the friction force in the time
domain (alternating frequency–time, AFT) and solves for the harmonics by Newton. With one
harmonic the answer has a closed form (the describing function); with more harmonics we compare
against an exact event-driven time integration.

Run: ``.venv/bin/python scripts/demo_friction_hbm.py``
"""
# %% [markdown]
# ## The oscillator
# Units N, mm, s, tonne. The friction element is the 3D element of the resonator with its second
# tangential and normal directions grounded (-1), so only t1 moves.
# %%
import time

import numpy as np

from hbm import FrictionContacts, HarmonicBalance, LinearStructure
from hbm.reference import StickSlipIntegrator, jenkins_frf_h1

m, k, c = 1e-3, 1e3, 2e-3          # t, N/mm, N·s/mm
kt, mu, n0 = 4e3, 0.5, 10.0        # N/mm, -, N  → f_s = 5 N
F = 8.0                            # N: mostly slipping near resonance
s = LinearStructure(np.array([[m]]), np.array([[k]]), np.array([[c]]))
contact = FrictionContacts(np.array([[[0, -1, -1], [-1, -1, -1]]]), kt=kt, kn=1e3, mu=mu, n0=n0)

# %% [markdown]
# ## One harmonic against the describing function
# %%
w_stuck = np.sqrt((k + kt) / m)
omegas = w_stuck * np.linspace(0.6, 1.1, 11)
hb1 = HarmonicBalance(s, contact, harmonics=1, samples=1024)
err = 0.0
for w in omegas:
    a_hbm = hb1.solve(w, np.array([F])).amplitude(0)
    a_ref = jenkins_frf_h1(w, m, k, c, kt, mu * n0, F)
    err = max(err, np.min(np.abs(a_ref - a_hbm)) / a_hbm)
print(f"H = 1: largest relative difference to the closed form over {len(omegas)} frequencies: {err:.1e}")

# %% [markdown]
# ## More harmonics against the exact time integration
# Near the peak the slider sticks and slips twice a period, so the force is far from harmonic;
# the first-harmonic amplitude converges as harmonics are added.
# %%
w = 0.8 * w_stuck
exact = StickSlipIntegrator([[m]], [[c]], [[k]], [(0, -1, kt, mu * n0)], [F], w)
X = exact.harmonics(exact.steady_state(), dof=0, H=1)
a_exact = float(np.hypot(X[1], X[2]))
print(f"exact time integration: amplitude {1e3 * a_exact:.4f} µm")
for H in (1, 3, 5):
    hb = HarmonicBalance(s, contact, harmonics=H, samples=256)
    t0 = time.perf_counter()
    a = hb.solve(w, np.array([F])).amplitude(0)
    dt = time.perf_counter() - t0
    print(f"H = {H}: amplitude {1e3 * a:.4f} µm ({1e3 * dt:.1f} ms), error vs exact "
          f"{abs(a - a_exact) / a_exact:.2e}")
# the number the test checks against the closed form
print(f"RESULT h1_relative_error = {err:.3e}")
