#!/usr/bin/env python3
"""The static (cycle-mean) shear in the joint at the resonance peak, and where it comes from.

For the ``baseline`` joint of a run folder that holds the ``mesh``, ``fe`` and ``contact`` stages
(e.g. ``fe-joint run --preset quick --stages mesh,fe,contact --out /tmp/q``) this sweeps each
requested level as the study does (``study.frf.frf_with_peak``), then at the refined peak prints

* the joint's mean shear ΣT_x (0th harmonic of the element forces) and its ratio to μΣN0, the
  area-weighted mean slip u_x0 and the bolt's mean shear force (= −ΣT_x by equilibrium);
* the check of that equilibrium: the residual of K q0 + Bᵀ F0 = 0 (structure alone) and the mean
  slip predicted by the bolt's lateral compliance (equal and opposite area-weighted x loads on
  the two lap faces, reduced model without contact);
* ΣT_x and u_x0 by element status and by radius from the bolt axis;
* d(ΣT_x)/d(u_x0) of the elements (a uniform shift of their mean u_x; ≈ 0 when the mean state
  is set by the orbit alone, ≈ Σk_t when stuck elements remember their rest state);
* the largest change of ΣT_x when the AFT march starts at another phase (same orbit).

Usage: ``PYTHONPATH=. .venv/bin/python scripts/mean_shear.py /tmp/q --preset quick [--levels 0 1 2]
[--harmonics H --samples NT]``
"""
from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import scipy.linalg as sla

from fe_joint.case.loading import load_case
from fe_joint.model.joint import stuck_modes
from fe_joint.model.reduced_model import ReducedModel
from fe_joint.study import contact as ms
from fe_joint.study.configurations import choose_levels, joint_baseline
from fe_joint.study.frf import SWEEP_TOLERANCES, SweepSettings, _setup, frf_with_peak

NAMES = ("stuck", "stick-slip", "gross slip", "partly open", "open")
RADII = (0.0, 6.0, 8.0, 10.0, np.inf)


