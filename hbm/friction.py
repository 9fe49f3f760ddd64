"""3D friction contact elements (two coupled Jenkins directions + normal spring), vectorized.

Each element joins a DOF triple of body A to one of body B (or ground) in its local frame
(t1, t2, n). Relative displacement u = q_A - q_B; u_n > 0 closes (docs/design.md, "Units and
conventions").

* Normal: N = max(0, n0 + kn (u_n - g)).
* Tangential: slider w, force T = kt (u_t - w) inside the circular Coulomb limit |T| <= L = mu N
  (the two directions are coupled). While slipping T = L e and the slider moves along e.
  Separation (N = 0) gives T = 0 and resets the slider, w = u_t.
* The force added to the structure's left-hand side is (T1, T2, N - n0) on A and the opposite on
  B, so the preloaded rest state u = 0 adds nothing.

AFT march (docs/design.md, "Friction dynamics")
-----------------------------------------------
Each element starts from rest (w = 0) and the period is marched until the state at t = T equals
the state at t = 0 within ``close_tol``. Step j goes from sample j-1 to sample j (tau in [0, 1])
along the cubic through the samples j-2..j+1 of (u_t, u_n), and integrates the element on it:

* stick: w constant;
* slip: with T = L e, e = exp(i psi) in complex form, de/dtau = a - conj(a) e^2 with
  a = kt u_t'(tau) / (2 L(tau)) (a Riccati equation). e is the ratio p/q of the linear system
  (p, q)' = [[0, a], [conj a, 0]] (p, q), so a step is the Möbius map of exp(Omega), Omega the
  4th-order Magnus exponent on two Gauss points (closed form: Omega^2 is a multiple of I). 1D slip
  (a parallel to e) is reproduced exactly;
* switches inside the step are located on the path by safeguarded Newton: closing (N = 0; the
  slider resets there, or slip starts at once along u_t' when kt |u_t'| > L'), stick -> slip
  (|kt (u_t - w)| = L; also when the stuck force leaves the limit only between the samples,
  found from the largest excess on the step, _stick_peak: the end sample alone would miss it
  and make the force jump where that sample crosses the limit) and slip -> stick (slip rate
  kt e.u_t' - L' = 0). Opening needs none: the force at the next sample is zero whatever
  happened before.

2D slip is 4th order in h = 2 pi / n_t (the backward-Euler radial return at each sample used
before was 1st order); the least accurate steps are those right after a closing into slip, where
the slip equation is singular (L = 0). The harmonics keep the O(h^2) aliasing of the force's
kinks (scripts/bench_aft2d.py).

With ``shakedown`` (nonlinear modes, which have no time origin), a closed element that can stick
all cycle on some slider takes the admissible slider nearest rest (hbm.shakedown) and is not
marched: the march's choice depends on where t = 0 falls in the cycle.
Elements that stay closed and within the cone all along the path from w = 0 (stuck) or open at every
sample are recognized by a vectorized test and never marched: stuck elements are exactly linear
(T = kt u_t), open ones carry the constant -n0. The analytic Jacobian of the force harmonics is
the exact derivative of the computed map: each step's derivative (hand-coded for the common
full-step slip, forward-mode replay of the recorded switches for the rare switching steps, with
the switch times differentiated implicitly) is propagated through the closed cycle, and through
the cycles before closure for elements whose cycle map is neutral. With numba, the march and these
step derivatives and their propagation run compiled (hbm.friction_jit, same formulas).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from . import friction_jit, shakedown
from .errors import ConvergenceError, CycleNotClosed
from .fourier import Fourier

STUCK, STICK_SLIP, GROSS_SLIP, PARTLY_OPEN, OPEN = 0, 1, 2, 3, 4
#: fraction of the cycle spent slipping above which a closed element counts as gross slip
GROSS_SLIP_FRACTION = 0.9
#: up to this many marched elements the forward march runs on Python scalars (less overhead)
SCALAR_LIMIT = 4
#: march with the compiled kernels of hbm.friction_jit when numba is there (else numpy)
USE_JIT = True
#: ... and differentiate it with them too (else the numpy Jacobian; tests and
#: scripts/bench_aft2d.py compare the two)
JIT_JACOBIAN = True
#: |det(I - A_cycle)| below which the slider fixed point is treated as neutral (plain iteration)
NEWTON_DET = 1e-6
#: cycle budget of the plain-repetition redo of neutral elements, × max_cycles
REDO_CYCLES_FACTOR = 5
#: the redo predicts its closure from the contraction per period after this many periods ...
GIVE_UP_AFTER = 10
#: ... and gives up when the predicted periods exceed this multiple of its budget
GIVE_UP_MARGIN = 2.0
#: up to this many marched elements the Jacobian recurrence uses a prefix scan
SCAN_LIMIT = 16
#: a start force within this relative distance of the limit is on it (it is there up to rounding)
SLIP_TOL = 1e-12
#: a force this close to the limit (relative) at the start of a stick phase is on it (rounding)
EDGE_TOL = 1e-12
#: a stuck force that exceeds the limit between two samples by more than this (relative to the
#: limit) slips there, even when it is back inside at the step end (see _stick_peak)
PEAK_TOL = 1e-9
#: grid of the search for the largest excess of a stick phase (then refined by Newton)
PEAK_GRID = 16
#: switches located inside one step (3 occur at n_t = 16 with large 2D motion and separation;
#: a 4th would be ignored: the step would end in the state then reached)
MAX_SWITCH = 3
#: switch times are located to this absolute accuracy in tau (Newton, bisection as safeguard)
ROOT_TOL, ROOT_ITER = 1e-14, 60
#: a Newton step shorter than this ends the search (the next would be ~ its square: converged)
ROOT_NEWTON = 1e-8
#: steps a round of the vectorized march looks ahead (see _cycle_vector)
WINDOW = 32
_WIN = np.arange(WINDOW)

# what a step did: the fast paths, or a step with switches (replayed for the Jacobian)
STICK_STEP, SLIP_STEP, OPEN_STEP, EVENT_STEP = 0, 1, 2, 3
# state at the start of a step with switches
M_STICK, M_SLIP, M_OPEN = 0, 1, 2
# switches (the _AT ones happen at the start of the phase, their time is not a root)
(SW_OPEN_STICK, SW_OPEN_SLIP, SW_STICK_SLIP, SW_STICK_SLIP_AT, SW_SLIP_STICK,
 SW_SLIP_STICK_AT) = range(1, 7)

#: power coefficients of the cubic through the samples at tau = -1, 0, 1, 2 (c = _VINV @ samples)
_VINV = np.array([[0.0, 1.0, 0.0, 0.0],
                  [-1.0 / 3.0, -0.5, 1.0, -1.0 / 6.0],
                  [0.5, -1.0, 0.5, 0.0],
                  [-1.0 / 6.0, 0.5, -0.5, 1.0 / 6.0]])
#: sample offsets of the stencil of step j (samples j-2..j+1)
_STENCIL = np.arange(-2, 2)
_S6 = math.sqrt(3.0) / 6.0
#: Gauss–Legendre points of [0, 1] (the 4th-order Magnus step)
_GAUSS = (0.5 - _S6, 0.5 + _S6)
#: Lagrange weights l_m(tau_g) and l_m'(tau_g) of the stencil samples at the Gauss points, (2, 4)
_LG = np.array([[g ** i for i in range(4)] for g in _GAUSS]) @ _VINV
_DLG = np.array([[i * g ** (i - 1) if i else 0.0 for i in range(4)] for g in _GAUSS]) @ _VINV
#: derivative slots of a replayed step: Re w, Im w, u_t1 (4 samples), u_t2 (4), u_n (4), tau
NSLOT = 15


def _param(name: str, value, ne: int, lo: float, allow_equal: bool = True) -> np.ndarray:
    """A parameter as a finite (ne,) array >= lo (> lo unless allow_equal); ValueError if not."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(ne, float(arr))
    if arr.shape != (ne,):
        raise ValueError(f"{name} must be a scalar or an array of shape ({ne},), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    bad = arr < lo if allow_equal else arr <= lo
    if np.any(bad):
        rel = ">=" if allow_equal else ">"
        raise ValueError(f"{name} must be {rel} {lo}, got min {arr.min()!r}")
    return arr


# ---------------------------------------------------------------------------- forward-mode numbers
class _Dual:
    """Values v (b,) with their derivatives d (b, NSLOT) w.r.t. real inputs (forward mode).

    Only the replay of switching steps uses it: those steps chain root-found switch times through
    Magnus steps, and differentiating every branch by hand would be error-prone for few steps.
    """
    __slots__ = ("v", "d")
    __array_ufunc__ = None              # ndarray (op) _Dual defers to the reflected operators

    def __init__(self, v, d) -> None:
        self.v, self.d = v, d

    @staticmethod
    def _col(o):
        o = np.asarray(o)
        return o[:, None] if o.ndim == 1 else o

    def __add__(self, o):
        if isinstance(o, _Dual):
            return _Dual(self.v + o.v, self.d + o.d)
        return _Dual(self.v + o, self.d)

    __radd__ = __add__

    def __neg__(self):
        return _Dual(-self.v, -self.d)

    def __sub__(self, o):
        return self + (-o)

    def __rsub__(self, o):
        return (-self) + o

    def __mul__(self, o):
        if isinstance(o, _Dual):
            return _Dual(self.v * o.v, self.d * o.v[:, None] + o.d * self.v[:, None])
        return _Dual(self.v * o, self.d * self._col(o))

    __rmul__ = __mul__

    def __truediv__(self, o):
        if isinstance(o, _Dual):
            q = self.v / o.v
            return _Dual(q, (self.d - o.d * q[:, None]) / o.v[:, None])
        return _Dual(self.v / o, self.d / self._col(o))

    def __rtruediv__(self, o):
        q = o / self.v
        return _Dual(q, -self.d * (q / self.v)[:, None])

    def conjugate(self):
        return _Dual(np.conj(self.v), np.conj(self.d))

    @property
    def real(self):
        return _Dual(np.real(self.v), np.real(self.d))

    @property
    def imag(self):
        return _Dual(np.imag(self.v), np.imag(self.d))

    def __abs__(self):
        r = np.abs(self.v)
        return _Dual(r, np.real(np.conj(self.v)[:, None] * self.d) / r[:, None])


# ---------------------------------------------------------------------------- path and slip step
# These work on Python scalars (few-element march), numpy arrays (vectorized march) and _Dual
# (Jacobian replay) alike. c is a tuple of the 4 power coefficients of a cubic in tau.
def _poly(c, t):
    """sum c_i t^i (Horner)."""
    return c[0] + t * (c[1] + t * (c[2] + t * c[3]))


def _dpoly(c, t):
    """d/dt of _poly."""
    return c[1] + t * (2.0 * c[2] + t * (3.0 * c[3]))


def _cs_array(x: np.ndarray, deriv: bool = False):
    """(c, s) proportional to (cosh r, sinh r / r), r = sqrt(x), for real x of any sign.

    x >= 0 is scaled by 1 / cosh r (c = 1, s = tanh r / r: no overflow in deep slip); x < 0 is
    (cos r', sin r' / r'), r' = sqrt(-x). The Möbius map does not see the scale. With deriv, also
    dc/dx and ds/dx. Series below |x| = 1e-4 avoid the cancellation.
    """
    r = np.sqrt(np.abs(x))
    pos = x >= 0.0
    small = r < 1e-2
    th = np.tanh(r)
    sp = np.where(small, 1.0 + x * (-1.0 / 3.0 + x * (2.0 / 15.0)), th / np.where(small, 1.0, r))
    cn = np.cos(r)
    sn = np.sinc(r / np.pi)                                   # sin r / r, exact at 0
    c, s = np.where(pos, 1.0, cn), np.where(pos, sp, sn)
    if not deriv:
        return c, s
    xs = np.where(small, 1.0, x)
    dsp = np.where(small, -1.0 / 3.0 + x * (4.0 / 15.0 - x * 17.0 / 105.0), (1.0 - th * th - sp) / (2.0 * xs))
    dsn = np.where(small, 1.0 / 6.0 + x * (1.0 / 60.0 + x / 1680.0), (cn - sn) / (2.0 * xs))
    return c, s, np.where(pos, 0.0, 0.5 * sn), np.where(pos, dsp, dsn)


def _cs_scalar(x: float):
    """_cs_array for one Python float (same formulas)."""
    r = math.sqrt(abs(x))
    small = r < 1e-2
    if x >= 0.0:
        return 1.0, (1.0 + x * (-1.0 / 3.0 + x * (2.0 / 15.0)) if small else math.tanh(r) / r)
    return math.cos(r), (math.sin(r) / r if r > 0.0 else 1.0)


def _cs(x):
    """_cs_array for arrays, Python floats or _Dual (value and derivative)."""
    if isinstance(x, _Dual):
        c, s, dc, ds = _cs_array(x.v, True)
        return _Dual(c, dc[:, None] * x.d), _Dual(s, ds[:, None] * x.d)
    if isinstance(x, np.ndarray):
        return _cs_array(x)
    return _cs_scalar(x)


def _mobius_a(a1, a2, d):
    """Möbius coefficients (al, be) of a slip step of length d from the Riccati rates a at its
    two Gauss points: exp(Omega) ∝ [[al, be], [conj be, conj al]], Omega = [[i gam, A], [conj A,
    -i gam]] with A = d (a1 + a2)/2 (first Magnus term) and gam = (sqrt 3 / 6) d^2 Im(a2 conj a1)
    (the commutator term); Omega^2 = (|A|^2 - gam^2) I gives the exponential in closed form."""
    A = (0.5 * d) * (a1 + a2)
    gam = (_S6 * d * d) * (a2 * a1.conjugate()).imag
    c, s = _cs((A * A.conjugate()).real - gam * gam)
    return c + 1j * (s * gam), s * A


def _rate(ct, Lc, kt, t):
    """Riccati rate a = kt u_t'(t) / (2 L(t)) (per unit tau)."""
    return kt * _dpoly(ct, t) / (2.0 * _poly(Lc, t))


def _magnus(ct, Lc, kt, z, ta, tb):
    """Slip direction z (unit complex) at tau = tb from its value at ta (4th-order Magnus step)."""
    d = tb - ta
    al, be = _mobius_a(_rate(ct, Lc, kt, ta + _GAUSS[0] * d), _rate(ct, Lc, kt, ta + _GAUSS[1] * d), d)
    return (al * z + be) / (be.conjugate() * z + al.conjugate())


def _magnus_k(ct, Lc, kt, z, ta, tb):
    """_magnus and its derivative K = dz(tb)/dz(ta) (the map is holomorphic in z)."""
    d = tb - ta
    al, be = _mobius_a(_rate(ct, Lc, kt, ta + _GAUSS[0] * d), _rate(ct, Lc, kt, ta + _GAUSS[1] * d), d)
    D = be.conjugate() * z + al.conjugate()
    return (al * z + be) / D, ((al * al.conjugate()).real - (be * be.conjugate()).real) / (D * D)


def _slip_rate(ct, Lc, kt, z, t):
    """kt e.u_t' - L' at t (per unit tau): the slider keeps moving while it is > 0."""
    return kt * (z.conjugate() * _dpoly(ct, t)).real - _dpoly(Lc, t)


def _excess(ct, Lc, kt, w, t):
    """|kt (u_t(t) - w)| - L(t): > 0 when the stuck force would leave the limit."""
    return abs(kt * (_poly(ct, t) - w)) - _poly(Lc, t)


# Root functions: value and t-derivative (Newton) of the switch conditions.
def _close_fun(Nc):
    """N(t) and N'(t): the closing instant is a root of N."""
    return lambda t: (_poly(Nc, t), _dpoly(Nc, t))


def _excess_fun(ct, Lc, kt, w):
    """_excess at slider w and its t-derivative: stick -> slip is a root of it."""
    def fun(t):
        d = _poly(ct, t) - w
        ad = abs(d)
        return (kt * ad - _poly(Lc, t),
                kt * (d.conjugate() * _dpoly(ct, t)).real / (ad + (ad == 0)) - _dpoly(Lc, t))
    return fun





def _stop_quadratic(ct, Lc, kt, z, t0, z1, rate0, rate1):
    """Power coefficients in s = (tau - t0) / (1 - t0) of the quadratic through the slip rate at
    the phase start t0 (direction z), the midpoint and the step end (direction z1).

    Slip -> stick is located on it, not on the Magnus solution itself: the slider depends on that
    time only at second order (at the switch the slip rate vanishes, so the stick and slip
    trajectories are tangent), the quadratic's time error is O(h^2) in tau, so O(h^6) in the
    slider; evaluating the Magnus solution inside every Newton iteration cost most of the march,
    and end slopes would be singular at a closing (L = 0).
    """
    tm = 0.5 * (t0 + 1.0)
    rm = _slip_rate(ct, Lc, kt, _magnus(ct, Lc, kt, z, t0, tm), tm)
    return rate0, 4.0 * rm - 3.0 * rate0 - rate1, 2.0 * (rate0 + rate1) - 4.0 * rm, 0.0 * rate0


def _stop_fun(c, t0):
    """-(quadratic slip rate) and its tau-derivative (c from _stop_quadratic)."""
    D = 1.0 - t0
    return lambda t: (-_poly(c, (t - t0) / D), -_dpoly(c, (t - t0) / D) / D)


def _root_vector(fun, lo, hi, flo, fhi):
    """Roots of fun on [lo, hi] (arrays, flo <= 0 <= fhi): Newton safeguarded by bisection."""
    den = flo - fhi
    # regula falsi, kept inside: f may vanish at lo too (a phase starting on the limit)
    frac = np.where(den < 0, flo / np.where(den < 0, den, -1.0), 0.5)
    t = lo + (hi - lo) * np.clip(frac, 0.01, 0.99)
    done = np.zeros(t.shape, dtype=bool)
    for _ in range(ROOT_ITER):
        f, df = fun(t)
        lo = np.where(f < 0, t, lo)
        hi = np.where(f > 0, t, hi)
        tn = t - np.divide(f, df, out=np.full(t.shape, np.inf), where=df != 0)
        newton = (tn > lo) & (tn < hi)
        tn = np.where(newton, tn, 0.5 * (lo + hi))
        tn = np.where((f == 0) | done, t, tn)
        step = np.abs(tn - t)
        done |= (step <= ROOT_TOL) | (newton & (step <= ROOT_NEWTON))
        t = tn
        if done.all():
            break
    return t


def _root_scalar(fun, lo: float, hi: float, flo: float, fhi: float) -> float:
    """_root_vector for Python floats."""
    den = flo - fhi
    t = lo + (hi - lo) * (min(max(flo / den, 0.01), 0.99) if den < 0 else 0.5)
    for _ in range(ROOT_ITER):
        f, df = fun(t)
        if f == 0:
            return t
        if f < 0:
            lo = t
        else:
            hi = t
        tn = t - f / df if df != 0 else lo
        newton = lo < tn < hi
        if not newton:
            tn = 0.5 * (lo + hi)
        if abs(tn - t) <= (ROOT_NEWTON if newton else ROOT_TOL):
            return tn
        t = tn
    return t


# ---------------------------------------------------------------------------- per-step tables
class _StepTables:
    """What the march needs at each step, vectorized over elements (k) and steps (nt).

    Step j goes from sample j-1 to sample j along the cubic through the samples j-2..j+1.
    Attributes (first axis: element): kt, mu, kn (k,); ut (k, nt) complex u_t1 + i u_t2, mm;
    N (k, nt) normal force, N; closed (k, nt) N > 0; tcl (k, nt) closed with friction (mu > 0);
    L (k, nt) limit mu N (0 where not tcl); ct, Nc, Lc (k, nt, 4) cubic coefficients of u_t,
    n0 + kn (u_n - g) and mu (n0 + kn (u_n - g)); pg, Lg (k, nt, 2) u_t' and L at the Gauss
    points; al, be (k, nt) Möbius coefficients of a full-step slip; pe, Lpe (k, nt) u_t' and L'
    at the step end; bad (k, nt) closed at both samples but not at a Gauss point (treated as a
    reclosing inside the step, searched from tlo); scale (k,) slider length scale, mm.
    """

    def __init__(self, u, kt, mu, kn, n0, gap) -> None:
        k, _, nt = u.shape
        self.kt, self.mu, self.kn = kt, mu, kn
        if USE_JIT and friction_jit.AVAILABLE:
            self._compiled(u, n0, gap)
            return
        self.ut = u[:, 0] + 1j * u[:, 1]
        nraw = n0[:, None] + kn[:, None] * (u[:, 2] - gap[:, None])
        self.N = np.maximum(0.0, nraw)
        self.closed = nraw > 0.0
        self.tcl = self.closed & (mu > 0.0)[:, None]
        self.L = np.where(self.tcl, mu[:, None] * self.N, 0.0)
        st = (np.arange(nt)[:, None] + _STENCIL) % nt
        self.ct = self.ut[:, st] @ _VINV.T
        self.Nc = nraw[:, st] @ _VINV.T
        self.Lc = mu[:, None, None] * self.Nc
        c, n = tuple(np.moveaxis(self.ct, -1, 0)), tuple(np.moveaxis(self.Nc, -1, 0))
        self.pg = np.stack([_dpoly(c, g) for g in _GAUSS], axis=-1)
        ng = np.stack([_poly(n, g) for g in _GAUSS], axis=-1)
        self.Lg = mu[:, None, None] * ng
        self.bad = np.roll(self.tcl, 1, axis=1) & self.tcl & (ng <= 0.0).any(axis=-1)
        self.tlo = np.where(self.bad, np.where(ng[..., 1] <= 0.0, _GAUSS[1], _GAUSS[0]), 0.0)
        lg = np.where((self.Lg > 0.0).all(axis=-1, keepdims=True), self.Lg, 1.0)
        a = kt[:, None, None] * self.pg / (2.0 * lg)
        self.al, self.be = _mobius_a(a[..., 0], a[..., 1], 1.0)
        self.pe = _dpoly(c, 1.0)
        self.Lpe = mu[:, None] * _dpoly(n, 1.0)
        self.scale = np.maximum((mu[:, None] * self.N).max(axis=1), 1e-300) / kt
        self.det = (self.al * self.al.conj()).real - (self.be * self.be.conj()).real

    def _compiled(self, u, n0, gap) -> None:
        """The same arrays by :func:`hbm.friction_jit.step_tables` (to rounding: tested)."""
        k, _, nt = u.shape
        c, r = np.empty((k, nt), dtype=complex), np.empty((k, nt))
        self.ut, self.al, self.be, self.pe = c, c.copy(), c.copy(), c.copy()
        self.N, self.L, self.tlo, self.Lpe, self.det = r, r.copy(), r.copy(), r.copy(), r.copy()
        self.closed, self.tcl, self.bad = (np.empty((k, nt), dtype=bool) for _ in range(3))
        self.ct, self.Nc, self.Lc = np.empty((k, nt, 4), dtype=complex), np.empty((k, nt, 4)), np.empty((k, nt, 4))
        self.pg, self.Lg = np.empty((k, nt, 2), dtype=complex), np.empty((k, nt, 2))
        self.scale = np.empty(k)
        friction_jit.step_tables(np.asarray(u, float), np.asarray(self.kt, float), np.asarray(self.mu, float),
                                 np.asarray(self.kn, float), np.asarray(n0, float), np.asarray(gap, float),
                                 self.ut, self.N, self.closed, self.tcl, self.L, self.ct, self.Nc,
                                 self.Lc, self.pg, self.Lg, self.bad, self.tlo, self.al, self.be,
                                 self.pe, self.Lpe, self.scale, self.det)

    def packed(self) -> np.ndarray:
        """What a round of _advance reads, (k, nt, 6), packed so that one gather serves it."""
        if not hasattr(self, "_packed"):
            flags = np.roll(self.tcl, 1, axis=1) + 2.0 * self.tcl + 4.0 * self.bad
            self._packed = np.stack([self.ut, self.al, self.be, self.pe, self.L + 1j * self.Lpe,
                                     flags + 0j], axis=-1)
        return self._packed

    def take(self, rows) -> "_StepTables":
        new = object.__new__(_StepTables)
        for name, val in vars(self).items():
            if name != "_packed":
                setattr(new, name, val[rows])
        return new

    def scalars(self) -> SimpleNamespace:
        """The tables of a one-element set as Python lists (for the scalar march)."""
        def rows(a):
            return [tuple(r) for r in a[0].tolist()]
        return SimpleNamespace(
            kt=float(self.kt[0]), ut=self.ut[0].tolist(), tcl=self.tcl[0].tolist(),
            L=self.L[0].tolist(), al=self.al[0].tolist(), be=self.be[0].tolist(),
            pe=self.pe[0].tolist(), Lpe=self.Lpe[0].tolist(), bad=self.bad[0].tolist(),
            tlo=self.tlo[0].tolist(), ct=rows(self.ct), Nc=rows(self.Nc), Lc=rows(self.Lc))

    def force(self, rec: "_Record") -> np.ndarray:
        """Tangential force samples (k, 2, nt), N, of a marched period."""
        w = np.concatenate([rec.wst[:, 1:], rec.wend[:, None]], axis=1)   # slider at sample j
        T = np.where(self.tcl, self.kt[:, None] * (self.ut - w), 0.0)
        return np.stack([T.real, T.imag], axis=1)


class _Record:
    """What each step of one marched period did (the Jacobian replays it), for k elements.

    code (k, nt) STICK/SLIP/OPEN/EVENT_STEP; wst (k, nt) slider at the start of the step, mm;
    mode0 (k, nt) state at the start of an EVENT_STEP; evc, evt (k, nt, MAX_SWITCH) its switches
    and their times tau; slip (k, nt) slipped during the step; wend (k,) slider at the end.
    AP, AQ (k, nt) a switching step's d w_j = AP d w_{j-1} + AQ conj(d w_{j-1}), and cP, cQ (k,)
    the same for the whole period once cdone (see _cycle_matrix): exact but for the switch-time
    terms, which are O(h^4) (the trajectories are tangent at stick/slip switches). They only
    steer the Newton restarts and the neutral test; the Jacobian is exact.
    """

    def __init__(self, k: int, nt: int) -> None:
        self.code = np.zeros((k, nt), dtype=np.int8)
        self.wst = np.zeros((k, nt), dtype=complex)
        self.mode0 = np.zeros((k, nt), dtype=np.int8)
        self.evc = np.zeros((k, nt, MAX_SWITCH), dtype=np.int8)
        self.evt = np.zeros((k, nt, MAX_SWITCH))
        self.slip = np.zeros((k, nt), dtype=bool)
        self.AP = np.ones((k, nt), dtype=complex)
        self.AQ = np.zeros((k, nt), dtype=complex)
        self.wend = np.zeros(k, dtype=complex)
        self.cP = np.ones(k, dtype=complex)
        self.cQ = np.zeros(k, dtype=complex)
        self.cdone = np.ones(k, dtype=bool)                # cP, cQ are known

    def take(self, rows) -> "_Record":
        new = object.__new__(_Record)
        for name, val in vars(self).items():
            setattr(new, name, val[rows])
        return new

    def put(self, rows, other: "_Record") -> None:
        for name, val in vars(other).items():
            getattr(self, name)[rows] = val



# ---------------------------------------------------------------------------- switching steps
class _Switching:
    """State of the switching steps of one round, vectorized over them (see _events_vector).

    P, Q track d(state) = P d w0 + Q conj(d w0), the state being w in stick and z in slip."""

    def __init__(self, ct, Nc, Lc, kt, w, mode, tlo, u1, L1) -> None:
        self.ct, self.Nc, self.Lc = ct, Nc, Lc                      # (b, 4)
        self.kt, self.w, self.mode, self.tlo = kt, w.copy(), mode.copy(), tlo
        self.u1, self.L1 = u1, L1
        b = w.size
        T0 = kt * (ct[:, 0] - w)
        r0 = np.where(mode == M_SLIP, np.abs(T0), 1.0)
        self.z = T0 / r0
        self.P = np.where(mode == M_STICK, 1.0, np.where(mode == M_SLIP, -kt / (2.0 * r0), 0.0)) + 0j
        self.Q = np.where(mode == M_SLIP, -self.P * self.z ** 2, 0.0)
        self.t = np.zeros(b)
        self.run = np.ones(b, dtype=bool)
        self.slipped = mode == M_SLIP
        self.codes = np.zeros((b, MAX_SWITCH), dtype=np.int8)
        self.taus = np.zeros((b, MAX_SWITCH))

    def rows(self, ix):
        return tuple(self.ct[ix].T), tuple(self.Lc[ix].T), self.kt[ix]

    def switch(self, ix, s, mode, t, code) -> None:
        self.mode[ix], self.t[ix], self.codes[ix, s], self.taus[ix, s] = mode, t, code, t

    def scale(self, ix, f) -> None:
        self.P[ix] *= f
        self.Q[ix] *= f


def _sw_close(S: _Switching, ix, s: int) -> None:
    """Closing inside the step: the slider resets at the root of N, or slip starts there."""
    ct, Lc, kt = S.rows(ix)
    Nc = tuple(S.Nc[ix].T)
    lo = S.tlo[ix]
    tc = _root_vector(_close_fun(Nc), lo, np.ones(ix.size), _poly(Nc, lo), _poly(Nc, 1.0))
    pd = _dpoly(ct, tc)
    ad = np.abs(pd)
    imm = kt * ad > _dpoly(Lc, tc)            # the force grows faster than the limit: slip at once
    S.z[ix] = np.where(imm, pd / np.where(imm, ad, 1.0), S.z[ix])
    S.w[ix] = np.where(imm, S.w[ix], _poly(ct, tc))
    S.scale(ix, 0.0)                          # the state forgets the start
    S.slipped[ix] |= imm
    S.switch(ix, s, np.where(imm, M_SLIP, M_STICK), tc, np.where(imm, SW_OPEN_SLIP, SW_OPEN_STICK))


def _sw_slide(S: _Switching, ix, s: int) -> None:
    """Stick: ends the step stuck, or starts slipping where |kt (u_t - w)| reaches L."""
    end = np.abs(S.kt[ix] * (S.u1[ix] - S.w[ix])) > S.L1[ix]
    peak, tpk = _stick_peak(S.ct[ix], S.Lc[ix], S.kt[ix], S.w[ix], S.t[ix])
    over = end | peak
    S.run[ix[~over]] = False
    ix, tpk, peak = ix[over], tpk[over], peak[over]
    if not ix.size:
        return
    ct, Lc, kt = S.rows(ix)
    w, t0 = S.w[ix], S.t[ix]
    # the first excursion: up to the largest excess inside the step if there is one, else the end
    thi = np.where(peak, tpk, 1.0)
    f0 = _excess(ct, Lc, kt, w, t0)
    # already outside at the phase start? (a phase that starts on the limit, after a closing or
    # a stop, has f0 = 0 up to rounding)
    at = f0 > EDGE_TOL * S.L1[ix]
    ts = t0.copy()
    r = np.nonzero(~at)[0]
    if r.size:
        cr, lr, kr = tuple(c[r] for c in ct), tuple(c[r] for c in Lc), kt[r]
        ts[r] = _root_vector(_excess_fun(cr, lr, kr, w[r]), t0[r], thi[r],
                             np.minimum(f0[r], 0.0), np.maximum(_excess(cr, lr, kr, w[r], thi[r]), 0.0))
    d = _poly(ct, ts) - w
    ad = np.abs(d)
    z = d / ad
    P, Q = S.P[ix], S.Q[ix]                        # dz = -(dw - z^2 conj dw) / (2 |d|)
    S.P[ix], S.Q[ix] = -(P - z * z * Q.conj()) / (2.0 * ad), -(Q - z * z * P.conj()) / (2.0 * ad)
    S.z[ix] = z
    S.slipped[ix] = True
    S.switch(ix, s, M_SLIP, ts, np.where(at, SW_STICK_SLIP_AT, SW_STICK_SLIP))


def _sw_stop(S: _Switching, ix, s: int) -> None:
    """Slip: ends the step slipping, or sticks where the slip rate vanishes."""
    ct, Lc, kt = S.rows(ix)
    z, t0 = S.z[ix], S.t[ix]
    z1, K1 = _magnus_k(ct, Lc, kt, z, t0, 1.0)
    rate1 = _slip_rate(ct, Lc, kt, z1, 1.0)
    keep = rate1 > 0
    f = -(S.L1[ix] / kt)
    S.w[ix[keep]] = (S.u1[ix] + f * z1)[keep]
    S.scale(ix[keep], (f * K1)[keep])
    S.run[ix[keep]] = False
    r = np.nonzero(~keep)[0]
    if not r.size:
        return
    ix, ct, Lc, kt = ix[r], tuple(c[r] for c in ct), tuple(c[r] for c in Lc), kt[r]
    z, t0, rate1, z1 = z[r], t0[r], rate1[r], z1[r]
    rate0 = _slip_rate(ct, Lc, kt, z, t0)
    at = rate0 <= 0                               # stops at the phase start
    tr = t0.copy()
    q = np.nonzero(~at)[0]
    if q.size:
        cq, lq, kq, tq = tuple(c[q] for c in ct), tuple(c[q] for c in Lc), kt[q], t0[q]
        h = _stop_quadratic(cq, lq, kq, z[q], tq, z1[q], rate0[q], rate1[q])
        tr[q] = _root_vector(_stop_fun(h, tq), tq, np.ones(q.size), -rate0[q], -rate1[q])
    zr, Kr = _magnus_k(ct, Lc, kt, z, t0, tr)
    S.z[ix] = zr
    L = _poly(Lc, tr)
    S.w[ix] = _poly(ct, tr) - L * zr / kt
    S.scale(ix, -(L / kt) * Kr)
    S.switch(ix, s, M_STICK, tr, np.where(at, SW_SLIP_STICK_AT, SW_SLIP_STICK))


def _events_vector(ct, Nc, Lc, kt, w, mode, tlo, u1, L1):
    """Steps with switches inside the interval, vectorized over them.

    Args:
        ct, Nc, Lc: (b, 4) cubic coefficients of u_t (complex, mm), n0 + kn (u_n - g) and L, N.
        kt: (b,) N/mm. w: (b,) complex slider at the start, mm. mode: (b,) M_STICK / M_SLIP /
        M_OPEN at the start. tlo: (b,) where a closing is searched from. u1, L1: (b,) u_t and
        L at the end sample.

    Returns:
        w (b,) at the end, slipped (b,) bool, switch codes (b, MAX_SWITCH), times
        (b, MAX_SWITCH), and (P, Q) (b,) with d w = P d w0 + Q conj(d w0) (see _Record).
    """
    S = _Switching(ct, Nc, Lc, kt, w, mode, tlo, u1, L1)
    for s in range(MAX_SWITCH):
        moved = ~S.run
        for m, fn in ((M_OPEN, _sw_close), (M_STICK, _sw_slide), (M_SLIP, _sw_stop)):
            ix = np.nonzero(~moved & (S.mode == m))[0]
            if ix.size:
                fn(S, ix, s)
                moved[ix] = True
        if not S.run.any():
            break
    ix = np.nonzero(S.run & (S.mode == M_SLIP))[0]      # switch budget spent while slipping
    if ix.size:
        ct_, Lc_, kt_ = S.rows(ix)
        z1, K1 = _magnus_k(ct_, Lc_, kt_, S.z[ix], S.t[ix], 1.0)
        S.w[ix] = S.u1[ix] - (S.L1[ix] / kt_) * z1
        S.scale(ix, -(S.L1[ix] / kt_) * K1)
    return S.w, S.slipped, S.codes, S.taus, S.P, S.Q


def _event_scalar(ct, Nc, Lc, kt, w, mode, tlo, u1, L1):
    """_events_vector for one step of one element on Python scalars (same decisions)."""
    t, z, slipped, p, q = 0.0, 0j, mode == M_SLIP, 0j, 0j
    if mode == M_STICK:
        p = 1.0 + 0j
    elif slipped:
        T0 = kt * (ct[0] - w)
        r0 = abs(T0)
        z = T0 / r0
        p = -kt / (2.0 * r0) + 0j
        q = -p * z * z
    codes, taus = [], []
    while len(codes) < MAX_SWITCH:
        if mode == M_OPEN:
            t = _root_scalar(_close_fun(Nc), tlo, 1.0, _poly(Nc, tlo), _poly(Nc, 1.0))
            pd = _dpoly(ct, t)
            p = q = 0j
            if kt * abs(pd) > _dpoly(Lc, t):
                mode, z, code, slipped = M_SLIP, pd / abs(pd), SW_OPEN_SLIP, True
            else:
                mode, w, code = M_STICK, _poly(ct, t), SW_OPEN_STICK
        elif mode == M_STICK:
            peak, tpk = _stick_over_scalar(ct, Lc, kt, w, t)
            thi = tpk if peak else 1.0
            if abs(kt * (u1 - w)) <= L1 and not peak:
                return w, slipped, codes, taus, p, q
            f0 = _excess(ct, Lc, kt, w, t)
            code = SW_STICK_SLIP_AT if f0 > EDGE_TOL * L1 else SW_STICK_SLIP
            if code == SW_STICK_SLIP:
                t = _root_scalar(_excess_fun(ct, Lc, kt, w), t, thi, min(f0, 0.0),
                                 max(_excess(ct, Lc, kt, w, thi), 0.0))
            d = _poly(ct, t) - w
            ad = abs(d)
            mode, z, slipped = M_SLIP, d / ad, True
            p, q = -(p - z * z * q.conjugate()) / (2.0 * ad), -(q - z * z * p.conjugate()) / (2.0 * ad)
        else:
            z1, K1 = _magnus_k(ct, Lc, kt, z, t, 1.0)
            rate1 = _slip_rate(ct, Lc, kt, z1, 1.0)
            if rate1 > 0:
                f = -(L1 / kt) * K1
                return u1 - (L1 / kt) * z1, slipped, codes, taus, f * p, f * q
            rate0 = _slip_rate(ct, Lc, kt, z, t)
            code = SW_SLIP_STICK_AT if rate0 <= 0 else SW_SLIP_STICK
            if rate0 > 0:
                h = _stop_quadratic(ct, Lc, kt, z, t, z1, rate0, rate1)
                tr = _root_scalar(_stop_fun(h, t), t, 1.0, -rate0, -rate1)
                z, K = _magnus_k(ct, Lc, kt, z, t, tr)
                t, p, q = tr, K * p, K * q
            L = _poly(Lc, t)
            mode, w, p, q = M_STICK, _poly(ct, t) - L * z / kt, -(L / kt) * p, -(L / kt) * q
        codes.append(code)
        taus.append(t)
    if mode == M_SLIP:
        z1, K1 = _magnus_k(ct, Lc, kt, z, t, 1.0)
        w, f = u1 - (L1 / kt) * z1, -(L1 / kt) * K1
        p, q = f * p, f * q
    return w, slipped, codes, taus, p, q


# ---------------------------------------------------------------------------- excursions of a stick phase
#: (i, j, k) = [i + j == k]: power coefficients of a product of two cubics
_CONV = np.array([[[float(i + j == k) for k in range(7)] for j in range(4)] for i in range(4)])
#: Bernstein coefficients on [0, 1] of a degree-6 polynomial from its power coefficients
_BERN = np.array([[math.comb(k, i) / math.comb(6, i) if i <= k else 0.0 for i in range(7)]
                  for k in range(7)])
_BERN_L = _BERN.tolist()


def _excess_sq(ct, Lc, kt, w):
    """Power coefficients (..., 7) of kt^2 |u_t - w|^2 - L^2 along the step (ct (..., 4) complex,
    Lc (..., 4)): > 0 exactly where the stuck force is outside the limit (L >= 0)."""
    d = np.array(ct, dtype=complex)
    d[..., 0] -= w
    M = (kt ** 2)[..., None, None] * (d[..., :, None] * d[..., None, :].conj()).real
    M -= Lc[..., :, None] * Lc[..., None, :]
    return np.einsum("...ij,ijk->...k", M, _CONV)


def _horner(a, t):
    """sum_k a[:, k] t^k (a (b, n) with t (b,), or a (b, n, 1) with t (b, m))."""
    v = a[:, -1]
    for k in range(a.shape[1] - 2, -1, -1):
        v = v * t + a[:, k]
    return v


def _stick_clear(ct, Lc, kt, w):
    """True where the stuck force certainly stays inside the limit over the whole step (all
    Bernstein coefficients of _excess_sq <= 0; conservative).

    Steps deep inside are cleared first by the bound of ``_stick_over_scalar``,
    kt sum |d_i| <= L_0 - sum_{i>0} |L_i| (d = ct - w: on [0, 1] |u_t - w| <= sum |d_i| and
    L >= L_0 - sum |L_i|), so that only the rest build the degree-6 polynomial: at a low
    excitation most steps of a stuck element are (session 12: the default model's baseline
    curve at the low level took 8.9 s instead of 12.4, _classify 1.4 s instead of 4.5)."""
    ct, Lc = np.asarray(ct), np.asarray(Lc)
    shape = np.broadcast_shapes(ct.shape[:-1], Lc.shape[:-1], np.shape(kt), np.shape(w))
    # flat over the steps (a scalar step too), so that the rest can be picked by a mask
    ct = np.broadcast_to(ct, shape + (4,)).reshape(-1, 4)
    Lc = np.broadcast_to(Lc, shape + (4,)).reshape(-1, 4)
    kt, w = np.broadcast_to(kt, shape).ravel(), np.broadcast_to(w, shape).ravel()
    d = np.abs(ct[:, 1:]).sum(axis=-1) + np.abs(ct[:, 0] - w)
    out = kt * d <= Lc[:, 0] - np.abs(Lc[:, 1:]).sum(axis=-1)
    rest = ~out
    if rest.any():
        out[rest] = (_excess_sq(ct[rest], Lc[rest], kt[rest], w[rest]) @ _BERN.T).max(axis=-1) <= 0.0
    return out.reshape(shape)


def _stick_peak(ct, Lc, kt, w, t0):
    """Largest excess of a stick phase from t0 to the step end (arrays over steps, ct (b, 4)).

    The samples only bound a step: the stuck force can leave the limit between them and be back
    inside at the end. Testing the end sample alone then misses that slip, and the missed slip
    makes the force jump where the end sample crosses the limit (or, in a periodic state whose
    end sample lies on the limit, flip by rounding between two periodic states). The largest
    excess is located on a grid, refined by Newton on the polynomial _excess_sq.

    Returns:
        over (b,) the excess exceeds PEAK_TOL max(L, L(1)) somewhere in (t0, 1], tpk (b,) where it is
        largest (the bracket end of the stick -> slip root).
    """
    a = _excess_sq(ct, Lc, kt, w)                                     # (b, 7)
    s = np.linspace(0.0, 1.0, PEAK_GRID + 1)
    tg = t0[:, None] + (1.0 - t0)[:, None] * s                          # (b, m)
    G = _horner(a[:, :, None], tg)
    m = np.argmax(G, axis=1)
    r = np.arange(m.size)
    t = tg[r, m]
    lo, hi = tg[r, np.maximum(m - 1, 0)], tg[r, np.minimum(m + 1, PEAK_GRID)]
    a1 = a[:, 1:] * np.arange(1, 7)
    a2 = a1[:, 1:] * np.arange(1, 6)
    for _ in range(8):
        g2 = _horner(a2, t)
        step = np.divide(_horner(a1, t), g2, out=np.zeros_like(t), where=g2 < 0.0)
        tn = np.clip(t - step, lo, hi)
        if np.all(np.abs(tn - t) <= ROOT_TOL):
            t = tn
            break
        t = tn
    t = np.where(_horner(a, t) > G[r, m], t, tg[r, m])
    c, l = tuple(np.moveaxis(np.asarray(ct), -1, 0)), tuple(np.moveaxis(np.asarray(Lc), -1, 0))
    L = _poly(l, t)
    # (relative to the larger of the limit there and at the step end: right after a closing the
    # limit vanishes, and rounding-level excesses near it are no excursion)
    over = kt * np.abs(_poly(c, t) - w) - L > PEAK_TOL * np.maximum(np.maximum(L, _poly(l, 1.0)), 1e-300)
    return over, t


def _stick_over_scalar(ct, Lc, kt, w, t0=0.0):
    """_stick_peak for one step on Python scalars: (over, tpk); (False, 1.0) when certainly clear."""
    d = (ct[0] - w, ct[1], ct[2], ct[3])
    # |kt (u_t - w)| <= kt sum |d_i| and L >= L_0 - sum |L_i| (i > 0) on [0, 1]: deep inside
    if t0 == 0.0 and kt * (abs(d[0]) + abs(d[1]) + abs(d[2]) + abs(d[3])) <= (
            Lc[0] - abs(Lc[1]) - abs(Lc[2]) - abs(Lc[3])):
        return False, 1.0
    k2 = kt * kt
    a = [0.0] * 7
    for i in range(4):
        for j in range(4):
            a[i + j] += k2 * (d[i] * d[j].conjugate()).real - Lc[i] * Lc[j]
    if t0 == 0.0 and max(sum(_BERN_L[k][i] * a[i] for i in range(k + 1)) for k in range(7)) <= 0.0:
        return False, 1.0
    return _stick_peak_scalar(a, ct, Lc, kt, w, float(t0))


def _hornerl(a, t: float) -> float:
    """sum_k a[k] t^k for a list a (Python scalars)."""
    v = a[-1]
    for k in range(len(a) - 2, -1, -1):
        v = v * t + a[k]
    return v


def _stick_peak_scalar(a, ct, Lc, kt: float, w: complex, t0: float):
    """_stick_peak for one step on Python scalars, given the excess coefficients a (list of 7):
    the same grid search and Newton refinement (a numpy call per step cost 10x more on the few
    elements marched one by one). Returns (over, tpk)."""
    G, tg = [], []
    for i in range(PEAK_GRID + 1):
        t = t0 + (1.0 - t0) * (i / PEAK_GRID)
        tg.append(t)
        G.append(_hornerl(a, t))
    m = max(range(PEAK_GRID + 1), key=G.__getitem__)
    t = tg[m]
    lo, hi = tg[max(m - 1, 0)], tg[min(m + 1, PEAK_GRID)]
    a1 = [a[k] * k for k in range(1, 7)]
    a2 = [a1[k] * k for k in range(1, 6)]
    for _ in range(8):
        g2 = _hornerl(a2, t)
        step = _hornerl(a1, t) / g2 if g2 < 0.0 else 0.0
        tn = min(max(t - step, lo), hi)
        if abs(tn - t) <= ROOT_TOL:
            t = tn
            break
        t = tn
    if not _hornerl(a, t) > G[m]:
        t = tg[m]
    L = _poly(Lc, t)
    over = kt * abs(_poly(ct, t) - w) - L > PEAK_TOL * max(max(L, _poly(Lc, 1.0)), 1e-300)
    return over, t


# ---------------------------------------------------------------------------- one period
def _cycle_vector(tab: _StepTables, rows: np.ndarray, w: np.ndarray) -> _Record:
    """March one period of the elements rows of tab from their sliders w (complex, mm),
    vectorized over the elements.

    Each element has its own step pointer. A round advances every element through its current
    stick, slip or open phase (_advance, up to WINDOW steps), then processes together the
    steps with switches that the elements reached (_switch_steps). A period takes about as many
    rounds as an element has phases: stepping all elements sample by sample, with one small
    batch of switching steps per sample, cost most of the march in numpy call overhead.
    """
    k, nt = rows.size, tab.ut.shape[1]
    rec = _Record(k, nt)
    rec.cdone[:] = False
    w = w.copy()
    pos = np.zeros(k, dtype=int)
    while True:
        act = np.nonzero(pos < nt)[0]
        if not act.size:
            break
        ev = _advance(tab, rows, rec, w, pos, act)
        if ev.size:
            _switch_steps(tab, rows, rec, w, pos, ev)
    rec.wend = w
    return rec


def _cycle_jit(tab: _StepTables, rows: np.ndarray, w: np.ndarray) -> _Record:
    """_cycle_vector compiled (:mod:`hbm.friction_jit`): the scalar path's algorithm, one
    element at a time at machine speed."""
    rec = _Record(rows.size, tab.ut.shape[1])
    rec.cdone[:] = False
    friction_jit.cycle(rows, w, tab.kt, tab.ut, tab.tcl, tab.L, tab.al, tab.be, tab.pe, tab.Lpe,
                       tab.bad, tab.tlo, tab.ct, tab.Nc, tab.Lc, rec.code, rec.wst, rec.slip,
                       rec.mode0, rec.AP, rec.AQ, rec.evc, rec.evt, rec.wend)
    return rec


def _cycle_matrix(tab: _StepTables, rows, rec: _Record) -> np.ndarray:
    """(k, 2, 2) derivative of the end slider w.r.t. the start one for the records rec of the
    elements rows of tab (see _Record.cP): from the steps' (AP, AQ) (switching steps: recorded by
    _switch_steps; full-step slips: dw_j = (L_j / (2 |T0|)) K (dw - z0^2 conj dw), K the Möbius
    derivative), unless the march accumulated it."""
    todo = np.nonzero(~rec.cdone)[0]
    if todo.size and USE_JIT and friction_jit.AVAILABLE:
        cP, cQ = np.empty(todo.size, dtype=complex), np.empty(todo.size, dtype=complex)
        friction_jit.cycle_matrix(np.asarray(rows)[todo], tab.kt, tab.ut, tab.L, tab.al, tab.be,
                                  tab.det, rec.code[todo], rec.wst[todo], rec.AP[todo],
                                  rec.AQ[todo], cP, cQ)
        rec.cP[todo], rec.cQ[todo] = cP, cQ
        rec.cdone[todo] = True
    elif todo.size:
        code = rec.code[todo]
        P = np.where(code == STICK_STEP, 1.0 + 0j, np.where(code == EVENT_STEP, rec.AP[todo], 0j))
        Q = np.where(code == EVENT_STEP, rec.AQ[todo], 0j)
        e, j = np.nonzero(code == SLIP_STEP)
        g = rows[todo][e]
        T0 = tab.kt[g] * (tab.ut[g, j - 1] - rec.wst[todo[e], j])
        r0 = np.abs(T0)
        z0 = T0 / r0
        den = _cmul(tab.be[g, j].conj(), z0) + tab.al[g, j].conj()
        K = tab.det[g, j] / _cmul(den, den)
        P[e, j] = tab.L[g, j] / (2.0 * r0) * K
        Q[e, j] = -_cmul(P[e, j], _cmul(z0, z0))
        rec.cP[todo], rec.cQ[todo] = _compose(P, Q)
        rec.cdone[todo] = True
    return _to_real(rec.cP, rec.cQ)


def _mobius_scan(al, be):
    """Inclusive prefix products along axis 1 of the Möbius matrices [[al, be], [conj be,
    conj al]], later steps on the left (Hillis–Steele)."""
    a, b = al.copy(), be.copy()
    s = 1
    while s < a.shape[1]:
        a1, b1, a2, b2 = a[:, s:], b[:, s:], a[:, :-s], b[:, :-s]
        a[:, s:], b[:, s:] = a1 * a2 + b1 * b2.conj(), a1 * b2 + b1 * a2.conj()
        s *= 2
    return a, b


def _compose(P, Q):
    """Composition along axis 1 (later on the left) of the maps dv -> P dv + Q conj(dv)."""
    while P.shape[1] > 1:
        if P.shape[1] % 2:
            P = np.concatenate([P, np.ones_like(P[:, :1])], axis=1)
            Q = np.concatenate([Q, np.zeros_like(Q[:, :1])], axis=1)
        P1, Q1, P2, Q2 = P[:, 0::2], Q[:, 0::2], P[:, 1::2], Q[:, 1::2]
        P, Q = _cmul(P2, P1) + _cmul(Q2, Q1.conj()), _cmul(P2, Q1) + _cmul(Q2, P1.conj())
    return P[:, 0], Q[:, 0]


def _cmul(a, b):
    """a b for complex arrays in real arithmetic, each operation rounded on its own. With numpy's
    complex products the Newton-closed march (``_cycle_matrix``) gave different last bits for the
    same inputs between calls, and a curve different paths between runs (issue 16, session 20);
    numpy's complex loops may or may not fuse a multiply and an add, and what chose the path was
    not pinned down (not the operands' alignment). Each real operation here is exactly rounded."""
    ar, ai, br, bi = a.real, a.imag, b.real, b.imag
    return (ar * br - ai * bi) + 1j * (ar * bi + ai * br)


def _advance(tab: _StepTables, rows, rec: _Record, w, pos, act):
    """Advance the elements act (indices into rows, w, pos, rec; tab row rows[act]), each from its
    own step pos, through their current stick, slip or open phase (at most WINDOW steps; an
    opening step ends a phase and is done). w, pos and rec are updated in place. Returns the
    elements that stopped at a step with switches."""
    nt = tab.ut.shape[1]
    g = rows[act]
    J = pos[act, None] + _WIN
    inside = J < nt
    u1, al, be, pe, lim, fl = np.moveaxis(tab.packed()[g[:, None], np.minimum(J, nt - 1)], -1, 0)
    L1, flags = lim.real, fl.real.astype(np.int8)
    c1, ok = (flags & 2) > 0, (flags & 5) == 1                  # ok: closed before, not bad
    kt, wa, p0 = tab.kt[g], w[act], pos[act] - 1
    T0 = kt * (tab.ut[g, p0] - wa)
    r0 = np.abs(T0)
    closed0 = (flags[:, 0] & 1) > 0
    slip0 = closed0 & (r0 >= tab.L[g, p0] * (1.0 - SLIP_TOL))
    stick0 = closed0 & ~slip0
    cont = np.where(stick0[:, None], ok & c1 & (np.abs(kt[:, None] * (u1 - wa[:, None])) <= L1), ~c1)
    # stick steps that end inside the limit may still leave it between the samples
    cs = np.nonzero(stick0[:, None] & cont)
    if cs[0].size:
        Jc = np.minimum(J[cs], nt - 1)
        ctc, Lcc, ktc, wc = tab.ct[g[cs[0]], Jc], tab.Lc[g[cs[0]], Jc], kt[cs[0]], wa[cs[0]]
        q = np.nonzero(~_stick_clear(ctc, Lcc, ktc, wc))[0]
        if q.size:
            over, _ = _stick_peak(ctc[q], Lcc[q], ktc[q], wc[q], np.zeros(q.size))
            cont[cs[0][q[over]], cs[1][q[over]]] = False
    w_after = np.where(stick0[:, None] & c1, wa[:, None], u1)
    s = np.nonzero(slip0)[0]
    if s.size:
        z0 = T0[s] / r0[s]
        A_, B_ = _mobius_scan(al[s], be[s])
        # (deep slip makes a step's matrix rank one in floating point, and a product of two can
        # vanish across a reversal: the NaN then fails the slip test and the step switches)
        ks = kt[s, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (A_ * z0[:, None] + B_) / (B_.conj() * z0[:, None] + A_.conj())
            cont[s] = ok[s] & c1[s] & (ks * (z.conj() * pe[s]).real > lim[s].imag)
            w_after[s] = np.where(c1[s], u1[s] - (L1[s] / ks) * z, u1[s])
    cont &= inside
    n = np.where(cont.all(axis=1), WINDOW, np.argmin(cont, axis=1))
    rows, nb = np.arange(act.size), np.minimum(n, WINDOW - 1)
    brk = (n < WINDOW) & inside[rows, nb]
    opening = brk & closed0 & ~c1[rows, nb]
    stop = brk & ~opening
    m = n + opening                                                    # steps done this round
    done = _WIN < m[:, None]
    code = np.where(c1, np.where(slip0, SLIP_STEP, np.where(stick0, STICK_STEP, OPEN_STEP))[:, None],
                    OPEN_STEP)
    e, j = np.broadcast_to(act[:, None], J.shape)[done], J[done]
    rec.wst[e, j] = np.concatenate([wa[:, None], w_after[:, :-1]], axis=1)[done]
    rec.code[e, j] = code[done]
    rec.slip[e, j] = rec.code[e, j] == SLIP_STEP
    w[act] = np.where(m > 0, w_after[rows, np.maximum(m - 1, 0)], wa)
    pos[act] += m
    ev = act[stop]
    rec.mode0[ev, pos[ev]] = np.where(ok[rows, nb][stop], np.where(slip0[stop], M_SLIP, M_STICK), M_OPEN)
    return ev


def _switch_steps(tab: _StepTables, rows, rec: _Record, w, pos, ev) -> None:
    """Do the steps with switches at which the elements ev stopped (pos[ev]), as one batch."""
    j, g = pos[ev], rows[ev]
    w1, sl, codes, taus, P, Q = _events_vector(tab.ct[g, j], tab.Nc[g, j], tab.Lc[g, j], tab.kt[g],
                                               w[ev], rec.mode0[ev, j], tab.tlo[g, j], tab.ut[g, j],
                                               tab.L[g, j])
    rec.wst[ev, j], rec.code[ev, j], rec.slip[ev, j] = w[ev], EVENT_STEP, sl
    rec.evc[ev, j], rec.evt[ev, j], rec.AP[ev, j], rec.AQ[ev, j] = codes, taus, P, Q
    w[ev] = w1
    pos[ev] += 1





def _give_up_if_slow(st: SimpleNamespace, rows: np.ndarray, cycle: int, max_cycles: int) -> None:
    """Raise ConvergenceError as soon as plain repetition is predicted not to close the elements
    rows within max_cycles.

    Plain repetition contracts geometrically (w_n - w* ~ rho^n), so after a few cycles the ratio
    of successive closure errors predicts the cycles still needed. Marching on until the budget
    is spent (1000 periods on the resonator, most of an evaluation's time with the 4th-order
    march) ends in the same ConvergenceError; the caller then keeps the Newton-closed state.
    """
    if cycle < GIVE_UP_AFTER or not rows.size:
        return
    dev, prev = st.dev[rows], st.prev[rows]
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(prev > 0.0, dev / prev, 1.0)
        need = np.where(rho < 1.0, np.log(st.close_tol / np.maximum(dev, 1e-300))
                        / np.log(np.where(rho < 1.0, rho, 0.5)), np.inf)
    if np.any(cycle + need > GIVE_UP_MARGIN * max_cycles):
        raise ConvergenceError(f"friction cycle predicted not to close in {max_cycles} periods "
                               f"(contraction {rho.max():.6f} per period)", float(dev.max()))


def _cycle_scalar(tl: SimpleNamespace, w: complex) -> _Record:
    """_cycle_vector for one element on Python scalars (tl from _StepTables.scalars)."""
    rec = _Record(1, len(tl.ut))
    rec.cdone[:] = False
    rec.wend[0] = _steps_scalar(tl, w, rec)
    return rec


def _steps_scalar(tl: SimpleNamespace, w: complex, rec: _Record) -> complex:
    """March one element over a period on Python scalars, recording into rec (one row).
    Returns the end slider."""
    nt = len(tl.ut)
    kt, ut, tcl, L = tl.kt, tl.ut, tl.tcl, tl.L
    code, wst, slip, evs = [STICK_STEP] * nt, [0j] * nt, [False] * nt, []
    for j in range(nt):
        wst[j] = w
        if not tcl[j]:
            code[j], w = OPEN_STEP, ut[j]
            continue
        if tcl[j - 1] and not tl.bad[j]:
            T0 = kt * (ut[j - 1] - w)
            r0 = abs(T0)
            if r0 >= L[j - 1] * (1.0 - SLIP_TOL):
                z0, a, b = T0 / r0, tl.al[j], tl.be[j]
                z1 = (a * z0 + b) / (b.conjugate() * z0 + a.conjugate())
                if kt * (z1.conjugate() * tl.pe[j]).real > tl.Lpe[j]:
                    code[j], slip[j], w = SLIP_STEP, True, ut[j] - (L[j] / kt) * z1
                    continue
                mode = M_SLIP
            elif abs(kt * (ut[j] - w)) <= L[j] and not _stick_over_scalar(tl.ct[j], tl.Lc[j], kt, w)[0]:
                continue
            else:
                mode = M_STICK
        else:
            mode = M_OPEN
        code[j] = EVENT_STEP
        w, slip[j], codes, taus, p, q = _event_scalar(tl.ct[j], tl.Nc[j], tl.Lc[j], kt, w, mode,
                                                      tl.tlo[j], ut[j], L[j])
        evs.append((j, mode, codes, taus, p, q))
    rec.code[0], rec.wst[0], rec.slip[0] = code, wst, slip
    for j, mode, codes, taus, p, q in evs:
        rec.mode0[0, j], rec.AP[0, j], rec.AQ[0, j] = mode, p, q
        rec.evc[0, j, :len(codes)], rec.evt[0, j, :len(taus)] = codes, taus
    return w


# ---------------------------------------------------------------------------- step derivatives
def _to_real(P, Q):
    """Real 2x2 blocks (b, 2, 2) of the R-linear maps dv -> P dv + Q conj(dv)."""
    c0, c1 = P + Q, 1j * (P - Q)
    return np.stack([np.stack([c0.real, c1.real], -1), np.stack([c0.imag, c1.imag], -1)], -2)


def _slip_jacobians(tab: _StepTables, rec: _Record, e, j):
    """Exact derivatives of full-step slips (most steps, so hand-coded rather than replayed).

    With z1 = (al z0 + be) / D, D = conj(be) z0 + conj(al):
    dz1 = det/D^2 dz0 + [dal z0 + dbe - z1 (conj(dbe) z0 + conj(dal))] / D, and (al, be) follow
    from (A, gam) of _mobius_a, themselves from the Gauss-point rates a_g = kt p'_g / (2 L_g).

    Returns:
        A (b, 2, 2) = d w_j / d w_{j-1} and G (b, 2, 3, 4) = d w_j / d(u_t1, u_t2, u_n of the
        stencil samples j-2..j+1), w as (Re, Im).
    """
    kt, mukn = tab.kt[e], tab.mu[e] * tab.kn[e]
    Lg = tab.Lg[e, j]
    a = (0.5 * kt)[:, None] * tab.pg[e, j] / Lg                       # (b, 2)
    a1, a2 = a[:, 0], a[:, 1]
    A = 0.5 * (a1 + a2)
    gam = _S6 * (a2 * a1.conj()).imag
    c, s, dc, ds = _cs_array((A * A.conj()).real - gam * gam, True)
    al, be = c + 1j * s * gam, s * A
    T0 = kt * (tab.ut[e, j - 1] - rec.wst[e, j])
    r0 = np.abs(T0)
    z0 = T0 / r0
    D = be.conj() * z0 + al.conj()
    z1 = (al * z0 + be) / D
    K0 = ((al * al.conj()).real - (be * be.conj()).real) / D ** 2
    ax = dc + 1j * ds * gam                                            # d al / dx, d be / dx
    Kx = (ax * z0 + ds * A - z1 * z0 * ds * A.conj() - z1 * ax.conj()) / D
    PA = s / D + Kx * A.conj()                                         # dz1 = PA dA + QA conj(dA)
    QA = -z1 * z0 * s / D + Kx * A
    h = (0.5j * _S6) * (1j * s * (z0 + z1) / D - 2.0 * gam * Kx)       # (i sqrt3/12) dz1/dgam
    P = np.stack([0.5 * PA + h * a2.conj(), 0.5 * PA - h * a1.conj()], 1)   # coefficient of da_g
    Q = np.stack([0.5 * QA - h * a2, 0.5 * QA + h * a1], 1)                 # of conj(da_g)
    ka = (0.5 * kt)[:, None] / Lg                                      # da_g / dp'_g
    Pu, Qu = (P * ka) @ _DLG, (Q * ka) @ _DLG                          # (b, 4) per sample
    Rn = (-(P * a + Q * a.conj()) / Lg) @ _LG * mukn[:, None]
    Pw, Qw = -kt * K0 / (2.0 * r0), kt * K0 * z0 ** 2 / (2.0 * r0)     # through z0 = T0/|T0|
    Pu[:, 1] -= Pw
    Qu[:, 1] -= Qw
    f = (-tab.L[e, j] / kt)[:, None]                                   # w_j = u_j - L_j z1 / kt
    Pu, Qu, Rn = f * Pu, f * Qu, f * Rn
    Pu[:, 2] += 1.0
    Rn[:, 2] -= z1 * mukn / kt
    G = np.empty((e.size, 2, 3, 4))
    blk = _to_real(Pu, Qu)                                             # (b, 4, 2, 2)
    G[:, :, 0:2] = blk.transpose(0, 2, 3, 1)
    G[:, 0, 2], G[:, 1, 2] = Rn.real, Rn.imag
    return _to_real(f[:, 0] * Pw, f[:, 0] * Qw), G


def _implicit(fun, tau: np.ndarray) -> _Dual:
    """Switch time as a _Dual: tau solves fun(tau; inputs) = 0, so dtau = -f_x / f_tau (the last
    derivative slot is tau's own)."""
    d = np.zeros((tau.size, NSLOT))
    d[:, -1] = 1.0
    fd = np.real(fun(_Dual(tau, d)).d)
    ft = fd[:, -1:]
    out = np.zeros_like(fd)
    out[:, :-1] = -fd[:, :-1] / np.where(ft != 0, ft, np.inf)
    return _Dual(tau, out)


def _replay(mode0: int, codes, taus, ct, Nc, Lc, kt, w, u1, L1):
    """The slider at the end of switching steps as a _Dual, following the recorded switches
    (same formulas as _event_scalar / _events_vector; the branch decisions are not retaken)."""
    t, z, mode = 0.0, None, mode0
    if mode0 == M_SLIP:
        T0 = kt * (ct[0] - w)
        z = T0 / abs(T0)
    for s, code in enumerate(codes):
        tau = taus[:, s]
        if code in (SW_OPEN_STICK, SW_OPEN_SLIP):
            t = _implicit(lambda x: _poly(Nc, x), tau)
            if code == SW_OPEN_STICK:
                w, mode = _poly(ct, t), M_STICK
            else:
                pd = _dpoly(ct, t)
                z, mode = pd / abs(pd), M_SLIP
        elif code in (SW_STICK_SLIP, SW_STICK_SLIP_AT):
            if code == SW_STICK_SLIP:
                t = _implicit(lambda x: _excess(ct, Lc, kt, w, x), tau)
            d = _poly(ct, t) - w
            z, mode = d / abs(d), M_SLIP
        else:
            if code == SW_SLIP_STICK:
                z1 = _magnus(ct, Lc, kt, z, t, 1.0)
                h = _stop_quadratic(ct, Lc, kt, z, t, z1, _slip_rate(ct, Lc, kt, z, t),
                                    _slip_rate(ct, Lc, kt, z1, 1.0))
                ta, za = t, z
                t = _implicit(lambda x: _poly(h, (x - ta) / (1.0 - ta)), tau)
                z = _magnus(ct, Lc, kt, za, ta, t)
            w, mode = _poly(ct, t) - _poly(Lc, t) * z / kt, M_STICK
    if mode == M_STICK:
        return w
    return u1 - L1 * _magnus(ct, Lc, kt, z, t, 1.0) / kt


def _seeds(tab: _StepTables, rec: _Record, e, j):
    """Inputs of steps (e, j) as _Dual: slider, cubic coefficients, end sample and limit. Slots:
    Re w, Im w, u_t1, u_t2, u_n of the 4 stencil samples, and tau last."""
    b = e.size
    kn, mu = tab.kn[e], tab.mu[e]

    def dual(v, slots=()):
        d = np.zeros((b, NSLOT), dtype=complex)
        for sl, val in slots:
            d[:, sl] = val
        return _Dual(v, d)
    w = dual(rec.wst[e, j], [(0, 1.0), (1, 1j)])
    ct = tuple(dual(tab.ct[e, j, i], [(slice(2, 6), _VINV[i]), (slice(6, 10), 1j * _VINV[i])])
               for i in range(4))
    Nc = tuple(dual(tab.Nc[e, j, i], [(slice(10, 14), kn[:, None] * _VINV[i])]) for i in range(4))
    u1 = dual(tab.ut[e, j], [(4, 1.0), (8, 1j)])
    L1 = dual(tab.L[e, j], [(12, mu * kn)])
    return w, ct, Nc, tuple(mu * c for c in Nc), u1, L1


def _event_jacobians(tab: _StepTables, rec: _Record, e, j):
    """Exact derivatives of switching steps by forward-mode replay, grouped by switch sequence.

    Returns A (b, 2, 2) and G (b, 2, 3, 4) as _slip_jacobians.
    """
    b = e.size
    A, G = np.empty((b, 2, 2)), np.empty((b, 2, 3, 4))
    sig = np.concatenate([rec.mode0[e, j, None], rec.evc[e, j]], axis=1)
    keys, group = np.unique(sig, axis=0, return_inverse=True)
    for g, key in enumerate(keys):
        q = np.nonzero(group.ravel() == g)[0]
        eq, jq = e[q], j[q]
        w, ct, Nc, Lc, u1, L1 = _seeds(tab, rec, eq, jq)
        codes = [int(c) for c in key[1:] if c]
        d = _replay(int(key[0]), codes, rec.evt[eq, jq], ct, Nc, Lc, tab.kt[eq], w, u1, L1).d
        A[q] = np.stack([np.stack([d[:, 0].real, d[:, 1].real], -1),
                         np.stack([d[:, 0].imag, d[:, 1].imag], -1)], -2)
        G[q, 0] = d[:, 2:14].real.reshape(-1, 3, 4)
        G[q, 1] = d[:, 2:14].imag.reshape(-1, 3, 4)
    return A, G





def _local_jacobians(tab: _StepTables, rec: _Record):
    """d w_j / d w_{j-1} (k, nt, 2, 2) and d w_j / d(stencil samples) (k, nt, 2, 3, 4) of every
    step of a recorded period (stick: I, 0; open: 0, w_j = u_j)."""
    k, nt = rec.code.shape
    A, G = np.zeros((k, nt, 2, 2)), np.zeros((k, nt, 2, 3, 4))
    A[rec.code == STICK_STEP] = np.eye(2)
    op = rec.code == OPEN_STEP
    G[op, 0, 0, 2] = 1.0
    G[op, 1, 1, 2] = 1.0
    for code, fn in ((SLIP_STEP, _slip_jacobians), (EVENT_STEP, _event_jacobians)):
        e, j = np.nonzero(rec.code == code)
        if e.size:
            A[e, j], G[e, j] = fn(tab, rec, e, j)
    return A, G





def _newton_restart(w_start, w_end, P):
    """Next cycle's start slider: Newton step on w = Phi(w) (slope P of the cycle map), which
    closes 2D stick-slip cycles in a few periods instead of the slow geometric convergence of
    plain repetition. Neutral elements (det(I - P) ~ 0, e.g. sticking all the closing cycle) keep
    the plain repetition, i.e. their history from rest."""
    M = np.eye(2) - P
    det = M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]
    ok = np.abs(det) > NEWTON_DET
    w = w_end.copy()
    if ok.any():
        d = w_end[ok] - w_start[ok]
        x = np.linalg.solve(M[ok], np.stack([d.real, d.imag], -1)[:, :, None])[:, :, 0]
        w[ok] = w_start[ok] + x[:, 0] + 1j * x[:, 1]
    return w


def _affine_scan(A, B):
    """Inclusive prefix composition of x_{i+1} = A_i x_i + B_i along axis 1 (Hillis–Steele).

    Returns (P, D) with x_{i+1} = P_i x_0 + D_i."""
    P, D = A.copy(), B.copy()
    n = A.shape[1]
    step = 1
    while step < n:
        Pn = P[:, step:] @ P[:, :-step]
        Dn = P[:, step:] @ D[:, :-step] + D[:, step:]
        P[:, step:], D[:, step:] = Pn, Dn
        step *= 2
    return P, D


# ---------------------------------------------------------------------------- elements
class FrictionContacts:
    """A set of 3D friction elements.

    Args:
        dofs: int array (ne, 2, 3): DOF index of body A (row 0) and body B (row 1) for the
            directions t1, t2, n; -1 means ground (zero displacement).
        kt: tangential element stiffness, N/mm (scalar or (ne,)), > 0.
        kn: normal element stiffness, N/mm, > 0.
        mu: friction coefficient, >= 0.
        n0: preload normal force, N, >= 0.
        gap: initial normal gap g, mm (g > 0 open at rest); default 0.
        close_tol: relative tolerance on the slider state for cycle closure.
        max_cycles: cycles marched before declaring non-closure.
    """

    def __init__(self, dofs, kt, kn, mu, n0, gap=0.0, close_tol: float = 1e-10,
                 max_cycles: int = 200) -> None:
        d = np.asarray(dofs)
        if d.ndim != 3 or d.shape[1:] != (2, 3):
            raise ValueError(f"dofs must have shape (ne, 2, 3), got {d.shape}")
        if d.shape[0] < 1:
            raise ValueError("dofs must describe at least one element (ne >= 1)")
        if not np.issubdtype(d.dtype, np.integer):
            if not np.all(np.isfinite(d)) or np.any(d != np.round(d)):
                raise ValueError("dofs must be integers (-1 = ground)")
            d = d.astype(int)
        if np.any(d < -1):
            raise ValueError("dofs must be >= -1 (-1 = ground)")
        self.dofs = d.astype(np.int64)
        self.ne = d.shape[0]
        ne = self.ne
        # (elements without stiffness carry no force: drop them before building the contacts)
        self.kt = _param("kt", kt, ne, 0.0, allow_equal=False)
        self.kn = _param("kn", kn, ne, 0.0, allow_equal=False)
        self.mu = _param("mu", mu, ne, 0.0)
        self.n0 = _param("n0", n0, ne, 0.0)
        g = np.asarray(gap, dtype=float)
        self.gap = np.full(ne, float(g)) if g.ndim == 0 else g
        if self.gap.shape != (ne,) or not np.all(np.isfinite(self.gap)):
            raise ValueError(f"gap must be a finite scalar or array of shape ({ne},)")
        if not (0 < close_tol < 1):
            raise ValueError(f"close_tol must be in (0, 1), got {close_tol}")
        self.close_tol = float(close_tol)
        self.max_cycles = int(max_cycles)
        #: elements that can stick all cycle on a slider other than rest take the admissible one
        #: nearest rest (hbm.shakedown), independent of the time origin, and are not marched;
        #: False (default): the march from rest at t = 0 decides. A forced response's t = 0 is the
        #: excitation's; a nonlinear mode has none, and continue_backbone sets this for its run
        self.shakedown = False
        #: how often a neutral element kept its Newton-closed periodic state (see ``march``)
        self.neutral_kept = 0
        #: closed at rest (u = 0): these contribute their stuck stiffness to the linear base
        self.closed_at_rest = self.n0 - self.kn * self.gap > 0.0

    # ------------------------------------------------------------------ linear base
    def base_stiffness(self) -> np.ndarray:
        """Element stiffness of the linear base state, (ne, 3): (kt, kt, kn) if closed at rest, else 0."""
        k = np.stack([self.kt, self.kt, self.kn], axis=1)
        return k * self.closed_at_rest[:, None]

    def check_dofs(self, n: int) -> None:
        """Raise ValueError if a DOF index is outside 0..n-1 (or -1)."""
        if np.any(self.dofs >= n):
            raise ValueError(f"dofs must be < n = {n} (number of structure DOFs), got max {self.dofs.max()}")

    # ------------------------------------------------------------------ classification
    def _classify(self, u: np.ndarray, U: np.ndarray, idx: np.ndarray):
        """Vectorized over samples: the elements open all cycle, and those stuck all cycle with
        their slider (0 when stuck from rest; with ``shakedown``, the admissible slider nearest
        rest of those that can stick all cycle only after slipping).

        Args:
            u: (k, 3, nt) samples of the elements idx; U: (k, 3, nH) their harmonics.

        Returns:
            open_all (k,) bool, stuck_all (k,) bool, w (k,) complex slider of the stuck, mm, and
            times (k, 2) the instants whose disks fix w (shakedown.refine; nan for none: stuck
            from rest).
        """
        k, nt = len(idx), u.shape[2]
        w, times = np.zeros(k, dtype=complex), np.full((k, 2), np.nan)
        st = (np.arange(nt)[:, None] + _STENCIL) % nt
        if USE_JIT and friction_jit.AVAILABLE:
            N, (open_all, closed_all, stuck_all) = np.empty((k, nt)), (np.empty(k, dtype=bool) for _ in range(3))
            friction_jit.classify(np.asarray(u, float), self.kt[idx], self.mu[idx], self.kn[idx],
                                  self.n0[idx], self.gap[idx], N, open_all, closed_all, stuck_all)
        else:
            N, open_all, closed_all, stuck_all = self._classify_numpy(u, idx, st)
        if self.shakedown:
            self._shaken(u, U, idx, N, closed_all & ~stuck_all, st, stuck_all, w, times)
        return open_all, stuck_all, w, times

    def _classify_numpy(self, u: np.ndarray, idx: np.ndarray, st: np.ndarray):
        """:meth:`_classify`'s tests in numpy: N (k, nt), open_all, closed_all, stuck_all (k,)."""
        N = self.n0[idx, None] + self.kn[idx, None] * (u[:, 2] - self.gap[idx, None])
        open_all = np.all(N <= 0.0, axis=1)
        closed_all = np.all(N > 0.0, axis=1)
        T2 = self.kt[idx, None] ** 2 * (u[:, 0] ** 2 + u[:, 1] ** 2)
        stuck_all = closed_all & np.all(T2 <= (self.mu[idx, None] * N) ** 2, axis=1)
        c = np.nonzero(stuck_all)[0]
        if c.size:
            # as the march would find from w = 0: no excursion outside the limit, and no opening,
            # between the samples either (else the linear shortcut would jump where a sample
            # crosses the limit)
            ut = u[c, 0] + 1j * u[c, 1]
            ct = ut[:, st] @ _VINV.T
            Nc, ng = _gauss_normal(N[c], st)
            Lc = self.mu[idx[c], None, None] * Nc
            kt = np.broadcast_to(self.kt[idx[c], None], ut.shape)
            ok = (ng > 0.0).all(axis=(1, 2)) | (self.mu[idx[c]] == 0.0)
            clear = _stick_clear(ct, Lc, kt, np.zeros(ut.shape))
            e, j = np.nonzero(~clear)
            if e.size:
                over, _ = _stick_peak(ct[e, j], Lc[e, j], kt[e, j], np.zeros(e.size), np.zeros(e.size))
                ok[e[over]] = False
            stuck_all[c[~ok]] = False
        return N, open_all, closed_all, stuck_all

    def _shaken(self, u, U, idx, N, cand, st, stuck_all, w, times) -> None:
        """Mark stuck (in place) the closed elements that can stick all cycle on some slider, with
        the admissible slider nearest rest (hbm.shakedown: a march from rest at t = 0 made it
        depend on where t = 0 falls in the cycle)."""
        c = np.nonzero(cand & (self.mu[idx] > 0.0))[0]
        if not c.size:
            return
        # closed between the samples too (an opening resets the slider: the march's business)
        c = c[(_gauss_normal(N[c], st)[1] > 0.0).all(axis=(1, 2))]
        if not c.size:
            return
        e = idx[c]
        ut, rho = u[c, 0] + 1j * u[c, 1], self.mu[e, None] * N[c] / self.kt[e, None]
        ws, act, ok = shakedown.nearest_admissible(ut, rho)
        # stuck at every sample from rest (the march finds a slip between two): stuck from rest
        rest = ok & (act[:, 0] < 0)
        stuck_all[c[rest]] = True
        s = np.nonzero(ok & ~rest)[0]
        if not s.size:
            return
        Ct, R = self._path(U[c[s]], e[s])
        ws, ts, ok = shakedown.refine(Ct, R, ws[s], act[s], ut[s], rho[s])
        s = c[s[ok]]
        stuck_all[s] = True
        w[s], times[s] = ws[ok], ts[ok]

    def _path(self, U: np.ndarray, e: np.ndarray):
        """Harmonics of u_t1 + i u_t2 and of rho = mu N / kt (N = n0 + kn (u_n - g)) of the
        elements e, (k, nH) each (shakedown's input)."""
        g = self.mu[e] / self.kt[e]
        R = (g * self.kn[e])[:, None] * U[:, 2]
        R[:, 0] += g * (self.n0[e] - self.kn[e] * self.gap[e])
        return U[:, 0] + 1j * U[:, 1], R

    # ------------------------------------------------------------------ time march
    def march(self, u: np.ndarray, idx: np.ndarray, fourier: Fourier | None = None,
              jacobian: bool = False, newton: bool = True, max_cycles: int | None = None):
        """March the elements ``idx`` over periods of the sampled motion until the cycle closes.

        The forward pass records what each step did (``_Record``). The Jacobian is obtained
        afterwards from it: each step's derivative, d w_j = A_j d w_{j-1} + G_j (x) E_{stencil},
        is an affine recurrence for the slider sensitivity, and dT_j = kt (E_j - d w_j).

        Args:
            u: relative displacement samples (k, 3, nt), mm.
            idx: element indices (k,).
            fourier: needed when jacobian=True.
            jacobian: also return d(force samples)/d(harmonics).
            newton: close 2D cycles by Newton restarts on the slider (else plain repetition).
            max_cycles: cycle budget (default ``self.max_cycles``).

        Returns:
            T (k, 2, nt) tangential force N, N (k, nt) normal force N, slip (k, nt) bool
            (slipped during the step ending at the sample), closed (k, nt) bool, cycles marched,
            and when jacobian: dT (k, 2, nt, 3 nH),
            dN (k, nt, 3 nH) in the element's (direction, harmonic) layout.
        """
        out, jac = self._march(u, idx, fourier, jacobian, newton, max_cycles)
        if not jacobian:
            return out
        dT, wN = jac()
        k, nt = wN.shape
        dN = np.zeros((k, nt, 3, fourier.nH))
        dN[:, :, 2] = wN[..., None] * fourier.E[None]
        return out + [dT, dN.reshape(k, nt, -1)]

    def _march(self, u: np.ndarray, idx: np.ndarray, fourier: Fourier | None, jacobian: bool,
               newton: bool = True, max_cycles: int | None = None):
        """:meth:`march` with its Jacobian deferred: (the forward results, a function that
        returns (dT, wN) (:func:`_march_jacobian`) on its first call and the same arrays after;
        None without jacobian).
        A Newton line search rejects most of its trials: their Jacobians are never needed."""
        tab = _StepTables(u, self.kt[idx], self.mu[idx], self.kn[idx], self.n0[idx], self.gap[idx])
        n_cycles = self.max_cycles if max_cycles is None else int(max_cycles)
        if not newton and USE_JIT and friction_jit.AVAILABLE:
            # plain repetition: all periods in one compiled call (no history kept: the neutral
            # elements' sensitivity is propagated when the Jacobian is asked for)
            final, cyc, hist = self._repeat(tab, fourier, jacobian, n_cycles)
            jumped = np.zeros(len(idx), dtype=bool)
        else:
            final, hist, cyc, err, jumped = self._forward(tab, newton, n_cycles, jacobian)
            if err > self.close_tol:
                raise CycleNotClosed(f"friction cycle did not close in {n_cycles} periods", err)
        # Elements that stick through the whole closing cycle have a neutral, history-dependent
        # slider; if a Newton restart touched their history, redo them by plain repetition from
        # rest so that state and Jacobian are those of the march from rest.
        redo = np.zeros(len(idx), dtype=bool)
        jr = np.nonzero(jumped)[0] if newton else np.zeros(0, dtype=int)
        if jr.size:
            M = np.eye(2) - _cycle_matrix(tab, jr, final.take(jr))
            redo[jr] = np.abs(M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]) <= NEWTON_DET
        T, slip, n_cyc = tab.force(final), final.slip, int(cyc.max())
        sub_jac = None
        if redo.any():
            # Plain repetition contracts only geometrically: rates of 0.93 per cycle and, for an
            # element that barely slips at one sample, 1 − 1e-6 were seen on the resonator. These
            # few elements get a larger budget; if even that does not close, the Newton-closed
            # state is kept: it is a periodic state too (the neutral direction only shifts the
            # slider), and its Jacobian is the plain propagation used for neutral elements.
            try:
                sub, sub_jac = self._march(u[redo], idx[redo], fourier, jacobian, newton=False,
                                           max_cycles=REDO_CYCLES_FACTOR * n_cycles)
            except ConvergenceError:
                redo[:] = False
                self.neutral_kept += 1
            else:
                T[redo], slip[redo] = sub[0], sub[2]
                n_cyc = max(n_cyc, sub[4])
        out = [T, tab.N, slip, tab.closed, n_cyc]
        if not jacobian:
            return out, None

        def jac():
            dT, wN = _march_jacobian(tab, final, hist() if callable(hist) else hist, cyc, fourier)
            if sub_jac is not None:
                dT[redo], wN[redo] = sub_jac()
            return dT, wN
        return out, once(jac)

    def _repeat(self, tab: _StepTables, fourier: Fourier | None, jacobian: bool, max_cycles: int):
        """Plain repetition from rest, compiled (friction_jit.repeat): the march of ``_forward``
        with newton=False, its give-up test included.

        Returns:
            final record (each element's closing period), periods per element, and (None without
            jacobian) a function returning the slider sensitivity at the start of the closing
            period propagated from rest, (k, 2, 3 nH).
        Raises:
            ConvergenceError: predicted not to close within the budget (as _give_up_if_slow);
            CycleNotClosed: the budget was spent.
        """
        k, nt = tab.ut.shape

        def run(jac: bool):
            rec = _Record(k, nt)
            rec.cdone[:] = False
            E = fourier.E if jac else np.zeros((nt, 1))
            cyc, dwh, info = np.zeros(k, dtype=np.int64), np.zeros((k, 2, 3 * E.shape[1])), np.zeros(2)
            status = friction_jit.repeat(
                tab.kt, tab.mu, tab.kn, tab.ut, tab.tcl, tab.L, tab.al, tab.be, tab.pe, tab.Lpe,
                tab.bad, tab.tlo, tab.ct, tab.Nc, tab.Lc, tab.Lg, tab.pg, tab.scale, self.close_tol,
                max_cycles, GIVE_UP_AFTER, GIVE_UP_MARGIN, E, jac, rec.code, rec.wst, rec.slip,
                rec.mode0, rec.AP, rec.AQ, rec.evc, rec.evt, rec.wend, cyc, dwh, info)
            if status == friction_jit.GAVE_UP:
                raise ConvergenceError(f"friction cycle predicted not to close in {max_cycles} "
                                       f"periods (contraction {info[0]:.6f} per period)", float(info[1]))
            if status == friction_jit.BUDGET_SPENT:
                raise CycleNotClosed(f"friction cycle did not close in {max_cycles} periods",
                                     float(info[1]))
            return rec, cyc, dwh
        # most repetitions on the resonator give up (a contraction too slow): march without the
        # sensitivities, and again with them (the same periods) only when they are asked for
        rec, cyc, _ = run(False)
        return rec, cyc, (once(lambda: run(True)[2]) if jacobian else None)

    def _forward(self, tab: _StepTables, newton: bool, max_cycles: int, keep: bool):
        """Forward march of all elements until each one's cycle closes.

        Many elements are marched together (vectorized), and an element leaves the set once its
        cycle has closed; the last few (<= SCALAR_LIMIT), or few from the start, are marched one
        by one on Python scalars, where numpy's per-call overhead would dominate.

        Returns:
            final record (the closing cycle of each element), history [(cycle, rows, record)]
            (when keep), cycles per element, largest closure error, jumped (a Newton restart
            changed the element's history).
        """
        k, nt = tab.ut.shape
        st = SimpleNamespace(tab=tab, final=_Record(k, nt), hist=[], keep=keep, newton=newton,
                             close_tol=self.close_tol,
                             cyc=np.zeros(k, dtype=int), dev=np.zeros(k), prev=np.zeros(k),
                             jumped=np.zeros(k, dtype=bool))
        rows, w, cycle = np.arange(k), np.zeros(k, dtype=complex), 0
        jit = USE_JIT and friction_jit.AVAILABLE
        march_one = _cycle_jit if jit else _cycle_vector
        while rows.size > (0 if jit else SCALAR_LIMIT) and cycle < max_cycles:
            cycle += 1
            rows, w = self._after_cycle(st, cycle, rows, w, march_one(tab, rows, w))
            if not newton:
                _give_up_if_slow(st, rows, cycle, max_cycles)
        for i in range(rows.size):
            e, w_e = rows[i:i + 1], w[i:i + 1]
            tl = tab.take(e).scalars()
            for c in range(cycle + 1, max_cycles + 1):
                e, w_e = self._after_cycle(st, c, e, w_e, _cycle_scalar(tl, complex(w_e[0])))
                if not e.size:
                    break
                if not newton:
                    _give_up_if_slow(st, e, c, max_cycles)
        return st.final, st.hist, st.cyc, st.dev.max(), st.jumped

    def _after_cycle(self, st: SimpleNamespace, cycle: int, rows, w, rec: _Record):
        """Bookkeeping after a marched period of the elements rows: record it, test closure,
        Newton-restart the open elements (from the second period on: 1D stick-slip and
        transients close by then).

        Returns the elements still to march and their start sliders."""
        st.final.put(rows, rec)
        st.cyc[rows] = cycle
        if st.keep:
            st.hist.append((cycle, rows, rec))
        dev = np.abs(rec.wend - w) / st.tab.scale[rows]
        st.prev[rows] = st.dev[rows]
        st.dev[rows] = dev
        go = np.nonzero(dev > self.close_tol)[0]
        w_next = rec.wend[go]
        if st.newton and cycle >= 2 and go.size:
            rg = rec.take(go)
            w_next = _newton_restart(w[go], rg.wend, _cycle_matrix(st.tab, rows[go], rg))
            st.jumped[rows[go]] |= w_next != rg.wend
        return rows[go], w_next

    # ------------------------------------------------------------------ AFT
    def evaluate(self, U: np.ndarray, fourier: Fourier, jacobian: bool = True,
                 deferred: bool = False):
        """Force harmonics and their Jacobian for relative-displacement harmonics U.

        Args:
            U: (ne, 3, nH) harmonics of u = q_A - q_B in the element frame, mm.
            fourier: the Fourier object (harmonics, samples).
            jacobian: compute the Jacobian.
            deferred: return the Jacobian as a function that computes it on its first call (and
                returns the same array after): a line search's rejected trials never ask.

        Returns:
            F: (ne, 3, nH) harmonics of (T1, T2, N - n0), N.
            nl: indices of the elements whose Jacobian differs from the linear base stiffness.
            DF: (len(nl), 3 nH, 3 nH) Jacobian dF/dU of those elements, N/mm, in the element
                layout index = direction * nH + harmonic (None when jacobian=False; a function
                returning it when deferred).
        """
        ne, nH = self.ne, fourier.nH
        if U.shape != (ne, 3, nH):
            raise ValueError(f"U must have shape ({ne}, 3, {nH}), got {U.shape}")
        u = fourier.to_time(U)                                    # (ne, 3, nt)
        allidx = np.arange(ne)
        open_all, stuck_all, w, times = self._classify(u, U, allidx)
        F = np.zeros((ne, 3, nH))
        # stuck all cycle: linear about the slider w (0: from rest)
        s = stuck_all
        F[s, 0:2] = self.kt[s, None, None] * U[s, 0:2]
        F[s, 0, 0] -= self.kt[s] * w[s].real
        F[s, 1, 0] -= self.kt[s] * w[s].imag
        F[s, 2] = self.kn[s, None] * U[s, 2]
        F[s, 2, 0] -= self.kn[s] * self.gap[s]
        # open all cycle: the structure still feels -n0
        F[open_all, 2, 0] = -self.n0[open_all]
        base = self.closed_at_rest
        shaken = np.isfinite(times[:, 0])
        lin = (stuck_all & base & ~shaken) | (open_all & ~base)
        marched = np.nonzero(~(open_all | stuck_all))[0]
        nl = np.nonzero(~lin)[0]
        jac = None
        if marched.size:
            res, jac = self._march(u[marched], marched, fourier, jacobian)
            T, Nt = res[0], res[1]
            F[marched, 0:2] = fourier.to_freq(T)
            F[marched, 2] = fourier.to_freq(Nt - self.n0[marched, None])
        if not jacobian:
            return F, nl, None
        sd = SimpleNamespace(U=U, w=w, times=times, shaken=shaken)
        DF = once(lambda: self._force_jacobian(nl, stuck_all, marched, jac, fourier, sd))
        return F, nl, (DF if deferred else DF())

    def _force_jacobian(self, nl: np.ndarray, stuck_all: np.ndarray, marched: np.ndarray, jac,
                        fourier: Fourier, sd: SimpleNamespace) -> np.ndarray:
        """The blocks dF/dU of the elements nl (see :meth:`evaluate`): k_t, k_n for the stuck
        elements outside the linear base (less k_t dw/dU on the mean tangential force where the
        slider is not at rest, ``sd``: harmonics, sliders and active instants of ``_classify``), the
        march's Jacobian (``jac()``) for the marched."""
        nH = fourier.nH
        DF = np.zeros((nl.size, 3 * nH, 3 * nH))
        pos = np.full(self.ne, -1)
        pos[nl] = np.arange(nl.size)
        # stuck elements that are not in the base (closed only under vibration), or that stick
        # on a slider other than rest: kt, kn
        sx = np.nonzero(stuck_all & (~self.closed_at_rest | sd.shaken))[0]
        if sx.size:
            eye = np.eye(nH)
            blk = np.zeros((sx.size, 3 * nH, 3 * nH))
            for dd, kk in enumerate((self.kt[sx], self.kt[sx], self.kn[sx])):
                blk[:, dd * nH:(dd + 1) * nH, dd * nH:(dd + 1) * nH] = kk[:, None, None] * eye
            sh = np.nonzero(sd.shaken[sx])[0]
            if sh.size:
                e = sx[sh]
                Ct, R = self._path(sd.U[e], e)
                dw = shakedown.slider_jacobian(Ct, R, sd.w[e], sd.times[e],
                                               self.mu[e] * self.kn[e] / self.kt[e])
                # T = kt (u_t - w): w is constant in time, so it moves the mean (harmonic 0) only
                blk[sh, 0] -= self.kt[e, None] * dw[:, 0]
                blk[sh, nH] -= self.kt[e, None] * dw[:, 1]
            DF[pos[sx]] = blk
        if marched.size:
            dT, wN = jac()
            D = fourier.D
            blk = np.empty((marched.size, 3 * nH, 3 * nH))
            blk[:, 0:nH] = D @ dT[:, 0]
            blk[:, nH:2 * nH] = D @ dT[:, 1]
            # N depends on u_n alone, sample by sample
            blk[:, 2 * nH:, :2 * nH] = 0.0
            blk[:, 2 * nH:, 2 * nH:] = D @ (wN[:, :, None] * fourier.E[None])
            DF[pos[marched]] = blk
        return DF

    # ------------------------------------------------------------------ post-processing
    def histories(self, U: np.ndarray, fourier: Fourier):
        """Time histories over one closed period and the per-element status.

        Returns:
            dict with u_t (ne, 2, nt) mm, T (ne, 2, nt) N, N (ne, nt) N (total normal force),
            status (ne,) int, slip_fraction (ne,).
        """
        ne = self.ne
        u = fourier.to_time(U)
        allidx = np.arange(ne)
        open_all, stuck_all, w, _ = self._classify(u, U, allidx)
        Nt = np.maximum(0.0, self.n0[:, None] + self.kn[:, None] * (u[:, 2] - self.gap[:, None]))
        T = np.zeros((ne, 2, fourier.nt))
        s = stuck_all
        T[s] = self.kt[s, None, None] * (u[s, 0:2] - np.stack([w[s].real, w[s].imag], axis=1)[:, :, None])
        slip = np.zeros((ne, fourier.nt), dtype=bool)
        marched = np.nonzero(~(open_all | stuck_all))[0]
        if marched.size:
            res = self.march(u[marched], marched)
            T[marched] = res[0]
            slip[marched] = res[2]
        closed = Nt > 0
        frac = slip.mean(axis=1)
        status = np.full(ne, STICK_SLIP)
        status[frac >= GROSS_SLIP_FRACTION] = GROSS_SLIP
        status[~slip.any(axis=1)] = STUCK
        status[closed.any(axis=1) & ~closed.all(axis=1)] = PARTLY_OPEN
        status[~closed.any(axis=1)] = OPEN
        return {"u_t": u[:, 0:2].copy(), "T": T, "N": Nt, "status": status, "slip_fraction": frac}


