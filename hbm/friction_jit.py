"""Compiled forward march of the friction elements and its Jacobian (numba), one element at a time.

The march of :mod:`hbm.friction` is sequential in time: each step starts from the slider the
previous one left, and a step with a switch (closing, stick -> slip, slip -> stick) is located
by a root search on the step's cubic path. In numpy it runs vectorized over the elements
(``_cycle_vector``), where each phase of each element costs a few dozen numpy calls: on the
resonator most of an evaluation was numpy's per-call overhead, not arithmetic. Here the same
algorithm, the same formulas and the same decisions as the scalar path of ``friction.py``
(``_steps_scalar`` / ``_event_scalar``, which tests compare with the vectorized one), compiled
by numba: one loop over elements and steps at machine speed.

The Jacobian (``sensitivities``, used by ``friction._march_jacobian``) is compiled the same way:
each step's derivative (the hand-coded full-step slip of ``_slip_jacobians``; the forward-mode
dual-number replay of ``_replay`` for the switching steps, with the switch times differentiated
implicitly) and its propagation through the period, the same formulas in the same order.

numba is Debian's python3-numba (a dependency of python3-basix, which python3-dolfinx pulls
in; ``scripts/setup`` installs it explicitly). Without it, or with ``FE_JOINT_NO_JIT=1``,
:data:`AVAILABLE` is False and the march and its Jacobian stay in numpy. The first call compiles
(forward march ~5 s, Jacobian ~13 s of CPU), cached in ``__pycache__`` for later processes.
"""
from __future__ import annotations

import math
import os

import numpy as np

try:                                           # pragma: no cover - depends on the system
    if os.environ.get("FE_JOINT_NO_JIT", "") not in ("", "0"):
        raise ImportError("disabled by FE_JOINT_NO_JIT")
    from numba import njit
    AVAILABLE = True
except ImportError:                            # pragma: no cover
    AVAILABLE = False

    def njit(*args, **kw):
        """Stand-in decorator: the functions stay plain Python (never called in the march)."""
        if args and callable(args[0]):
            return args[0]
        return lambda f: f

# error_model="numpy" everywhere: a division by zero gives inf / nan as in the numpy marches
# (which run under np.errstate(divide="ignore", invalid="ignore") and discard such values by
# their decisions); numba's default raised ZeroDivisionError (the default run's v1 at 101 N)

# the constants of hbm.friction (duplicated as literals: numba freezes module globals at compile
# time; test_hbm_friction_jit checks they equal friction's)
SLIP_TOL = 1e-12
EDGE_TOL = 1e-12
PEAK_TOL = 1e-9
PEAK_GRID = 16
MAX_SWITCH = 3
ROOT_TOL, ROOT_ITER, ROOT_NEWTON = 1e-14, 60, 1e-8
S6 = math.sqrt(3.0) / 6.0
GAUSS0, GAUSS1 = 0.5 - S6, 0.5 + S6
STICK_STEP, SLIP_STEP, OPEN_STEP, EVENT_STEP = 0, 1, 2, 3
M_STICK, M_SLIP, M_OPEN = 0, 1, 2
(SW_OPEN_STICK, SW_OPEN_SLIP, SW_STICK_SLIP, SW_STICK_SLIP_AT, SW_SLIP_STICK,
 SW_SLIP_STICK_AT) = range(1, 7)
#: Bernstein coefficients on [0, 1] of a degree-6 polynomial from its power coefficients
BERN = np.array([[math.comb(k, i) / math.comb(6, i) if i <= k else 0.0 for i in range(7)]
                 for k in range(7)])
# root-function kinds of _root
_CLOSE, _EXCESS, _STOP = 0, 1, 2


@njit(cache=True, error_model="numpy")
def _cdiv(a, b):
    """a / b for complex a or b as numpy divides: a zero b gives (a.real / 0, a.imag / 0) (inf or
    nan, which the march's decisions discard as the numpy marches do); numba's complex division
    raises ZeroDivisionError whatever the error model (the default run's v1 at 101 N)."""
    if b == 0:
        return complex(a.real / 0.0, a.imag / 0.0)
    return a / b


@njit(cache=True, error_model="numpy")
def _poly(c, t):
    return c[0] + t * (c[1] + t * (c[2] + t * c[3]))


@njit(cache=True, error_model="numpy")
def _dpoly(c, t):
    return c[1] + t * (2.0 * c[2] + t * (3.0 * c[3]))


@njit(cache=True, error_model="numpy")
def _cs(x):
    r = math.sqrt(abs(x))
    small = r < 1e-2
    if x >= 0.0:
        if small:
            return 1.0, 1.0 + x * (-1.0 / 3.0 + x * (2.0 / 15.0))
        return 1.0, math.tanh(r) / r
    if r > 0.0:
        return math.cos(r), math.sin(r) / r
    return math.cos(r), 1.0


@njit(cache=True, error_model="numpy")
def _mobius_a(a1, a2, d):
    A = (0.5 * d) * (a1 + a2)
    gam = (S6 * d * d) * (a2 * a1.conjugate()).imag
    c, s = _cs((A * A.conjugate()).real - gam * gam)
    return c + 1j * (s * gam), s * A


@njit(cache=True, error_model="numpy")
def _rate(ct, Lc, kt, t):
    return _cdiv(kt * _dpoly(ct, t), 2.0 * _poly(Lc, t))


@njit(cache=True, error_model="numpy")
def _magnus_k(ct, Lc, kt, z, ta, tb):
    d = tb - ta
    al, be = _mobius_a(_rate(ct, Lc, kt, ta + GAUSS0 * d), _rate(ct, Lc, kt, ta + GAUSS1 * d), d)
    D = be.conjugate() * z + al.conjugate()
    return _cdiv(al * z + be, D), _cdiv((al * al.conjugate()).real - (be * be.conjugate()).real, D * D)


@njit(cache=True, error_model="numpy")
def _slip_rate(ct, Lc, kt, z, t):
    return kt * (z.conjugate() * _dpoly(ct, t)).real - _dpoly(Lc, t)


@njit(cache=True, error_model="numpy")
def _excess(ct, Lc, kt, w, t):
    return abs(kt * (_poly(ct, t) - w)) - _poly(Lc, t)


@njit(cache=True, error_model="numpy")
def _fun(kind, ct, Nc, Lc, kt, w, h, t0, t):
    """Value and t-derivative of a switch condition (friction's _close_fun, _excess_fun,
    _stop_fun)."""
    if kind == _CLOSE:
        return _poly(Nc, t), _dpoly(Nc, t)
    if kind == _EXCESS:
        d = _poly(ct, t) - w
        ad = abs(d)
        return (kt * ad - _poly(Lc, t),
                kt * (d.conjugate() * _dpoly(ct, t)).real / (ad + (1.0 if ad == 0 else 0.0))
                - _dpoly(Lc, t))
    D = 1.0 - t0
    return -_poly(h, (t - t0) / D), -_dpoly(h, (t - t0) / D) / D


@njit(cache=True, error_model="numpy")
def _root(kind, ct, Nc, Lc, kt, w, h, t0, lo, hi, flo, fhi):
    """friction._root_scalar on the condition ``kind``."""
    den = flo - fhi
    if den < 0:
        t = lo + (hi - lo) * min(max(flo / den, 0.01), 0.99)
    else:
        t = lo + (hi - lo) * 0.5
    for _ in range(ROOT_ITER):
        f, df = _fun(kind, ct, Nc, Lc, kt, w, h, t0, t)
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


@njit(cache=True, error_model="numpy")
def _stop_quadratic(ct, Lc, kt, z, t0, z1, rate0, rate1):
    tm = 0.5 * (t0 + 1.0)
    zm, _ = _magnus_k(ct, Lc, kt, z, t0, tm)
    rm = _slip_rate(ct, Lc, kt, zm, tm)
    h = np.empty(4)
    h[0], h[1], h[2], h[3] = rate0, 4.0 * rm - 3.0 * rate0 - rate1, 2.0 * (rate0 + rate1) - 4.0 * rm, 0.0
    return h


