"""Frequency responses of the reduced resonator with a friction element per active pair.

Thin layer between the study and the ``hbm`` package: it turns a
:class:`~fe_joint.model.joint.JointModel` into ``FrictionContacts`` (element stiffness = k · area; only
the elements with a contact stiffness are modelled), runs one FRF by continuation, and keeps what
the report needs at resonance — per-element status, dissipated energy, cycle-mean normal load,
tangential force amplitude and loops — as plain arrays (:class:`CurveResult`, saved as ``.npz``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from pathlib import Path

import numpy as np

from hbm import (ContinuationSettings, ConvergenceError, FrictionContacts, HarmonicBalance,
                 LinearStructure)

from ..model.joint import JointModel
from .artifacts import CurveKey, save_dataclass_npz

OPEN = 4   # status code of elements left out of the dynamics (hbm's OPEN)


class SweepIncomplete(ConvergenceError):
    """A frequency sweep that did not cover its band (its peak may be missing)."""

    def __init__(self, message: str) -> None:
        RuntimeError.__init__(self, message)
        self.residual = float("nan")


@dataclass(frozen=True)
class SweepSettings:
    """The harmonic-balance settings of every FRF of a study, built once from the case.

    Attributes:
        harmonics: highest harmonic H.
        samples: AFT samples per period.
        band: (low, high) sweep band as fractions of the stuck linear frequency.
        max_points: cap on continuation points per curve.
        mu: friction coefficient.
    """
    harmonics: int
    samples: int
    band: tuple[float, float]
    max_points: int
    mu: float

    def continuation(self, w0: float, w1: float) -> ContinuationSettings:
        """hbm's continuation settings of a full sweep over [w0, w1] rad/s.

        Step guards: at most 1/50 of the band per step and at most 25 % change of the response
        amplitude per step (hbm's defaults, 1/100 and 10 %, doubled the points for the same peak
        to 0.01 % on the quick model).
        """
        return ContinuationSettings(max_points=self.max_points, max_domega=(w1 - w0) / 50,
                                    max_damp=0.25)

    @classmethod
    def from_case(cls, case) -> "SweepSettings":
        """From the validated case's ``[dynamics]`` and ``[contact]`` sections."""
        d = case.dynamics
        return cls(harmonics=d.harmonics, samples=d.samples, band=(d.band[0], d.band[1]),
                   max_points=d.max_points, mu=case.contact.mu)


#: the validated structures of the last reduced models (``structure``): (rm, LinearStructure)
_STRUCTURES: list = []


def structure(rm) -> LinearStructure:
    """The reduced linear structure; modal damping applies to the modes of the stuck assembly.

    Kept for the two reduced models used last (by identity; a stage's jobs share one): its
    validation (symmetry, a Cholesky of M) took 0.5 s of each curve's 1.3 s set-up on the
    default model (2198 DOFs), and every curve, pass and backbone builds one."""
    hit = [(m, s) for m, s in _STRUCTURES if m is rm]
    s = hit[0][1] if hit else LinearStructure(rm.M, rm.K, damping_ratio=rm.damping_ratio)
    _STRUCTURES[:] = [(rm, s)] + [(m, s_) for m, s_ in _STRUCTURES if m is not rm][:1]
    return s


def contacts(rm, joint: JointModel, mu: float) -> tuple[FrictionContacts, np.ndarray]:
    """Friction elements of the active pairs (k_n, k_t > 0) and their indices."""
    act = np.nonzero((joint.kn > 0) & (joint.kt > 0))[0]
    if len(act) == 0:
        raise ValueError(f"configuration {joint.name}: no pair has a contact stiffness")
    A = joint.area[act]
    c = FrictionContacts(np.asarray(rm.pair_dofs)[act], kt=joint.kt[act] * A,
                         kn=joint.kn[act] * A, mu=mu, n0=joint.n0[act], gap=joint.gap[act])
    return c, act


