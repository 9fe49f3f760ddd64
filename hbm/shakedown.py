"""The slider of a friction element that sticks through its whole periodic cycle (shakedown).

A closed element whose stuck force kt (u_t(t) - w) stays inside the Coulomb limit mu N(t) at every
sample is periodic for *any* slider w of the admissible set

    C = ∩_j {w : |u_t(t_j) - w| <= rho_j},   rho_j = mu N(t_j) / kt,

so the periodic (harmonic balance) state does not fix w: the history does. A march from rest
(w = 0 at t = 0) picks the w its transient leaves, which depends on where t = 0 falls in the cycle;
a mode's sign (arbitrary in an eigensolver) moves a backbone's motion by half a period against
t = 0, and so moved the backbone's results (docs/design.md, "Friction dynamics").

Where the motion has no time origin, a nonlinear mode (``FrictionContacts.shakedown``, set by
``nonlinear_mode.continue_backbone``; a forced response has the excitation's), w is the
admissible slider nearest its rest position w = 0, the projection of 0 on C: the
least slip that lets the element stick all cycle. It is what a vibration that grows slowly from
rest leaves in 1D (the slider is pushed to the nearer end of the admissible interval), it does not
depend on the time origin, and it is continuous in the motion: 0 while the element sticks from
rest, and the single point of C where C closes down and slip starts.

The projection on an intersection of disks is an LP-type problem whose optimum is fixed by at most
two disks (in the plane): an active-set iteration takes the nearest point of the active disks and
the most violated one (at most three disks: their single projections and pairwise vertices) until
nothing is violated. The nearest point's norm grows strictly at each step, so it ends; vectorized
over elements, a few steps on the resonator.

The samples only locate it. Between them the active disk slides along the motion, and a
projection on the sampled disks would be smooth only piecewise (it sits at a vertex of two
neighbouring samples' disks for a while, then slides on), with derivatives that grow as the
neighbours' normals align: Newton then stalls at the kinks. So the active instants are refined on
the motion itself (a trigonometric polynomial): one disk, t* maximizes |u_t(t)| - rho(t) and
w = u_t - rho u_t/|u_t| there; two, w and the two instants solve |w - u_t(t_i)| = rho(t_i) with
each instant a maximum of the excess. The derivative of w then follows the active instants.
"""
from __future__ import annotations

import numpy as np

#: relative tolerance (of the disks' scale) of the feasibility of the projection
FEAS_TOL = 1e-11
#: active-set steps before an element is given up (it is then marched, as before)
MAX_STEPS = 64
#: |det| of the two active normals below which the vertex's derivative is ill-posed (the disks
#: touch: C is nearly a point and slip starts); such an element is marched (see :func:`refine`)
MIN_DET = 1e-6


def nearest_admissible(c: np.ndarray, rho: np.ndarray):
    """The admissible slider nearest rest, w = argmin |w| over C (see the module docstring).

    Args:
        c: (k, m) complex, the tangential displacement samples u_t1 + i u_t2, mm.
        rho: (k, m) radii mu N / kt, mm, > 0.

    Returns:
        w (k,) complex slider, mm; active (k, 2) int, the samples whose disks fix w (-1: none;
        (j, -1) one disk, (i, j) a vertex of two); ok (k,) bool, False where C is empty (the
        element slips) or the iteration gave up.
    """
    k, m = c.shape
    rows = np.arange(k)
    scale = np.abs(c).max(axis=1) + rho.max(axis=1)
    tol = FEAS_TOL * scale
    d = np.abs(c) - rho
    j0 = d.argmax(axis=1)
    w = np.zeros(k, dtype=complex)
    active = np.full((k, 2), -1)
    inside = d[rows, j0] <= 0.0            # 0 is admissible: the element sticks from rest
    out = ~inside
    cj = c[out, j0[out]]
    w[out] = cj * (1.0 - rho[out, j0[out]] / np.abs(cj))
    active[out, 0] = j0[out]
    ok = np.ones(k, dtype=bool)
    live = out.copy()
    for _ in range(MAX_STEPS):
        r = np.nonzero(live)[0]
        if not r.size:
            break
        viol = np.abs(w[r, None] - c[r]) - rho[r]
        v = viol.argmax(axis=1)
        done = viol[np.arange(r.size), v] <= tol[r]
        live[r[done]] = False
        r, v = r[~done], v[~done]
        wn, an, found = _nearest_of_three(c[r], rho[r], active[r], v, tol[r])
        w[r[found]], active[r[found]] = wn[found], an[found]
        ok[r[~found]] = False
        live[r[~found]] = False
    ok[live] = False
    return w, active, ok


