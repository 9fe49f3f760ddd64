"""Speed against error of the study's numerical knobs, for the report.

Each table varies one knob with the others at the case's values and compares against the finest
setting computed in the same run: the global BEM grid (real contact area), the number of
harmonics and the AFT samples (first-harmonic amplitude at the baseline's resonance, middle level).
The HBM solves start cold at the peak frequency of the continued branch; where that branch folds
(softening friction joints do), a cold start lands on the lower of the co-existing solutions, so
the amplitudes in these tables can be below the FRF peak — the convergence in H and n_t they show
is that of the solution they found. Element count and mesh size need new FE models; their tables come from ``scripts/bench_fe.py``
and ``scripts/bench_geometry.py`` (README).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from . import contact as ms
from .frf import contacts, structure


def bem_grid(rm, case, grids=(64, 128, 256, 512)) -> list[dict]:
    """Real contact area and time of the global rough solve (Rq of the v-configurations) vs grid."""
    rows = []
    r = case.roughness
    for n in grids:
        rr = dataclasses.replace(r, grid=n)
        setup = ms.interface_setup(rm, case.geometry, case.material, rr)
        t0 = time.perf_counter()
        sc = ms.rough_contact(setup, r.v_rq_um, r.corr_length, r.seed, stiffness=False)
        rows.append({"grid": f"{n}²", "contact [%]": 100 * sc.contact_fraction,
                     "iterations": sc.iterations, "time [s]": time.perf_counter() - t0})
    ref = rows[-1]["contact [%]"]
    for row in rows:
        row["error vs finest [%]"] = 100 * abs(row["contact [%]"] - ref) / ref
    return rows


def hbm_knobs(rm, joint, level: float, mu: float, omega: float,
              harmonics=(1, 3, 5, 7), samples=(16, 32, 64, 128, 256), h_fixed: int = 3) -> dict:
    """First-harmonic response amplitude and solve time vs H and vs AFT samples at one frequency."""
    from hbm import ConvergenceError, HarmonicBalance
    c, _ = contacts(rm, joint, mu)
    s = structure(rm)
    force = np.zeros(rm.K.shape[0])
    force[rm.excitation_dof] = level

    def solve(H, nt):
        hb = HarmonicBalance(s, c, harmonics=H, samples=nt)
        t0 = time.perf_counter()
        try:
            sol = hb.solve(omega, force)
        except ConvergenceError as e:   # a table row says so; the run's results are not affected
            return float("nan"), f"did not converge ({e})"
        return sol.amplitude(rm.response_dof), time.perf_counter() - t0

    hr = []
    nt_h = max(256, 4 * (2 * max(harmonics) + 1))
    for H in harmonics:
        a, t = solve(H, nt_h)
        hr.append({"harmonics": H, "samples": nt_h, "amplitude [µm]": 1e3 * a, "time [s]": t})
    for row in hr:
        row["error vs H=%d [%%]" % harmonics[-1]] = 100 * abs(row["amplitude [µm]"] - hr[-1]["amplitude [µm]"]) / hr[-1]["amplitude [µm]"]
    sr = []
    for nt in samples:
        a, t = solve(h_fixed, nt)
        sr.append({"harmonics": h_fixed, "samples": nt, "amplitude [µm]": 1e3 * a, "time [s]": t})
    for row in sr:
        row["error vs finest [%]"] = 100 * abs(row["amplitude [µm]"] - sr[-1]["amplitude [µm]"]) / sr[-1]["amplitude [µm]"]
    return {"harmonics (baseline, middle level, one cold-start solve at its peak frequency)": hr,
            "AFT samples (baseline, middle level, one cold-start solve at its peak frequency)": sr}