@dataclass
class CurveResult:
    """One FRF and the joint's state at its peak. Arrays over all pairs (ne) unless noted."""
    config: str
    level: float                 # N, excitation amplitude on mass A in x
    omega_hz: np.ndarray         # (p,) Hz
    amplitude: np.ndarray        # (p,) mm, first harmonic at the response DOF
    stable: np.ndarray           # (p,) bool
    peak_hz: float
    peak_amplitude: float        # mm
    status: np.ndarray           # (ne,) 0 stuck, 1 stick-slip, 2 gross slip, 3 partly open, 4 open
    energy: np.ndarray           # (ne,) N·mm per cycle at the peak
    mean_normal: np.ndarray      # (ne,) N, cycle mean at the peak
    q_amp: np.ndarray            # (ne, 2) N, tangential force amplitude per direction
    loop_u: np.ndarray           # (nt,) mm, joint loop: area-weighted mean relative u_x
    loop_T: np.ndarray           # (nt,) N, joint loop: Σ T_x
    elem_u: np.ndarray           # (ne, nt) mm, element u_x over the cycle (0 for inactive)
    elem_T: np.ndarray           # (ne, nt) N, element T_x over the cycle
    seconds: float
    newton_iterations: int
    n_points: int
    n_active: int
    n_nonlinear: int             # elements slipping or separating at the peak
    level_index: int = -1        # which study level (-1: the small-excitation check)
    rq_um: float = float("nan")  # Rq of the surface behind the joint, µm (NaN: none)
    # the Newton tolerance the sweep ended at (SWEEP_TOLERANCES[0]; THRASH_TOLERANCES after a
    # hand-over at a fold; the strict one after a rerun), and the frequency from which it went on
    # at THRASH_TOLERANCES, Hz (NaN: no hand-over); NaN for a local branch (``peak_near``)
    sweep_tol: float = float("nan")
    handover_hz: float = float("nan")
    # the contact harmonics at the peak, (ne, 3, 2H + 1), zeros for inactive pairs: the warm
    # start of a peak search on a slightly changed joint or other H (the speed stage's rows from
    # the study's curve); (0, 3, 0) in files written before it
    peak_contact: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 0)))

    @property
    def key(self) -> CurveKey:
        """The curve's typed key (stored inside its file)."""
        return CurveKey.from_fields(self.config, self.level_index, self.rq_um)

    def with_key(self, key: CurveKey) -> "CurveResult":
        """A copy labelled with ``key`` (configuration, level index, Rq)."""
        return replace(self, **key.to_fields())

    def save(self, path: Path) -> None:
        save_dataclass_npz(self, path)

    @classmethod
    def load(cls, path: Path) -> "CurveResult":
        with np.load(path, allow_pickle=False) as d:
            kw = {k: d[k] for k in d.files}
        for k in ("config",):
            kw[k] = str(kw[k])
        for k in ("level", "peak_hz", "peak_amplitude", "seconds", "rq_um", "sweep_tol",
                  "handover_hz"):
            if k in kw:          # the last two are missing from files written before them
                kw[k] = float(kw[k])
        for k in ("newton_iterations", "n_points", "n_active", "n_nonlinear", "level_index"):
            kw[k] = int(kw[k])
        return cls(**kw)

    @property
    def dissipated(self) -> float:
        """Energy dissipated by friction per cycle at the peak, N·mm."""
        return float(self.energy.sum())


def frf(rm, joint: JointModel, level: float, f_lin: float, settings: SweepSettings) -> CurveResult:
    """FRF of one configuration at one excitation level, and the joint state at its peak.

    Args:
        rm: ReducedModel.
        joint: the configuration's element parameters.
        level: excitation amplitude on mass A in x, N.
        f_lin: stuck linear frequency of the configuration, Hz (sets the band).
        settings: harmonics, samples, band (fractions of f_lin), max_points, μ.
    """
    return frf_with_peak(rm, joint, level, f_lin, settings)[0]


#: Tolerances of the FRF sweeps: (Newton, GMRES) relative; first the fast pair, then hbm's defaults.
#: The fast pair takes 20-30 % less time than hbm's on the resonator's curves (fewer Newton and
#: GMRES iterations) and moves the polished peaks by ≈ 2e-5 in frequency and 1e-6 in amplitude,
#: far below the v3 tolerance (1e-3). It once made the continuation lose its direction at a fold
#: (v1's top-level curve retraced its branch below the band); a sweep that fails with it is
#: therefore rerun with the strict pair before the failure is reported. Newton 1e-6 is 9-20 %
#: faster than 1e-7 on the default model's curves, but on a quick-preset model the top-level
#: smooth-ms sweep at 1e-6 sat at a corner fold for 550 points whose tangents flipped back and
#: forth (311 sign LUs, 217 s instead of 14 s at 1e-7; issue 16, session 15): a sweep that
#: thrashes so, or whose step falls below its minimum, goes back 20 points and on from there at
#: THRASH_TOLERANCES (``hbm.continuation.THRASH_TURNS``, ``ContinuationSettings.tight_tol``).
SWEEP_TOLERANCES = ((1e-6, 1e-8), (1e-9, 1e-11))
#: the fast sweep's tolerances from where it thrashes at a fold (see SWEEP_TOLERANCES)
THRASH_TOLERANCES = (1e-7, 1e-8)


def _setup(rm, joint: JointModel, level: float, settings: SweepSettings,
           tols: tuple[float, float] = SWEEP_TOLERANCES[0]):
    c, act = contacts(rm, joint, settings.mu)
    hb = HarmonicBalance(structure(rm), c, harmonics=settings.harmonics, samples=settings.samples,
                         tol=tols[0], krylov_tol=tols[1])
    force = np.zeros(rm.K.shape[0])
    force[rm.excitation_dof] = level
    return hb, force, act


