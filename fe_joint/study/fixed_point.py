"""The v3 fixed point (paper §2.3, Fig. 4): FRF → cycle-mean loads and tangential amplitudes at
resonance → patch k_n, k_t → FRF …, relaxed by Aitken's factor, until the peak stops moving."""
from __future__ import annotations

import time

import numpy as np

from hbm import ConvergenceError

from ..model.joint import JointModel, stuck_modes
from . import contact as ms
from .configurations import joint_v2
from .frf import frf, frf_with_peak, peak_near

#: bounds of the Aitken relaxation factor of the v3 fixed point
V3_RELAX_MIN, V3_RELAX_MAX = 0.1, 1.5
#: the local peak search of a v3 pass starts this far (relative) above the predicted peak
PEAK_START_MARGIN = 1e-3


def _aitken(x: np.ndarray, r: np.ndarray, r_prev: np.ndarray | None, w_prev: float) -> float:
    """Aitken's dynamic relaxation factor for the fixed point x ← x + ω r (r = F(x) − x).

    ω_k = −ω_{k−1} r_{k−1}·(r_k − r_{k−1}) / |r_k − r_{k−1}|², the secant estimate of the
    optimal step along the last two residuals (Irons–Tuck; Küttler & Wall 2008 for coupled
    problems): it damps an oscillating iteration and lengthens the steps of a creeping one.
    The first update is plain (ω = 1); ω is kept in [V3_RELAX_MIN, V3_RELAX_MAX].
    """
    if r_prev is None:
        return 1.0
    d = r - r_prev
    dd = float(d @ d)
    if dd == 0.0:
        return w_prev
    return float(np.clip(-w_prev * float(r_prev @ d) / dd, V3_RELAX_MIN, V3_RELAX_MAX))


def _find_peak(inp, joint: JointModel, level: float, lin, prev, f_lin_prev, state,
               full_first: bool = True):
    """One pass's peak: a local search from the previous peak (``prev`` not None), or for pass 0
    without ``full_first`` from just above the stuck frequency, else — or if that fails — a full
    sweep.

    Returns:
        (CurveResult, contact harmonics at the peak, "local" | "sweep", why the local search failed).
    """
    why = None
    if prev is not None or not full_first:
        # the peak moves about as the stuck frequency does; start just above it (pass 0: above
        # the stuck frequency itself, which friction only lowers)
        f_start = (prev.peak_hz * lin.frequency / f_lin_prev if prev is not None
                   else lin.frequency) * (1 + PEAK_START_MARGIN)
        try:
            # polished, not refined: passes are compared to kt_tol, and the converged joint's
            # full FRF refines its peak
            curve, state = peak_near(inp.rm, joint, level, f_start, state, inp.settings,
                                     refine=False)
            return curve, state, "local", None
        except ConvergenceError as e:
            why = " ".join(str(e).split())
    curve, state = frf_with_peak(inp.rm, joint, level, lin.frequency, inp.settings)
    return curve, state, "sweep", why


def _relaxed_update(inp, sc, joint: JointModel, curve, r_prev, relax: float):
    """The next joint: patch k_n, k_t at the peak's loads, relaxed by Aitken's factor.

    Only elements in contact at the mean load are updated; an element the BEM finds out of
    contact leaves the joint (as the plain update would).

    Returns:
        (next JointModel, residual r = F(x) − x for the next Aitken step, relaxation used).
    """
    loaded = sc.n0 > 0
    n_mean = np.where(loaded, np.maximum(curve.mean_normal, 0.0), 0.0)
    kn_new, kt_new = ms.element_loop_stiffness(inp.setup, sc.z, n_mean, curve.q_amp,
                                               inp.case.contact.mu)
    keep = loaded & (kn_new > 0) & (kt_new > 0)
    x = np.concatenate([joint.kn[keep], joint.kt[keep]])
    r = np.concatenate([kn_new[keep], kt_new[keep]]) - x
    if r_prev is not None and r_prev.shape != r.shape:
        r_prev = None
    relax = _aitken(x, r, r_prev, relax)
    # a relaxed step keeps every stiffness positive (ω ≤ V3_RELAX_MAX may extrapolate)
    x = np.maximum(x + relax * r, 0.1 * x)
    kn, kt = np.zeros_like(joint.kn), np.zeros_like(joint.kt)
    kn[keep], kt[keep] = x[:keep.sum()], x[keep.sum():]
    nxt = JointModel(joint.name, n0=sc.n0, gap=sc.gap_el, kn=kn, kt=kt, area=inp.setup.area,
                     rq_um=sc.rq_um)
    return nxt, r, relax