@njit(cache=True, error_model="numpy")
def _horner(a, t):
    v = a[a.size - 1]
    for k in range(a.size - 2, -1, -1):
        v = v * t + a[k]
    return v


@njit(cache=True, error_model="numpy")
def _stick_peak(a, ct, Lc, kt, w, t0):
    """friction._stick_peak_scalar."""
    G = np.empty(PEAK_GRID + 1)
    tg = np.empty(PEAK_GRID + 1)
    m = 0
    for i in range(PEAK_GRID + 1):
        tg[i] = t0 + (1.0 - t0) * (i / PEAK_GRID)
        G[i] = _horner(a, tg[i])
        if G[i] > G[m]:
            m = i
    t = tg[m]
    lo, hi = tg[max(m - 1, 0)], tg[min(m + 1, PEAK_GRID)]
    a1 = np.empty(6)
    for k in range(1, 7):
        a1[k - 1] = a[k] * k
    a2 = np.empty(5)
    for k in range(1, 6):
        a2[k - 1] = a1[k] * k
    for _ in range(8):
        g2 = _horner(a2, t)
        step = _horner(a1, t) / g2 if g2 < 0.0 else 0.0
        tn = min(max(t - step, lo), hi)
        if abs(tn - t) <= ROOT_TOL:
            t = tn
            break
        t = tn
    if not _horner(a, t) > G[m]:
        t = tg[m]
    L = _poly(Lc, t)
    over = kt * abs(_poly(ct, t) - w) - L > PEAK_TOL * max(max(L, _poly(Lc, 1.0)), 1e-300)
    return over, t


@njit(cache=True, error_model="numpy")
def _stick_over(ct, Lc, kt, w, t0):
    """friction._stick_over_scalar: (over, tpk); (False, 1.0) when certainly clear."""
    d = np.empty(4, dtype=np.complex128)
    d[0], d[1], d[2], d[3] = ct[0] - w, ct[1], ct[2], ct[3]
    if t0 == 0.0 and kt * (abs(d[0]) + abs(d[1]) + abs(d[2]) + abs(d[3])) <= (
            Lc[0] - abs(Lc[1]) - abs(Lc[2]) - abs(Lc[3])):
        return False, 1.0
    k2 = kt * kt
    a = np.zeros(7)
    for i in range(4):
        for j in range(4):
            a[i + j] += k2 * (d[i] * d[j].conjugate()).real - Lc[i] * Lc[j]
    if t0 == 0.0:
        mx = -np.inf
        for k in range(7):
            s = 0.0
            for i in range(k + 1):
                s += BERN[k, i] * a[i]
            mx = max(mx, s)
        if mx <= 0.0:
            return False, 1.0
    return _stick_peak(a, ct, Lc, kt, w, t0)


@njit(cache=True, error_model="numpy")
def _event(ct, Nc, Lc, kt, w, mode, tlo, u1, L1, codes, taus):
    """friction._event_scalar: one step with switches. Writes the switch codes and times into
    codes, taus (MAX_SWITCH,); returns (w, slipped, p, q)."""
    t, z, slipped = 0.0, 0j, mode == M_SLIP
    p, q = 0j, 0j
    noh = np.zeros(4)
    if mode == M_STICK:
        p = 1.0 + 0j
    elif slipped:
        T0 = kt * (ct[0] - w)
        r0 = abs(T0)
        z = _cdiv(T0, r0)
        p = -kt / (2.0 * r0) + 0j
        q = -p * z * z
    n = 0
    while n < MAX_SWITCH:
        if mode == M_OPEN:
            t = _root(_CLOSE, ct, Nc, Lc, kt, w, noh, 0.0, tlo, 1.0, _poly(Nc, tlo), _poly(Nc, 1.0))
            pd = _dpoly(ct, t)
            p = 0j
            q = 0j
            if kt * abs(pd) > _dpoly(Lc, t):
                mode, z, code, slipped = M_SLIP, _cdiv(pd, abs(pd)), SW_OPEN_SLIP, True
            else:
                mode, w, code = M_STICK, _poly(ct, t), SW_OPEN_STICK
        elif mode == M_STICK:
            peak, tpk = _stick_over(ct, Lc, kt, w, t)
            thi = tpk if peak else 1.0
            if abs(kt * (u1 - w)) <= L1 and not peak:
                return w, slipped, p, q
            f0 = _excess(ct, Lc, kt, w, t)
            code = SW_STICK_SLIP_AT if f0 > EDGE_TOL * L1 else SW_STICK_SLIP
            if code == SW_STICK_SLIP:
                t = _root(_EXCESS, ct, Nc, Lc, kt, w, noh, 0.0, t, thi, min(f0, 0.0),
                          max(_excess(ct, Lc, kt, w, thi), 0.0))
            d = _poly(ct, t) - w
            ad = abs(d)
            mode, z, slipped = M_SLIP, _cdiv(d, ad), True
            p, q = _cdiv(-(p - z * z * q.conjugate()), 2.0 * ad), _cdiv(-(q - z * z * p.conjugate()), 2.0 * ad)
        else:
            z1, K1 = _magnus_k(ct, Lc, kt, z, t, 1.0)
            rate1 = _slip_rate(ct, Lc, kt, z1, 1.0)
            if rate1 > 0:
                f = -(L1 / kt) * K1
                return u1 - (L1 / kt) * z1, slipped, f * p, f * q
            rate0 = _slip_rate(ct, Lc, kt, z, t)
            code = SW_SLIP_STICK_AT if rate0 <= 0 else SW_SLIP_STICK
            if rate0 > 0:
                h = _stop_quadratic(ct, Lc, kt, z, t, z1, rate0, rate1)
                tr = _root(_STOP, ct, Nc, Lc, kt, w, h, t, t, 1.0, -rate0, -rate1)
                z, K = _magnus_k(ct, Lc, kt, z, t, tr)
                t, p, q = tr, K * p, K * q
            L = _poly(Lc, t)
            mode, w, p, q = M_STICK, _poly(ct, t) - L * z / kt, -(L / kt) * p, -(L / kt) * q
        codes[n] = code
        taus[n] = t
        n += 1
    if mode == M_SLIP:
        z1, K1 = _magnus_k(ct, Lc, kt, z, t, 1.0)
        f = -(L1 / kt) * K1
        w, p, q = u1 - (L1 / kt) * z1, f * p, f * q
    return w, slipped, p, q


@njit(cache=True, error_model="numpy")
def _steps(kt, ut, tcl, L, al, be, pe, Lpe, bad, tlo, ct, Nc, Lc, w,
           code, wst, slip, mode0, AP, AQ, evc, evt):
    """friction._steps_scalar for one element over one period; fills its record rows and
    returns the end slider."""
    nt = ut.size
    for j in range(nt):
        wst[j] = w
        code[j] = STICK_STEP
        slip[j] = False
        jm = (j - 1) % nt
        if not tcl[j]:
            code[j] = OPEN_STEP
            w = ut[j]
            continue
        if tcl[jm] and not bad[j]:
            T0 = kt * (ut[jm] - w)
            r0 = abs(T0)
            if r0 >= L[jm] * (1.0 - SLIP_TOL):
                z0, a, b = _cdiv(T0, r0), al[j], be[j]
                z1 = _cdiv(a * z0 + b, b.conjugate() * z0 + a.conjugate())
                if kt * (z1.conjugate() * pe[j]).real > Lpe[j]:
                    code[j] = SLIP_STEP
                    slip[j] = True
                    w = ut[j] - (L[j] / kt) * z1
                    continue
                mode = M_SLIP
            elif abs(kt * (ut[j] - w)) <= L[j] and not _stick_over(ct[j], Lc[j], kt, w, 0.0)[0]:
                continue
            else:
                mode = M_STICK
        else:
            mode = M_OPEN
        code[j] = EVENT_STEP
        mode0[j] = mode
        w, sl, p, q = _event(ct[j], Nc[j], Lc[j], kt, w, mode, tlo[j], ut[j], L[j], evc[j], evt[j])
        slip[j] = sl
        AP[j] = p
        AQ[j] = q
    return w


