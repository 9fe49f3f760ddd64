"""Single-nonlinear-mode synthesis (SNMS) of the forced response from a backbone (Krack 2014/2015).

Derivation
----------
Forced problem M q'' + C q' + K q + f(q) = Re(F e^{i W t}) near the mode. Ansatz: the response is
the nonlinear mode at its amplitude, q = Re(a psi(a) e^{i (W t - theta)}) in the first harmonic,
psi the mass-normalized first-harmonic shape of the backbone (``Backbone.shape``, psi^H M psi = 1
over the kept modes) and a = ||eta_1|| (``Backbone.mass_amplitude``). Project the first harmonic of
the equation on psi^H (Galerkin):

    a (-W^2 + i W xi_v + psi^H K~ psi) + psi^H f_1(a) = psi^H F e^{i theta},    xi_v = psi^H C psi.

The mode satisfies the same projection with W -> w(a) and C -> C - xi(a) M and no force:

    a (-w^2 + i w (xi_v - xi) + psi^H K~ psi) + psi^H f_1(a) = 0.

The friction force is rate-independent, so f_1(a) is the same in both (the modal assumption: same
amplitude, same shape). Subtracting removes the stiffness and the friction terms:

    a (w^2 - W^2 + i (W xi_v + w xi_f)) = psi^H F e^{i theta},      xi_f = xi - xi_v,

i.e. the viscous part of the damping scales with the excitation frequency W and the friction
part stays at the mode's frequency. Taking the modulus gives, per amplitude a,

    (w^2 - W^2)^2 + (W xi_v + w xi_f)^2 = (P / a)^2,      P = |psi^H F|,

a quartic in W: W^4 + (xi_v^2 - 2 w^2) W^2 + 2 xi_v xi_f w W + w^4 + w^2 xi_f^2 - (P/a)^2 = 0.
Its two positive roots near w are the two branches (below and above the backbone) at that
amplitude. (With xi_v = 0 they are W^2 = w^2 -+ sqrt((P/a)^2 - (xi w)^2); the common form
2 zeta w W puts all damping on W instead, a difference of order zeta (W - w) / w.)

Peak: the two branches meet where the left side's minimum over W equals (P/a)^2,
a sqrt(D_min(a)) = P(a), D_min at the root of 4 W^3 + 2 (xi_v^2 - 2 w^2) W + 2 xi_v xi_f w = 0
near w (W = w and a xi w = P exactly when xi_v = 0: the peak is where the force balances the
mode's damping, the phase resonance). The backbone is interpolated in log a (cubic splines of w,
xi_v, xi_f, P and the response ratio) between its points, held at its linear values up to
the onset of slip (a point of the backbone: xi has a corner there) and interpolated in
t = sqrt(log a - log a_onset) above it (a Jenkins element's describing function is smooth in t); the first amplitude where
a sqrt(D_min) - P changes sign is the peak (the response reached from low amplitude).
The response at the backbone's DOF is a x (displacement_amplitude / mass_amplitude)(a).

Off-resonant correction
-----------------------
The mode alone misses what the other modes and the static residual flexibility contribute at the
response DOF (on the benchmark's synthetic structure, 17-43 % of the peak amplitude). When the
backbone carries its linear base's off-resonant receptance (``Backbone.background``, every kept
mode but the mode of interest plus the residual flexibility, linear: those modes are not near
resonance), the synthesized response at the DOF is the sum of the two phasors,

    X(W) = (psi^H F) r(a) / D(W, a) + H_bg(W) F,    D = w^2 - W^2 + i (W xi_v + w xi_f),

with r = displacement / mass_amplitude the mode's complex response at the DOF per unit modal
amplitude ((psi^H F) r does not depend on the phase of psi, so it is interpolated as one complex
quantity). The peak is then the maximum of |X| along the synthesized curve (both branches,
parametrized by u = +-sqrt(s_pk - s), smooth through the point where they meet), not where the
branches meet.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline, make_interp_spline
from scipy.optimize import brentq

from .nonlinear_mode import Backbone


@dataclass
class SynthesizedResponse:
    """Forced response near a nonlinear mode at one force (q amplitudes up to the peak).

    Attributes:
        mass_amplitude: (q,) modal amplitude a (Backbone.mass_amplitude), mm·t^0.5.
        amplitude: (q,) the mode's own first-harmonic amplitude at the backbone's DOF, mm.
        omega_low, omega_high: (q,) excitation frequency of the branch below / above the
            backbone at that amplitude, rad/s (equal where the branches meet).
        amplitude_low, amplitude_high: (q,) response at the DOF on each branch, mode + off-resonant
            background (= ``amplitude`` without background), mm; nan where the branch is missing.
        peak_omega: frequency of the peak, rad/s (nan if the peak is outside the backbone).
        peak_amplitude: amplitude at the DOF at the peak, mm (nan likewise); with the background,
            the maximum of |X| along the curve.
        peak_mass_amplitude: modal amplitude at the peak, mm·t^0.5.
        background: whether the off-resonant background was added.
        in_range: False if the peak lies above the last backbone amplitude, or below the first
            one when that is already nonlinear (then the arrays go up to the last amplitude). A
            peak below a linear first point is in closed form (the arrays then start a decade
            below it).
    """

    mass_amplitude: np.ndarray
    amplitude: np.ndarray
    omega_low: np.ndarray
    omega_high: np.ndarray
    peak_omega: float
    peak_amplitude: float
    peak_mass_amplitude: float
    in_range: bool
    amplitude_low: np.ndarray | None = None
    amplitude_high: np.ndarray | None = None
    background: bool = False


class _Interp:
    """Backbone quantities as functions of s = log(mass amplitude)."""

    def __init__(self, bb: Backbone, force: np.ndarray) -> None:
        a = bb.mass_amplitude
        if a.size < 2 or np.any(np.diff(a) <= 0):
            raise ValueError("the backbone's mass_amplitude must increase strictly (>= 2 points)")
        s = np.log(a)
        pf = np.conj(bb.shape) @ force
        P = np.abs(pf)
        # (psi^H F) r: the mode's response at the DOF per 1/D, independent of psi's phase
        r = (bb.displacement / a if bb.displacement is not None
             else bb.displacement_amplitude / a * np.exp(1j * np.angle(bb.shape[:, bb.dof])))
        Q = pf * r
        vals = np.stack([bb.omega, bb.xi_viscous, bb.xi - bb.xi_viscous, P,
                         bb.displacement_amplitude / a, Q.real, Q.imag], axis=1)
        # up to the onset the mode is linear (these five quantities constant); a spline through
        # the corner there would ring on both sides, so the linear part is held constant and the
        # spline starts at the last linear point
        lin = np.nonzero(bb.modal_amplitude <= bb.onset_amplitude)[0]
        self.i0 = i0 = int(lin[-1]) if lin.size and lin[-1] < a.size - 1 else 0
        self.lin = vals[i0]
        # Past the onset a Jenkins element's describing function moves as (a - a_s)^(3/2) (the
        # in-phase part) and (a - a_s) (the dissipative part): smooth in t = sqrt(log a - log a_s),
        # not in log a, so the spline runs in t (10-100x smaller errors next to the onset)
        on = bb.onset_amplitude
        self.s_on = np.log(on) if np.isfinite(on) and 0 < on <= bb.modal_amplitude[i0] else None
        x, y = self._x(s[i0:]), vals[i0:]
        if x.size >= 3:
            # at the onset (t = 0) those leading terms have zero slope in t; the default
            # not-a-knot end would put an O(h^3) error into the first interval
            left = (1, np.zeros(y.shape[1])) if self.s_on is not None and x[0] == 0 else "not-a-knot"
            self.spl = CubicSpline(x, y, bc_type=(left, "not-a-knot"))
        else:
            self.spl = make_interp_spline(x, y, k=1)
        self.s0, self.s1 = s[0], s[-1]
        self.s = s
        #: below the first point the mode is the linear one (so a peak there has a closed form)
        self.linear_below = bool(bb.modal_amplitude[0] <= bb.onset_amplitude)

    def _x(self, s):
        return s if self.s_on is None else np.sqrt(np.maximum(s - self.s_on, 0.0))

    def __call__(self, s):
        """(w, xi_v, xi_f, P / a, displacement / mass amplitude) at s = log(a)."""
        v = self.values(s)
        return v[0], v[1], v[2], v[3] / np.exp(s), v[4]

    def values(self, s):
        """All interpolated columns at s (w, xi_v, xi_f, P, ratio, Re Q, Im Q)."""
        return self.lin if s <= self.s[self.i0] else self.spl(self._x(s))

    def mode_response(self, s, W):
        """The mode's complex response at the DOF at amplitude exp(s) and frequency W, mm."""
        w, xv, xf, _, _, qr, qi = self.values(s)
        return (qr + 1j * qi) / (w * w - W * W + 1j * (W * xv + w * xf))