def frf_with_peak(rm, joint: JointModel, level: float, f_lin: float, settings: SweepSettings):
    """:func:`frf`, also returning the contact harmonics at the peak, (ne, 3, 2H+1) over all pairs
    (zeros for inactive ones): the warm start of :func:`peak_near` on a slightly changed joint.

    A sweep that fails with the fast tolerances is run once more with hbm's strict ones
    (``SWEEP_TOLERANCES``) before the failure is reported."""
    fast, strict = SWEEP_TOLERANCES
    t0 = time.perf_counter()
    try:
        return _sweep(rm, joint, level, f_lin, settings, fast)
    except ConvergenceError:
        cr, contact = _sweep(rm, joint, level, f_lin, settings, strict)
        # the curve's seconds count the failed fast sweep too (it was 80 of 100 s of the quick
        # model's top-level baseline job once, and the timings showed 20 s)
        return replace(cr, seconds=time.perf_counter() - t0), contact


def _sweep(rm, joint: JointModel, level: float, f_lin: float, settings: SweepSettings,
           tols: tuple[float, float]):
    t0 = time.perf_counter()
    hb, force, act = _setup(rm, joint, level, settings, tols)
    max_points = settings.max_points
    w0, w1 = 2 * np.pi * f_lin * settings.band[0], 2 * np.pi * f_lin * settings.band[1]
    cs = settings.continuation(w0, w1)
    if tols == SWEEP_TOLERANCES[0]:
        cs = replace(cs, tight_tol=THRASH_TOLERANCES)
    res = hb.frf(w0, w1, force, dof=rm.response_dof, settings=cs)
    sweep_tol = hb.tol                   # before the peak search (it restores hb.tol anyway)
    # a branch that stops short of the band end may miss the peak: say so, never report it
    if res.omega[-1] < w1 * (1 - 1e-9):
        why = ("raise dynamics.max_points" if len(res.omega) >= max_points else
               "the continuation turned back at a fold and retraced the branch")
        raise SweepIncomplete(
            f"FRF of {joint.name} at {level:.4g} N stopped at {res.omega[-1] / 2 / np.pi:.2f} Hz after "
            f"{len(res.omega)} points, before the band end {w1 / 2 / np.pi:.2f} Hz: {why}")
    k = int(np.argmax(res.amplitude))
    if k in (0, len(res.omega) - 1) or res.omega[k] <= res.omega.min() * (1 + 1e-9):
        raise SweepIncomplete(
            f"FRF of {joint.name} at {level:.4g} N peaks at the edge of its branch "
            f"({res.omega[k] / 2 / np.pi:.2f} Hz): widen dynamics.band")
    branch, kb, its = res, k, 0
    gap = max(abs(res.omega[k + 1] - res.omega[k]), abs(res.omega[k] - res.omega[k - 1]))
    if gap > PEAK_GAP * res.omega[k]:
        # the sweep stepped over the top (its steps may be 1/50 of the band): resample its two
        # steps next to the largest point, or where that cannot be done trace the branch again
        # finely from there, so that the peak search starts next to the maximum
        fine = _scan_top(hb, force, rm.response_dof, res, k)
        if fine is not None:
            branch, kb, its = fine
        else:
            try:
                branch, kb, its = _local_branch(hb, force, rm.response_dof, float(res.omega[k]),
                                                res.solutions[k])
            except ConvergenceError:
                branch, kb, its = res, k, 0
    peak_sol = _refine_peak(hb, force, rm.response_dof,
                            _polish_peak(hb, force, rm.response_dof, branch, kb))
    cr = _curve_result(hb, rm, joint, level, act, peak_sol, res.omega, res.amplitude,
                       np.asarray(res.stable, bool), res.newton_iterations + its, t0)
    at = res.tightened_at
    cr = replace(cr, sweep_tol=sweep_tol,
                 handover_hz=float(res.omega[at] / (2 * np.pi)) if at >= 0 else float("nan"))
    return cr, _full_contact(joint, act, peak_sol)


def _full_contact(joint: JointModel, act: np.ndarray, sol) -> np.ndarray:
    out = np.zeros((len(joint.area),) + sol.contact.shape[1:])
    out[act] = sol.contact
    return out


#: half-width of the frequency window :func:`peak_near` may search, relative
PEAK_WINDOW = 0.03
#: relative fall of the amplitude beyond a maximum that ends the local search
PEAK_DROP = 0.01
#: a sweep whose largest point is farther than this (relative) from a neighbour is resampled
#: around it (``_scan_top``), or traced again finely (``_local_branch``) where its frequency is
#: not monotone there, before the peak search. Without either, the quick model's v3-rq10 at the
#: top level went from 241.35 to 241.77 Hz over a peak at 241.51 Hz, and the peak search from
#: there, through a bracket grown to 1.7e-3, ended 3.4e-5 apart on 1 and 2 ranks; the small
#: case's baseline at the top level (tests/test_workflow.py) found a bump 2.5e-4 away and 3e-3
#: lower than its sharp top. Tracing cost 2-4 s at the default model's middle level and 10-32 s
#: at its top (its steps cross corner folds, each oriented by a dense LU); the resampling
#: 0.2-4 s for the same peaks (issue 16, session 10).
PEAK_GAP = 2e-4
#: a top the sweep stepped over is resampled with this many sub-steps per step (``_scan_top``)
SCAN_SUBDIVISIONS = 4