@njit(cache=True, error_model="numpy")
def cycle(rows, w, kt, ut, tcl, L, al, be, pe, Lpe, bad, tlo, ct, Nc, Lc,
          code, wst, slip, mode0, AP, AQ, evc, evt, wend):
    """March one period of the elements ``rows`` (of the step tables) from their sliders w,
    filling the record arrays (first axis: position in rows; evc/evt/AP/AQ/mode0 written only
    at switching steps, so they must come initialized as friction._Record does)."""
    for i in range(rows.size):
        g = rows[i]
        wend[i] = _steps(kt[g], ut[g], tcl[g], L[g], al[g], be[g], pe[g], Lpe[g], bad[g], tlo[g],
                         ct[g], Nc[g], Lc[g], w[i], code[i], wst[i], slip[i], mode0[i], AP[i],
                         AQ[i], evc[i], evt[i])


# ============================================================================ Jacobian
# friction._march_jacobian's per-element work compiled: each step's derivative (the hand-coded
# full-step slip of _slip_jacobians, the forward-mode replay of _replay for switching steps) and
# its propagation through the period (_sources, _propagate), one element at a time. In numpy these
# were batched over elements but cost a few hundred numpy calls per batch, and the replay's
# dual numbers one numpy call per arithmetic operation.

#: derivative slots of a replayed step (friction.NSLOT): Re w, Im w, u_t1, u_t2, u_n of the 4
#: stencil samples, tau; a dual number is a complex row (NS,): value, then the slots
NSLOT = 15
NS = NSLOT + 1
#: friction._VINV: power coefficients of the cubic through the samples at tau = -1, 0, 1, 2
VINV = np.array([[0.0, 1.0, 0.0, 0.0],
                 [-1.0 / 3.0, -0.5, 1.0, -1.0 / 6.0],
                 [0.5, -1.0, 0.5, 0.0],
                 [-1.0 / 6.0, 0.5, -0.5, 1.0 / 6.0]])
#: friction._LG, _DLG: Lagrange weights l_m and l_m' of the stencil samples at the Gauss points
LG = np.array([[g ** i for i in range(4)] for g in (GAUSS0, GAUSS1)]) @ VINV
DLG = np.array([[i * g ** (i - 1) if i else 0.0 for i in range(4)] for g in (GAUSS0, GAUSS1)]) @ VINV


@njit(cache=True, error_model="numpy")
def _cs_deriv(x: float) -> tuple:
    """friction._cs_array(x, deriv=True) for one float: (c, s, dc/dx, ds/dx)."""
    r = math.sqrt(abs(x))
    small = r < 1e-2
    th = math.tanh(r)
    sp = 1.0 + x * (-1.0 / 3.0 + x * (2.0 / 15.0)) if small else th / r
    cn = math.cos(r)
    sn = math.sin(r) / r if r > 0.0 else 1.0
    xs = 1.0 if small else x
    if x >= 0.0:
        dsp = -1.0 / 3.0 + x * (4.0 / 15.0 - x * 17.0 / 105.0) if small else (1.0 - th * th - sp) / (2.0 * xs)
        return 1.0, sp, 0.0, dsp
    dsn = 1.0 / 6.0 + x * (1.0 / 60.0 + x / 1680.0) if small else (cn - sn) / (2.0 * xs)
    return cn, sn, 0.5 * sn, dsn


@njit(cache=True, error_model="numpy")
def _slip_jac(kt: float, mukn: float, Lg0: float, Lg1: float, pg0: complex, pg1: complex,
              u0: complex, w: complex, Lj: float, A: np.ndarray, G: np.ndarray) -> None:
    """friction._slip_jacobians for one full-step slip: fills A (2, 2) = d w_j / d w_{j-1} and
    G (2, 3, 4) = d w_j / d(u_t1, u_t2, u_n of the stencil samples), w as (Re, Im).

    Args:
        kt: N/mm. mukn: mu kn, N/mm. Lg0, Lg1: limit at the Gauss points, N. pg0, pg1: u_t' there
        (complex, mm per unit tau). u0: u_t at the step start, mm. w: slider at the start, mm.
        Lj: limit at the step end, N.
    """
    a1, a2 = _cdiv(0.5 * kt * pg0, Lg0), _cdiv(0.5 * kt * pg1, Lg1)
    Am = 0.5 * (a1 + a2)
    gam = S6 * (a2 * a1.conjugate()).imag
    c, s, dc, ds = _cs_deriv((Am * Am.conjugate()).real - gam * gam)
    al, be = c + 1j * s * gam, s * Am
    T0 = kt * (u0 - w)
    r0 = abs(T0)
    z0 = _cdiv(T0, r0)
    D = be.conjugate() * z0 + al.conjugate()
    z1 = _cdiv(al * z0 + be, D)
    K0 = _cdiv((al * al.conjugate()).real - (be * be.conjugate()).real, D ** 2)
    ax = dc + 1j * ds * gam                                     # d al / dx, d be / dx
    Kx = _cdiv(ax * z0 + ds * Am - z1 * z0 * ds * Am.conjugate() - z1 * ax.conjugate(), D)
    PA = _cdiv(s, D) + Kx * Am.conjugate()                      # dz1 = PA dA + QA conj(dA)
    QA = _cdiv(-z1 * z0 * s, D) + Kx * Am
    h = (0.5j * S6) * (_cdiv(1j * s * (z0 + z1), D) - 2.0 * gam * Kx)
    P0, P1 = 0.5 * PA + h * a2.conjugate(), 0.5 * PA - h * a1.conjugate()   # of da_g
    Q0, Q1 = 0.5 * QA - h * a2, 0.5 * QA + h * a1                           # of conj(da_g)
    ka0, ka1 = 0.5 * kt / Lg0, 0.5 * kt / Lg1                               # da_g / dp'_g
    R0, R1 = _cdiv(-(P0 * a1 + Q0 * a1.conjugate()), Lg0), _cdiv(-(P1 * a2 + Q1 * a2.conjugate()), Lg1)
    Pw, Qw = _cdiv(-kt * K0, 2.0 * r0), _cdiv(kt * K0 * z0 ** 2, 2.0 * r0)  # through z0 = T0/|T0|
    f = -Lj / kt                                                            # w_j = u_j - L_j z1 / kt
    for m in range(4):
        Pu = (P0 * ka0) * DLG[0, m] + (P1 * ka1) * DLG[1, m]
        Qu = (Q0 * ka0) * DLG[0, m] + (Q1 * ka1) * DLG[1, m]
        Rn = (R0 * LG[0, m] + R1 * LG[1, m]) * mukn
        if m == 1:
            Pu, Qu = Pu - Pw, Qu - Qw
        Pu, Qu, Rn = f * Pu, f * Qu, f * Rn
        if m == 2:
            Pu += 1.0
            Rn -= z1 * mukn / kt
        c0, c1 = Pu + Qu, 1j * (Pu - Qu)                        # friction._to_real
        G[0, 0, m], G[0, 1, m], G[1, 0, m], G[1, 1, m] = c0.real, c1.real, c0.imag, c1.imag
        G[0, 2, m], G[1, 2, m] = Rn.real, Rn.imag
    c0, c1 = f * Pw + f * Qw, 1j * (f * Pw - f * Qw)
    A[0, 0], A[0, 1], A[1, 0], A[1, 1] = c0.real, c1.real, c0.imag, c1.imag