def _gauss_normal(N: np.ndarray, st: np.ndarray):
    """Cubic coefficients (k, nt, 4) of n0 + kn (u_n - g) on each step (samples N (k, nt),
    stencil st) and its values at the steps' two Gauss points (k, nt, 2)."""
    Nc = N[:, st] @ _VINV.T
    return Nc, np.stack([_poly(tuple(np.moveaxis(Nc, -1, 0)), g) for g in _GAUSS], axis=-1)


# ---------------------------------------------------------------------------- Jacobian of a march
def _sources(G: np.ndarray, E: np.ndarray, code: np.ndarray) -> np.ndarray:
    """G_j (x) E of the stencil samples: (k, nt, 2, 3 nH) sources of the slider recurrence
    (zero for stick steps; an open step's is E_j: w_j = u_j)."""
    k, nt = G.shape[:2]
    nH = E.shape[1]
    S = np.zeros((k, nt, 2, 3, nH))
    e, j = np.nonzero((code == SLIP_STEP) | (code == EVENT_STEP))
    Est = E[(j[:, None] + _STENCIL) % nt]                              # (b, 4, nH)
    S[e, j] = (G[e, j].reshape(-1, 6, 4) @ Est).reshape(-1, 2, 3, nH)
    e, j = np.nonzero(code == OPEN_STEP)
    S[e, j, 0, 0], S[e, j, 1, 1] = E[j], E[j]
    return S.reshape(k, nt, 2, 3 * nH)


