"""Pseudo-arc-length continuation of harmonic-balance solutions in the frequency.

* Scaled unknowns Y = (U / u_s, w / w_s): w_s is the start frequency, u_s the norm of the current
  solution (updated every step, so steps are relative changes), and the frequency step is capped
  at ``max_domega`` (default range/100) so that flat parts cannot step over a narrow peak.
* Predictor (``ContinuationSettings.predictor``): the secant through the last two points (the
  default, ``PREDICTORS``), oriented by the direction of travel; the tangent below is solved at a
  branch's start, beyond a corner restart, and at every point with ``"tangent"``.
* Tangent: null vector of [J, dR/dw] from the bordered system with the previous tangent
  as last row, oriented so that the sign of the bordered determinant is that of the previous
  point: with a consistently oriented tangent that sign is an invariant of the branch (it changes
  only at a branch point). The sign comes with the dense path's LU; a point solved by GMRES has
  none of its own, its tangent keeps t . t_prev > 0, and a smooth step (t . t_prev >=
  ``SHARP_TURN``) carries the last known sign on (0 while none has been computed). So a branch
  whose linear solves switch between the two paths never compares a sign with one the other
  path did not compute or carry.
* Corrector: damped Newton on {R(U, w) = 0, t . (Y - Y_pred) = 0}; the bordered system is solved
  directly (reduced on the nonlinear elements), so it stays regular at turning points.
* Corner folds: with sampled piecewise-linear contact laws a turning point generically sits where
  one time sample switches state (a corner of the branch). When no point exists on the hyperplane
  ahead, the tangent of the piece beyond the corner is taken at the predictor, oriented by the
  determinant sign, and the corrector restarts from the corner along it. There the tangent can
  turn by more than 90 deg, and t . t_prev > 0 would send the branch back the way it came. So on
  the GMRES path the sign at the predictor comes from a dense LU of the bordered system
  (``linsolve_aug(exact_sign=True)``) where the tangent there turned sharply (t . t_prev <
  ``SHARP_TURN``; a smaller turn keeps t . t_prev > 0, no LU), and so does the current point's
  while no sign is known
  yet (the first corner of a branch); the point accepted beyond the corner is oriented by
  t . t_beyond > 0 against the tangent of the piece it lies on. A step whose GMRES tangent turned
  sharply (t . t_prev < ``SHARP_TURN``, a corner passed within one step, or a second corner right
  after the first) gets its sign from a dense LU too. One LU per corner met, plus one per branch
  and per sharp turn; smooth GMRES stretches need none. (Session 9: the carried signs equalled
  freshly computed ones at all 28 corners of the default model's four top-level sweeps, and the
  sweeps were point for point those of the former rule, which took three LUs per corner.)
* Step length grows x1.5 after <= 3 corrector iterations, shrinks x0.7 after >= 7, halves on failure;
  ``ConvergenceError`` below ds_min. Turning points (sign changes of the w-component of the tangent)
  are listed in ``FRFResult.turning_points``.
* Retraces: a corrected point on the last few segments turns the tangent round once
  (``_retraces``); one on a part of the branch traced long before means the branch went back
  onto itself: on at ``tight_tol`` from THRASH_POINTS back (as below ds_min), or a
  ``ConvergenceError`` (``_turned_back``).

Code layout (predictor / corrector / step control kept apart, as in pyHarm): the settings are a
frozen, validated :class:`ContinuationSettings`; :class:`_Scaling` maps (U, w) to Y; ``_tangent``
is the predictor, ``_correct`` (with ``_line_search``) the corrector, ``_cap_step`` and
``_adapt_step`` the step control; :class:`_Branch` holds the state of one run (current point,
tangent, step, points so far) and handles corner folds and the end of the range;
``_turning_points`` and ``_stability`` assemble the result.
"""
from __future__ import annotations

import numbers
import time
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np

from .errors import ConvergenceError, CycleNotClosed
from . import stability as stab

#: accepted values of ``ContinuationSettings.stability``
STABILITY_METHODS = ("auto", "hill", "fold", "none")
#: accepted values of ``ContinuationSettings.predictor``. The tangent at each accepted point costs
#: a friction Jacobian and a bordered solve at the Krylov tolerance: on the default model's
#: top-level sweeps 145 tangents took 22 of 64 s (GMRES ~47 iterations each, issue 16). The
#: secant through the last two points costs nothing and is oriented by the direction of travel;
#: the corrector needs a few more iterations on curved stretches (baseline@L1: 4.0 -> 4.3
#: residuals per point, 336 -> 274 linear solves in all). Where the branch has no secant yet (its first point) or lies beyond a corner restart
#: (the piece beyond a corner fold), the tangent is still solved for.
PREDICTORS = ("secant", "tangent")