def _dmin(w, xv, xf):
    """min over W of (w^2 - W^2)^2 + (W xv + w xf)^2 and its argmin (scalars)."""
    r = np.roots([4.0, 0.0, 2.0 * (xv * xv - 2.0 * w * w), 2.0 * xv * xf * w])
    r = r[(np.abs(r.imag) <= 1e-9 * w) & (r.real > 0)].real
    f = (w * w - r * r) ** 2 + (r * xv + w * xf) ** 2
    i = int(np.argmin(f))
    return f[i], r[i]


def _branches(w, xv, xf, rhs):
    """Positive roots of the quartic next to w on either side: (low, high), nan where none
    (rhs = (P/a)^2). Below the peak the left side at W = w is (w xi)^2 < rhs, so the roots
    straddle w; the low one is missing where the amplitude exceeds the quasi-static response."""
    c = [1.0, 0.0, xv * xv - 2.0 * w * w, 2.0 * xv * xf * w, w ** 4 + w * w * xf * xf - rhs]
    r = np.roots(c)
    r = r[(np.abs(r.imag) <= 1e-7 * w) & (r.real > 0)].real
    lo, hi = r[r <= w], r[r >= w]
    return (lo.max() if lo.size else np.nan), (hi.min() if hi.size else np.nan)


def synthesize(bb: Backbone, force, samples: int = 200,
               background: bool = True) -> SynthesizedResponse:
    """SNMS forced response to Re(force e^{i W t}) near the mode of ``bb`` (module docstring).

    Args:
        bb: the backbone (its ``dof`` is the response DOF).
        force: (n,) force amplitude (real: force cos(W t); complex phasors allowed), N.
        samples: log-spaced amplitudes from the first backbone amplitude up to the peak.
        background: add the off-resonant response of the other modes and the residual
            flexibility (``bb.background``; ignored when the backbone has none).

    Returns:
        SynthesizedResponse.
    """
    F = np.asarray(force)
    if F.shape != bb.shape.shape[1:] or not np.all(np.isfinite(F)):
        raise ValueError(f"force must be finite with shape {bb.shape.shape[1:]}, got {F.shape}")
    if isinstance(samples, bool) or int(samples) != samples or samples < 2:
        raise ValueError(f"samples must be an integer >= 2, got {samples!r}")
    ip = _Interp(bb, F)

    def h(s):
        w, xv, xf, Pa, _ = ip(s)
        return np.sqrt(_dmin(w, xv, xf)[0]) - Pa

    hs = np.array([h(s) for s in ip.s])
    in_range = False
    s_pk, s_start = ip.s1, ip.s0
    if hs[0] < 0:
        cross = np.nonzero(hs >= 0)[0]
        if cross.size:
            i = cross[0]
            s_pk = brentq(h, ip.s[i - 1], ip.s[i], xtol=1e-14, rtol=1e-14)
            in_range = True
    elif ip.linear_below:
        # the peak is below the first point, where the mode is linear: a sqrt(D_min) = P
        w, xv, xf, Pa, _ = ip(ip.s0)
        s_pk = np.log(Pa * np.exp(ip.s0) / np.sqrt(_dmin(w, xv, xf)[0]))
        s_start = min(ip.s0, s_pk - np.log(10.0))
        in_range = True
    ss = np.linspace(s_start, s_pk, int(samples))
    lo, hi, amp = np.full(ss.size, np.nan), np.full(ss.size, np.nan), np.empty(ss.size)
    for i, s in enumerate(ss):
        w, xv, xf, Pa, ratio = ip(s)
        amp[i] = np.exp(s) * ratio
        lo[i], hi[i] = _branches(w, xv, xf, Pa * Pa)
    pk_w = pk_a = np.nan
    if in_range:
        w, xv, xf, Pa, ratio = ip(s_pk)
        pk_w = _dmin(w, xv, xf)[1]
        pk_a = np.exp(s_pk) * ratio
        lo[-1] = hi[-1] = pk_w
    s_peak = s_pk
    bg = bb.background if background else None
    if bg is None:
        a_lo, a_hi = np.where(np.isfinite(lo), amp, np.nan), np.where(np.isfinite(hi), amp, np.nan)
    else:
        def total(s, W):
            return abs(ip.mode_response(s, W) + bg.response(W, F)) if np.isfinite(W) else np.nan
        a_lo = np.array([total(s, W) for s, W in zip(ss, lo)])
        a_hi = np.array([total(s, W) for s, W in zip(ss, hi)])
        if in_range:
            pk_w, pk_a, s_peak = _peak_with_background(ip, bg, F, s_pk, s_start, total)
    return SynthesizedResponse(np.exp(ss), amp, lo, hi, float(pk_w), float(pk_a),
                               float(np.exp(s_peak)) if in_range else np.nan, in_range,
                               a_lo, a_hi, bg is not None)


