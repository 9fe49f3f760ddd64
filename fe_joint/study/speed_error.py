"""Speed against error of the study's numerical knobs, for the report.

Each table varies one knob with the others at the case's values and compares against the finest
setting computed in the same run: the global BEM grid (real contact area), the number of
harmonics and the AFT samples (the baseline's FRF peak at the middle level: frequency and
first-harmonic amplitude, each found by a short sweep through the peak, :data:`PEAK_BAND`; a
cold-start solve at the peak frequency landed on the lower branch of the fold, 158.5 vs 492 µm on
the default case, and measured the wrong solution's convergence). Element count and mesh size need new FE models; their tables come from ``scripts/bench_fe.py``
and ``scripts/bench_geometry.py`` (README).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from . import contact as ms
from .frf import SweepSettings, frf


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


#: the band of the speed-against-error sweeps, as fractions of the study curve's peak: the sweep
#: starts below the fold of a softening peak (where the response is single-valued) and passes
#: through the peak, so each row measures the FRF peak itself, not a cold start's lower branch
PEAK_BAND = (0.99, 1.005)


def hbm_knobs(rm, joint, level: float, settings: SweepSettings, f_peak_hz: float,
              harmonics=(1, 3, 5, 7), samples=(16, 32, 64, 128, 256), h_fixed: int = 3) -> dict:
    """The FRF peak (frequency, amplitude) and its sweep's time vs H and vs AFT samples.

    Args:
        rm: ReducedModel; joint: the configuration; level: N.
        settings: the study's sweep settings (μ, max_points; H, samples and band are varied).
        f_peak_hz: the study curve's peak at that level, Hz (centre of :data:`PEAK_BAND`).
        harmonics, samples: the values tried; h_fixed: H of the samples table.
    Returns:
        {table title: rows}, each row with H, samples, peak [Hz], amplitude [µm], time [s],
        points, and its errors against the finest row.
    """
    from hbm import ConvergenceError

    def row(H, nt):
        st = dataclasses.replace(settings, harmonics=H, samples=nt, band=PEAK_BAND)
        out = {"harmonics": H, "samples": nt}
        t0 = time.perf_counter()
        try:
            cr = frf(rm, joint, level, f_peak_hz, st)
        except ConvergenceError as e:   # a table row says so; the run's results are not affected
            return {**out, "peak [Hz]": float("nan"), "amplitude [µm]": float("nan"),
                    "time [s]": time.perf_counter() - t0, "points": 0, "note": f"not found ({e})"}
        return {**out, "peak [Hz]": cr.peak_hz, "amplitude [µm]": 1e3 * cr.peak_amplitude,
                "time [s]": time.perf_counter() - t0, "points": cr.n_points}

    nt_h = max(256, 4 * (2 * max(harmonics) + 1))
    hr = _errors([row(H, nt_h) for H in harmonics], f"H={harmonics[-1]}")
    sr = _errors([row(h_fixed, nt) for nt in samples], "finest")
    return {"harmonics (baseline, middle level, FRF peak by a sweep through it)": hr,
            "AFT samples (baseline, middle level, FRF peak by a sweep through it)": sr}


def _errors(rows: list[dict], ref_name: str) -> list[dict]:
    """Add each row's peak frequency and amplitude errors (%) against the last row."""
    f0, a0 = rows[-1]["peak [Hz]"], rows[-1]["amplitude [µm]"]
    for r in rows:
        r[f"f error vs {ref_name} [%]"] = 100 * abs(r["peak [Hz]"] - f0) / f0
        r[f"amplitude error vs {ref_name} [%]"] = 100 * abs(r["amplitude [µm]"] - a0) / a0
    return rows