def _nearest_of_three(c, rho, active, v, tol):
    """The nearest point to 0 of the intersection of the disks active[:, 0], active[:, 1] (-1:
    absent) and v, for each row; found False where the intersection is empty."""
    b = len(v)
    rows = np.arange(b)
    idx = np.stack([active[:, 0], np.where(active[:, 1] >= 0, active[:, 1], active[:, 0]), v], axis=1)
    cc = c[rows[:, None], idx]                     # (b, 3)
    rr = rho[rows[:, None], idx]
    # candidates: the projection on each disk, and the two vertices of each pair
    ac = np.abs(cc)
    single = np.where(ac > rr, cc * (1.0 - rr / np.where(ac > 0, ac, 1.0)), 0.0)
    pairs = ((0, 1), (0, 2), (1, 2))
    verts, defs = [single], [np.stack([idx, np.full((b, 3), -1)], axis=-1)]
    for p, q in pairs:
        vx, valid = _vertices(cc[:, p], rr[:, p], cc[:, q], rr[:, q])
        verts.append(np.where(valid[:, None], vx, np.nan))
        defs.append(np.broadcast_to(np.stack([idx[:, p], idx[:, q]], axis=-1)[:, None], (b, 2, 2)))
    cand = np.concatenate(verts, axis=1)           # (b, 9)
    cdef = np.concatenate(defs, axis=1)            # (b, 9, 2)
    dist = np.abs(cand[:, :, None] - cc[:, None, :]) - rr[:, None, :]
    feas = (dist <= tol[:, None, None]).all(axis=2) & np.isfinite(cand)
    norm = np.where(feas, np.abs(cand), np.inf)
    best = norm.argmin(axis=1)
    found = np.isfinite(norm[rows, best])
    return cand[rows, best], cdef[rows, best], found


def _vertices(c1, r1, c2, r2):
    """The two intersection points (b, 2) of the circles |w - c1| = r1 and |w - c2| = r2, and
    valid (b,) where they meet (touching circles give one point twice)."""
    e = c2 - c1
    d = np.abs(e)
    valid = (d > 0.0) & (d <= r1 + r2) & (d >= np.abs(r1 - r2))
    ds = np.where(valid, d, 1.0)
    x = (ds ** 2 + r1 ** 2 - r2 ** 2) / (2.0 * ds)
    h = np.sqrt(np.maximum(r1 ** 2 - x ** 2, 0.0))
    u = e / ds
    base = c1 + x * u
    return np.stack([base + 1j * h * u, base - 1j * h * u], axis=1), valid


