#!/usr/bin/env python3
"""Validation of the harmonic balance on the resonator against the time-domain integration.

On a finished run's reduced model and contact surfaces (the ``fe`` and ``contact`` stages, e.g.
of the quick preset), for one configuration at one excitation level (default: baseline at the
middle level), at three frequencies around the HBM peak (H = 7: the peak, and the peak ∓ a
step), it compares the harmonic balance with H = 1, 3, 7 against
``hbm.time_domain.FrictionTimeIntegrator`` marched from the preloaded rest state to the periodic
steady state:

* the first-harmonic amplitude at the response DOF;
* the cycle-mean joint shear Σ T_x (the HBM's mean state is that of its own 0th harmonic; the
  time domain's is the one the history from rest leaves in the joint);
* the energy per cycle dissipated by friction, and by viscous damping (W_in − W_friction for the
  HBM, W_in = π F b1).

The HBM problem (contacts, structure, force) and its peak come from ``fe_joint.study.frf``, the
same functions the dynamics stage calls. Each HBM solution starts from the time domain's own
harmonics, so both are on the same branch; where the HBM's branch through its peak gives another
solution (a fold: marching from rest can land on the lower branch), it is listed too ("HBM upper").
Finally the time domain is started from the highest H's solutions (their state at t = 0, the AFT's
sliders): whether they are periodic states of the time-domain system too, and what mean state
they keep (the mean state depends on the history, not only on the excitation).

Prints markdown tables. Minutes per frequency (the lightly damped peak settles slowly).

Usage: OMP_NUM_THREADS=1 python scripts/validate_time_domain.py RUN_DIR [--config baseline]
       [--level 1] [--steps 128] [--samples 256] [--df 1.0] [--rtol 3e-6] [--cutoff-hz 20000]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from fe_joint.case.loading import load_case  # noqa: E402
from fe_joint.model.joint import stuck_modes  # noqa: E402
from fe_joint.model.reduced_model import ReducedModel  # noqa: E402
from fe_joint.study import contact as ms  # noqa: E402
from fe_joint.study import frf  # noqa: E402
from fe_joint.study.configurations import choose_levels, fixed_joints  # noqa: E402
from hbm import ConvergenceError  # noqa: E402
from hbm.time_domain import FrictionTimeIntegrator  # noqa: E402

HARMONICS = (1, 3, 7)
#: the local peak searches start this far above the previous H's peak (relative)
START_ABOVE = 3e-3


def load_study(run: Path, config: str):
    """The case, reduced model, joint configurations, levels and stuck frequency of a run."""
    case = load_case(run / "case.toml")
    rm = ReducedModel.load(str(run / "fe" / "reduced_model.h5"))
    setup = ms.interface_setup(rm, case.geometry, case.material, case.roughness)
    surfaces, extra = ms.load_surfaces(run / "contact" / "surfaces.npz")
    joints = fixed_joints(setup, surfaces, extra["kn_smooth"], case)
    if config not in joints:
        raise SystemExit(f"configuration {config!r} not among {sorted(joints)}")
    levels, _ = choose_levels(rm, joints["baseline"], case)
    f_lin = stuck_modes(rm.K, rm.M, rm.pair_dofs, joints[config]).frequency
    return case, rm, joints[config], levels, f_lin


def time_harmonics(x: np.ndarray, H: int) -> np.ndarray:
    """[a0, a1, b1, ...] (…, 2H+1) of samples x (…, N) at theta_j = 2 pi (j+1)/N."""
    N = x.shape[-1]
    th = 2 * np.pi * np.arange(1, N + 1) / N
    out = [x.mean(axis=-1)]
    for h in range(1, H + 1):
        out += [2 * np.mean(x * np.cos(h * th), axis=-1), 2 * np.mean(x * np.sin(h * th), axis=-1)]
    return np.stack(out, axis=-1)


def hbm_row(hb, sol, force, rm) -> dict:
    """Amplitude, mean Σ T_x, friction and viscous work per cycle of an HBM solution."""
    er = hb.element_results(sol)
    b1 = sol.dof_coefficients(rm.excitation_dof)[2]
    w_in = np.pi * force[rm.excitation_dof] * b1
    w_fr = float(er.energy.sum())
    return {"amp": sol.amplitude(rm.response_dof), "shear": float(er.T[:, 0].sum(axis=0).mean()),
            "fric": w_fr, "visc": float(w_in - w_fr), "nl": int(np.sum(er.status > 0))}


def hbm_state(hb, sol, omega: float) -> tuple:
    """The HBM solution's state at t = 0 as a time-domain start: (q0 mm, v0 mm/s, sliders mm).

    The sliders are those of the AFT's closed cycle at its first sample (u_t - T / k_t closed,
    u_t open)."""
    X = sol.coefficients
    h = np.arange(1, (X.shape[0] - 1) // 2 + 1)
    q0 = X[0] + X[1::2].sum(axis=0)
    v0 = (omega * h[:, None] * X[2::2]).sum(axis=0)
    hist = hb.c.histories(sol.contact, hb.fourier)
    closed = hist["N"][:, 0] > 0
    w0 = np.where(closed[:, None], hist["u_t"][:, :, 0] - hist["T"][:, :, 0] / hb.c.kt[:, None],
                  hist["u_t"][:, :, 0])
    return q0, v0, w0


def td_row(r, t0: float, start: str) -> dict:
    """A table row of a TimeDomainResult."""
    return {"amp": r.amplitude, "shear": float(r.joint_shear[0]), "fric": r.friction_work,
            "visc": r.viscous_work, "nl": int(np.sum(r.status > 0)),
            "note": f"{start}: {r.periods} periods, {time.perf_counter() - t0:.0f} s, "
                    f"balance {r.energy_balance:.1e}"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="run folder with fe/reduced_model.h5 and contact/surfaces.npz")
    ap.add_argument("--config", default="baseline")
    ap.add_argument("--level", type=int, default=1, help="index into the run's levels (1 = middle)")
    ap.add_argument("--steps", type=int, default=128, help="time steps per period")
    ap.add_argument("--samples", type=int, default=256, help="AFT samples per period of the HBM")
    ap.add_argument("--df", type=float, default=1.0, help="the other two frequencies: peak ∓ df, Hz")
    ap.add_argument("--rtol", type=float, default=3e-6, help="period-to-period change at convergence")
    ap.add_argument("--cutoff-hz", type=float, default=2e4,
                    help="base modes above respond quasi-statically in the time domain")
    args = ap.parse_args()

    case, rm, joint, levels, f_lin = load_study(args.run, args.config)
    level = levels[args.level]
    base = frf.SweepSettings.from_case(case)
    print(f"# Time domain vs HBM: {args.config} at {level:.4g} N (level {args.level}), run {args.run}\n")
    print(f"{rm.n_dofs} reduced DOFs, stuck frequency {f_lin:.3f} Hz, μ = {base.mu}, "
          f"HBM n_t = {args.samples}, time domain {args.steps} steps/period, rtol {args.rtol:g}, "
          f"modes above {args.cutoff_hz:g} Hz quasi-static\n")

    hbs = {}
    for H in HARMONICS:
        st = replace(base, harmonics=H, samples=args.samples)
        hbs[H] = frf._setup(rm, joint, level, st, frf.SWEEP_TOLERANCES[1])
    hb0, force, act = hbs[HARMONICS[0]]

    # ---- the HBM peaks: H = 1 by the dynamics stage's full sweep; H = 3, 7 by its local peak
    # search, started START_ABOVE above the previous peak (single-valued there) from the previous
    # H's solution at that frequency (higher harmonics zero)
    peaks = {}
    prev = None
    for H in HARMONICS:
        st = replace(base, harmonics=H, samples=args.samples)
        t0 = time.perf_counter()
        if prev is None:
            cr, contact = frf.frf_with_peak(rm, joint, level, f_lin, st)
        else:
            f0 = prev[0].peak_hz * (1 + START_ABOVE)
            hb_prev = hbs[prev[2]][0]
            sol = hb_prev.solve(2 * np.pi * f0, force, guess=SimpleNamespace(contact=prev[1][act]))
            guess = np.zeros(prev[1].shape[:2] + (2 * H + 1,))
            guess[act, :, :sol.contact.shape[2]] = sol.contact
            cr, contact = frf.peak_near(rm, joint, level, f0, guess, st, max_points=300)
        peaks[H] = (cr, contact, time.perf_counter() - t0)
        print(f"HBM H={H}: peak {cr.peak_hz:.3f} Hz, {cr.peak_amplitude:.5f} mm "
              f"({peaks[H][2]:.0f} s)", file=sys.stderr)
        prev = (cr, contact, H)
    print("## HBM peaks\n")
    print("| H | peak (Hz) | amplitude (mm) | mean Σ T_x (N) | friction work (N·mm) | "
          "elements slipping or opening | s |")
    print("|---|---|---|---|---|---|---|")
    for H, (cr, _, sec) in peaks.items():
        print(f"| {H} | {cr.peak_hz:.3f} | {cr.peak_amplitude:.5f} | {cr.loop_T.mean():.2f} | "
              f"{cr.dissipated:.4g} | {cr.n_nonlinear} | {sec:.0f} |")
    fp = peaks[HARMONICS[-1]][0].peak_hz
    freqs = [fp - args.df, fp, fp + args.df]

    # ---- time domain, then HBM on the same branch, at each frequency
    td = FrictionTimeIntegrator.from_problem(hb0.s, hb0.c, max_frequency=2 * np.pi * args.cutoff_hz)
    rows = []
    for f in freqs:
        w = 2 * np.pi * f

        def progress(p, ch, amp, f=f):
            if p % 100 == 0:
                print(f"[{f:.3f} Hz] period {p}: change {ch:.2e}, amplitude {amp:.5f} mm",
                      file=sys.stderr)

        def march(start, initial=None):
            t0 = time.perf_counter()
            r = td.run(w, force, rm.response_dof, steps_per_period=args.steps, rtol=args.rtol,
                       max_periods=5000, callback=progress, initial=initial)
            row = td_row(r, t0, start)
            print(f"[{f:.3f} Hz] time domain: {row['amp']:.5f} mm, {row['note']}", file=sys.stderr)
            return r, row

        r, row = march("from rest")
        rows.append((f, "time domain", row))
        for H in HARMONICS:
            hb, _, _ = hbs[H]
            last = {}                  # this H's solutions (the last H's are kept)
            guess = SimpleNamespace(contact=time_harmonics(r.u, H))
            try:
                sol = hb.solve(w, force, guess=guess)
                row = hbm_row(hb, sol, force, rm)
                row["note"] = "from the time domain's harmonics"
                rows.append((f, f"HBM H={H}", row))
                last["same"] = sol
            except ConvergenceError as e:
                rows.append((f, f"HBM H={H}", {"note": f"no convergence ({e})"}))
                sol = None
            # the branch through the HBM peak, if it is another solution here (a fold)
            try:
                up = hb.solve(w, force, guess=SimpleNamespace(contact=peaks[H][1][act]))
            except ConvergenceError:
                continue
            amp = None if sol is None else sol.amplitude(rm.response_dof)
            if amp is None or abs(up.amplitude(rm.response_dof) - amp) > 1e-3 * amp:
                row = hbm_row(hb, up, force, rm)
                row["note"] = "from its peak: another branch"
                rows.append((f, f"HBM H={H} upper", row))
                last["upper"] = up
        # is the highest H's solution a periodic state of the time domain? (start there)
        hb = hbs[HARMONICS[-1]][0]
        for which, sol in last.items():
            _, row = march(f"from the HBM H={HARMONICS[-1]} state", hbm_state(hb, sol, w))
            name = f"time domain from HBM H={HARMONICS[-1]}" + (" upper" if which == "upper" else "")
            rows.append((f, name, row))

    print("\n## Time domain vs HBM\n")
    print("| f (Hz) | method | amplitude (mm) | vs time domain | mean Σ T_x (N) | friction work "
          "(N·mm) | viscous work (N·mm) | elements slipping or opening | note |")
    print("|---|---|---|---|---|---|---|---|---|")
    ref = None
    for f, name, row in rows:
        if name == "time domain":
            ref = row
        if "amp" not in row:
            print(f"| {f:.3f} | {name} | – | – | – | – | – | – | {row['note']} |")
            continue
        rel = "" if name == "time domain" else f"{100 * (row['amp'] - ref['amp']) / ref['amp']:+.2f} %"
        print(f"| {f:.3f} | {name} | {row['amp']:.5f} | {rel} | {row['shear']:.2f} | "
              f"{row['fric']:.4g} | {row['visc']:.4g} | {row['nl']} | {row['note']} |")


if __name__ == "__main__":
    main()