#: t . t_prev below which a tangent found by GMRES (no determinant sign) is oriented again with
#: exact signs: the turn may be a corner fold. The tangent flips met at points reached without a
#: corner restart in small friction problems had |t . t_prev| of 0.75-0.85 (cos 25.8 deg = 0.9).
SHARP_TURN = 0.9
#: the corrector gives up at its this-many-th line search without decrease: where no point lies
#: on the hyperplane (a corner fold ahead) Newton stalls there and wanders. On the default
#: model's top-level v2 and baseline sweeps the failed correctors (12 each) had taken all 12
#: iterations, 134 of 590 and 144 of 626 in all, their line searches failing from the 2nd-5th
#: on; of the 291 correctors that converged, 3 had damped a step at all.
CORRECTOR_STALLS = 2
#: the corrector also gives up when its residual, still above SLOW_ABOVE times the tolerance,
#: fell by less than the factor SLOW_RATIO in SLOW_STEPS iterations in a row: Newton has lost its
#: convergence (where no point lies on the hyperplane it creeps). On the default model's
#: top-level sweeps (issue 16, session 14) every failed corrector had crept so from its 2nd or
#: 3rd iteration (ratios 0.86-0.99 at 100-10000 times the tolerance) and went on for 4-11
#: iterations (2-3 s at 350 elements); of the 570 correctors that converged none had two such
#: iterations in a row, on the quick model 8 of 763 had (then converged after 6-12 iterations)
SLOW_RATIO = 0.7
SLOW_STEPS = 2
SLOW_ABOVE = 10.0
#: a branch thrashes at a fold when at least THRASH_TURNS of its last THRASH_POINTS points turned
#: sharply (t . t_prev < SHARP_TURN) or lay beyond a corner restart, and those points got less
#: than THRASH_PROGRESS of their path length away from where they started (scaled unknowns): it
#: crawls to and fro through a cluster of corner folds in steps of 1e-5 … 1e-4, its tangent
#: flipping, because its points are too inexact for the tangents (a quick-preset model's
#: top-level smooth-ms sweep at Newton 1e-6: 550 points at 244.3 Hz, 311 sign LUs, 217 s instead
#: of 14 s at 1e-7, issue 16). Then the branch goes back THRASH_POINTS points and on from there
#: at ``ContinuationSettings.tight_tol`` when set (going on from the thrashing point at 1e-7, the
#: step fell below ds_min there; from 20 points back it passed: 31 s, the peak 1e-10 from the
#: strict sweep's). The resonator's sweeps that did not thrash (33 traced curves, sessions
#: 12-16) had at most 7 sharp turns in 20 points, the thrashing ones 16-18; a branch with closely
#: spaced corners (the 1-DOF inclined contact at 32 samples) has 12 in 20 at any tolerance, but
#: moves on.
THRASH_POINTS = 20
THRASH_TURNS = 10
THRASH_PROGRESS = 0.25
#: how many segments of the branch before the current point a new point is checked against
#: (``_Branch._retraces``)
RETRACE_SEGMENTS = 8
#: a new point within this fraction of a segment's length of a segment retraces it
RETRACE_DISTANCE = 0.1
#: a branch that starts on the GMRES path with a reduced system of at most this many unknowns
#: takes its determinant sign there, by a dense LU (~0.1 s): a sign is a branch invariant, and
#: the first corner or sharp turn would otherwise need one at the point before it, where many
#: more elements slip (the default model's top-level sweeps: 71 nonlinear elements at the
#: start, 1491 unknowns; 313-353 at the first sharp turn, 6600-7400 unknowns, 2.9-3.7 s)
START_SIGN_SIZE = 3000


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
        tightened_at: index of the first point solved at ``ContinuationSettings.tight_tol``
            (the branch thrashed at a fold, or its step fell below ds_min, after it), -1 if none.
    """

    omega: np.ndarray
    amplitude: np.ndarray
    stable: np.ndarray
    solutions: list = field(repr=False)
    turning_points: list
    method: str
    wall_time: float
    newton_iterations: int
    tightened_at: int = -1


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
        predictor: "secant" (the default): the next point is predicted along the secant through the
            last two points, and the bordered system is solved only by the corrector; "tangent":
            along the branch's tangent, one more linear solve (and friction Jacobian) per point.
            See :data:`PREDICTORS`.
        tight_tol: None, or the (Newton, GMRES) tolerances, each in (0, 1), the branch goes on
            with once it thrashes at a fold (:data:`THRASH_TURNS`) or its step fell below
            ``ds_min``: the solver's ``tol`` and ``krylov_tol`` are set to them, and the branch
            goes back :data:`THRASH_POINTS` points and on from there (step ``ds``). A fast loose
            tolerance with a tighter one where the loose one's points are too inexact to pass a
            corner fold.

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
    tight_tol: tuple[float, float] | None = None
    predictor: str = "secant"

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
        if self.tight_tol is not None:
            tt = self.tight_tol
            if (not isinstance(tt, (tuple, list)) or len(tt) != 2
                    or not all(isinstance(v, numbers.Real) and not isinstance(v, bool) and 0 < v < 1
                               for v in tt)):
                raise ValueError("ContinuationSettings.tight_tol must be None or a pair (Newton, "
                                 f"GMRES) of tolerances in (0, 1), got {tt!r}")
            put("tight_tol", (float(tt[0]), float(tt[1])))
        if not isinstance(self.predictor, str) or self.predictor not in PREDICTORS:
            raise ValueError(f"ContinuationSettings.predictor must be one of {'|'.join(PREDICTORS)}, "
                             f"got {self.predictor!r}")
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


# ---------------------------------------------------------------------------------- pieces
class _Eval:
    """Residual R (n_H, n_c), correction force g, nonlinear elements nl, their dg/dU blocks Dg,
    and the norm scale max(|U|, |U_lin|) of the convergence test (mm).

    Dg is computed when first read (``HarmonicBalance.residual(deferred=True)``): a line
    search's rejected trials never read it."""
    __slots__ = ("R", "g", "nl", "_Dg", "scale")

    def __init__(self, R: np.ndarray, g: np.ndarray, nl: np.ndarray, Dg, scale: float) -> None:
        self.R, self.g, self.nl, self._Dg, self.scale = R, g, nl, Dg, scale

    @property
    def Dg(self) -> np.ndarray | None:
        return self._Dg() if callable(self._Dg) else self._Dg