# ---------------------------------------------------------------------------- dual numbers
# friction._Dual's operations on duals that are rows (value, then the NSLOT derivative slots) of
# a workspace ``ws = (W, n)``: W (WS_ROWS, NS) complex, n[0] its next free row, reset for each
# step. A dual is its row index; a cubic's coefficients are 4 consecutive rows, named by the
# first. Every operation writes a fresh row: allocating each intermediate (~0.1 µs) or viewing
# it (~0.03 µs) cost more than its arithmetic. The derivative formulas and their operand order
# are _Dual's (the compiled Jacobian is numpy's to ~1e-13). Loops, not array expressions: numba
# compiles each array expression into its own kernel (the replay's took a minute to compile).
#: workspace rows; a replayed step takes at most ~610 (slip -> stick -> slip -> stick)
WS_ROWS = 2048


@njit(cache=True, error_model="numpy")
def workspace() -> tuple:
    """A dual-number workspace (W, n) for _event_jac."""
    return np.empty((WS_ROWS, NS), dtype=np.complex128), np.zeros(1, dtype=np.int64)


@njit(cache=True, error_model="numpy")
def _new(ws: tuple, m: int) -> int:
    """Index of m fresh consecutive rows of ws."""
    W, n = ws
    i = n[0]
    if i + m > W.shape[0]:
        raise RuntimeError("friction_jit: dual workspace exhausted (raise WS_ROWS)")
    n[0] = i + m
    return i


@njit(cache=True, error_model="numpy")
def _dk(ws: tuple, v: complex) -> int:
    """The constant v as a dual."""
    W, x = ws[0], _new(ws, 1)
    W[x, :] = 0.0
    W[x, 0] = v
    return x


@njit(cache=True, error_model="numpy")
def _dadd(ws: tuple, a: int, b: int) -> int:
    """a + b."""
    W, x = ws[0], _new(ws, 1)
    for i in range(NS):
        W[x, i] = W[a, i] + W[b, i]
    return x


@njit(cache=True, error_model="numpy")
def _dsub(ws: tuple, a: int, b: int) -> int:
    """a - b."""
    W, x = ws[0], _new(ws, 1)
    for i in range(NS):
        W[x, i] = W[a, i] - W[b, i]
    return x


@njit(cache=True, error_model="numpy")
def _dsc(ws: tuple, c: complex, a: int) -> int:
    """c a for a plain number c."""
    W, x = ws[0], _new(ws, 1)
    for i in range(NS):
        W[x, i] = W[a, i] * c
    return x


@njit(cache=True, error_model="numpy")
def _dquo(ws: tuple, a: int, c: float) -> int:
    """a / c for a plain number c."""
    W, x = ws[0], _new(ws, 1)
    for i in range(NS):
        W[x, i] = _cdiv(W[a, i], c)
    return x


@njit(cache=True, error_model="numpy")
def _dplus(ws: tuple, a: int, c: float) -> int:
    """a + c for a plain number c."""
    W, x = ws[0], _new(ws, 1)
    for i in range(NS):
        W[x, i] = W[a, i]
    W[x, 0] += c
    return x


@njit(cache=True, error_model="numpy")
def _dmul(ws: tuple, a: int, b: int) -> int:
    """a b."""
    W, x = ws[0], _new(ws, 1)
    va, vb = W[a, 0], W[b, 0]
    W[x, 0] = va * vb
    for i in range(1, NS):
        W[x, i] = W[a, i] * vb + W[b, i] * va
    return x


@njit(cache=True, error_model="numpy")
def _ddiv(ws: tuple, a: int, b: int) -> int:
    """a / b."""
    W, x = ws[0], _new(ws, 1)
    vb = W[b, 0]
    q = _cdiv(W[a, 0], vb)
    W[x, 0] = q
    for i in range(1, NS):
        W[x, i] = _cdiv(W[a, i] - W[b, i] * q, vb)
    return x


@njit(cache=True, error_model="numpy")
def _dconj(ws: tuple, a: int) -> int:
    """conj(a)."""
    W, x = ws[0], _new(ws, 1)
    for i in range(NS):
        W[x, i] = W[a, i].conjugate()
    return x


@njit(cache=True, error_model="numpy")
def _dabs(ws: tuple, a: int) -> int:
    """|a| (a real dual)."""
    W, x = ws[0], _new(ws, 1)
    va = W[a, 0]
    r = abs(va)
    W[x, 0] = r
    for i in range(1, NS):
        W[x, i] = (va.conjugate() * W[a, i]).real / r
    return x


@njit(cache=True, error_model="numpy")
def _dre(ws: tuple, a: int) -> int:
    """Re a."""
    W, x = ws[0], _new(ws, 1)
    for i in range(NS):
        W[x, i] = W[a, i].real
    return x


@njit(cache=True, error_model="numpy")
def _dim(ws: tuple, a: int) -> int:
    """Im a."""
    W, x = ws[0], _new(ws, 1)
    for i in range(NS):
        W[x, i] = W[a, i].imag
    return x


@njit(cache=True, error_model="numpy")
def _xpoly(ws: tuple, c: int, t: int) -> int:
    """friction._poly on duals (c: the cubic's first row, t)."""
    return _dadd(ws, c, _dmul(ws, t, _dadd(ws, c + 1, _dmul(ws, t, _dadd(ws, c + 2, _dmul(ws, t, c + 3))))))


@njit(cache=True, error_model="numpy")
def _xdpoly(ws: tuple, c: int, t: int) -> int:
    """friction._dpoly on duals."""
    return _dadd(ws, c + 1, _dmul(ws, t, _dadd(ws, _dsc(ws, 2.0, c + 2), _dmul(ws, t, _dsc(ws, 3.0, c + 3)))))


@njit(cache=True, error_model="numpy")
def _xcs(ws: tuple, x: int) -> tuple:
    """friction._cs on a (real) dual: (c, s)."""
    W = ws[0]
    c, s, dc, ds = _cs_deriv(W[x, 0].real)
    cd, sd = _dsc(ws, dc, x), _dsc(ws, ds, x)
    W[cd, 0], W[sd, 0] = c, s
    return cd, sd


@njit(cache=True, error_model="numpy")
def _xmobius_a(ws: tuple, a1: int, a2: int, d: int) -> tuple:
    """friction._mobius_a on duals."""
    A = _dmul(ws, _dsc(ws, 0.5, d), _dadd(ws, a1, a2))
    gam = _dmul(ws, _dmul(ws, _dsc(ws, S6, d), d), _dim(ws, _dmul(ws, a2, _dconj(ws, a1))))
    c, s = _xcs(ws, _dsub(ws, _dre(ws, _dmul(ws, A, _dconj(ws, A))), _dmul(ws, gam, gam)))
    return _dadd(ws, c, _dsc(ws, 1j, _dmul(ws, s, gam))), _dmul(ws, s, A)


@njit(cache=True, error_model="numpy")
def _xrate(ws: tuple, ct: int, Lc: int, kt: float, t: int) -> int:
    """friction._rate on duals."""
    return _ddiv(ws, _dsc(ws, kt, _xdpoly(ws, ct, t)), _dsc(ws, 2.0, _xpoly(ws, Lc, t)))


@njit(cache=True, error_model="numpy")
def _xmagnus(ws: tuple, ct: int, Lc: int, kt: float, z: int, ta: int, tb: int) -> int:
    """friction._magnus on duals."""
    d = _dsub(ws, tb, ta)
    al, be = _xmobius_a(ws, _xrate(ws, ct, Lc, kt, _dadd(ws, ta, _dsc(ws, GAUSS0, d))),
                        _xrate(ws, ct, Lc, kt, _dadd(ws, ta, _dsc(ws, GAUSS1, d))), d)
    return _ddiv(ws, _dadd(ws, _dmul(ws, al, z), be), _dadd(ws, _dmul(ws, _dconj(ws, be), z), _dconj(ws, al)))