def peak_near(rm, joint: JointModel, level: float, f_guess: float, guess: np.ndarray,
              settings: SweepSettings, max_points: int = 80,
              refine: bool = True) -> tuple[CurveResult, np.ndarray]:
    """The resonance peak of ``joint`` near ``f_guess``, without sweeping the whole band.

    For the v3 fixed point, whose joint changes little from pass to pass: Newton at ``f_guess``
    from ``guess`` (the previous pass's peak contact harmonics, as returned here and by
    :func:`frf_with_peak`), then pseudo-arc-length continuation from
    there in the direction in which the amplitude grows (turning points included) until it has
    passed its maximum, then the same parabolic polish and (``refine``) golden-section peak search
    as :func:`frf`. The returned curve holds only the points of that short branch (stability not
    computed: all marked stable).

    ``refine=False`` keeps the polished peak (to about 1e-6 in frequency): the v3 fixed point's
    passes compare peaks to ``contact.kt_tol`` (1e-3), and the search to 1e-9 at tight tolerances
    was half of a local pass (6 of 11-13 s on the default model at the middle level).

    Returns:
        (CurveResult, contact harmonics at the peak (ne, 3, 2H+1)).

    Raises:
        SweepIncomplete (a ConvergenceError) when no interior peak is found within ±PEAK_WINDOW;
        ConvergenceError when Newton fails — callers fall back to :func:`frf_with_peak`.
    """
    t0 = time.perf_counter()
    hb, force, act = _setup(rm, joint, level, settings)
    start = None
    if guess is not None:
        n_h = 2 * settings.harmonics + 1
        if guess.shape[1:] != (3, n_h):
            raise ValueError(f"guess must have shape (ne, 3, {n_h}), got {guess.shape}")
        start = SimpleNamespace(contact=guess[act])   # elements new to the set start at rest
    dof = rm.response_dof
    try:
        branch, k, its = _local_branch(hb, force, dof, 2 * np.pi * f_guess, start, max_points)
    except SweepIncomplete:
        raise SweepIncomplete(f"no resonance peak of {joint.name} at {level:.4g} N within "
                              f"±{100 * PEAK_WINDOW:g} % of {f_guess:.2f} Hz") from None
    omega, amp = branch.omega, branch.amplitude
    peak_sol = _polish_peak(hb, force, dof, branch, k)
    if refine:
        peak_sol = _refine_peak(hb, force, dof, peak_sol)
    order = np.argsort(omega)   # a short branch near the peak: shown by frequency
    cr = _curve_result(hb, rm, joint, level, act, peak_sol, omega[order], amp[order],
                       np.ones(len(omega), bool), its, t0)
    return cr, cr.peak_contact


def _scan_top(hb, force: np.ndarray, dof: int, res, k: int, n: int | None = None):
    """The sweep's top resampled at fixed frequencies: ``n - 1`` evenly spaced inside each of the
    two steps next to the largest point k (n = ``SCAN_SUBDIVISIONS`` unless given), each solve
    started from the contact harmonics interpolated between the step's ends.

    Only where the branch is a function of ω there: the frequencies of points k - 1, k, k + 1
    strictly monotone (no turning point between them). Fixed-frequency solves need no tangent
    and no bordered system, so no dense LU at the corner folds that a traced branch
    (:func:`_local_branch`) orients by one.

    Returns:
        (branch with omega, amplitude, solutions sorted by ω; index of its largest point;
        Newton iterations), or None where ω is not monotone or a solve fails (then the caller
        traces the branch).
    """
    n = SCAN_SUBDIVISIONS if n is None else n
    ends = (k - 1, k, k + 1)
    w = [float(res.omega[i]) for i in ends]
    if not (w[0] < w[1] < w[2] or w[0] > w[1] > w[2]):
        return None
    pts = {w[j]: res.solutions[i] for j, i in enumerate(ends)}
    its = 0
    for a, b in ((k - 1, k), (k, k + 1)):
        wa, wb = float(res.omega[a]), float(res.omega[b])
        step = {wa: res.solutions[a], wb: res.solutions[b]}
        for j in range(1, n):
            wj = wa + (wb - wa) * j / n
            try:
                sol = hb.solve(wj, force, guess=_interpolated_start(wj, step, res.solutions[a]))
            except ConvergenceError:
                return None
            its += sol.iterations
            pts[wj] = sol
    omega = np.array(sorted(pts))
    sols = [pts[x] for x in omega]
    amp = np.array([x.amplitude(dof) for x in sols])
    kk = int(np.argmax(amp))
    if not 0 < kk < len(omega) - 1:
        return None
    return SimpleNamespace(omega=omega, amplitude=amp, solutions=sols), kk, its


