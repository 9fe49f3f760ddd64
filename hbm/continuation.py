"""Pseudo-arc-length continuation of harmonic-balance solutions in the frequency.

Scaled unknowns Y = (U / u_s, w / w_s) (u_s: norm of the first solution, w_s: the start
frequency). Tangent predictor from dU/dw = -J^-1 dR/dw, corrector on
{R(U, w) = 0, t . (Y - Y_pred) = 0} solved by bordering with the reduced Newton solve (the same
two right-hand sides share one factorization). Step length adapts to the corrector's iteration
count; a failed corrector halves the step. Turning points are where the w-component of the
tangent changes sign; they are recorded in ``FRFResult.turning_points``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .errors import ConvergenceError
from . import stability as stab


@dataclass
class FRFResult:
    """A frequency-response branch.

    Attributes:
        omega: (p,) frequencies, rad/s.
        amplitude: (p,) first-harmonic amplitude at the response DOF, mm.
        stable: (p,) bool, stability of each point (Hill's method or fold parity, see ``method``).
        solutions: list of Solution, one per point.
        turning_points: indices of points next to a fold (tangent's w-component changed sign).
        method: stability method used, "hill" or "fold-parity".
        wall_time: seconds spent.
        newton_iterations: total corrector iterations.
    """

    omega: np.ndarray
    amplitude: np.ndarray
    stable: np.ndarray
    solutions: list = field(repr=False)
    turning_points: list
    method: str
    wall_time: float
    newton_iterations: int


def continue_frf(hb, omega_start: float, omega_end: float, force, dof: int,
                 max_points: int = 1000, ds: float | None = None, ds_max: float | None = None,
                 ds_min: float | None = None, max_corrector: int = 12,
                 stability: str = "auto") -> FRFResult:
    """Continue the periodic response from omega_start to omega_end (rad/s).

    Args:
        hb: the HarmonicBalance solver.
        omega_start, omega_end: frequency range, rad/s (either order).
        force: (n,) amplitude of force·cos(wt), N.
        dof: response DOF for ``amplitude``.
        max_points: stop after this many points.
        ds: initial arc-length step in scaled units (default |Δw|/w_s/100).
        ds_max, ds_min: step bounds (default 4 ds, 1e-6 ds).
        max_corrector: corrector iterations before a step is retried shorter.
        stability: "auto" (Hill if small enough, else fold parity), "hill", "fold", "none".

    Returns:
        FRFResult. Raises ConvergenceError if the step falls below ds_min.
    """
    t0 = time.perf_counter()
    w0 = hb._check_omega(omega_start)
    w1 = hb._check_omega(omega_end)
    force = hb._check_force(force)
    if int(dof) != dof or not (0 <= dof < hb.s.n):
        raise ValueError(f"dof must be an integer in [0, {hb.s.n - 1}], got {dof!r}")
    if w0 == w1:
        raise ValueError("omega_start and omega_end must differ")
    if stability not in ("auto", "hill", "fold", "none"):
        raise ValueError(f"stability must be auto|hill|fold|none, got {stability!r}")
    direction = np.sign(w1 - w0)
    ws = w0
    if ds is None:
        ds = abs(w1 - w0) / ws / 100.0
    ds_max = 4 * ds if ds_max is None else ds_max
    ds_min = 1e-6 * ds if ds_min is None else ds_min

    sol = hb.solve(w0, force)
    U = hb._from_el(sol.contact)
    us = max(np.linalg.norm(U), 1e-300) if np.linalg.norm(U) > 0 else 1.0
    tol = hb.tol
    total_it = sol.iterations

    def tangent(U, w, prev, ev=None):
        R, g, nl, Dg = hb.residual(U, w, hb.ulin(w, force)) if ev is None else ev
        (b,) = hb.linsolve(w, nl, Dg, [-hb.r_omega(w, force, g)])
        t = np.concatenate([b.ravel() / us, [1.0 / ws]])
        t /= np.linalg.norm(t)
        if prev is None:
            return t * direction
        return t if t @ prev >= 0 else -t

    keep_jac = 2 * hb.nH * hb.s.n <= stab.HILL_LIMIT
    t = tangent(U, w0, None)
    sols, taus = [sol], [t[-1]]
    w = w0
    while len(sols) < max_points:
        Y = np.concatenate([U.ravel() / us, [w / ws]])
        while True:
            Yp = Y + ds * t
            Uc, wc = Yp[:-1].reshape(U.shape) * us, Yp[-1] * ws
            ok = False
            for it in range(1, max_corrector + 1):
                if wc <= 0:
                    break
                Ul = hb.ulin(wc, force)
                R, g, nl, Dg = hb.residual(Uc, wc, Ul)
                scale = max(np.linalg.norm(Uc), np.linalg.norm(Ul), 1e-300)
                cval = t @ (np.concatenate([Uc.ravel() / us, [wc / ws]]) - Yp)
                if np.linalg.norm(R) <= tol * scale and it > 1:
                    ok = True
                    break
                a, b = hb.linsolve(wc, nl, Dg, [-R, -hb.r_omega(wc, force, g)])
                tU, tw = t[:-1], t[-1]
                dw = -(cval + tU @ a.ravel() / us) / (tU @ b.ravel() / us + tw / ws)
                Uc = Uc + a + dw * b
                wc = wc + dw
            total_it += it
            if ok:
                break
            ds *= 0.5
            if ds < ds_min:
                raise ConvergenceError(f"continuation step fell below ds_min near omega = {w:.6g} rad/s",
                                       float(np.linalg.norm(R) / scale))
        U, w = Uc, wc
        t = tangent(U, w, t, (R, g, nl, Dg))
        sols.append(hb.make_solution(w, force, U, float(np.linalg.norm(R) / scale), it, nl.size,
                                     g=g, jac=(nl, Dg) if keep_jac else None))
        taus.append(t[-1])
        if it <= 3:
            ds = min(ds * 1.5, ds_max)
        elif it >= 7:
            ds *= 0.7
        if (w - w1) * direction >= 0:
            # land exactly on omega_end from the last point
            try:
                last = hb.solve(w1, force, guess=sols[-1])
                sols[-1] = last
            except ConvergenceError:
                pass
            break
        if (w - w0) * direction < -abs(w1 - w0):
            break
    omega = np.array([s_.omega for s_ in sols])
    amp = np.array([s_.amplitude(dof) for s_ in sols])
    taus = np.array(taus)
    turning = [i for i in range(1, len(taus)) if np.sign(taus[i]) != np.sign(taus[i - 1])]
    method = stability
    if stability == "auto":
        method = "hill" if stab.hill_available(hb) else "fold"
    if method == "hill":
        stable = np.array([stab.is_stable_hill(hb, s_) for s_ in sols])
    elif method == "fold":
        flips = np.zeros(len(sols), dtype=int)
        for i in turning:
            flips[i:] += 1
        stable = flips % 2 == 0
        method = "fold-parity"
    else:
        stable = np.ones(len(sols), dtype=bool)
    return FRFResult(omega, amp, stable, sols, turning, method, time.perf_counter() - t0, total_it)
