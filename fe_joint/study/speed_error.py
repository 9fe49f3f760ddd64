"""Speed against error of the study's numerical knobs, for the report.

Each table varies one knob with the others at the case's values and compares against the finest
setting computed in the same run: the global BEM grid (real contact area), the number of
harmonics and the AFT samples (the baseline's FRF peak at the middle level: frequency and
first-harmonic amplitude, each found by a short sweep through the peak, :data:`PEAK_BAND`; a
cold-start solve at the peak frequency landed on the lower branch of the fold, 158.5 vs 492 µm on
the default case, and measured the wrong solution's convergence), and the element count: the
lap mesh size sets how many friction elements the interface has (:func:`mesh_rows`, on reduced
models the ``speed`` stage builds at coarser lap meshes; the FE side of mesh convergence is in
``scripts/bench_fe.py`` and ``scripts/bench_geometry.py``).
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


#: lap mesh sizes of the element-count table, as multiples of the case's (coarser only: a finer
#: mesh multiplies the FE and HBM cost; the default's 2.8 mm gives 4.0 mm, the quick preset's mesh)
LAP_MESH_FACTORS = (1.43, 1.21)


def lap_mesh_sizes(lap_mesh_size: float) -> list[float]:
    """The coarser lap mesh sizes of the element-count table, mm (rounded to 0.1 mm)."""
    return [round(f * lap_mesh_size, 1) for f in LAP_MESH_FACTORS]


def mesh_rows(models: list, level: float, settings: SweepSettings, f_peak_hz: float) -> list[dict]:
    """The baseline's stuck frequency and FRF peak at one level against the interface element
    count.

    Args:
        models: [(lap mesh size mm, ReducedModel, FE seconds, baseline JointModel on it)], the
            case's own mesh last (the reference row).
        level: N; settings: the study's sweep settings (H, samples, μ; band replaced).
        f_peak_hz: the study's peak at that level (its mesh), Hz; each model's sweep is centred
            on it scaled by the model's stuck frequency against the study's.
    Returns:
        rows with lap mesh size, elements (interface pairs), closed at preload, reduced DOFs,
        stuck and peak frequencies, peak amplitude, FE and HBM times, errors against the last.
    """
    from hbm import ConvergenceError

    from ..model.joint import stuck_modes
    stuck = [(j, stuck_modes(rm.K, rm.M, rm.pair_dofs, j).frequency) for _, rm, _, j in models]
    rows = []
    for (size, rm, fe_s, _), (joint, f_st) in zip(models, stuck):
        f_centre = f_peak_hz * f_st / stuck[-1][1]
        st = dataclasses.replace(settings, band=PEAK_BAND)
        out = {"lap mesh [mm]": size, "elements": int(rm.n_pairs),
               "closed": int(np.sum(np.asarray(rm.preload_status) != 0)), "reduced DOFs": int(rm.n_dofs),
               "stuck [Hz]": f_st, "FE time [s]": fe_s}
        t0 = time.perf_counter()
        try:
            cr = frf(rm, joint, level, f_centre, st)
            out.update({"peak [Hz]": cr.peak_hz, "amplitude [µm]": 1e3 * cr.peak_amplitude,
                        "HBM time [s]": time.perf_counter() - t0, "points": cr.n_points})
        except ConvergenceError as e:
            out.update({"peak [Hz]": float("nan"), "amplitude [µm]": float("nan"),
                        "HBM time [s]": time.perf_counter() - t0, "points": 0, "note": f"not found ({e})"})
        rows.append(out)
    f0 = rows[-1]["stuck [Hz]"]
    for r in rows:
        r["stuck error vs case mesh [%]"] = 100 * abs(r["stuck [Hz]"] - f0) / f0
    return _errors(rows, "case mesh")


def _errors(rows: list[dict], ref_name: str) -> list[dict]:
    """Add each row's peak frequency and amplitude errors (%) against the last row."""
    f0, a0 = rows[-1]["peak [Hz]"], rows[-1]["amplitude [µm]"]
    for r in rows:
        r[f"f error vs {ref_name} [%]"] = 100 * abs(r["peak [Hz]"] - f0) / f0
        r[f"amplitude error vs {ref_name} [%]"] = 100 * abs(r["amplitude [µm]"] - a0) / a0
    return rows