@njit(cache=True, error_model="numpy")
def _xslip_rate(ws: tuple, ct: int, Lc: int, kt: float, z: int, t: int) -> int:
    """friction._slip_rate on duals."""
    return _dsub(ws, _dsc(ws, kt, _dre(ws, _dmul(ws, _dconj(ws, z), _xdpoly(ws, ct, t)))), _xdpoly(ws, Lc, t))


@njit(cache=True, error_model="numpy")
def _xexcess(ws: tuple, ct: int, Lc: int, kt: float, w: int, t: int) -> int:
    """friction._excess on duals."""
    return _dsub(ws, _dabs(ws, _dsc(ws, kt, _dsub(ws, _xpoly(ws, ct, t), w))), _xpoly(ws, Lc, t))


@njit(cache=True, error_model="numpy")
def _xstop_quadratic(ws: tuple, ct: int, Lc: int, kt: float, z: int, t0: int, rate0: int,
                     rate1: int) -> int:
    """friction._stop_quadratic on duals: the coefficients' first row."""
    tm = _dsc(ws, 0.5, _dplus(ws, t0, 1.0))
    rm = _xslip_rate(ws, ct, Lc, kt, _xmagnus(ws, ct, Lc, kt, z, t0, tm), tm)
    h1 = _dsub(ws, _dsub(ws, _dsc(ws, 4.0, rm), _dsc(ws, 3.0, rate0)), rate1)
    h2 = _dsub(ws, _dsc(ws, 2.0, _dadd(ws, rate0, rate1)), _dsc(ws, 4.0, rm))
    h3 = _dsc(ws, 0.0, rate0)
    W, h = ws[0], _new(ws, 4)
    W[h], W[h + 1], W[h + 2], W[h + 3] = W[rate0], W[h1], W[h2], W[h3]
    return h


@njit(cache=True, error_model="numpy")
def _ximplicit(ws: tuple, kind: int, ct: int, Nc: int, Lc: int, kt: float, w: int, h: int, ta: int,
               tau: float) -> int:
    """friction._implicit: the switch time tau (a root of the condition ``kind``) as a dual,
    dtau = -f_x / f_tau (f_tau from the tau slot, which the result leaves zero)."""
    W = ws[0]
    x = _dk(ws, tau)
    W[x, NSLOT] = 1.0
    if kind == _CLOSE:
        f = _xpoly(ws, Nc, x)
    elif kind == _EXCESS:
        f = _xexcess(ws, ct, Lc, kt, w, x)
    else:
        f = _xpoly(ws, h, _ddiv(ws, _dsub(ws, x, ta), _dplus(ws, _dsc(ws, -1.0, ta), 1.0)))
    ft = W[f, NSLOT].real if W[f, NSLOT].real != 0 else np.inf
    out = _dk(ws, tau)
    for i in range(1, NSLOT):
        W[out, i] = -W[f, i].real / ft
    return out


@njit(cache=True, error_model="numpy")
def _xreplay(ws: tuple, mode0: int, codes: np.ndarray, taus: np.ndarray, ct: int, Nc: int, Lc: int,
             kt: float, w: int, u1: int, L1: int) -> int:
    """friction._replay for one step: the end slider as a dual, following the recorded switches
    codes, taus (MAX_SWITCH,; zero-padded) from the start state mode0."""
    t, z, t1, mode = _dk(ws, 0.0), _dk(ws, 0.0), _dk(ws, 1.0), mode0
    if mode0 == M_SLIP:
        T0 = _dsc(ws, kt, _dsub(ws, ct, w))
        z = _ddiv(ws, T0, _dabs(ws, T0))
    for s in range(MAX_SWITCH):
        code = codes[s]
        if code == 0:
            break
        if code == SW_OPEN_STICK or code == SW_OPEN_SLIP:
            t = _ximplicit(ws, _CLOSE, ct, Nc, Lc, kt, w, -1, t, taus[s])
            if code == SW_OPEN_STICK:
                w, mode = _xpoly(ws, ct, t), M_STICK
            else:
                pd = _xdpoly(ws, ct, t)
                z, mode = _ddiv(ws, pd, _dabs(ws, pd)), M_SLIP
        elif code == SW_STICK_SLIP or code == SW_STICK_SLIP_AT:
            if code == SW_STICK_SLIP:
                t = _ximplicit(ws, _EXCESS, ct, Nc, Lc, kt, w, -1, t, taus[s])
            d = _dsub(ws, _xpoly(ws, ct, t), w)
            z, mode = _ddiv(ws, d, _dabs(ws, d)), M_SLIP
        else:
            if code == SW_SLIP_STICK:
                z1 = _xmagnus(ws, ct, Lc, kt, z, t, t1)
                h = _xstop_quadratic(ws, ct, Lc, kt, z, t, _xslip_rate(ws, ct, Lc, kt, z, t),
                                     _xslip_rate(ws, ct, Lc, kt, z1, t1))
                ta = t
                t = _ximplicit(ws, _STOP, ct, Nc, Lc, kt, w, h, ta, taus[s])
                z = _xmagnus(ws, ct, Lc, kt, z, ta, t)
            w, mode = _dsub(ws, _xpoly(ws, ct, t), _dquo(ws, _dmul(ws, _xpoly(ws, Lc, t), z), kt)), M_STICK
    if mode == M_STICK:
        return w
    return _dsub(ws, u1, _dquo(ws, _dmul(ws, L1, _xmagnus(ws, ct, Lc, kt, z, t, t1)), kt))


@njit(cache=True, error_model="numpy")
def _event_jac(ws: tuple, ct: np.ndarray, Nc: np.ndarray, kt: float, mu: float, kn: float, w: complex,
               u1: complex, L1: float, mode0: int, codes: np.ndarray, taus: np.ndarray, A: np.ndarray,
               G: np.ndarray) -> None:
    """friction._event_jacobians for one switching step (A, G as _slip_jac): the replay seeded
    as friction._seeds (slots Re w, Im w, u_t1, u_t2, u_n of the stencil samples, tau)."""
    W, n = ws
    n[0] = 0
    wd, u1d, L1d = _dk(ws, w), _dk(ws, u1), _dk(ws, L1)
    W[wd, 1], W[wd, 2] = 1.0, 1j
    W[u1d, 5], W[u1d, 9], W[L1d, 13] = 1.0, 1j, mu * kn
    ctd, Ncd = _new(ws, 4), _new(ws, 4)
    W[ctd:ctd + 4] = 0.0
    W[Ncd:Ncd + 4] = 0.0
    for i in range(4):
        W[ctd + i, 0], W[Ncd + i, 0] = ct[i], Nc[i]
        for m in range(4):
            W[ctd + i, 3 + m], W[ctd + i, 7 + m] = VINV[i, m], 1j * VINV[i, m]
            W[Ncd + i, 11 + m] = kn * VINV[i, m]
    Lcd = _new(ws, 4)
    for i in range(4):
        W[Lcd + i] = W[_dsc(ws, mu, Ncd + i)]
    d = _xreplay(ws, mode0, codes, taus, ctd, Ncd, Lcd, kt, wd, u1d, L1d)
    A[0, 0], A[0, 1], A[1, 0], A[1, 1] = W[d, 1].real, W[d, 2].real, W[d, 1].imag, W[d, 2].imag
    for r in range(3):
        for m in range(4):
            G[0, r, m], G[1, r, m] = W[d, 3 + 4 * r + m].real, W[d, 3 + 4 * r + m].imag