class _Correction(NamedTuple):
    """Corrector outcome: converged?, last iterate (U (n_H, n_c) mm, w rad/s), its evaluation
    (None when the march did not close at the predictor itself), iterations used."""
    ok: bool
    U: np.ndarray
    w: float
    ev: _Eval | None
    it: int


class _Scaling:
    """Scaled unknowns Y = (U / us, w / ws) in which the arc length is measured.

    Args:
        us: amplitude scale, mm (the norm of the current solution; see :meth:`rescale`).
        ws: frequency scale, rad/s (the start frequency).
        shape: shape (n_H, n_c) of U.
    """

    def __init__(self, us: float, ws: float, shape: tuple) -> None:
        self.us, self.ws, self.shape = us, ws, shape

    def Y(self, U: np.ndarray, w: float) -> np.ndarray:
        """Scaled vector (U.size + 1,) of (U, w); also maps a direction (dU, dw) to scaled units."""
        return np.concatenate([U.ravel() / self.us, [w / self.ws]])

    def unscale(self, Y: np.ndarray) -> tuple[np.ndarray, float]:
        """(U (n_H, n_c) mm, w rad/s) of a scaled vector Y."""
        return Y[:-1].reshape(self.shape) * self.us, Y[-1] * self.ws

    def border(self, t: np.ndarray) -> tuple[np.ndarray, float]:
        """Last row (tU, tw) of the bordered system for the scaled direction t: t . dY = tU . dU + tw dw."""
        return t[:-1].reshape(self.shape) / self.us, t[-1] / self.ws

    def rescale(self, U: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Make us the norm of U (so steps stay relative changes); returns t in the new scaling."""
        nu = np.linalg.norm(U)
        if nu > 0 and nu != self.us:
            tu = np.concatenate([t[:-1] * (self.us / nu), t[-1:]])
            t = tu / np.linalg.norm(tu)
            self.us = nu
        return t


def _evaluate(hb, force: np.ndarray, U: np.ndarray, w: float) -> _Eval:
    """Residual and Jacobian blocks at (U mm, w rad/s) for force amplitude ``force`` (N)."""
    Ul = hb.ulin(w, force)
    R, g, nl, Dg = hb.residual(U, w, Ul, deferred=True)
    return _Eval(R, g, nl, Dg, max(np.linalg.norm(U), np.linalg.norm(Ul), 1e-300))


def _tangent(hb, force: np.ndarray, sc: _Scaling, w: float, ev: _Eval, prev: np.ndarray,
             ref_sign: int | None, exact_sign: bool = False) -> tuple[np.ndarray, int]:
    """Predictor: unit tangent of the branch at the point evaluated in ``ev`` (frequency w, rad/s).

    Solves the bordered system with the previous tangent ``prev`` as last row (so t . prev > 0
    before orientation) and flips t when the bordered determinant's sign differs from
    ``ref_sign``, the oriented sign at the previous point: robust at the corner folds of the
    piecewise-linear contact laws, where the tangent can turn by > 90 deg. Only two signs of
    the dense path are compared: a sign of 0 (unknown: GMRES path), here or in ``ref_sign``,
    never flips, so t . prev > 0 then. ``exact_sign``: get the sign by a dense LU on the GMRES
    path too (corner folds).

    Returns:
        (t (U.size + 1,) scaled and of unit norm, sign of the bordered determinant with t as
        last row: ``ref_sign`` after a flip, else the sign found; 0 on the GMRES path).
    """
    Rw = hb.r_omega(w, force, ev.g)
    tU, tw = sc.border(prev)
    [(dU, dw)], sign = hb.linsolve_aug(w, ev.nl, ev.Dg, Rw, tU, tw, [(np.zeros(sc.shape), -1.0)],
                                       exact_sign=exact_sign)
    t = sc.Y(dU, dw)
    t /= np.linalg.norm(t)
    if ref_sign and sign and sign != ref_sign:
        t, sign = -t, -sign
    return t, sign


def _line_search(hb, force: np.ndarray, U: np.ndarray, w: float, dU: np.ndarray, dw: float,
                 r: float):
    """Damping of a corrector step: halve alpha (at most 6 times) while ||R|| does not decrease.

    Args:
        U, w: current iterate (mm, rad/s); dU, dw: full Newton step; r: ||R|| at (U, w).

    Returns:
        (alpha, U + a dU, w + a dw, evaluation there or None, decreased?) where ``a`` is the
        last alpha tried; after 6 failed tries (decreased False) alpha has been halved once more
        than ``a`` (kept as it was). The caller rejects the step when the frequency of the last
        try is <= 0.
    """
    alpha, evt = 1.0, None
    for _ in range(6):
        Ut, wt = U + alpha * dU, w + alpha * dw
        if wt > 0:
            try:
                evt = _evaluate(hb, force, Ut, wt)
            except CycleNotClosed:
                # a trial far from the branch can drive an element's march into a state that
                # does not close: a shorter step, like a larger residual
                evt = None
            else:
                if np.linalg.norm(evt.R) <= (1 - 1e-4 * alpha) * r:
                    return alpha, Ut, wt, evt, True
        alpha *= 0.5
    return alpha, Ut, wt, evt, False


def _correct(hb, force: np.ndarray, sc: _Scaling, Yp: np.ndarray, t: np.ndarray,
             max_corrector: int) -> _Correction:
    """Corrector: damped Newton on {R = 0, t . (Y - Yp) = 0} from the scaled predictor Yp.

    Args:
        t: scaled unit tangent that defines the hyperplane through Yp.
        max_corrector: iteration limit.

    Returns:
        _Correction; ``ok`` False if the limit is reached, a step would make w <= 0, the
        ``CORRECTOR_STALLS``-th line search finds no decrease, or the residual creeps
        (``SLOW_RATIO``, ``SLOW_STEPS``) (the last iterate is returned: the corner a restart
        starts from).
    """
    U, w = sc.unscale(Yp)
    try:
        ev = _evaluate(hb, force, U, w)
    except CycleNotClosed:
        return _Correction(False, U, w, None, 0)      # the predictor is too far: shorter step
    step, stalls, slow, r_prev = np.inf, 0, 0, np.inf
    for it in range(1, max_corrector + 1):
        r = np.linalg.norm(ev.R)
        if it > 1 and hb.converged(r, ev.scale, step):
            return _Correction(True, U, w, ev, it)
        slow = slow + 1 if r > SLOW_ABOVE * hb.tol * ev.scale and r > SLOW_RATIO * r_prev else 0
        if slow >= SLOW_STEPS:
            return _Correction(False, U, w, ev, it)
        r_prev = r
        Rw = hb.r_omega(w, force, ev.g)
        cval = t @ (sc.Y(U, w) - Yp)
        tU, tw = sc.border(t)
        # the step's linear residual need not be below a tenth of the tolerance (inexact Newton,
        # harmonic_balance.KRYLOV_FORCING); the tangent (``_tangent``) stays at krylov_tol
        [(dU, dw)], _ = hb.linsolve_aug(w, ev.nl, ev.Dg, Rw, tU, tw, [(ev.R, cval)],
                                        atol=[hb.step_atol(ev.scale)])
        if not (np.all(np.isfinite(dU)) and np.isfinite(dw)):
            # a singular bordered system (its LU met a zero pivot): no corner restart from here
            # (its tangent's system is singular too), the caller shortens the step
            return _Correction(False, U, w, None, it)
        alpha, Ut, wt, evt, decreased = _line_search(hb, force, U, w, dU, dw, r)
        if wt <= 0 or evt is None:
            return _Correction(False, U, w, ev, it)
        stalls += not decreased
        if stalls >= CORRECTOR_STALLS:
            return _Correction(False, Ut, wt, evt, it)
        step = max(np.linalg.norm(alpha * dU), abs(alpha * dw) / sc.ws * ev.scale)
        U, w, ev = Ut, wt, evt
    return _Correction(False, U, w, ev, max_corrector)


def _cap_step(ds: float, t: np.ndarray, ws: float, max_domega: float) -> float:
    """Step ds (scaled) shortened so that the frequency moves by at most max_domega (rad/s)."""
    return min(ds, max_domega / (abs(t[-1]) * ws)) if t[-1] != 0 else ds


def _adapt_step(ds: float, iterations: int, ds_max: float) -> float:
    """Next step after an accepted point: x1.5 (<= ds_max) after <= 3 corrector iterations,
    x0.7 after >= 7."""
    if iterations <= 3:
        return min(ds * 1.5, ds_max)
    if iterations >= 7:
        return ds * 0.7
    return ds


def _middle_slope(h1: float, s1: float, h2: float, s2: float) -> float:
    """dw/ds at the middle of three points from the parabola through them: segments of lengths h1,
    h2 whose unit secants have w-components s1, s2 (scaled unknowns)."""
    return (h1 * s2 + h2 * s1) / (h1 + h2)


def _turning_points(taus: np.ndarray) -> list[int]:
    """Indices i >= 1 where the w-component of the tangent changed sign from point i - 1."""
    s = np.sign(taus)
    return (np.flatnonzero(s[1:] != s[:-1]) + 1).tolist()


def _stability(hb, sols: list, turning: list[int], stability: str) -> tuple[np.ndarray, str]:
    """Stability flag of each point and the method used ("hill", "fold-parity" or "none")."""
    method = stability
    if stability == "auto":
        method = "hill" if stab.hill_available(hb) else "fold"
    if method == "hill":
        return np.array([stab.is_stable_hill(hb, s_) for s_ in sols]), method
    if method == "fold":
        # the branch starts stable and stability flips at every turning point
        flips = np.searchsorted(np.asarray(turning, dtype=int), np.arange(len(sols)), side="right")
        return flips % 2 == 0, "fold-parity"
    return np.ones(len(sols), dtype=bool), method


# ---------------------------------------------------------------------------------- one run
class _Path:
    """The accepted points of a branch in their raw unknowns (U raveled, mm; w, rad/s) and each
    segment's raw ‖ΔU‖, so that a new point is compared with the whole branch in the current
    scaling without converting every Solution again (``_Branch._retraces``, ``_turned_back``)."""

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []
        self.w: list[float] = []
        self.du: list[float] = []          # segment j joins points j and j + 1

    def append(self, U: np.ndarray, w: float) -> None:
        """Add the next accepted point."""
        r = np.array(U, dtype=float).ravel()
        if self.rows:
            self.du.append(float(np.linalg.norm(r - self.rows[-1])))
        self.rows.append(r)
        self.w.append(float(w))

    def truncate(self, k: int) -> None:
        """Keep the first k points."""
        del self.rows[k:], self.w[k:], self.du[max(k - 1, 0):]

    def retraces(self, U: np.ndarray, w: float, sc: "_Scaling", first: int, stop: int) -> bool:
        """Whether (U, w) lies within RETRACE_DISTANCE of a segment's length of one of the
        segments first … stop - 1 (scaled by ``sc``). Only segments whose frequency range,
        widened by that distance, holds w are measured in full."""
        first, stop = max(first, 0), min(stop, len(self.du))
        if stop <= first:
            return False
        ws = np.asarray(self.w[first:stop + 1])
        length = np.hypot(np.asarray(self.du[first:stop]) / sc.us, np.diff(ws) / sc.ws)
        slack = RETRACE_DISTANCE * length * sc.ws
        near = (w >= np.minimum(ws[:-1], ws[1:]) - slack) & (w <= np.maximum(ws[:-1], ws[1:]) + slack)
        y = sc.Y(U, w)
        for i in np.nonzero(near & (length > 0))[0]:
            j = first + i
            a = np.append(self.rows[j] / sc.us, ws[i] / sc.ws)
            d = np.append(self.rows[j + 1] / sc.us, ws[i + 1] / sc.ws) - a
            L2 = float(d @ d)
            u = min(max(float((y - a) @ d) / L2, 0.0), 1.0)
            if np.linalg.norm(y - a - u * d) <= RETRACE_DISTANCE * np.sqrt(L2):
                return True
        return False


class _Branch:
    """State of one continuation run: current point (U, w), tangent t, step ds, points so far.

    Args:
        hb: the HarmonicBalance solver.
        force: (n,) validated force amplitude, N.
        dof: response DOF of the amplitudes.
        w0, w1: validated start and end frequencies, rad/s.
        settings: the run's ContinuationSettings.
        guess: optional Solution (or object with ``.contact``) to start Newton from at w0.
    """

    def __init__(self, hb, force: np.ndarray, dof: int, w0: float, w1: float,
                 settings: ContinuationSettings, guess=None) -> None:
        self.hb, self.force, self.dof, self.w0, self.w1 = hb, force, dof, w0, w1
        self.settings = settings
        self.direction = np.sign(w1 - w0)
        self.ds = settings.ds
        self.max_domega = settings.frequency_cap(w0, w1)
        sol = hb.solve(w0, force, guess=guess)
        self.U, self.w = hb.from_contact(sol.contact), w0
        # amplitude scale: the norm of the current solution, updated at every step, so that the
        # arc length measures *relative* changes of the response (a friction-limited peak far
        # below the linear one is resolved as well as a linear one)
        us = np.linalg.norm(self.U) if np.linalg.norm(self.U) > 0 else 1.0
        self.sc = _Scaling(us, w0, self.U.shape)
        self.total_it = sol.iterations
        t_guess = np.zeros(self.U.size + 1)
        t_guess[-1] = self.direction
        ev0 = _evaluate(hb, force, self.U, w0)
        self.t, self.ref_sign = _tangent(hb, force, self.sc, w0, ev0, t_guess, None)
        if self.t[-1] * self.direction < 0:
            # the branch starts towards w1; the determinant sign of that orientation is the reference
            self.t = -self.t
            self.ref_sign = -self.ref_sign
        if not self.ref_sign and 3 * hb.nH * ev0.nl.size <= START_SIGN_SIZE:
            self._exact_reference()
        # keep the Jacobian on each point only where Hill's method may use it (memory)
        self.keep_jac = 2 * hb.nH * hb.s.n <= stab.HILL_LIMIT
        self.t_beyond = None      # tangent of the piece beyond the last corner restart
        self.sols, self.taus = [sol], [self.t[-1]]
        # per point: the length and w-component of the secant step that reached it (scaled),
        # None where its direction is a solved tangent (the start, beyond a corner, the tangent
        # predictor)
        self.seg: list[tuple[float, float] | None] = [None]
        self.path = _Path()
        self.path.append(self.U, w0)
        self.amp_prev = sol.amplitude(dof)
        self.amps = [self.amp_prev]
        self.turns: list[bool] = []   # per accepted point: turned sharply or beyond a corner
        self.tightened_at = -1

    def run(self, stop: Callable[[list], bool] | None) -> None:
        """Add points until max_points, the end of the range, a return below the start by more
        than the range, or ``stop(amplitudes so far)`` returns True."""
        while len(self.sols) < self.settings.max_points:
            self.t = self.sc.rescale(self.U, self.t)
            self._accept(*self._next_point())
            if self._past_end():
                break
            self.amps.append(self.amp_prev)
            self._tighten_if_thrashing()
            if stop is not None and stop(self.amps):
                break

    def _next_point(self) -> tuple[_Correction, bool]:
        """Predict along t and correct, halving ds until a point is accepted.

        Returns:
            (the accepted correction, True if it lies beyond a corner fold (corner restart)).

        Raises:
            ConvergenceError when ds falls below ds_min.
        """
        s = self.settings
        Y = self.sc.Y(self.U, self.w)
        flipped = False
        while True:
            self.ds = _cap_step(self.ds, self.t, self.sc.ws, self.max_domega)
            Yp = Y + self.ds * self.t
            corr = _correct(self.hb, self.force, self.sc, Yp, self.t, s.max_corrector)
            self.total_it += corr.it
            plain, beyond = corr.ok, False
            if not plain and corr.ev is not None:     # None: the predictor's march did not close
                corr, beyond = self._corner_restart(Y, Yp, corr)
            if (plain or beyond) and self._amplitude_step_ok(corr):
                if self._turned_back(corr):
                    # the loose tolerance's points may be what the fold cannot be passed from,
                    # as below ds_min: on at the tight one from THRASH_POINTS back; or give up
                    # now (the sweep's caller runs it again at the strict tolerances)
                    if self._tighten():
                        Y, flipped = self.sc.Y(self.U, self.w), False
                        continue
                    res = float(np.linalg.norm(corr.ev.R) / corr.ev.scale)
                    raise ConvergenceError("the continuation turned back onto its branch near "
                                           f"omega = {self.w:.6g} rad/s", res)
                if flipped or not self._retraces(corr):
                    return corr, beyond
                # the step went back along the branch already traced: the tangent here points
                # backwards; once, turn it round and step again
                self.t, self.ref_sign, flipped = -self.t, -self.ref_sign, True
                continue
            self.ds *= 0.5
            if plain:
                continue
            if self.ds < s.ds_min and self._tighten():
                # the loose tolerance's points may be what the corner fold cannot be passed
                # from (ContinuationSettings.tight_tol): on from 20 points back, at the tight one
                Y, flipped = self.sc.Y(self.U, self.w), False
                continue
            if self.ds < s.ds_min:
                res = (float(np.linalg.norm(corr.ev.R) / corr.ev.scale) if corr.ev is not None
                       else float("nan"))
                raise ConvergenceError(f"continuation step fell below ds_min near omega = {self.w:.6g} rad/s",
                                       res)

    def _retraces(self, corr: _Correction) -> bool:
        """True if the corrected point lies on the branch already traced before the current
        point: within a tenth of a segment's length of one of the last ``RETRACE_SEGMENTS``
        segments that end before it (scaled unknowns, ``_Path.retraces``). On 1 rank smooth-ms's
        top-level sweep of the quick model stepped from 0.568 mm back to 0.470 mm at a corner
        fold and traced 0.47 → 0.57 mm a second time (five points more than on 2 ranks)."""
        n = len(self.sols)
        return self.path.retraces(corr.U, corr.w, self.sc, n - 1 - RETRACE_SEGMENTS, n - 2)

    def _turned_back(self, corr: _Correction) -> bool:
        """True if the corrected point lies on a part of the branch traced more than
        ``RETRACE_SEGMENTS`` points before the current one (``_Path.retraces``): the branch has
        turned back onto itself, beyond what :meth:`_retraces` (a step back, turned round once)
        mends. On a quick-preset model smooth-ms's top-level sweep crawled at a corner for 20
        points (ds 1e-4), then went back down the branch it had come up, and retraced 140
        points to below the band before the sweep failed and was run again at the strict
        tolerances (29 of its 43 s; issue 16, session 20)."""
        return self.path.retraces(corr.U, corr.w, self.sc, 0, len(self.sols) - 1 - RETRACE_SEGMENTS)

    def _amplitude_step_ok(self, corr: _Correction) -> bool:
        """The arc length lives on the contact unknowns; the response DOF may resonate in a mode
        the contacts hardly see, so its relative change per step is bounded by max_damp too, and
        the frequency's by 3 max_domega (unless ds is already within 4 ds_min). Corner restarts
        are held to the same bounds: on 2 ranks, v2's top-level sweep of the quick model restarted
        at a corner fold next to its peak (241.1 Hz, 1.38 mm) onto a point beyond the band end
        (0.41 mm), which ended the sweep there: 42 points of the falling flank were missing."""
        s = self.settings
        if self.ds <= 4 * s.ds_min:
            return True
        if abs(corr.w - self.w) > 3 * self.max_domega:
            return False
        cand = self.hb.make_solution(corr.w, self.force, corr.U, 0.0, corr.it, 0, g=corr.ev.g)
        a_new = cand.amplitude(self.dof)
        return abs(a_new - self.amp_prev) <= s.max_damp * max(a_new, self.amp_prev)

    def _corner_restart(self, Y: np.ndarray, Yp: np.ndarray, failed: _Correction):
        """Corner fold of the piecewise-linear contact laws.

        The branch turns back exactly where a time sample switches state, so no point exists on
        the hyperplane ahead. Take the tangent of the piece beyond the corner (Jacobian at the
        predictor Yp), orient it by the bordered-determinant sign, and restart the corrector from
        the corner (the failed corrector's last iterate) along it. The predictor's sign is exact
        (dense LU on the GMRES path, unless the turn is small: ``_small_turn``); the current
        point's is the sign carried along the branch, computed here only when none is known yet
        (``_exact_reference``). The oriented tangent is kept as ``t_beyond``, the orientation of
        the point accepted beyond the corner.

        Returns:
            (the restart's _Correction, accepted?: converged and moved by > 1e-3 ds from Y).
        """
        Up, wp = self.sc.unscale(Yp)
        evp = _evaluate(self.hb, self.force, Up, wp)
        tb = self._small_turn(wp, evp)
        if tb is None:
            self._exact_reference()
            tb, _ = _tangent(self.hb, self.force, self.sc, wp, evp, self.t, self.ref_sign,
                             exact_sign=True)
        if not np.all(np.isfinite(tb)):
            # the bordered system at the predictor is singular with the current direction as its
            # last row (an LU's zero pivot; a NaN tangent made NaN frequencies in the restart's
            # corrector): no restart from this predictor, the caller halves the step
            return failed, False
        self.t_beyond = tb
        Yc = self.sc.Y(failed.U, failed.w)
        corr = _correct(self.hb, self.force, self.sc, Yc + self.ds * tb, tb, self.settings.max_corrector)
        self.total_it += corr.it
        return corr, bool(corr.ok and np.linalg.norm(self.sc.Y(corr.U, corr.w) - Y) > 1e-3 * self.ds)

    def _small_turn(self, wp: float, evp: _Eval) -> np.ndarray | None:
        """The restart's tangent at the predictor (frequency wp, evaluated in ``evp``) without a
        dense LU where the turn is small: on the GMRES path, the tangent found with the current
        one as last row (so t . t_prev > 0) when t . t_prev >= SHARP_TURN, the orientation a
        smooth step keeps (a corner that turns the branch back turns it by far more). None on
        the dense path (its sign comes with the solve; the caller takes it there) and for a
        sharper turn (the caller's dense LU orients it).

        Session 13: the default model's top-level corner restarts turned by 0.90-0.99 (every one
        failed, each after a 3.4 s LU); the restarts the 32-sample speed-stage search needed
        turned by 0.95 and 0.99, the quick model's by -0.40 … 0.99. Halving instead of such a
        restart (tried first) missed those: their branch crawled up to a corner in steps of
        1e-8 and stopped below ds_min."""
        if self.hb.nH * 3 * evp.nl.size <= self.hb.dense_limit:
            return None
        tg, sign = _tangent(self.hb, self.force, self.sc, wp, evp, self.t, None)
        if sign != 0 or tg @ self.t < SHARP_TURN:
            return None
        self.hb.stats["unsigned_restarts"] += 1
        return tg

    def _exact_reference(self) -> None:
        """Make ``ref_sign`` known at the current point when no sign has been computed on the
        branch yet (0): the sign of the bordered determinant with its own tangent as last row, by
        a dense LU (one more evaluation of the Jacobian there)."""
        if not self.ref_sign:
            ev = _evaluate(self.hb, self.force, self.U, self.w)
            _, self.ref_sign = _tangent(self.hb, self.force, self.sc, self.w, ev, self.t, None,
                                        exact_sign=True)

    def _accept(self, corr: _Correction, beyond_corner: bool = False) -> None:
        """Make the corrected point current: new direction, Solution, amplitude, next step.

        With the secant predictor the new direction is the secant to the point (:meth:`_secant`),
        except beyond a corner restart, where the tangent of the new piece is solved as below.

        The new tangent is found with the tangent of the piece the point lies on as last row:
        the previous point's, or after a corner restart (``beyond_corner``) ``t_beyond``. A GMRES
        tangent that turned from it by less than acos(SHARP_TURN) keeps t . prev > 0 and carries
        the branch's sign on; one that turned more is oriented by exact determinant signs (dense
        LU), as where the branch may have passed a corner fold within the step."""
        hb, ev = self.hb, corr.ev
        prev = self.t_beyond if beyond_corner else self.t
        if self.settings.predictor == "secant" and not beyond_corner:
            t, sign = self._secant(corr)
        else:
            t, sign = _tangent(hb, self.force, self.sc, corr.w, ev, prev, self.ref_sign)
            exact = sign == 0 and t @ prev < SHARP_TURN
            if sign == 0 and not exact:
                sign = self.ref_sign
            if exact:
                self._exact_reference()           # at the previous point, so before moving on
                t, sign = _tangent(hb, self.force, self.sc, corr.w, ev, prev, self.ref_sign, exact_sign=True)
            self.seg.append(None)
        self.turns.append(bool(beyond_corner or t @ prev < SHARP_TURN))
        # the reference of the next orientation: this point's sign, found or carried
        self.U, self.w, self.t, self.ref_sign = corr.U, corr.w, t, sign
        self.sols.append(self._solution(corr))
        self.path.append(corr.U, corr.w)
        self.amp_prev = self.sols[-1].amplitude(self.dof)
        self.taus.append(self.t[-1])
        self.ds = _adapt_step(self.ds, corr.it, self.settings.ds_max)

    def _secant(self, corr: _Correction) -> tuple[np.ndarray, int]:
        """The secant predictor at the corrected point ``corr`` (``ContinuationSettings.predictor``):
        the unit direction from the current point to it, and the determinant sign carried on.

        The secant is oriented by the direction of travel, so it needs no determinant sign of its
        own. The branch's sign (``ref_sign``, the orientation a corner restart's tangent gets) is
        carried on through smooth steps; after a sharp turn (t . t_prev < SHARP_TURN: a corner may
        lie within the step) it is unknown (0) and found again, by a dense LU, only if a corner
        restart needs it (``_exact_reference``). The point's w-component (``taus``, the turning
        points) is the secant's until the next point arrives; then the previous point's becomes the
        derivative of the parabola through its two neighbours (:func:`_middle_slope`), a tangent's
        to O(ds^2).
        """
        sec = self.sc.Y(corr.U, corr.w) - self.sc.Y(self.U, self.w)
        h = float(np.linalg.norm(sec))
        t = sec / h
        if self.seg[-1] is not None:
            self.taus[-1] = _middle_slope(*self.seg[-1], h, t[-1])
        self.seg.append((h, t[-1]))
        return t, (self.ref_sign if t @ self.t >= SHARP_TURN else 0)

    def _tighten_if_thrashing(self) -> None:
        """Go on at ``settings.tight_tol`` once the branch thrashes at a fold (:data:`THRASH_TURNS`
        of the last :data:`THRASH_POINTS` points turned sharply, and they hardly moved on); once
        per branch."""
        if (self.settings.tight_tol is None or self.tightened_at >= 0
                or sum(self.turns[-THRASH_POINTS:]) < THRASH_TURNS):
            return
        ys = np.array([self.sc.Y(self.hb.from_contact(p.contact), p.omega)
                       for p in self.sols[-THRASH_POINTS - 1:]])
        path = float(np.linalg.norm(np.diff(ys, axis=0), axis=1).sum())
        if np.linalg.norm(ys[-1] - ys[0]) < THRASH_PROGRESS * path:
            self._tighten()

    def _tighten(self) -> bool:
        """Set the solver's tolerances to ``settings.tight_tol`` for the rest of the branch and go
        back to the point THRASH_POINTS before the current one (the loose points since may be
        what the fold cannot be passed from): solve it again at them (on the hyperplane through
        it normal to the secant from the point before it) with its tangent, and drop the points
        after it. False when there is no tight_tol, or it is set already."""
        if self.settings.tight_tol is None or self.tightened_at >= 0:
            return False
        hb = self.hb
        hb.tol, hb.krylov_tol = self.settings.tight_tol
        self.ds = self.settings.ds
        k = max(len(self.sols) - 1 - THRASH_POINTS, 1)
        Yk = self.sc.Y(hb.from_contact(self.sols[k].contact), self.sols[k].omega)
        sec = Yk - self.sc.Y(hb.from_contact(self.sols[k - 1].contact), self.sols[k - 1].omega)
        norm = float(np.linalg.norm(sec))
        sec = sec / norm if norm > 0 else self.t
        corr = _correct(hb, self.force, self.sc, Yk, sec, self.settings.max_corrector)
        if not corr.ok:                 # on from the current point, at the tight tolerance
            self.tightened_at = len(self.sols)
            return True
        t, sign = _tangent(hb, self.force, self.sc, corr.w, corr.ev, sec, None)
        del self.sols[k:], self.taus[k:], self.amps[k:], self.seg[k:]
        self.path.truncate(k)
        self.turns[k - 1:] = [False]          # one per point after the first, the new one's too
        self.U, self.w, self.t, self.ref_sign, self.t_beyond = corr.U, corr.w, t, sign, None
        self.sols.append(self._solution(corr))
        self.path.append(corr.U, corr.w)
        self.amp_prev = self.sols[-1].amplitude(self.dof)
        self.amps.append(self.amp_prev)
        self.taus.append(self.t[-1])
        self.seg.append(None)
        self.tightened_at = k
        return True

    def _solution(self, corr: _Correction):
        """The Solution of a corrected point (current tolerances)."""
        ev = corr.ev
        return self.hb.make_solution(corr.w, self.force, corr.U, float(np.linalg.norm(ev.R) / ev.scale),
                                     corr.it, ev.nl.size, g=ev.g,
                                     jac=(ev.nl, ev.Dg) if self.keep_jac else None)

    def _past_end(self) -> bool:
        """True if the last point is beyond w1 (then re-solved exactly at w1 when Newton manages)
        or back below w0 by more than the range."""
        if (self.w - self.w1) * self.direction >= 0:
            try:
                self.sols[-1] = self.hb.solve(self.w1, self.force, guess=self.sols[-1])
            except ConvergenceError:
                pass
            return True
        return bool((self.w - self.w0) * self.direction < -abs(self.w1 - self.w0))

    def result(self, t_start: float) -> FRFResult:
        """FRFResult of the points so far, with stability; wall time from ``t_start`` (perf_counter)."""
        sols = self.sols
        omega = np.array([s_.omega for s_ in sols])
        amp = np.array([s_.amplitude(self.dof) for s_ in sols])
        turning = _turning_points(np.array(self.taus))
        stable, method = _stability(self.hb, sols, turning, self.settings.stability)
        return FRFResult(omega, amp, stable, sols, turning, method, time.perf_counter() - t_start,
                         self.total_it, self.tightened_at)


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
    branch = _Branch(hb, force, dof, w0, w1, settings, guess)
    branch.run(stop)
    return branch.result(t0)