def _local_branch(hb, force: np.ndarray, dof: int, w: float, start, max_points: int = 80):
    """A short, finely stepped branch through the peak next to ``w`` (rad/s), from ``start``.

    Pseudo-arc-length continuation with small steps (≤ 0.1 % in frequency, ≤ 5 % in amplitude)
    first towards lower frequencies, then, if the amplitude falls that way, towards higher ones,
    each until it has passed a maximum (two points beyond it and 1 % below it).

    Returns:
        (branch with omega, amplitude, solutions; index of its largest point; Newton iterations).

    Raises:
        SweepIncomplete when the largest point is an end of the branch (no peak within
        ±PEAK_WINDOW); ConvergenceError when Newton fails.
    """
    # the secant predictor, as the sweeps (session 23): the tangent's solve at every point was
    # 5.6 of the 14.8 s of a default-model v3 job's local branches (v3-rq5: 40.3 -> 35.6 s for the
    # job). On a bumpy top (corners of the sampled friction law) which neighbouring maximum the
    # polish lands on depends on the branch's points, whatever the predictor: the small case's
    # Rq 1 µm passes 2.9e-4 in amplitude from the sweep's refined peak with the secant, the
    # default model's Rq 1 µm 1.1e-4 with the tangent (study 23a) and 1.7e-7 with the secant
    local = ContinuationSettings(max_points=max_points, max_domega=w * 1e-3, max_damp=0.05,
                                 stability="none", predictor="secant")

    def passed(amps):
        # two points beyond a maximum and 1 % below it (small bumps of the sampled friction
        # law are passed over); or as far below the start (the other way is up)
        k = int(np.argmax(amps))
        return len(amps) > k + 2 and amps[-1] < amps[k] * (1 - PEAK_DROP)

    # first towards lower frequencies (callers start just above the expected peak, where the
    # branch is single-valued even when it folds below the peak), then, if the amplitude falls
    # that way, towards higher ones; the two pieces joined at the start bracket the maximum
    pieces, its = [], 0
    for direction in (-1.0, 1.0):
        res = hb.frf(w, w * (1 + direction * PEAK_WINDOW), force, dof=dof, settings=local,
                     guess=start, stop=passed)
        its += res.newton_iterations
        pieces.append(res)
        if int(np.argmax(res.amplitude)) > 0:
            break
    if len(pieces) == 1:
        omega, amp, sols = pieces[0].omega, pieces[0].amplitude, list(pieces[0].solutions)
    else:
        lo, hi = pieces
        omega = np.concatenate([lo.omega[::-1], hi.omega[1:]])
        amp = np.concatenate([lo.amplitude[::-1], hi.amplitude[1:]])
        sols = list(lo.solutions)[::-1] + list(hi.solutions)[1:]
    k = int(np.argmax(amp))
    if not 0 < k < len(omega) - 1:
        raise SweepIncomplete(f"no resonance peak within ±{100 * PEAK_WINDOW:g} % of "
                              f"{w / 2 / np.pi:.2f} Hz")
    return SimpleNamespace(omega=omega, amplitude=amp, solutions=sols), k, its


def _curve_result(hb, rm, joint, level, act, peak_sol, omega, amplitude, stable, iterations,
                  t0) -> CurveResult:
    peak_hz = float(peak_sol.omega / (2 * np.pi))
    peak_amp = float(peak_sol.amplitude(rm.response_dof))
    er = hb.element_results(peak_sol)
    ne, nt = len(joint.area), er.T.shape[-1]
    status = np.full(ne, OPEN, dtype=np.int64)
    status[act] = er.status
    energy = np.zeros(ne)
    energy[act] = er.energy
    mean_normal = np.zeros(ne)
    mean_normal[act] = er.mean_normal
    q_amp = np.zeros((ne, 2))
    q_amp[act] = 0.5 * (er.T.max(axis=2) - er.T.min(axis=2))
    elem_u = np.zeros((ne, nt))
    elem_T = np.zeros((ne, nt))
    elem_u[act] = er.u_t[:, 0, :]
    elem_T[act] = er.T[:, 0, :]
    w = joint.area / joint.area.sum()
    return CurveResult(
        config=joint.name, level=float(level), omega_hz=np.asarray(omega) / (2 * np.pi),
        amplitude=np.asarray(amplitude), stable=stable,
        peak_hz=peak_hz, peak_amplitude=peak_amp,
        status=status, energy=energy, mean_normal=mean_normal, q_amp=q_amp,
        loop_u=(w[:, None] * elem_u).sum(axis=0), loop_T=elem_T.sum(axis=0),
        elem_u=elem_u, elem_T=elem_T, seconds=time.perf_counter() - t0,
        newton_iterations=int(iterations), n_points=len(omega),
        n_active=len(act), n_nonlinear=int(np.sum(er.status > 0)),
        peak_contact=_full_contact(joint, act, peak_sol))