@njit(cache=True, error_model="numpy")
def _step(ws: tuple, i: int, e: int, j: int, kt, mu, kn, ut, L, Lg, pg, ct, Nc, code, wst, mode0,
          evc, evt, A: np.ndarray, G: np.ndarray) -> None:
    """Derivatives A, G (see _slip_jac) of step j of record row i (step tables row e), a slip
    or switching step."""
    if code[i, j] == SLIP_STEP:
        _slip_jac(kt[e], mu[e] * kn[e], Lg[e, j, 0], Lg[e, j, 1], pg[e, j, 0], pg[e, j, 1],
                  ut[e, j - 1], wst[i, j], L[e, j], A, G)
    else:
        _event_jac(ws, ct[e, j], Nc[e, j], kt[e], mu[e], kn[e], wst[i, j], ut[e, j], L[e, j],
                   mode0[i, j], evc[i, j], evt[i, j], A, G)


@njit(cache=True, error_model="numpy")
def _propagate(j: int, A: np.ndarray, G: np.ndarray, E: np.ndarray, P: np.ndarray, D: np.ndarray,
               P2: np.ndarray, D2: np.ndarray, S: np.ndarray) -> None:
    """One step of friction._propagate: (P2, D2) = A (P, D) + (0, G (x) E of the stencil of step
    j) (friction._sources), harmonics in the element layout direction * nH + harmonic."""
    nt, nH = E.shape
    S[:] = 0.0
    for m in range(4):
        Em = E[(j - 2 + m) % nt]
        for r in range(2):
            for dd in range(3):
                g = G[r, dd, m]
                for x in range(nH):
                    S[r, dd * nH + x] += g * Em[x]
    for r in range(2):
        for x in range(3 * nH):
            D2[r, x] = A[r, 0] * D[0, x] + A[r, 1] * D[1, x] + S[r, x]
        for c in range(2):
            P2[r, c] = A[r, 0] * P[0, c] + A[r, 1] * P[1, c]


@njit(cache=True, error_model="numpy")
def sensitivities(g: np.ndarray, kt, mu, kn, ut, L, Lg, pg, ct, Nc, code, wst, mode0, evc, evt,
                  E: np.ndarray, full: bool, Ps: np.ndarray, Ds: np.ndarray) -> None:
    """Slider sensitivities of recorded periods (friction._local_jacobians, _sources and
    _propagate compiled), one record row at a time: after step j, dw_j = Ps[j] dw_0 + Ds[j].

    Args:
        g: (k,) step-table row of each record row. kt, mu, kn, ut, L, Lg, pg, ct, Nc: the step
            tables (friction._StepTables). code, wst, mode0, evc, evt: the records (k, nt, ...).
        E: (nt, nH) inverse DFT. full: snapshots after every step, else after the last only.
        Ps, Ds: outputs (k, nt or 1, 2, 2) and (k, 2, nt or 1, 3 nH) (laid out as the force
            sensitivities, see force_sensitivities), mm per mm of harmonic, harmonics in the
            element layout direction * nH + harmonic.
    """
    ws, bufs = workspace(), _buffers(E.shape[1])
    for i in range(g.size):
        _row_sensitivities(ws, bufs, i, g[i], kt, mu, kn, ut, L, Lg, pg, ct, Nc, code, wst, mode0,
                           evc, evt, E, full, Ps, Ds)


@njit(cache=True, error_model="numpy")
def _buffers(nH: int) -> tuple:
    """Scratch arrays of _row_sensitivities: P, D, P2, D2, A, G, S."""
    return (np.empty((2, 2)), np.empty((2, 3 * nH)), np.empty((2, 2)), np.empty((2, 3 * nH)),
            np.empty((2, 2)), np.empty((2, 3, 4)), np.empty((2, 3 * nH)))


@njit(cache=True, error_model="numpy")
def _row_sensitivities(ws: tuple, bufs: tuple, i: int, e: int, kt, mu, kn, ut, L, Lg, pg, ct, Nc,
                       code, wst, mode0, evc, evt, E: np.ndarray, full: bool, Ps: np.ndarray,
                       Ds: np.ndarray) -> None:
    """:func:`sensitivities` of record row i (step tables row e)."""
    nt, nH = E.shape
    P, D, P2, D2, A, G, S = bufs
    P[:] = 0.0
    P[0, 0] = P[1, 1] = 1.0
    D[:] = 0.0
    for j in range(nt):
        if code[i, j] == OPEN_STEP:                # w_j = u_j: forgets the start
            P[:] = 0.0
            D[:] = 0.0
            D[0, 0:nH], D[1, nH:2 * nH] = E[j], E[j]
        elif code[i, j] != STICK_STEP:             # (stick: A = I, no source)
            _step(ws, i, e, j, kt, mu, kn, ut, L, Lg, pg, ct, Nc, code, wst, mode0, evc,
                  evt, A, G)
            _propagate(j, A, G, E, P, D, P2, D2, S)
            P, P2, D, D2 = P2, P, D2, D
        if full or j == nt - 1:
            jj = j if full else 0
            Ps[i, jj] = P
            Ds[i, 0, jj], Ds[i, 1, jj] = D[0], D[1]


# ============================================================================ plain repetition
#: repeat's outcomes
CLOSED, GAVE_UP, BUDGET_SPENT = 0, 1, 2


@njit(cache=True, error_model="numpy")
def repeat(kt, mu, kn, ut, tcl, L, al, be, pe, Lpe, bad, tlo, ct, Nc, Lc, Lg, pg, scale,
           close_tol: float, max_cycles: int, give_up_after: int, give_up_margin: float,
           E: np.ndarray, jacobian: bool, code, wst, slip, mode0, AP, AQ, evc, evt, wend,
           cyc, dwh, info) -> int:
    """Plain repetition from rest of every element of the step tables (friction's march with
    ``newton=False``) in one call: period after period, each element until its cycle closes
    (|w_end - w_start| <= close_tol * scale). The elements go in lockstep, so the give-up test
    (friction._give_up_if_slow) sees the same elements at the same period as the numpy loop;
    the Python loop paid ~150 µs of bookkeeping per period, and a neutral element may need
    thousands.

    Args:
        kt ... pg, scale: the step tables (friction._StepTables), k elements.
        close_tol, max_cycles: closure tolerance (relative to scale) and period budget.
        give_up_after, give_up_margin: friction.GIVE_UP_AFTER, friction.GIVE_UP_MARGIN.
        E: (nt, nH) inverse DFT (read only with jacobian).
        jacobian: also propagate the slider sensitivity from rest through the periods before
            the closing one (friction._neutral_history, the same recurrence in the same order).
        code ... wend: record arrays (friction._Record, k rows), filled with each element's
            closing period.
        cyc: (k,) periods marched per element. dwh: (k, 2, 3 nH) the propagated sensitivity
            (zero without jacobian). info: (2,) the largest contraction per period and closure
            error of the elements still open when the march stopped.
    Returns:
        CLOSED, GAVE_UP (predicted not to close within give_up_margin * max_cycles) or
        BUDGET_SPENT.
    """
    k = kt.size
    nt, nH = E.shape
    w = np.zeros(k, dtype=np.complex128)
    dev, prev = np.zeros(k), np.zeros(k)
    is_open = np.ones(k, dtype=np.bool_)
    ws, bufs = workspace(), _buffers(nH)
    Ps, Ds = np.empty((k, 1, 2, 2)), np.empty((k, 2, 1, 3 * nH))
    dwh[:] = 0.0
    n_open, cycle = k, 0
    while n_open > 0 and cycle < max_cycles:
        cycle += 1
        for i in range(k):
            if not is_open[i]:
                continue
            # a fresh record row, as friction._Record makes one per period (the switch fields
            # are written at switching steps only)
            mode0[i, :] = 0
            evc[i, :, :] = 0
            evt[i, :, :] = 0.0
            AP[i, :] = 1.0
            AQ[i, :] = 0.0
            wend[i] = _steps(kt[i], ut[i], tcl[i], L[i], al[i], be[i], pe[i], Lpe[i], bad[i], tlo[i],
                             ct[i], Nc[i], Lc[i], w[i], code[i], wst[i], slip[i], mode0[i], AP[i],
                             AQ[i], evc[i], evt[i])
            cyc[i] = cycle
            prev[i], dev[i] = dev[i], abs(wend[i] - w[i]) / scale[i]
            if dev[i] <= close_tol:
                is_open[i] = False
                n_open -= 1
                continue
            if jacobian:               # a period before the closing one: chain its affine map
                _row_sensitivities(ws, bufs, i, i, kt, mu, kn, ut, L, Lg, pg, ct, Nc, code, wst,
                                   mode0, evc, evt, E, False, Ps, Ds)
                for x in range(3 * nH):
                    d0, d1 = dwh[i, 0, x], dwh[i, 1, x]
                    dwh[i, 0, x] = Ps[i, 0, 0, 0] * d0 + Ps[i, 0, 0, 1] * d1 + Ds[i, 0, 0, x]
                    dwh[i, 1, x] = Ps[i, 0, 1, 0] * d0 + Ps[i, 0, 1, 1] * d1 + Ds[i, 1, 0, x]
            w[i] = wend[i]
        if cycle >= give_up_after and n_open > 0:
            rho_max, dev_max, give_up = -np.inf, 0.0, False
            for i in range(k):
                if not is_open[i]:
                    continue
                rho = dev[i] / prev[i] if prev[i] > 0.0 else 1.0
                need = np.log(close_tol / max(dev[i], 1e-300)) / np.log(rho) if rho < 1.0 else np.inf
                give_up = give_up or cycle + need > give_up_margin * max_cycles
                rho_max, dev_max = max(rho_max, rho), max(dev_max, dev[i])
            if give_up:
                info[0], info[1] = rho_max, dev_max
                return GAVE_UP
    info[0], info[1] = 0.0, dev.max()
    return CLOSED if info[1] <= close_tol else BUDGET_SPENT


