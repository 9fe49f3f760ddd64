"""Pseudo-arc-length continuation of harmonic-balance solutions in the frequency.

* Scaled unknowns Y = (U / u_s, w / w_s): w_s is the start frequency, u_s the norm of the current
  solution (updated every step, so steps are relative changes), and the frequency step is capped
  at ``max_domega`` (default range/100) so that flat parts cannot step over a narrow peak.
* Tangent predictor: null vector of [J, dR/dw] from the bordered system with the previous tangent
  as last row, oriented so that the sign of the bordered determinant stays constant along the
  branch (dense path; the GMRES path keeps t . t_prev > 0).
* Corrector: damped Newton on {R(U, w) = 0, t . (Y - Y_pred) = 0}; the bordered system is solved
  directly (reduced on the nonlinear elements), so it stays regular at turning points.
* Corner folds: with sampled piecewise-linear contact laws a turning point generically sits where
  one time sample switches state (a corner of the branch). When no point exists on the hyperplane
  ahead, the tangent of the piece beyond the corner is taken at the predictor, oriented by the
  determinant sign, and the corrector restarts from the corner along it.
* Step length grows x1.5 after <= 3 corrector iterations, shrinks x0.7 after >= 7, halves on failure;
  ``ConvergenceError`` below ds_min. Turning points (sign changes of the w-component of the tangent)
  are listed in ``FRFResult.turning_points``.
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
                 stability: str = "auto", max_domega: float | None = None,
                 max_damp: float = 0.1, guess=None, stop=None) -> FRFResult:
    """Continue the periodic response from omega_start to omega_end (rad/s).

    Args:
        hb: the HarmonicBalance solver.
        omega_start, omega_end: frequency range, rad/s (either order).
        force: (n,) amplitude of force·cos(wt), N.
        dof: response DOF for ``amplitude``.
        max_points: stop after this many points.
        ds: initial arc-length step in scaled units (relative change of the response and of the
            frequency; default 0.02).
        ds_max, ds_min: step bounds (default 0.1, 1e-6 ds).
        max_corrector: corrector iterations before a step is retried shorter.
        stability: "auto" (Hill if small enough, else fold parity), "hill", "fold", "none".
        max_domega: largest frequency change per step, rad/s (default |Δw|/100): keeps the
            predictor from stepping over a lightly damped peak where the branch is flat.
        max_damp: largest relative change of the response amplitude per step (a step is halved
            otherwise), so the response DOF's peak is resolved even in a mode the contacts hardly see.
        guess: optional Solution to start Newton from at omega_start (e.g. a neighbouring solution
            of a slightly different system); default the linear-base response.
        stop: optional callable(amplitudes) -> bool, called with the amplitudes of the points so
            far after each point; True ends the branch there (e.g. once a peak has been passed).

    Returns:
        FRFResult. Raises ConvergenceError if the step falls below ds_min.
    """
    t0 = time.perf_counter()
    w0 = hb.check_omega(omega_start)
    w1 = hb.check_omega(omega_end)
    force = hb.check_force(force)
    if int(dof) != dof or not (0 <= dof < hb.s.n):
        raise ValueError(f"dof must be an integer in [0, {hb.s.n - 1}], got {dof!r}")
    if w0 == w1:
        raise ValueError("omega_start and omega_end must differ")
    if stability not in ("auto", "hill", "fold", "none"):
        raise ValueError(f"stability must be auto|hill|fold|none, got {stability!r}")
    direction = np.sign(w1 - w0)
    ws = w0
    if ds is None:
        ds = 0.02
    ds_max = 0.1 if ds_max is None else ds_max
    ds_min = 1e-6 * ds if ds_min is None else ds_min
    max_domega = abs(w1 - w0) / 100.0 if max_domega is None else float(max_domega)
    if not max_domega > 0:
        raise ValueError(f"max_domega must be > 0 rad/s, got {max_domega!r}")

    sol = hb.solve(w0, force, guess=guess)
    U = hb.from_contact(sol.contact)
    # amplitude scale: the norm of the current solution, updated at every step, so that the
    # arc length measures *relative* changes of the response (a friction-limited peak far below
    # the linear one is resolved as well as a linear one)
    us = np.linalg.norm(U) if np.linalg.norm(U) > 0 else 1.0
    total_it = sol.iterations
    shape = U.shape

    def Y_of(U, w):
        return np.concatenate([U.ravel() / us, [w / ws]])

    def evaluate(U, w):
        Ul = hb.ulin(w, force)
        R, g, nl, Dg = hb.residual(U, w, Ul)
        return R, g, nl, Dg, max(np.linalg.norm(U), np.linalg.norm(Ul), 1e-300)

    def tangent(U, w, ev, prev, ref_sign):
        """Unit tangent oriented by the sign of the bordered determinant (robust at the corner
        folds of the piecewise-linear contact laws, where the tangent can turn by > 90 deg)."""
        R, g, nl, Dg, _ = ev
        Rw = hb.r_omega(w, force, g)
        [(dU, dw)], sign = hb.linsolve_aug(w, nl, Dg, Rw, prev[:-1].reshape(shape) / us,
                                           prev[-1] / ws, [(np.zeros(shape), -1.0)])
        t = np.concatenate([dU.ravel() / us, [dw / ws]])
        t /= np.linalg.norm(t)
        if ref_sign is not None and sign != 0 and sign != ref_sign:
            t = -t
        return t, sign

    def corrector(Yp, t):
        """Damped Newton on {R = 0, t.(Y - Yp) = 0} from the predictor Yp."""
        Uc, wc = Yp[:-1].reshape(shape) * us, Yp[-1] * ws
        ev = evaluate(Uc, wc)
        step = np.inf
        tk = t
        for it in range(1, max_corrector + 1):
            R, g, nl, Dg, scale = ev
            r = np.linalg.norm(R)
            if it > 1 and hb.converged(r, scale, step):
                return True, Uc, wc, ev, it
            Rw = hb.r_omega(wc, force, g)
            cval = tk @ (Y_of(Uc, wc) - Yp)
            [(dU, dw)], _ = hb.linsolve_aug(wc, nl, Dg, Rw, tk[:-1].reshape(shape) / us, tk[-1] / ws,
                                            [(R, cval)])
            # damped step: halve while the residual does not decrease
            alpha = 1.0
            for _ in range(6):
                Ut, wt = Uc + alpha * dU, wc + alpha * dw
                if wt > 0:
                    evt = evaluate(Ut, wt)
                    if np.linalg.norm(evt[0]) <= (1 - 1e-4 * alpha) * r:
                        break
                alpha *= 0.5
            if wt <= 0:
                return False, Uc, wc, ev, it
            step = max(np.linalg.norm(alpha * dU), abs(alpha * dw) / ws * scale)
            Uc, wc, ev = Ut, wt, evt
        return False, Uc, wc, ev, max_corrector

    ev0 = evaluate(U, w0)
    t0_guess = np.zeros(U.size + 1)
    t0_guess[-1] = direction
    t, ref_sign = tangent(U, w0, ev0, t0_guess, None)
    if t[-1] * direction < 0:
        t = -t
        ref_sign = -ref_sign
    keep_jac = 2 * hb.nH * hb.s.n <= stab.HILL_LIMIT
    sols, taus = [sol], [t[-1]]
    amp_prev = sol.amplitude(dof)
    amps = [amp_prev]
    w = w0
    while len(sols) < max_points:
        nu = np.linalg.norm(U)
        if nu > 0 and nu != us:
            # rescale the tangent to the new amplitude scale
            tu = np.concatenate([t[:-1] * (us / nu), t[-1:]])
            t = tu / np.linalg.norm(tu)
            us = nu
        Y = Y_of(U, w)
        while True:
            # the frequency step is capped at max_domega
            ds = min(ds, max_domega / (abs(t[-1]) * ws)) if t[-1] != 0 else ds
            Yp = Y + ds * t
            ok, Uc, wc, ev, it = corrector(Yp, t)
            total_it += it
            if ok:
                # the arc length lives on the contact unknowns; the response DOF may resonate in a
                # mode the contacts hardly see, so also bound its relative change per step
                R_, g_, _, _, _ = ev
                cand = hb.make_solution(wc, force, Uc, 0.0, it, 0, g=g_)
                a_new = cand.amplitude(dof)
                if abs(a_new - amp_prev) <= max_damp * max(a_new, amp_prev) or ds <= 4 * ds_min:
                    break
                ds *= 0.5
                continue
            # Corner fold of the piecewise-linear contact laws: the branch turns back exactly where
            # a time sample switches state, so no point exists on the hyperplane ahead. Take the
            # tangent of the piece beyond the corner (Jacobian at the predictor), orient it by the
            # bordered-determinant sign, and restart from the corner point along it.
            evp = evaluate(Yp[:-1].reshape(shape) * us, Yp[-1] * ws)
            if ref_sign is not None:
                tb, _ = tangent(Yp[:-1].reshape(shape) * us, Yp[-1] * ws, evp, t, ref_sign)
                Yc = Y_of(Uc, wc)
                ok, Uc, wc, ev, it = corrector(Yc + ds * tb, tb)
                total_it += it
                if ok and np.linalg.norm(Y_of(Uc, wc) - Y) > 1e-3 * ds:
                    break
            ds *= 0.5
            if ds < ds_min:
                raise ConvergenceError(f"continuation step fell below ds_min near omega = {w:.6g} rad/s",
                                       float(np.linalg.norm(ev[0]) / ev[4]))
        U, w = Uc, wc
        t, sgn = tangent(U, w, ev, t, ref_sign)
        R, g, nl, Dg, scale = ev
        sols.append(hb.make_solution(w, force, U, float(np.linalg.norm(R) / scale), it, nl.size,
                                     g=g, jac=(nl, Dg) if keep_jac else None))
        amp_prev = sols[-1].amplitude(dof)
        taus.append(t[-1])
        if it <= 3:
            ds = min(ds * 1.5, ds_max)
        elif it >= 7:
            ds *= 0.7
        if (w - w1) * direction >= 0:
            # land exactly on omega_end from the last point
            try:
                sols[-1] = hb.solve(w1, force, guess=sols[-1])
            except ConvergenceError:
                pass
            break
        if (w - w0) * direction < -abs(w1 - w0):
            break
        amps.append(amp_prev)
        if stop is not None and stop(amps):
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