def _propagate(A, SE, active, d0, P0=None):
    """Slider sensitivities over the active samples: d_{i+1} = A d_i + SE; snapshots (k, n+1, 2, x)."""
    k = A.shape[0]
    if k <= SCAN_LIMIT and active.size:
        # few elements: prefix scan of the affine maps (log2(n) vectorized steps instead of one
        # small step per sample)
        Pc, Dc = _affine_scan(A[:, active], SE[:, active])
        Dc = Dc + Pc @ d0[:, None]
        Ps = np.concatenate([np.broadcast_to(np.eye(2), (k, 1, 2, 2)), Pc], axis=1)
        return Ps, np.concatenate([d0[:, None], Dc], axis=1)
    Ph, d = np.broadcast_to(np.eye(2), (k, 2, 2)).copy(), d0
    sP, sd = [Ph], [d]
    for j in active:
        d = A[:, j] @ d + SE[:, j]
        Ph = A[:, j] @ Ph
        sP.append(Ph)
        sd.append(d)
    return np.stack(sP, axis=1), np.stack(sd, axis=1)


def _march_jacobian(tab: _StepTables, final: _Record, hist, cyc, fourier: Fourier):
    """Sensitivities of the closed cycle (see ``FrictionContacts.march``).

    In the final (closed) cycle the slider sensitivity is affine in its start value,
    dw_j = Phi_j dw_0 + d_j. The start value is that of the periodic state,
    dw_0 = (I - Phi_nt)^-1 d_nt (implicit derivative of the fixed point w = Phi(w)); for neutral
    elements (det(I - Phi_nt) ~ 0) it is the plain propagation of the history from rest:
    ``hist`` is the march's history (``_forward``), or that propagation already done for every
    element, (k, 2, 3 nH) (``_repeat``).
    Compiled (hbm.friction_jit) when the march is, else in numpy.

    Returns:
        dT (k, 2, nt, 3 nH) and wN (k, nt): dN_j = wN_j du_n,j (k_n where closed), kept as
        weights: the full (k, nt, 3 nH) dN, two thirds zeros, cost 4 ms per Jacobian on the
        resonator to build and multiply.
    """
    k, nt = final.code.shape
    nH, E = fourier.nH, fourier.E
    nx = 3 * nH
    jit = _jit_jacobian()
    if jit:
        Ps, Ds = _sensitivities_jit(tab, np.arange(k), final, E, True)    # after every step
        D_end = Ds[:, :, -1]
    else:
        A, G = _local_jacobians(tab, final)
        SE = _sources(G, E, final.code)
        active = np.nonzero((final.code != STICK_STEP).any(axis=0))[0]  # samples where dw may change
        Ps, Ds = _propagate(A, SE, active, np.zeros((k, 2, nx)))
        D_end = Ds[:, -1]
    Mfix = np.eye(2) - Ps[:, -1]
    det = Mfix[:, 0, 0] * Mfix[:, 1, 1] - Mfix[:, 0, 1] * Mfix[:, 1, 0]
    fixed = np.abs(det) > NEWTON_DET
    dw0 = np.zeros((k, 2, nx))
    if fixed.any():
        dw0[fixed] = np.linalg.solve(Mfix[fixed], D_end[fixed])
    neutral = np.nonzero(~fixed)[0]
    if neutral.size:
        dw0[neutral] = (hist[neutral] if isinstance(hist, np.ndarray)
                        else _neutral_history(tab, hist, cyc, neutral, E))
    wN = tab.kn[:, None] * tab.closed
    if jit:
        friction_jit.force_sensitivities(tab.kt, Ps, dw0, E, Ds)         # dT, in place of Ds
        return Ds, wN
    # dw after step j = after the active steps up to and including j
    which = np.searchsorted(active, np.arange(nt), side="right")
    dws = Ps[:, which] @ dw0[:, None] + Ds[:, which]                     # (k, nt, 2, nx)
    Et = np.zeros((nt, 2, nx))
    Et[:, 0, 0:nH], Et[:, 1, nH:2 * nH] = E, E
    dT = (tab.kt[:, None, None, None] * (Et[None] - dws)).transpose(0, 2, 1, 3)
    return dT, wN