@njit(cache=True, error_model="numpy")
def step_jacobians(g: np.ndarray, kt, mu, kn, ut, L, Lg, pg, ct, Nc, code, wst, mode0, evc, evt,
                   A: np.ndarray, G: np.ndarray) -> None:
    """Every step's derivatives as friction._local_jacobians, A (k, nt, 2, 2), G (k, nt, 2, 3,
    4) (stick: I, 0; open: 0, the end sample); for tests (sensitivities works on the fly)."""
    ws = workspace()
    for i in range(g.size):
        for j in range(code.shape[1]):
            A[i, j] = 0.0
            G[i, j] = 0.0
            if code[i, j] == STICK_STEP:
                A[i, j, 0, 0] = A[i, j, 1, 1] = 1.0
            elif code[i, j] == OPEN_STEP:
                G[i, j, 0, 0, 2] = G[i, j, 1, 1, 2] = 1.0
            else:
                _step(ws, i, g[i], j, kt, mu, kn, ut, L, Lg, pg, ct, Nc, code, wst, mode0, evc,
                      evt, A[i, j], G[i, j])


@njit(cache=True, error_model="numpy")
def force_sensitivities(kt: np.ndarray, Ps: np.ndarray, dw0: np.ndarray, E: np.ndarray,
                        Ds: np.ndarray) -> None:
    """dT = kt (E_j - dw_j) with dw_j = Ps[:, j] dw0 + Ds[:, :, j] (friction._march_jacobian's
    last lines), written over Ds (k, 2, nt, 3 nH): N per mm of harmonic."""
    k, nt = Ps.shape[0], Ps.shape[1]
    nH = E.shape[1]
    for i in range(k):
        for r in range(2):
            for j in range(nt):
                for x in range(3 * nH):
                    dw = Ps[i, j, r, 0] * dw0[i, 0, x] + Ps[i, j, r, 1] * dw0[i, 1, x] + Ds[i, r, j, x]
                    ex = E[j, x - r * nH] if r * nH <= x < (r + 1) * nH else 0.0
                    Ds[i, r, j, x] = kt[i] * (ex - dw)


# ============================================================================ step tables
@njit(cache=True, error_model="numpy")
def _sinc_r(r: float) -> float:
    """sin r / r as friction._cs_array computes it (numpy's sinc of r / pi: the same bits)."""
    y = math.pi * (r / math.pi if r != 0.0 else 1.0e-20)
    return math.sin(y) / y


@njit(cache=True, error_model="numpy")
def _stencil_cubics(ue, nrow, j: int) -> tuple:
    """Power coefficients of the cubics through samples j-2..j+1 (friction._VINV, periodic) of
    one element's u_t = ue[0] + i ue[1] (4 complex) and of nrow (4 real): friction._StepTables'
    ct and Nc in numpy's summation order."""
    nt = nrow.size
    c0 = c1 = c2 = c3 = 0.0j
    n_0 = n_1 = n_2 = n_3 = 0.0
    for i in range(4):
        q = j + i - 2
        if q < 0:
            q += nt
        elif q >= nt:
            q -= nt
        x, xn = complex(ue[0, q], ue[1, q]), nrow[q]
        v0, v1, v2, v3 = VINV[0, i], VINV[1, i], VINV[2, i], VINV[3, i]
        # (x + 0 i) v: each part's product alone, as numpy's complex-by-real matmul
        c0 += complex(x.real * v0, x.imag * v0)
        c1 += complex(x.real * v1, x.imag * v1)
        c2 += complex(x.real * v2, x.imag * v2)
        c3 += complex(x.real * v3, x.imag * v3)
        n_0 += xn * v0
        n_1 += xn * v1
        n_2 += xn * v2
        n_3 += xn * v3
    return c0, c1, c2, c3, n_0, n_1, n_2, n_3


@njit(cache=True, error_model="numpy")
def step_tables(u, kt, mu, kn, n0, gap, ut, N, closed, tcl, L, ct, Nc, Lc, pg, Lg, bad, tlo, al,
                be, pe, Lpe, scale, det):
    """friction._StepTables' arrays for elements' samples u (k, 3, nt), filled in place (the
    attributes of the same names; the numpy constructor's formulas, one element and step at a
    time: its ~40 array operations over (k, nt, 4) cost 5.7 ms per residual on the resonator's
    top level, 7 % of a curve). The same numbers but for numpy's own tanh and cos (a few ulps
    in al, be, det)."""
    k, nt = ut.shape
    nraw = np.empty(nt)
    for e in range(k):
        m, kte = mu[e], kt[e]
        peak = 0.0
        for j in range(nt):
            ut[e, j] = complex(u[e, 0, j], u[e, 1, j])
            x = n0[e] + kn[e] * (u[e, 2, j] - gap[e])
            nraw[j] = x
            N[e, j] = max(0.0, x)
            closed[e, j] = x > 0.0
            tcl[e, j] = x > 0.0 and m > 0.0
            L[e, j] = m * N[e, j] if tcl[e, j] else 0.0
            peak = max(peak, m * N[e, j])
        scale[e] = max(peak, 1e-300) / kte
        for j in range(nt):
            c0, c1, c2, c3, n_0, n_1, n_2, n_3 = _stencil_cubics(u[e], nraw, j)
            ct[e, j, 0], ct[e, j, 1], ct[e, j, 2], ct[e, j, 3] = c0, c1, c2, c3
            Nc[e, j, 0], Nc[e, j, 1], Nc[e, j, 2], Nc[e, j, 3] = n_0, n_1, n_2, n_3
            Lc[e, j, 0], Lc[e, j, 1], Lc[e, j, 2], Lc[e, j, 3] = m * n_0, m * n_1, m * n_2, m * n_3
            ng0 = n_0 + GAUSS0 * (n_1 + GAUSS0 * (n_2 + GAUSS0 * n_3))
            ng1 = n_0 + GAUSS1 * (n_1 + GAUSS1 * (n_2 + GAUSS1 * n_3))
            p0 = c1 + GAUSS0 * (2.0 * c2 + GAUSS0 * (3.0 * c3))
            p1 = c1 + GAUSS1 * (2.0 * c2 + GAUSS1 * (3.0 * c3))
            pg[e, j, 0], pg[e, j, 1] = p0, p1
            lg0, lg1 = m * ng0, m * ng1
            Lg[e, j, 0], Lg[e, j, 1] = lg0, lg1
            b = tcl[e, j - 1 if j > 0 else nt - 1] and tcl[e, j] and (ng0 <= 0.0 or ng1 <= 0.0)
            bad[e, j] = b
            tlo[e, j] = (GAUSS1 if ng1 <= 0.0 else GAUSS0) if b else 0.0
            if not (lg0 > 0.0 and lg1 > 0.0):
                lg0, lg1 = 1.0, 1.0
            # numpy divides a complex by a real as (x + 0 i) / (2 lg): times 1 / (2 lg)
            s0, s1 = 1.0 / (2.0 * lg0), 1.0 / (2.0 * lg1)
            a0 = complex(kte * p0.real * s0, kte * p0.imag * s0)
            a1 = complex(kte * p1.real * s1, kte * p1.imag * s1)
            A = 0.5 * (a0 + a1)
            gam = S6 * (a1 * a0.conjugate()).imag
            x = (A * A.conjugate()).real - gam * gam
            r = math.sqrt(abs(x))
            if x >= 0.0:
                cc = 1.0
                ss = 1.0 + x * (-1.0 / 3.0 + x * (2.0 / 15.0)) if r < 1e-2 else math.tanh(r) / r
            else:
                cc = math.cos(r)
                ss = _sinc_r(r)
            a = complex(cc, ss * gam)
            bb = ss * A
            al[e, j], be[e, j] = a, bb
            det[e, j] = (a * a.conjugate()).real - (bb * bb.conjugate()).real
            pe[e, j] = c1 + 1.0 * (2.0 * c2 + 1.0 * (3.0 * c3))
            Lpe[e, j] = m * (n_1 + 1.0 * (2.0 * n_2 + 1.0 * (3.0 * n_3)))