def _interpolated_start(w: float, known: dict, fallback):
    """The warm start of a solve at ω = w (rad/s): the contact harmonics interpolated linearly
    between the solutions of ``known`` (ω -> Solution) nearest to w on either side, or
    ``fallback`` where w is not between two of them (or ``INTERPOLATED_START`` is off)."""
    lo = max((x for x in known if x < w), default=None)
    hi = min((x for x in known if x > w), default=None)
    if not INTERPOLATED_START or lo is None or hi is None:
        return fallback
    a = (w - lo) / (hi - lo)
    return SimpleNamespace(contact=(1 - a) * known[lo].contact + a * known[hi].contact)


def _polish_peak(hb, force: np.ndarray, dof: int, res, k: int, iterations: int = 6,
                 rtol: float = 1e-6):
    """The resonance peak to solver precision: successive parabolic interpolation on the branch.

    Continuation points are discrete (a step may change the amplitude by 25 %), so the largest
    point can miss the peak by a few 0.1 %, more than the v3 fixed point's tolerance. Starting
    from the largest point and its neighbours, each iteration solves at the vertex of the
    parabola through the best three points (warm start: the nearest solution) and keeps the
    best three. Stops when the vertex moves by less than ``rtol`` (relative frequency).

    Returns:
        the Solution at the peak (the largest continuation point if no better one is found).
    """
    pts = [(float(res.omega[i]), float(res.amplitude[i]), res.solutions[i]) for i in (k - 1, k, k + 1)]
    best = pts[1]
    for _ in range(iterations):
        pts.sort(key=lambda p: p[0])
        (x0, y0, _), (x1, y1, _), (x2, y2, _) = pts
        den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0)
        if den == 0:
            break
        xv = x1 - 0.5 * ((x1 - x0) ** 2 * (y1 - y2) - (x1 - x2) ** 2 * (y1 - y0)) / den
        if not (x0 < xv < x2) or abs(xv - best[0]) <= rtol * best[0]:
            break
        guess = _interpolated_start(xv, {p[0]: p[2] for p in pts},
                                    min(pts, key=lambda p: abs(p[0] - xv))[2])
        try:
            sol = hb.solve(xv, force, guess=guess)
        except ConvergenceError:
            break
        pts.append((xv, sol.amplitude(dof), sol))
        # keep the best point and its nearest neighbours on each side
        pts.sort(key=lambda p: p[0])
        j = max(range(len(pts)), key=lambda i: pts[i][1])
        if j == 0 or j == len(pts) - 1:
            break
        pts = pts[j - 1:j + 2]
        best = pts[1]
    return best[2]


#: Peak search: half-width of the first bracket around the polished peak, relative. Small, so
#: that on a softening branch the bracket stays on the near side of the fold below the peak.
PEAK_BRACKET = 1e-5
#: Peak search: the bracket grows by the golden ratio at most this many times
PEAK_EXPANSIONS = 12
#: Peak search: stop when the bracket is narrower than this (relative frequency): 0.00025 Hz at
#: the resonator's 245 Hz, where the report prints peaks to 0.01 Hz, the discretization moves them
#: by 3e-5 (AFT samples) … 5e-4 (interface mesh) and issue 16 compares them to 1e-4. Until
#: session 23 it was 1e-9: 19 golden sections instead of 5 from the first bracket, 3.5 → 2.1 s
#: (baseline@L1), 12.9 → 7.9 s (smooth-ms@L2, a top with kinks) and 3.5 → 2.3 s (v2@L2) of each
#: curve, the peaks moving by 1.1e-7, 4.4e-8 and 1.3e-7 (default model, one process each).
PEAK_XTOL = 1e-6
#: Tolerances (Newton, GMRES) of the peak search's solves. Tighter than hbm's strict pair: at
#: Newton 1e-9 two solves at the same ω from different warm starts gave amplitudes 2.5e-8 apart
#: (relative, v2's top-level peak of the quick model, residuals 4e-10 and 1e-11), more than a
#: comparison of amplitudes near a maximum can tolerate; one more Newton iteration (quadratic)
#: reaches ≈ 1e-15 there.
PEAK_TOLERANCES = (1e-12, 1e-11)
#: Peak search on a top with kinks: once this many of its points were kinks (the tight solve
#: stalled above hbm's strict tolerance, or failed again from a looser solution), its later points
#: are solved at ``KINK_TOLERANCES`` only. At a kink of the sampled friction law every tight
#: solve stalls: on one quick-preset model's top-level baseline each point took a failed tight
#: solve, a looser one and a failed tight one again (50-90, 12-36 and 50-90 residuals), 50 s for
#: one search instead of 3 s (issue 16, session 15).
KINK_POINTS = 2
#: Peak search: the tolerances (Newton, GMRES) of its solves on a top with kinks. The amplitudes
#: are then exact to ≈ 1e-7, which at a corner of slopes ±3 (dX/X over dω/ω) places the maximum
#: to ≈ 3e-8 in frequency.
KINK_TOLERANCES = (1e-7, 1e-8)
#: Peak search: half-width of the three-point stencil of the smooth top's vertex, relative
PEAK_STENCIL = 1e-5
#: Peak search: a vertex at most this much below the golden section's maximum (relative) is taken
PEAK_SMOOTH = 1e-10
#: Peak polish and search: start each solve from the contact harmonics interpolated between the
#: nearest solutions on either side (``_interpolated_start``). Its error is second order in their
#: spacing, the nearest solution's first order: at the tight tolerances Newton needs fewer
#: iterations (default model, one process each: the search's seconds 5.2 → 3.6 (v2@L2), 6.1 →
#: 3.8 (baseline@L1), 8.6 → 6.1 (v1@L1), 5.8 → 3.9 (smooth-ms@L1), the same peaks to 1e-12)
INTERPOLATED_START = True
#: the golden section's interior ratio, (3 − √5)/2
_GOLD = 0.3819660112501051
#: the golden ratio, the growth of the bracket
_PHI = 1.618033988749895