def _jit_jacobian() -> bool:
    """Differentiate the march with the compiled kernels (see JIT_JACOBIAN)."""
    return USE_JIT and JIT_JACOBIAN and friction_jit.AVAILABLE


def _sensitivities_jit(tab: _StepTables, g: np.ndarray, rec: _Record, E: np.ndarray,
                      full: bool) -> tuple[np.ndarray, np.ndarray]:
    """Slider sensitivities of the recorded periods rec (row i: step tables row g[i]), compiled.

    Returns:
        Ps (b, m, 2, 2), Ds (b, 2, m, 3 nH) with dw = Ps dw_0 + Ds (mm per mm of harmonic) after
        every step (m = nt, full) or after the period (m = 1); Ds is laid out as the force
        sensitivities, which friction_jit.force_sensitivities writes over it.
    """
    b, nt = rec.code.shape
    m = nt if full else 1
    Ps, Ds = np.empty((b, m, 2, 2)), np.empty((b, 2, m, 3 * E.shape[1]))
    friction_jit.sensitivities(g, tab.kt, tab.mu, tab.kn, tab.ut, tab.L, tab.Lg, tab.pg, tab.ct,
                               tab.Nc, rec.code, rec.wst, rec.mode0, rec.evc, rec.evt, E, full, Ps, Ds)
    return Ps, Ds


