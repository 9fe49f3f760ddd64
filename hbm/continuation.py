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

import numbers
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .errors import ConvergenceError
from . import stability as stab

#: accepted values of ``ContinuationSettings.stability``
STABILITY_METHODS = ("auto", "hill", "fold", "none")


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


# ---------------------------------------------------------------------------------- settings
def _integer(name: str, value, lo: int) -> int:
    """``value`` as an int >= lo (integral floats accepted), else ValueError naming ``name``."""
    if (isinstance(value, bool) or not isinstance(value, numbers.Real) or not np.isfinite(value)
            or float(value) != int(value) or value < lo):
        raise ValueError(f"ContinuationSettings.{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def _positive(name: str, value, finite: bool, unit: str = "") -> float:
    """``value`` as a float > 0 (and finite if ``finite``), else ValueError naming ``name``."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and value > 0
    if not ok or (finite and not np.isfinite(value)):
        rng = f"in (0, inf){unit}" if finite else f"> 0{unit} (inf allowed)"
        raise ValueError(f"ContinuationSettings.{name} must be {rng}, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class ContinuationSettings:
    """Step and stopping settings of :func:`continue_frf` (``HarmonicBalance.frf``), validated once.

    Attributes:
        max_points: stop after this many points (integer >= 1).
        ds: initial arc-length step in scaled units (relative change of the response and of the
            frequency), in (0, inf).
        ds_max: largest step, > 0 (inf: no bound).
        ds_min: smallest step, in (0, inf); ``ConvergenceError`` below it. None: 1e-6 ds
            (resolved on creation).
        max_corrector: corrector iterations before a step is retried shorter (integer >= 1).
        stability: "auto" (Hill if small enough, else fold parity), "hill", "fold" or "none".
        max_domega: largest frequency change per step, rad/s, > 0 (inf: no cap). None: |Δw|/100
            of the range of the run. Keeps the predictor from stepping over a lightly damped
            peak where the branch is flat.
        max_damp: largest relative change of the response amplitude per step, in (0, inf) (a
            step is halved otherwise), so the response DOF's peak is resolved even in a mode the
            contacts hardly see.

    Raises:
        ValueError naming the field and its allowed range.
    """

    max_points: int = 1000
    ds: float = 0.02
    ds_max: float = 0.1
    ds_min: float | None = None
    max_corrector: int = 12
    stability: str = "auto"
    max_domega: float | None = None
    max_damp: float = 0.1

    def __post_init__(self) -> None:
        def put(name, value):                 # frozen: normalized values are set once, here
            object.__setattr__(self, name, value)

        put("max_points", _integer("max_points", self.max_points, 1))
        put("max_corrector", _integer("max_corrector", self.max_corrector, 1))
        put("ds", _positive("ds", self.ds, finite=True))
        put("ds_max", _positive("ds_max", self.ds_max, finite=False))
        put("ds_min", 1e-6 * self.ds if self.ds_min is None else _positive("ds_min", self.ds_min, True))
        if self.max_domega is not None:
            put("max_domega", _positive("max_domega", self.max_domega, finite=False, unit=" rad/s"))
        put("max_damp", _positive("max_damp", self.max_damp, finite=True))
        if not isinstance(self.stability, str) or self.stability not in STABILITY_METHODS:
            raise ValueError(f"ContinuationSettings.stability must be one of {'|'.join(STABILITY_METHODS)}, "
                             f"got {self.stability!r}")

    @classmethod
    def from_options(cls, **options) -> ContinuationSettings:
        """Settings from ``frf``'s keyword options (the field names); None means the default."""
        return cls(**{k: v for k, v in options.items() if v is not None})

    def frequency_cap(self, omega_start: float, omega_end: float) -> float:
        """``max_domega`` for a run over [omega_start, omega_end], rad/s (default range/100)."""
        return abs(omega_end - omega_start) / 100.0 if self.max_domega is None else self.max_domega


def continue_frf(hb, omega_start: float, omega_end: float, force, dof: int,
                 settings: ContinuationSettings | None = None, *, guess=None,
                 stop: Callable[[list], bool] | None = None) -> FRFResult:
    """Continue the periodic response from omega_start to omega_end (rad/s).

    Args:
        hb: the HarmonicBalance solver.
        omega_start, omega_end: frequency range, rad/s (either order).
        force: (n,) amplitude of force·cos(wt), N.
        dof: response DOF for ``amplitude``.
        settings: ContinuationSettings (default: ``ContinuationSettings()``).
        guess: optional Solution to start Newton from at omega_start (e.g. a neighbouring solution
            of a slightly different system); default the linear-base response.
        stop: optional callable(amplitudes) -> bool, called with the list of amplitudes (mm) of
            the points so far after each point; True ends the branch there (e.g. once a peak
            has been passed).

    Returns:
        FRFResult. Raises ConvergenceError if the step falls below ds_min, ValueError on bad
        input, TypeError if ``settings`` is not a ContinuationSettings.
    """
    t0 = time.perf_counter()
    settings = ContinuationSettings() if settings is None else settings
    if not isinstance(settings, ContinuationSettings):
        raise TypeError(f"settings must be a ContinuationSettings, got {type(settings).__name__}")
    w0 = hb.check_omega(omega_start)
    w1 = hb.check_omega(omega_end)
    force = hb.check_force(force)
    if int(dof) != dof or not (0 <= dof < hb.s.n):
        raise ValueError(f"dof must be an integer in [0, {hb.s.n - 1}], got {dof!r}")
    if w0 == w1:
        raise ValueError("omega_start and omega_end must differ")
    direction = np.sign(w1 - w0)
    ws = w0
    ds, ds_max, ds_min, max_corrector = settings.ds, settings.ds_max, settings.ds_min, settings.max_corrector
    max_points, stability, max_damp = settings.max_points, settings.stability, settings.max_damp
    max_domega = settings.frequency_cap(w0, w1)

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