def _refine_peak(hb, force: np.ndarray, dof: int, sol, max_solves: int = 80):
    """The resonance peak: the largest amplitude of the branch near ``sol``, located by a
    golden-section search on solves at tight tolerances (``PEAK_TOLERANCES``).

    A bracket a < m < b with X(m) ≥ X(a), X(b) is found around the polished peak (first
    half-width ``PEAK_BRACKET``, grown by the golden ratio towards the larger end) and narrowed by
    golden sections to a relative width ``PEAK_XTOL``; the solution at its middle is returned.
    Where X is unimodal in the bracket, the result is the maximum whatever the start, to the
    bracket's width — also where the maximum is a corner of the sampled friction law, which the
    top-level peaks of the quick model are (slopes of +3 and −3 in dX/X over dω/ω, rounded over
    only ≈ 1e-6 relative). The previous refinement, Newton steps on a central difference of X
    with a stencil of 1e-4 … 1e-5, stopped where its stencil was not concave or a stencil solve
    failed (below the fold under a softening peak) and returned the point it stood on: two
    models 1e-10 apart gave v2's top-level peak 2.1e-5 apart in frequency and 1.2e-4 in amplitude.

    Every solve starts from the solutions next to it, interpolated (``INTERPOLATED_START``), or
    where it is not between two from the best solution so far, so the search stays on the branch
    of the peak; one that fails at the tight tolerances is repeated at hbm's strict and then at
    ``KINK_TOLERANCES`` (whatever the sweep's), and from a looser solution once more at the
    tight ones (when that fails too, the looser amplitude is used: at 1e-9 it may be off by
    ≈ 2.5e-8 on the resonator). A failed solve's best iterate (Newton stops on a stall,
    ``HarmonicBalance.newton``) that meets ``KINK_TOLERANCES`` is taken as that tolerance's
    solution: repeating the solve would retrace the same iterations (on the quick model's 2-rank
    top-level baseline peak those repeats and the stalls took most of 10 minutes). Once
    ``KINK_POINTS`` points were kinks (the tight solve stalled above hbm's strict tolerance, or
    failed again from the looser solution), the rest are solved at ``KINK_TOLERANCES`` only. A
    point where all fail counts as one below the peak (beyond a fold): a bracket end.

    Args:
        hb: the HarmonicBalance of the curve (its tolerances are restored on return).
        force: (n,) excitation amplitude, N.
        dof: response DOF.
        sol: the polished peak Solution (start).
        max_solves: solves at most (about 25 are needed from the first bracket).

    Returns:
        the Solution at the peak (``sol`` itself if no solve succeeds at its frequency).
    """
    own = hb.tol, hb.krylov_tol
    ladder = (PEAK_TOLERANCES, SWEEP_TOLERANCES[1], KINK_TOLERANCES)
    count = [0]
    kinks = [0]      # points where the tight solve stalled or failed again from a looser solution

    def attempt(w: float, guess, tols):
        """(Solution or None, the failed solve's best iterate or None)."""
        hb.tol, hb.krylov_tol = tols
        try:
            return hb.solve(w, force, guess=guess), None
        except ConvergenceError as e:
            return None, e.best

    solved = {}      # ω -> Solution of every converged solve, for the warm starts

    def solve(w: float, guess):
        """Down the ladder from its first rung (from ``KINK_TOLERANCES`` once ``KINK_POINTS``
        points were kinks): the Solution at w, or None."""
        rungs = ladder if kinks[0] < KINK_POINTS else ladder[-1:]
        # GMRES tolerances of Newton runs from this start that failed: another run with the same
        # one takes the same iterations (the Newton tolerance only decides where to stop)
        failed = set()
        for tols in rungs:
            if tols[1] in failed:
                continue
            s, best = attempt(w, guess, tols)
            if best is not None:
                failed.add(tols[1])
                # a kink: Newton stalled above hbm's strict tolerance
                kinks[0] += tols is PEAK_TOLERANCES and best.residual > SWEEP_TOLERANCES[1][0]
            if s is None and best is not None and best.residual <= KINK_TOLERANCES[0]:
                # Newton stalled (a kink of the sampled friction law) at an iterate that meets a
                # looser rung: a looser solve from the same start would retrace the same
                # iterations to about there, and a tight one from it stalls where this one did
                return best
            if s is not None:
                if tols is not rungs[0]:      # tight again from there, else the looser solution
                    tight = attempt(w, s, rungs[0])[0]
                    kinks[0] += tight is None
                    s = tight or s
                return s
        return None

    def amp(w: float, guess, interpolate: bool = True):
        """(X, Solution) at w, or (-inf, None) when no solve converges; from ``guess`` itself
        unless ``interpolate`` (and two solutions straddle w)."""
        count[0] += 1
        if interpolate:
            guess = _interpolated_start(w, solved, guess)
        s = solve(w, guess)
        if s is None:
            return -np.inf, None
        solved[w] = s
        return s.amplitude(dof), s

    try:
        wm = float(sol.omega)
        xm, sm = amp(wm, sol)
        if sm is None:
            return sol
        d = PEAK_BRACKET * wm
        (xa, sa), (xb, sb) = amp(wm - d, sm), amp(wm + d, sm)
        wa, wb = wm - d, wm + d
        # grow the bracket towards the larger end until the middle is the largest
        for _ in range(PEAK_EXPANSIONS):
            if xm >= xa and xm >= xb:
                break
            if xa > xb:      # move left: b <- m <- a, a further out
                wb, xb, sb, wm, xm, sm = wm, xm, sm, wa, xa, sa
                wa = wm - _PHI * (wb - wm)
                xa, sa = amp(wa, sm)
            else:
                wa, xa, sa, wm, xm, sm = wm, xm, sm, wb, xb, sb
                wb = wm + _PHI * (wm - wa)
                xb, sb = amp(wb, sm)
        else:
            if not (xm >= xa and xm >= xb):
                return max(((xa, sa), (xm, sm), (xb, sb)), key=lambda p: p[0])[1]
        # golden sections: probe the larger side; a probe no larger than the middle is an end
        while wb - wa > PEAK_XTOL * wm and count[0] < max_solves:
            left = wm - wa > wb - wm
            wx = wm - _GOLD * (wm - wa) if left else wm + _GOLD * (wb - wm)
            xx, sx = amp(wx, sm)
            if xx > xm:
                if left:
                    wb = wm
                else:
                    wa = wm
                wm, xm, sm = wx, xx, sx
            elif left:
                wa = wx
            else:
                wb = wx
        return _smooth_vertex(amp, wm, xm, sm)
    finally:
        hb.tol, hb.krylov_tol = own