#: The resonance peak with the background is searched where the excitation frequency is within
#: this fraction of the backbone's frequency. Far below the mode the low branch runs towards
#: W -> 0, where a free structure's rigid-body background (∝ 1/W²) outgrows any resonance: the
#: maximum of |X| there is not a peak of the mode (the resonator's v3 backbone at 101 N gave
#: 17.4 Hz for a 243 Hz mode), and the single-mode ansatz has no meaning that far off anyway.
NEAR_RESONANCE = 0.25


def _peak_with_background(ip: _Interp, bg, F, s_pk: float, s_start: float, total):
    """Maximum of |mode + background| along the synthesized curve.

    The curve is parametrized by u in [-U, U], s = s_pk - u^2, W on the low branch for u < 0
    and on the high one for u > 0: through the point where the branches meet (u = 0) both W and
    s are smooth in u. A grid in u brackets the maximum, a bounded Brent search polishes it.

    Returns:
        (peak frequency rad/s, peak amplitude mm, log modal amplitude at the peak).
    """
    from scipy.optimize import minimize_scalar

    def point(u):
        s = s_pk - u * u
        w, xv, xf, Pa, _ = ip(s)
        lo, hi = _branches(w, xv, xf, Pa * Pa)
        if u == 0.0 or not np.isfinite(lo if u < 0 else hi):
            lo = hi = _dmin(w, xv, xf)[1] if u == 0.0 else np.nan
        W = lo if u < 0 else hi
        if abs(W - w) > NEAR_RESONANCE * w:
            W = np.nan               # not the mode's response (see NEAR_RESONANCE)
        return s, W, total(s, W)

    U = np.sqrt(max(s_pk - s_start, 0.0))
    # near the top the branches open as sqrt(s_pk - s): a fine grid in u there
    us = np.concatenate([-U * np.geomspace(1.0, 1e-4, 200), [0.0], U * np.geomspace(1e-4, 1.0, 200)])
    vals = np.array([point(u)[2] for u in us])
    vals = np.where(np.isfinite(vals), vals, -np.inf)
    i = int(np.argmax(vals))
    a, b = us[max(i - 1, 0)], us[min(i + 1, us.size - 1)]
    if b > a:
        r = minimize_scalar(lambda u: -point(u)[2], bounds=(a, b), method="bounded",
                            options={"xatol": 1e-12 * max(U, 1e-300)})
        u_best = r.x if -r.fun >= vals[i] else us[i]
    else:
        u_best = us[i]
    s, W, X = point(u_best)
    return W, X, s