def _basis(t: np.ndarray, nH: int):
    """Harmonic rows e(t) = (1, cos t, sin t, cos 2t, ...) and their first two t-derivatives,
    each (..., nH) (hbm.fourier's layout)."""
    t = np.asarray(t, dtype=float)
    e, e1, e2 = (np.zeros(t.shape + (nH,)) for _ in range(3))
    e[..., 0] = 1.0
    for h in range(1, (nH - 1) // 2 + 1):
        c, s = np.cos(h * t), np.sin(h * t)
        e[..., 2 * h - 1], e[..., 2 * h] = c, s
        e1[..., 2 * h - 1], e1[..., 2 * h] = -h * s, h * c
        e2[..., 2 * h - 1], e2[..., 2 * h] = -h * h * c, -h * h * s
    return e, e1, e2


def _at(Ct, R, t):
    """u_t, u_t', u_t'' (complex) and rho, rho', rho'' at instants t (k,) of rows Ct, R (k, nH)."""
    e, e1, e2 = _basis(t, Ct.shape[1])
    return ((Ct * e).sum(-1), (Ct * e1).sum(-1), (Ct * e2).sum(-1),
            (R * e).sum(-1), (R * e1).sum(-1), (R * e2).sum(-1))


def _dot(a, b):
    """Real dot product of plane vectors written as complex numbers."""
    return (a.conj() * b).real


#: Newton iterations of the refinement of the active instants, and its convergence in t (rad)
REFINE_ITER, REFINE_TOL = 30, 1e-13


def _refine_one(Ct, R, t):
    """The instant t* (near t) maximizing |u_t(t)| - rho(t), and the projection of 0 on its disk.

    Returns w (k,) complex, t* (k,), converged (k,) bool (a maximum reached)."""
    conv = np.zeros(len(t), dtype=bool)
    for _ in range(REFINE_ITER):
        c, c1, c2, _, r1, r2 = _at(Ct, R, t)
        ac = np.abs(c)
        q = _dot(c, c1)
        hp = q / ac - r1
        hpp = (np.abs(c1) ** 2 + _dot(c, c2)) / ac - q * q / ac ** 3 - r2
        dt = np.where(hpp < 0.0, -hp / np.where(hpp < 0.0, hpp, -1.0), 0.0)
        dt = np.clip(dt, -0.1, 0.1)
        t = t + dt
        conv = (np.abs(dt) <= REFINE_TOL) & (hpp < 0.0)
        if conv.all():
            break
    c, _, _, r, _, _ = _at(Ct, R, t)
    return c * (1.0 - r / np.abs(c)), t, conv


def _refine_two(Ct, R, w, ta, tb):
    """w and the instants (t_a, t_b) of a vertex: |w - u_t(t_i)| = rho(t_i), d/dt of the excess
    zero at both (Newton on the 4 real unknowns from the sampled vertex).

    Returns w, t_a, t_b, converged (k,) bool."""
    k = len(w)
    conv = np.zeros(k, dtype=bool)
    J = np.zeros((k, 4, 4))
    F = np.zeros((k, 4))
    for _ in range(REFINE_ITER):
        for i, t in enumerate((ta, tb)):
            c, c1, c2, r, r1, r2 = _at(Ct, R, t)
            d = w - c
            F[:, 2 * i] = np.abs(d) ** 2 - r * r
            F[:, 2 * i + 1] = -2.0 * _dot(d, c1) - 2.0 * r * r1
            J[:, 2 * i, 0], J[:, 2 * i, 1] = 2.0 * d.real, 2.0 * d.imag
            J[:, 2 * i, 2 + i] = F[:, 2 * i + 1]
            J[:, 2 * i + 1, 0], J[:, 2 * i + 1, 1] = -2.0 * c1.real, -2.0 * c1.imag
            J[:, 2 * i + 1, 2 + i] = 2.0 * np.abs(c1) ** 2 - 2.0 * _dot(d, c2) - 2.0 * r1 * r1 - 2.0 * r * r2
            J[:, 2 * i, 3 - i] = J[:, 2 * i + 1, 3 - i] = 0.0
        det = np.linalg.det(J)
        good = np.isfinite(det) & (np.abs(det) > 0.0)
        dx = np.zeros((k, 4))
        dx[good] = np.linalg.solve(J[good], -F[good][..., None])[..., 0]
        dx[:, 2:] = np.clip(dx[:, 2:], -0.1, 0.1)
        w = w + dx[:, 0] + 1j * dx[:, 1]
        ta, tb = ta + dx[:, 2], tb + dx[:, 3]
        conv = good & (np.abs(dx[:, 2:]).max(axis=1) <= REFINE_TOL)
        if conv.all():
            break
    return w, ta, tb, conv


#: two active instants closer than this (rad) have merged into one: retried as one
MERGED = 1e-6
#: rounds of the refinement's own active-set step (a sample violated by the refined point joins)
REFINE_ROUNDS = 6


def refine(Ct: np.ndarray, R: np.ndarray, w: np.ndarray, active: np.ndarray, c: np.ndarray,
           rho: np.ndarray):
    """The nearest admissible slider on the motion between the samples (see the module docstring),
    from the sampled one (:func:`nearest_admissible`).

    Args:
        Ct: (k, nH) complex harmonics of u_t1 + i u_t2, mm; R: (k, nH) harmonics of rho, mm.
        w, active: :func:`nearest_admissible`'s results for these rows (active[:, 0] >= 0).
        c, rho: the samples it was given (k, nt), equally spaced from t = 0.

    Returns:
        w (k,) complex; times (k, 2) the active instants, rad (nan: none, the second for a
        vertex only); ok (k,) bool, False where the refinement did not settle on a point that
        keeps every sample admissible (such an element is marched).
    """
    k, nt = c.shape
    theta = 2.0 * np.pi * np.arange(nt) / nt
    a, b = active[:, 0], active[:, 1]
    # a vertex of neighbouring samples' disks is the sampling's: the motion's envelope is smooth
    gap = np.abs(a - b) % nt
    near = (b >= 0) & ((gap <= 1) | (gap == nt - 1))
    h = np.abs(c) - rho
    a = np.where(near & (h[np.arange(k), np.maximum(b, 0)] > h[np.arange(k), a]), b, a)
    times = np.stack([theta[a], np.where((b >= 0) & ~near, theta[np.maximum(b, 0)], np.nan)], axis=1)
    ok = np.zeros(k, dtype=bool)
    live = np.ones(k, dtype=bool)
    scale = np.abs(c).max(axis=1) + rho.max(axis=1)
    for _ in range(REFINE_ROUNDS):
        r = np.nonzero(live)[0]
        if not r.size:
            break
        wr, tr, conv = _refine_basis(Ct[r], R[r], w[r], times[r])
        w[r], times[r] = wr, tr
        live[r[~conv]] = False
        r = r[conv]
        # every sample admissible (the refined point lies in the motion's admissible set, inside
        # the sampled one up to rounding); else the most violated sample joins the active set
        viol = np.abs(w[r, None] - c[r]) - rho[r]
        v = viol.argmax(axis=1)
        done = viol[np.arange(r.size), v] <= 1e3 * FEAS_TOL * scale[r]
        ok[r[done]] = True
        live[r[done]] = False
        r, v = r[~done], v[~done]
        if r.size:
            tt = np.concatenate([times[r], theta[v][:, None]], axis=1)             # (b, 3)
            tt[:, 1] = np.where(np.isnan(tt[:, 1]), tt[:, 0], tt[:, 1])
            cs, _, _, rs, _, _ = _at(np.repeat(Ct[r], 3, axis=0), np.repeat(R[r], 3, axis=0), tt.ravel())
            act3 = np.tile([0, 1], (r.size, 1))
            act3[np.isnan(times[r, 1]), 1] = -1
            wn, an, found = _nearest_of_three(cs.reshape(-1, 3), rs.reshape(-1, 3), act3,
                                              np.full(r.size, 2), FEAS_TOL * scale[r])
            live[r[~found]] = False
            f = np.nonzero(found)[0]
            w[r[f]] = wn[f]
            t0 = tt[f, an[f, 0]]
            t1 = np.where(an[f, 1] >= 0, tt[f, np.maximum(an[f, 1], 0)], np.nan)
            times[r[f], 0], times[r[f], 1] = t0, t1
    # a vertex of nearly tangent disks: w's derivative is ill-posed there (slip about to start)
    r = np.nonzero(ok & np.isfinite(times[:, 1]))[0]
    if r.size:
        ca = _at(Ct[r], R[r], times[r, 0])
        cb = _at(Ct[r], R[r], times[r, 1])
        na, nb = (w[r] - ca[0]) / ca[3], (w[r] - cb[0]) / cb[3]
        ok[r[np.abs(na.real * nb.imag - na.imag * nb.real) <= MIN_DET]] = False
    return w, times, ok


def _refine_basis(Ct, R, w, times):
    """Newton on the active instants (one: _refine_one, two: _refine_two; two that merge (MERGED),
    or do not converge, are retried as one from the one with the larger excess). Two instants may
    lie within a sample spacing of each other: where the orbit turns sharply the stick disks'
    envelope has a corner between two samples.

    Returns w, times, converged (rows)."""
    k = len(w)
    conv = np.zeros(k, dtype=bool)
    two = np.nonzero(np.isfinite(times[:, 1]))[0]
    if two.size:
        w2, ta, tb, c2 = _refine_two(Ct[two], R[two], w[two], times[two, 0], times[two, 1])
        c2 &= np.abs(np.angle(np.exp(1j * (ta - tb)))) > MERGED
        w[two[c2]] = w2[c2]
        times[two[c2], 0], times[two[c2], 1] = ta[c2], tb[c2]
        conv[two[c2]] = True
        back = two[~c2]
        if back.size:
            ea = _excess(Ct[back], R[back], times[back, 0])
            eb = _excess(Ct[back], R[back], times[back, 1])
            times[back, 0] = np.where(eb > ea, times[back, 1], times[back, 0])
            times[back, 1] = np.nan
    one = np.nonzero(~conv)[0]
    if one.size:
        w1, t1, c1 = _refine_one(Ct[one], R[one], times[one, 0])
        w[one], times[one, 0] = w1, t1
        conv[one] = c1
    return w, times, conv


def _excess(Ct, R, t):
    """|u_t(t)| - rho(t): the distance of rest from the disk at t (> 0 outside)."""
    c, _, _, r, _, _ = _at(Ct, R, t)
    return np.abs(c) - r


def slider_jacobian(Ct: np.ndarray, R: np.ndarray, w: np.ndarray, times: np.ndarray,
                    drho_dun: np.ndarray) -> np.ndarray:
    """Derivative of the nearest admissible slider with respect to the element's harmonics.

    One active instant t*: w = p(t*) with p = u_t - rho u_t/|u_t|, and t* moves with the motion
    (dt* = -d(h')/h'', h = |u_t| - rho). Two: n_i . (w - u_t(t_i)) = rho(t_i), n_i the unit
    normals; the instants' motion drops out (each is a maximum of the excess).

    Args:
        Ct, R: as :func:`refine` (k, nH); w, times: its results for these rows (times[:, 0]
            finite).
        drho_dun: (k,) d rho / d u_n = mu kn / kt.

    Returns:
        (k, 2, 3 nH) d(Re w, Im w) / d(U_t1, U_t2, U_n) in the element layout (direction * nH +
        harmonic).
    """
    k, nH = Ct.shape
    rows = np.arange(k)
    out = np.zeros((k, 2, 3 * nH))
    one = np.isnan(times[:, 1])
    if one.any():
        r = rows[one]
        t = times[r, 0]
        e, e1, _ = _basis(t, nH)
        c, c1, c2, rho, r1, r2 = _at(Ct[r], R[r], t)
        ac = np.abs(c)
        n = np.stack([c.real, c.imag], axis=1) / ac[:, None]                    # c/|c|
        P = np.eye(2) - n[:, :, None] * n[:, None, :]
        A = np.eye(2) - (rho / ac)[:, None, None] * P
        g = drho_dun[r, None]
        # at fixed t: dp = A dc - n d rho
        for d in range(2):
            out[r, :, d * nH:(d + 1) * nH] = A[:, :, d, None] * e[:, None]
        out[r, :, 2 * nH:] = -n[:, :, None] * (g * e)[:, None]
        # the instant's motion: dt* = -(d h') / h''
        c1v = np.stack([c1.real, c1.imag], axis=1)
        q = _dot(c, c1)
        hpp = (np.abs(c1) ** 2 + _dot(c, c2)) / ac - q * q / ac ** 3 - r2
        Pc1 = np.einsum("kij,kj->ki", P, c1v) / ac[:, None]                     # d(c/|c|) . c'
        dhp = np.zeros((r.size, 3 * nH))
        for d in range(2):
            dhp[:, d * nH:(d + 1) * nH] = Pc1[:, d, None] * e + n[:, d, None] * e1
        dhp[:, 2 * nH:] = -g * e1
        dts = -dhp / hpp[:, None]
        pt = np.einsum("kij,kj->ki", A, c1v) - n * r1[:, None]                  # dp/dt
        out[r] += pt[:, :, None] * dts[:, None, :]
    two = ~one
    if two.any():
        r = rows[two]
        rhs = np.zeros((r.size, 2, 3 * nH))
        Mn = np.zeros((r.size, 2, 2))
        for i in range(2):
            t = times[r, i]
            e = _basis(t, nH)[0]
            c, _, _, rho, _, _ = _at(Ct[r], R[r], t)
            nv = (w[r] - c) / rho
            Mn[:, i, 0], Mn[:, i, 1] = nv.real, nv.imag
            rhs[:, i, 0:nH] = nv.real[:, None] * e
            rhs[:, i, nH:2 * nH] = nv.imag[:, None] * e
            rhs[:, i, 2 * nH:] = drho_dun[r, None] * e
        out[r] = np.linalg.solve(Mn, rhs)
    return out