def _smooth_vertex(amp, wm: float, xm: float, sm):
    """The golden section's maximum (wm, xm, sm), or the vertex of the parabola through
    X(wm(1 − h)), X(wm), X(wm(1 + h)) (h = ``PEAK_STENCIL``) when the top is smooth at that scale.

    On a smooth top the golden section is limited by the amplitude's noise: with noise ε and
    X ≈ X₀(1 − c δ²) (δ relative) it stops within ≈ √(ε/c) of the maximum. With the tight
    solves' ε ≈ 3e-12 that is 4e-9 at the quick model's baseline peak at the middle level
    (c ≈ 1.9e5) but 1.2e-7 on a flat top like the one-element test's (c ≈ 200). The
    parabola's vertex is far less sensitive (≈ ε/(c h)) and, to first order, does not depend on
    where in that range wm lies (a cubic term shifts it by h²X‴/(6X″) whatever wm). It is
    taken only when it is as high as the maximum, to ``PEAK_SMOOTH`` (≈ 30 ε): at a corner of
    slopes a and −b it lies ≈ h(a − b)/(2(a + b)) off the corner and well below it, and on a
    top that is not a parabola over ±h it is lower too (the baseline peak above: its vertex
    1.2e-6 off and 2.4e-7 below, so the golden section's maximum is kept).
    """
    h = PEAK_STENCIL * wm
    # the stencil's solves from one start: their amplitudes' errors then nearly cancel in the
    # vertex (from interpolated starts the vertex of the one-element test's smooth top moved by
    # 1.3e-10 between starts of the search; from sm by 5e-13)
    (xl, sl), (xr, sr) = amp(wm - h, sm, False), amp(wm + h, sm, False)
    curv = xl - 2 * xm + xr
    if not (curv < 0 and np.isfinite(xl) and np.isfinite(xr)):
        return sm
    wv = wm - 0.5 * h * (xr - xl) / curv
    if not abs(wv - wm) < h:
        return sm
    xv, sv = amp(wv, sm)
    return sv if xv >= xm * (1 - PEAK_SMOOTH) else sm