def rotate(X: np.ndarray, phi: float) -> np.ndarray:
    """Harmonics (..., 2H+1) of x(θ + φ) for harmonics X of x(θ)."""
    Y = X.copy()
    for h in range(1, (X.shape[-1] - 1) // 2 + 1):
        a, b = X[..., 2 * h - 1], X[..., 2 * h]
        c, s = np.cos(h * phi), np.sin(h * phi)
        Y[..., 2 * h - 1], Y[..., 2 * h] = a * c + b * s, b * c - a * s
    return Y


def bolt_compliance(rm: ReducedModel, act: np.ndarray) -> float:
    """Area-weighted relative x slip (u_A − u_B) per N of equal and opposite area-weighted x loads
    on the lap faces (+x on B), structure without contact (free–free, rigid modes shifted), mm/N."""
    K, M = rm.K, rm.M
    pd = np.asarray(rm.pair_dofs)[act]
    w = np.asarray(rm.pair_area)[act] / np.asarray(rm.pair_area)[act].sum()
    f = np.zeros(K.shape[0])
    np.add.at(f, pd[:, 1, 0], w)
    np.add.at(f, pd[:, 0, 0], -w)
    lam, Phi = sla.eigh(K, M, subset_by_index=[0, 6])
    Pr = M @ Phi[:, :6]
    x = np.linalg.solve(K + lam[6] * Pr @ Pr.T, f)
    return float(-np.sum(w * (x[pd[:, 0, 0]] - x[pd[:, 1, 0]])))


def report(rm: ReducedModel, hb, sol, act: np.ndarray, level: float) -> None:
    """Print the breakdown of the mean shear at the solution ``sol`` of ``hb``."""
    c, fo = hb.c, hb.fourier
    U = sol.contact
    F = c.evaluate(U, fo, jacobian=False)[0]
    status = c.histories(U, fo)["status"]
    T0, u0 = F[:, 0, 0], U[:, 0, 0]
    area = np.asarray(rm.pair_area)[act]
    r = np.hypot(*np.asarray(rm.pair_xyz)[act, :2].T)
    mun0 = c.mu * c.n0
    q0 = sol.coefficients[0]
    fc = hb.B.T @ F[:, :, 0].ravel()
    eq = np.linalg.norm(rm.K @ q0 + fc) / np.linalg.norm(fc)
    slip = np.average(u0, weights=area)
    cb = bolt_compliance(rm, act)
    print(f"\nlevel {level:.4g} N, peak {sol.omega / 2 / np.pi:.3f} Hz, amplitude "
          f"{sol.amplitude(rm.response_dof):.4f} mm")
    print(f"  mean shear ΣT_x = {T0.sum():.1f} N = {100 * T0.sum() / mun0.sum():.1f} % of μΣN0 "
          f"({mun0.sum():.0f} N); bolt mean shear force {-T0.sum():.1f} N; Σ(N − N0) mean {F[:, 2, 0].sum():.1f} N")
    print(f"  mean slip u_x0 (area-weighted) {1e3 * slip:.2f} µm; bolt compliance {cb:.4g} mm/N "
          f"predicts {-1e3 * cb * T0.sum():.2f} µm; |K q0 + Bᵀ F0| / |Bᵀ F0| = {eq:.1e}")
    print("  | status | n | ΣT_x0 (N) | μΣN0 (N) | mean u_x0 (µm) |")
    for s in range(5):
        m = status == s
        if m.any():
            print(f"  | {NAMES[s]} | {m.sum()} | {T0[m].sum():.0f} | {mun0[m].sum():.0f} | {1e3 * u0[m].mean():.1f} |")
    print("  | radius (mm) | n | ΣT_x0 (N) | μΣN0 (N) | statuses 0-4 |")
    for lo, hi in zip(RADII[:-1], RADII[1:]):
        m = (r >= lo) & (r < hi)
        print(f"  | {lo:g}–{hi:g} | {m.sum()} | {T0[m].sum():.0f} | {mun0[m].sum():.0f} | "
              f"{np.bincount(status[m], minlength=5).tolist()} |")
    V = U.copy()
    V[:, 0, 0] += 1e-3
    dT = c.evaluate(V, fo, jacobian=False)[0][:, 0, 0].sum() - T0.sum()
    print(f"  d(ΣT_x0)/d(u_x0) of the elements: {dT / 1e-3:.4g} N/mm (Σk_t {c.kt.sum():.4g}, bolt {1 / cb:.4g})")
    phis = 2 * np.pi * np.arange(1, 8) / 8
    moved = [rotate(c.evaluate(rotate(U, p), fo, jacobian=False)[0], -p)[:, 0, 0].sum() - T0.sum()
             for p in phis]
    print(f"  march started at another phase (k·π/4): ΣT_x0 changes by at most {np.abs(moved).max():.1f} N")


def main(argv: list[str] | None = None) -> None:
    """Command line: see the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="run folder with the mesh, fe and contact stages")
    ap.add_argument("--preset", default=None)
    ap.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--harmonics", type=int, default=None)
    ap.add_argument("--samples", type=int, default=None)
    a = ap.parse_args(argv)
    case = load_case(None, preset=a.preset)
    rm = ReducedModel.load(str(a.out / "fe" / "reduced_model.h5"))
    setup = ms.interface_setup(rm, case.geometry, case.material, case.roughness)
    joint = joint_baseline(setup, case.contact.k_ref)
    levels, _ = choose_levels(rm, joint, case)
    f_lin = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint).frequency
    st = SweepSettings.from_case(case)
    st = SweepSettings(a.harmonics or st.harmonics, a.samples or st.samples, st.band, st.max_points, st.mu)
    print(f"baseline, H = {st.harmonics}, n_t = {st.samples}, levels {[round(x, 4) for x in levels]} N")
    for i in a.levels:
        cr, Ufull = frf_with_peak(rm, joint, levels[i], f_lin, st)
        hb, force, act = _setup(rm, joint, levels[i], st, SWEEP_TOLERANCES[1])
        sol = hb.solve(2 * np.pi * cr.peak_hz, force, guess=SimpleNamespace(contact=Ufull[act]))
        report(rm, hb, sol, act, levels[i])


if __name__ == "__main__":
    main()
