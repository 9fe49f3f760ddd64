"""Compiled forward march of the friction elements (numba), one element at a time.

The march of :mod:`hbm.friction` is sequential in time: each step starts from the slider the
previous one left, and a step with a switch (closing, stick -> slip, slip -> stick) is located
by a root search on the step's cubic path. In numpy it runs vectorized over the elements
(``_cycle_vector``), where each phase of each element costs a few dozen numpy calls: on the
resonator most of an evaluation was numpy's per-call overhead, not arithmetic. Here the same
algorithm, the same formulas and the same decisions as the scalar path of ``friction.py``
(``_steps_scalar`` / ``_event_scalar``, which tests compare with the vectorized one), compiled
by numba: one loop over elements and steps at machine speed.

numba is Debian's python3-numba (a dependency of python3-basix, which python3-dolfinx pulls
in; ``scripts/setup`` installs it explicitly). Without it, or with ``FE_JOINT_NO_JIT=1``,
:data:`AVAILABLE` is False and the march stays in numpy. The first call compiles (cached in
``__pycache__`` for later processes).
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


@njit(cache=True)
def _poly(c, t):
    return c[0] + t * (c[1] + t * (c[2] + t * c[3]))


@njit(cache=True)
def _dpoly(c, t):
    return c[1] + t * (2.0 * c[2] + t * (3.0 * c[3]))


@njit(cache=True)
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


@njit(cache=True)
def _mobius_a(a1, a2, d):
    A = (0.5 * d) * (a1 + a2)
    gam = (S6 * d * d) * (a2 * a1.conjugate()).imag
    c, s = _cs((A * A.conjugate()).real - gam * gam)
    return c + 1j * (s * gam), s * A


@njit(cache=True)
def _rate(ct, Lc, kt, t):
    return kt * _dpoly(ct, t) / (2.0 * _poly(Lc, t))


@njit(cache=True)
def _magnus_k(ct, Lc, kt, z, ta, tb):
    d = tb - ta
    al, be = _mobius_a(_rate(ct, Lc, kt, ta + GAUSS0 * d), _rate(ct, Lc, kt, ta + GAUSS1 * d), d)
    D = be.conjugate() * z + al.conjugate()
    return (al * z + be) / D, ((al * al.conjugate()).real - (be * be.conjugate()).real) / (D * D)


@njit(cache=True)
def _slip_rate(ct, Lc, kt, z, t):
    return kt * (z.conjugate() * _dpoly(ct, t)).real - _dpoly(Lc, t)


@njit(cache=True)
def _excess(ct, Lc, kt, w, t):
    return abs(kt * (_poly(ct, t) - w)) - _poly(Lc, t)


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
def _stop_quadratic(ct, Lc, kt, z, t0, z1, rate0, rate1):
    tm = 0.5 * (t0 + 1.0)
    zm, _ = _magnus_k(ct, Lc, kt, z, t0, tm)
    rm = _slip_rate(ct, Lc, kt, zm, tm)
    h = np.empty(4)
    h[0], h[1], h[2], h[3] = rate0, 4.0 * rm - 3.0 * rate0 - rate1, 2.0 * (rate0 + rate1) - 4.0 * rm, 0.0
    return h


@njit(cache=True)
def _horner(a, t):
    v = a[a.size - 1]
    for k in range(a.size - 2, -1, -1):
        v = v * t + a[k]
    return v


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
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
        z = T0 / r0
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
                mode, z, code, slipped = M_SLIP, pd / abs(pd), SW_OPEN_SLIP, True
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
            mode, z, slipped = M_SLIP, d / ad, True
            p, q = -(p - z * z * q.conjugate()) / (2.0 * ad), -(q - z * z * p.conjugate()) / (2.0 * ad)
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


@njit(cache=True)
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
                z0, a, b = T0 / r0, al[j], be[j]
                z1 = (a * z0 + b) / (b.conjugate() * z0 + a.conjugate())
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


@njit(cache=True)
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