def _neutral_history(tab: _StepTables, hist, cyc, neutral, E):
    """Slider sensitivity at the start of the closing cycle of neutral elements: propagated from
    rest through the cycles before it. All those cycles are differentiated in one batch and each
    one's affine map composed at once; only the chaining of the cycles is sequential."""
    pos = np.full(cyc.size, -1)
    pos[neutral] = np.arange(neutral.size)
    rows, recs, owner = [], [], []
    for cycle, r, rec in hist:
        q = np.nonzero((pos[r] >= 0) & (cycle < cyc[r]))[0]
        if q.size:
            rows.append(r[q])
            recs.append(rec.take(q))
            owner.append(pos[r[q]])
    dwh = np.zeros((neutral.size, 2, 3 * E.shape[1]))
    if not rows:
        return dwh
    rec = _Record(sum(x.size for x in rows), E.shape[0])
    rec.put(slice(None), _concat_records(recs))
    if _jit_jacobian():
        Ps, Ds = _sensitivities_jit(tab, np.concatenate(rows), rec, E, False)
        D = Ds[:, :, -1]
    else:
        A, G = _local_jacobians(tab.take(np.concatenate(rows)), rec)
        act = np.nonzero((rec.code != STICK_STEP).any(axis=0))[0]
        Ps, Ds = _propagate(A, _sources(G, E, rec.code), act, np.zeros((A.shape[0], 2, dwh.shape[2])))
        D = Ds[:, -1]
    P = Ps[:, -1]                                   # each recorded cycle: dw -> P dw + D
    for i, p in enumerate(np.concatenate(owner)):   # in march order, so cycles chain in order
        dwh[p] = P[i] @ dwh[p] + D[i]
    return dwh


def _concat_records(recs):
    """One _Record holding the rows of several."""
    out = object.__new__(_Record)
    for name in vars(recs[0]):
        setattr(out, name, np.concatenate([getattr(r, name) for r in recs]))
    return out


def once(fn):
    """``fn()`` computed on the first call and returned again after (a deferred Jacobian)."""
    box = []

    def get():
        if not box:
            box.append(fn())
        return box[0]
    return get