# ============================================================================ period's map
@njit(cache=True, error_model="numpy")
def _cm(a, b):
    """friction._cmul: a b with each real operation rounded on its own."""
    return complex(a.real * b.real - a.imag * b.imag, a.real * b.imag + a.imag * b.real)


@njit(cache=True, error_model="numpy")
def _real_over(x, b):
    """x / b for real x and complex b as numpy divides (x + 0 i) / b (Smith's method with the
    reciprocal of the denominator)."""
    br, bi = b.real, b.imag
    if abs(br) >= abs(bi):
        if br == 0.0 and bi == 0.0:
            return complex(x / abs(br), 0.0 / abs(br))
        rat = bi / br
        scl = 1.0 / (br + bi * rat)
        return complex((x + 0.0 * rat) * scl, (0.0 - x * rat) * scl)
    rat = br / bi
    scl = 1.0 / (bi + br * rat)
    return complex((x * rat + 0.0) * scl, (0.0 * rat - x) * scl)


@njit(cache=True, error_model="numpy")
def _times_real(x, c):
    """x c for real x and complex c as numpy multiplies (x + 0 i) c."""
    return complex(x * c.real - 0.0 * c.imag, x * c.imag + 0.0 * c.real)


@njit(cache=True, error_model="numpy")
def cycle_matrix(g, kt, ut, L, al, be, det, code, wst, AP, AQ, cP, cQ):
    """friction._cycle_matrix's (cP, cQ) of records (code, wst, AP, AQ; rows i) of the step-table
    elements g[i]: each step's map dv -> P dv + Q conj(dv) composed over the period by the same
    pairwise tree as friction._compose, in the same operations (the same bits: tested)."""
    nt = ut.shape[1]
    P = np.empty(nt + 1, dtype=np.complex128)
    Q = np.empty(nt + 1, dtype=np.complex128)
    for i in range(g.size):
        e = g[i]
        for j in range(nt):
            c = code[i, j]
            if c == STICK_STEP:
                P[j], Q[j] = 1.0 + 0.0j, 0.0j
            elif c == EVENT_STEP:
                P[j], Q[j] = AP[i, j], AQ[i, j]
            elif c == SLIP_STEP:
                d = ut[e, j - 1 if j > 0 else nt - 1] - wst[i, j]
                T0 = _times_real(kt[e], d)
                r0 = abs(T0)
                if r0 == 0.0:
                    z0 = complex(T0.real / r0, T0.imag / r0)
                else:
                    s = 1.0 / r0
                    z0 = complex((T0.real + T0.imag * 0.0) * s, (T0.imag - T0.real * 0.0) * s)
                b, a = be[e, j], al[e, j]
                den = _cm(b.conjugate(), z0) + a.conjugate()
                K = _real_over(det[e, j], _cm(den, den))
                p = _times_real(L[e, j] / (2.0 * r0), K)
                P[j], Q[j] = p, -_cm(p, _cm(z0, z0))
            else:
                P[j], Q[j] = 0.0j, 0.0j
        n = nt
        while n > 1:
            if n % 2:
                P[n], Q[n] = 1.0 + 0.0j, 0.0j
                n += 1
            for m in range(n // 2):
                p1, q1, p2, q2 = P[2 * m], Q[2 * m], P[2 * m + 1], Q[2 * m + 1]
                P[m] = _cm(p2, p1) + _cm(q2, q1.conjugate())
                Q[m] = _cm(p2, q1) + _cm(q2, p1.conjugate())
            n //= 2
        cP[i], cQ[i] = P[0], Q[0]


# ============================================================================ classification
@njit(cache=True, error_model="numpy")
def classify(u, kt, mu, kn, n0, gap, N, open_all, closed_all, stuck_all):
    """friction.FrictionContacts._classify's tests for elements' samples u (k, 3, nt), in place:
    N (k, nt) n0 + kn (u_n - g); open_all, closed_all (k,); stuck_all (k,): closed at every
    sample with the stuck force inside the limit there, the normal load positive at the steps'
    Gauss points (or no friction) and the stuck force inside the limit between the samples too
    (:func:`_stick_over` from rest, as the march would find). The numpy version's ~50 array
    operations cost 3.3 ms per residual at the resonator's middle level (8 % of a curve)."""
    k, _, nt = u.shape
    ct = np.empty(4, dtype=np.complex128)
    Lc = np.empty(4)
    for e in range(k):
        m, kte = mu[e], kt[e]
        opn, cls, stk = True, True, True
        for j in range(nt):
            x = n0[e] + kn[e] * (u[e, 2, j] - gap[e])
            N[e, j] = x
            opn = opn and x <= 0.0
            cls = cls and x > 0.0
            u0, u1 = u[e, 0, j], u[e, 1, j]
            stk = stk and (kte * kte) * (u0 * u0 + u1 * u1) <= (m * x) * (m * x)
        open_all[e], closed_all[e] = opn, cls
        stk = stk and cls
        j = 0
        while stk and j < nt:
            c0, c1, c2, c3, n_0, n_1, n_2, n_3 = _stencil_cubics(u[e], N[e], j)
            ng0 = n_0 + GAUSS0 * (n_1 + GAUSS0 * (n_2 + GAUSS0 * n_3))
            ng1 = n_0 + GAUSS1 * (n_1 + GAUSS1 * (n_2 + GAUSS1 * n_3))
            if m != 0.0 and not (ng0 > 0.0 and ng1 > 0.0):
                stk = False
                break
            ct[0], ct[1], ct[2], ct[3] = c0, c1, c2, c3
            Lc[0], Lc[1], Lc[2], Lc[3] = m * n_0, m * n_1, m * n_2, m * n_3
            if _stick_over(ct, Lc, kte, 0.0j, 0.0)[0]:
                stk = False
            j += 1
        stuck_all[e] = stk