def run_v3(inp, rq: float, level: float, full_first: bool = True) -> dict:
    """The v3 fixed point on the surface of Rq = ``rq``: FRF → loads → BEM k_n, k_t → FRF …

    Pass 0 is v2 (k_t by Mindlin): a full FRF when ``full_first`` (the comparison surface, whose
    pass 0 is also the study's v2 curve), else a local peak search from just above the stuck
    frequency (session 12: 7.8–10.1 s against 17.8–36.9 s for the full sweep on the default
    model's other surfaces, the peak within 3e-6; a full sweep if it fails). Each further pass
    recomputes every loaded element's k_n at its cycle-mean normal load and k_t as the slope at
    load reversal of its patch's hysteresis loop under the tangential force amplitude at
    resonance, relaxed by Aitken's factor (the plain iteration was seen to oscillate, ±1.5 % in
    peak amplitude on Rq = 15 µm, and a fixed factor 0.5 to creep, 5–6 passes), and finds the new
    peak by a short continuation from the previous one (:func:`~fe_joint.study.frf.peak_near`; a
    full sweep if that fails). It stops when the peak frequency and amplitude change by less than
    ``contact.kt_tol``; the converged joint then gets its full FRF, whose refined peak is the
    last pass's polished one to about 1e-6 (both in the history, a check).

    Args:
        inp: the study's inputs (StudyInputs).
        rq: Rq of the surface, µm (a key of ``inp.surfaces``).
        level: excitation amplitude, N.
        full_first: pass 0 by a full sweep (its curve is kept as ``first``) rather than a
            local peak search.
    Returns:
        dict with the final ``curve`` (CurveResult), the pass-0 curve ``first``, ``kn``, ``kt``,
        per-pass ``history``, ``converged`` and ``f_lin``.
    """
    c = inp.case
    sc = inp.surfaces[rq]
    joint = joint_v2(inp.setup, sc, name="v3")
    history = []
    prev = first = None
    converged = False
    state = r_prev = None
    relax = 1.0
    for p in range(c.contact.kt_max_passes + 1):
        t0 = time.perf_counter()
        lin = stuck_modes(inp.rm.K, inp.rm.M, inp.rm.pair_dofs, joint)
        curve, state, search, why = _find_peak(inp, joint, level, lin, prev,
                                               history[-1]["f_lin"] if history else None, state,
                                               full_first)
        if p == 0:
            first = curve
        change = (None if prev is None else
                  max(abs(curve.peak_hz - prev.peak_hz) / prev.peak_hz,
                      abs(curve.peak_amplitude - prev.peak_amplitude) / prev.peak_amplitude))
        history.append({"pass": p, "peak_hz": curve.peak_hz, "peak_amplitude": curve.peak_amplitude,
                        "f_lin": lin.frequency, "kn_eq": joint.k_eq("kn"), "kt_eq": joint.k_eq("kt"),
                        "change": change, "search": search, "local_failed": why, "points": curve.n_points,
                        "seconds": time.perf_counter() - t0})
        if change is not None and change < c.contact.kt_tol:
            converged = True
            break
        if p == c.contact.kt_max_passes:
            break
        prev = curve
        joint, r_prev, relax = _relaxed_update(inp, sc, joint, curve, r_prev, relax)
        history[-1]["relaxation"] = relax
    final = curve
    if search == "local":
        final = frf(inp.rm, joint, level, lin.frequency, inp.settings)
        history[-1]["sweep_peak_hz"] = final.peak_hz
        history[-1]["sweep_peak_amplitude"] = final.peak_amplitude
    return {"curve": final, "first": first, "kn": joint.kn, "kt": joint.kt, "history": history,
            "converged": converged, "f_lin": history[-1]["f_lin"]}
