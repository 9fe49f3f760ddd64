"""Normal rough contact: Polonsky–Keer constrained conjugate gradient (load or approach control).

Problem (per grid cell i, cell area A): find the pressure p ≥ 0 and rigid approach δ with

    g_i = h_i + (K*p)_i − δ ≥ 0,   p_i ≥ 0,   p_i g_i = 0,   A Σ p_i = W  (load control),

where h is the initial separation, K the relative normal compliance of the two bodies and g the
deformed gap. Polonsky & Keer (Wear 231, 1999) solve it by conjugate gradients restricted to the
contact set, with projection on p ≥ 0, restart when cells enter the contact, and (in load control)
the mean gap over the contact set as the approach.

Stopping criterion (documented, checked on the iterate that the gap was computed from):

    err = max( Σ_c p_i |g_i| / (Σ p_i · s),  max_{p_i = 0} max(−g_i, 0) / s,  |AΣp − W| / W ),

i.e. the pressure-weighted gap on the contact set, the worst penetration outside it, and the load
mismatch, with the displacement scale s = max(peak-to-peak of h on the allowed cells, max K*p).
It stops when err < tol; reaching ``max_iter`` raises ConvergenceError with the err reached.

Hardness cap: with ``hardness=H`` the pressure is clipped to H (perfectly plastic asperities);
plastic cells leave the CG set and may interpenetrate (the interference is the plastic flattening).

All internals are batched over a leading axis so that many small patches solve at once
(``stiffness.patch_normal_stiffness``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ConvergenceError, positive_scalar
from .halfspace import ElasticHalfSpace

_AX = (-2, -1)
#: at most this many incremental updates of u = K*p in a row (round-off drift; see pk_normal_batch)
_EXACT_EVERY = 50


@dataclass
class NormalSolution:
    """Result of a normal contact solve.

    Attributes:
        pressure: (nx, ny) contact pressure in MPa (0 outside the contact and the mask).
        gap: (nx, ny) deformed gap h + K*p − δ in mm (≈ 0 in contact, ≥ 0 elsewhere; masked-out
            cells carry their unconstrained value).
        displacement: (nx, ny) elastic relative normal displacement K*p in mm.
        approach: rigid approach δ in mm (relative to the initial separation field).
        load: total normal force A Σ p in N.
        contact: (nx, ny) bool, cells with p > 0.
        contact_fraction: contact area / allowed (masked) area.
        iterations: CG iterations used.
        residual: final error measure (see module docstring).
        mask: (nx, ny) bool, cells allowed to carry pressure.
        initial_gap: (nx, ny) the initial separation h in mm.
        hardness: the pressure cap in MPa (inf = purely elastic).
    """

    pressure: np.ndarray
    gap: np.ndarray
    displacement: np.ndarray
    approach: float
    load: float
    contact: np.ndarray
    contact_fraction: float
    iterations: int
    residual: float
    mask: np.ndarray
    initial_gap: np.ndarray
    hardness: float = float("inf")


def _bsum(a: np.ndarray) -> np.ndarray:
    return a.sum(axis=_AX, keepdims=True)


def _bdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Σ a·b over the last two axes of (B, nx, ny) arrays, as (B, 1, 1).

    einsum, not a BLAS dot: OpenBLAS threads its dot, which on a loaded machine cost 20-50x the
    single-threaded loop (and a thread-count-dependent summation order would break determinism).
    """
    return np.einsum("bij,bij->b", a, b).reshape(-1, 1, 1)


def pk_normal_batch(apply_k, h: np.ndarray, allowed: np.ndarray, cell_area: float, *,
                    load: np.ndarray | None = None, approach: np.ndarray | None = None,
                    tol: float = 1e-8, max_iter: int = 2000, hardness: np.ndarray | None = None,
                    p0: np.ndarray | None = None) -> dict:
    """Batched Polonsky–Keer solve (internal; inputs already validated).

    Args:
        apply_k: callable (B, nx, ny) pressure → (B, nx, ny) displacement.
        h: (B, nx, ny) initial separation (mm).
        allowed: (B, nx, ny) bool, cells that may carry pressure.
        cell_area: mm².
        load: (B,) total loads N (load control) — exactly one of load / approach.
        approach: (B,) rigid approaches mm (approach control).
        tol: stopping tolerance on the error measure.
        max_iter: iteration cap.
        hardness: (B,) pressure caps MPa or None.
        p0: optional (B, nx, ny) initial pressure (warm start).

    Returns:
        dict with pressure, displacement, gap, approach (B,), iterations (B,), residual (B,).

    Raises:
        ConvergenceError: if some batch entry has not converged after max_iter iterations.
    """
    B = h.shape[0]
    load_ctrl = load is not None
    allowed = np.broadcast_to(allowed, h.shape)
    n_allowed = _bsum(allowed.astype(float))
    hmin = np.where(allowed, h, np.inf).min(axis=_AX, keepdims=True)
    hmax = np.where(allowed, h, -np.inf).max(axis=_AX, keepdims=True)
    hrange = np.where(np.isfinite(hmax - hmin), hmax - hmin, 0.0)
    H = np.full((B, 1, 1), np.inf) if hardness is None else np.asarray(hardness, float).reshape(B, 1, 1)
    if load_ctrl:
        W = np.asarray(load, float).reshape(B, 1, 1)
        trivial = (W <= 0).reshape(B)
        if p0 is None:
            p = np.where(allowed, W / (cell_area * np.maximum(n_allowed, 1)), 0.0)
        else:
            p = np.where(allowed, np.maximum(p0, 0.0), 0.0)
            s = _bsum(p) * cell_area
            p = np.where(s > 0, p * W / np.where(s > 0, s, 1.0),
                         np.where(allowed, W / (cell_area * np.maximum(n_allowed, 1)), 0.0))
        p = np.minimum(p, H)
        delta = np.zeros((B, 1, 1))
    else:
        delta = np.asarray(approach, float).reshape(B, 1, 1)
        W = None
        pen = np.where(allowed, np.maximum(delta - h, 0.0), 0.0)
        trivial = (~np.any(pen > 0, axis=_AX)).reshape(B)
        if p0 is None:
            # self-compliance of one cell gives the pressure scale; CG corrects the rest
            unit = np.zeros((1,) + h.shape[1:])
            unit[0, 0, 0] = 1.0
            p = np.minimum(0.1 * pen / apply_k(unit)[0, 0, 0], H)
        else:
            p = np.where(allowed, np.clip(p0, 0.0, H), 0.0)
    active = ~trivial
    iters = np.zeros(B, dtype=int)
    err = np.where(trivial, 0.0, np.inf)
    t = np.zeros_like(h)
    G_old = np.ones((B, 1, 1))
    use_beta = np.zeros((B, 1, 1), dtype=bool)
    tau_self = None  # the self-compliance step, computed when first needed
    u = apply_k(p)
    # u = K*p is updated by increments, u ← c (u − τ K*t), on steps where the projection changed
    # nothing: that saves one of the two convolutions of those iterations. Otherwise, and every
    # _EXACT_EVERY increments, u is recomputed from p, so round-off cannot accumulate; and an
    # entry accepted on an incremental u is re-checked on the exact K*p before the solve returns,
    # so the stopping test always holds for the exact displacement.
    u_exact, n_incr = True, 0
    pending = np.zeros(B, dtype=bool)
    # the loop is memory-bound at large grids: masked sums are dot products (einsum) with a 0/1
    # mask (numpy's ``where=`` reductions ran 20-50x slower on scattered masks), scratch buffers
    # are reused, and the hardness/mask tests are skipped when they cannot bind
    capped = hardness is not None
    masked = not allowed.all()
    kw = dict(axis=_AX, keepdims=True)
    g = np.empty_like(h)
    mI = np.empty_like(h)     # the CG set Ic as 0/1
    gI = np.empty_like(h)     # the gradient on Ic (0 elsewhere)
    tmp = np.empty_like(h)
    it = 0
    while True:
        np.add(h, u, out=g)
        Ic = p > 0
        if capped:
            plastic = p >= H
            Ic &= ~plastic
        if masked:
            Ic &= allowed
        nIc = np.count_nonzero(Ic, axis=_AX).reshape(B, 1, 1)
        np.copyto(mI, Ic)
        if load_ctrl:
            gbar = np.where(nIc > 0, _bdot(g, mI) / np.maximum(nIc, 1), hmin)
            delta = np.where(active.reshape(B, 1, 1), gbar, delta)
        g -= delta
        if capped:
            # a plastic cell needs a closed gap (p = H, g ≤ 0); one whose gap has opened (a
            # transient overshoot, a warm start from a higher load) rejoins the CG set so it can
            # unload. Without this it stayed at H for good: at Rq 5 µm every contact cell ended
            # at the cap with its gap open (issue 13)
            opened = plastic & (g > 0)
            if masked:
                opened &= allowed
            Ic |= opened
            np.copyto(mI, Ic)
        np.multiply(g, mI, out=gI)
        # --- error of the current iterate (p, g consistent) ---
        # max K*p (K > 0 and p ≥ 0: u ≥ 0 up to round-off, so max u = max |u|)
        scale = np.maximum(np.maximum(hrange, np.max(u, **kw)), 1e-300)
        psum = np.sum(p, **kw)
        e1 = _bdot(p, np.abs(gI, out=tmp)) / (np.where(psum > 0, psum, 1.0) * scale)
        # worst penetration off the contact set: g·[out] is 0 on it, and 0 does not lower the max
        # (without mask and cap, out is exactly the complement of Ic, so g·[out] = g − gI)
        if masked or capped:
            np.multiply(g, (p <= 0) & allowed if masked else p <= 0, out=tmp)
        else:
            np.subtract(g, gI, out=tmp)
        e2 = np.maximum(-np.min(tmp, **kw), 0.0) / scale
        e = np.maximum(e1, e2)
        if capped:
            # plastic cells: an open gap under p = H violates the cap's complementarity
            e = np.maximum(e, np.maximum(np.max(np.multiply(g, plastic, out=tmp), **kw), 0.0) / scale)
        if load_ctrl:
            e = np.maximum(e, np.abs(psum * cell_area - W) / np.where(W > 0, W, 1.0))
        e = e.reshape(B)
        err = np.where(active, e, err)
        done = active & (err < tol)
        if not u_exact:
            pending |= done  # accepted on an incremental u: confirmed on the exact K*p below
        active &= ~done
        if not active.any() or it == max_iter:
            if pending.any():
                # one convolution confirms all of them; an entry that fails (its error moved by
                # round-off across tol) resumes with a restarted CG
                u, u_exact, n_incr = apply_k(p), True, 0
                use_beta &= ~pending.reshape(B, 1, 1)
                active |= pending
                pending[:] = False
                continue
            break
        it += 1
        iters += active
        act = active.reshape(B, 1, 1)
        # --- conjugate direction on the contact set ---
        G = _bdot(gI, gI)
        beta = np.where(use_beta, G / np.where(G_old > 0, G_old, 1.0), 0.0)
        beta = np.where(beta < 1e4, beta, 0.0)  # a vanishing previous gradient: restart, don't blow up
        t *= beta
        t *= mI
        t += gI                            # t = (g + β t)·[Ic]
        G_old = np.where(act, G, G_old)
        r = apply_k(t)
        num = _bdot(g, t)                  # t = 0 outside the contact set
        den = _bdot(r, t)
        if load_ctrl:
            # the step of the load-preserving (zero-mean on the contact set) response r − r̄;
            # r itself stays K*t for the increment of u
            den -= _bdot(r, mI) / np.maximum(nIc, 1) * np.sum(t, **kw)
        # a single contact cell has a zero-mean gradient (t = 0): step the overlap set with the
        # self-compliance scale instead so that new cells can still enter the contact
        ok = (den > 0) & (num > 0)
        if tau_self is None and not ok.all():
            unit = np.zeros((1,) + h.shape[1:])
            unit[0, 0, 0] = 1.0
            tau_self = 0.5 / apply_k(unit)[0, 0, 0]
        tau = np.where(ok, num / np.where(den > 0, den, 1.0), tau_self if tau_self is not None else 0.0)
        q = np.multiply(t, -tau)
        q += p                             # q = p − τ t
        q_lo = np.min(q, **kw)
        p_new = np.maximum(q, 0.0)
        if capped:
            q_hi = np.max(q, **kw)
            np.minimum(p_new, H, out=p_new)
        Iol = (p_new <= 0) & (g < 0)
        if masked:
            Iol &= allowed
        has_ol = np.any(Iol, **kw)
        if has_ol.any():
            p_new = np.where(Iol, np.minimum(p_new - tau * g, H), p_new)
        if masked:
            p_new *= allowed
        c = np.ones((B, 1, 1))
        if load_ctrl:
            s_ = np.sum(p_new, **kw) * cell_area
            c = np.where(s_ > 0, W / np.where(s_ > 0, s_, 1.0), 1.0)
            p_new *= c
            if capped:
                np.minimum(p_new, H, out=p_new)
        use_beta = np.where(act, ~has_ol, use_beta)
        p = p_new if act.all() else np.where(act, p_new, p)
        # the increment is exact where p_new = c q: no cell clipped at 0 or H, none entered (the
        # mask cannot bind: p and t vanish outside it), the scaled maximum still below H
        exact = (q_lo >= 0) & ~has_ol
        if capped:
            exact &= (q_hi <= H) & (q_hi * c <= H)
        if n_incr < _EXACT_EVERY and exact.reshape(B)[active].all():
            r *= -tau
            r += u
            r *= c                         # r becomes c (u − τ K*t)
            u = r if act.all() else np.where(act, r, u)
            u_exact, n_incr = False, n_incr + 1
        else:
            u, u_exact, n_incr = apply_k(p), True, 0
    if active.any():
        worst = float(np.max(err[active]))
        raise ConvergenceError(
            f"solve_normal: {int(active.sum())} of {B} problems not converged to tol={tol:g}",
            worst, int(iters.max()))
    if load_ctrl:
        p = np.where(trivial.reshape(B, 1, 1), 0.0, p)
        u = apply_k(p) if trivial.any() else u
    g = h + u - delta
    return {"pressure": p, "displacement": u, "gap": g, "approach": delta.reshape(B),
            "iterations": iters, "residual": err}


def capped_load_control(apply_k, h: np.ndarray, allowed: np.ndarray, cell_area: float,
                        W: np.ndarray, H: float, tol: float,
                        max_steps: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Pressures (B, n, m) and approaches (B,) of problems pressed with loads W (B,) and the
    pressure capped at H (MPa); ``h`` (B, n, m) initial gaps, ``allowed`` (B, n, m) masks.

    Load-controlled Polonsky–Keer with a cap stagnated on small patches whose few asperities all
    reach H (no cell left below the cap to carry the rest of the load), while approach control
    converges in a few iterations. So the approach δ of each patch is found by a safeguarded
    secant (Illinois) on the monotone load N(δ) of approach-controlled solves, from the bracket
    [0, 2^k × the elastic approach] (capping lowers N(δ), so the elastic approach is below the
    capped one), until |N − W| ≤ 1e-6·W (the contact set, all k_n needs, is settled long
    before; an approach-controlled load is itself only accurate to about the solve tolerance) or
    the bracket is narrower than 1e-9 δ. The global capped solve falls back on it too (at 256²,
    Rq 1 µm, load control stalled at an error of 1.3e-2 after 2000 iterations).
    """
    ltol = max(tol, 1e-6)
    B = h.shape[0]
    ca = cell_area
    Hs = np.full(B, H)
    p = np.zeros_like(h)
    delta = np.zeros(B)
    live = W > 0
    if not live.any():
        return p, delta

    def load_at(d, idx, p0):
        # cold starts keep each trial independent of the bracket's history (a plastic cell whose
        # gap opens is released by pk_normal_batch, so a warm start would also be correct)
        r = pk_normal_batch(apply_k, h[idx], allowed[idx], ca, approach=d, tol=tol * 1e-2,
                            hardness=Hs[idx])
        return r["pressure"], r["pressure"].sum(axis=_AX) * ca

    idx = np.nonzero(live)[0]
    el = pk_normal_batch(apply_k, h[idx], allowed[idx], ca, load=W[idx], tol=tol)
    lo, hi = np.zeros(len(idx)), np.maximum(el["approach"], 1e-12)
    f_lo = -W[idx]
    p_hi, n_hi = load_at(hi, idx, el["pressure"])
    f_hi = n_hi - W[idx]
    for _ in range(60):                      # widen until N(hi) ≥ W
        short = f_hi < 0
        if not short.any():
            break
        lo[short], f_lo[short] = hi[short], f_hi[short]
        hi[short] *= 2
        ps, ns = load_at(hi[short], idx[short], p_hi[short])
        p_hi[short], f_hi[short] = ps, ns - W[idx][short]
    p_best, d_best = p_hi.copy(), hi.copy()
    done = np.abs(f_hi) <= ltol * W[idx]
    side = np.zeros(len(idx), int)
    for _ in range(max_steps):
        if done.all():
            break
        t = np.nonzero(~done)[0]
        den = f_hi[t] - f_lo[t]
        d = np.where(den > 0, (lo[t] * f_hi[t] - hi[t] * f_lo[t]) / np.where(den > 0, den, 1.0),
                     0.5 * (lo[t] + hi[t]))
        d = np.where((d <= lo[t]) | (d >= hi[t]), 0.5 * (lo[t] + hi[t]), d)
        ps, ns = load_at(d, idx[t], p_best[t])
        f = ns - W[idx][t]
        p_best[t], d_best[t] = ps, d
        # matched, or the bracket has closed (N(δ) of capped solves can jump by a cell entering
        # at the cap; the contact set is then that of the bracket's end)
        ok = (np.abs(f) <= ltol * W[idx][t]) | (hi[t] - lo[t] <= 1e-9 * hi[t])
        done[t[ok]] = True
        # Illinois: when the same end is kept twice, halve its function value
        a, fa = t[(f < 0) & ~ok], f[(f < 0) & ~ok]
        lo[a], f_lo[a] = d[(f < 0) & ~ok], fa
        f_hi[a] *= np.where(side[a] == -1, 0.5, 1.0)
        side[a] = -1
        b, fb = t[(f >= 0) & ~ok], f[(f >= 0) & ~ok]
        hi[b], f_hi[b] = d[(f >= 0) & ~ok], fb
        f_lo[b] *= np.where(side[b] == 1, 0.5, 1.0)
        side[b] = 1
    else:
        raise ConvergenceError(f"capped patch loads: {int((~done).sum())} of {len(idx)} not matched "
                               f"to tol={tol:g}", float("nan"), max_steps)
    p[idx], delta[idx] = p_best, d_best
    return p, delta



def _capped_by_approach(hs: ElasticHalfSpace, h: np.ndarray, allowed: np.ndarray, W: np.ndarray,
                        H: float, tol: float) -> dict:
    """A capped load-controlled solve as :func:`capped_load_control` (approach-controlled solves
    matched to the load), in the result layout of :func:`pk_normal_batch`. Load control with a
    cap can stall where no cell below the cap is left to carry the rest of the load."""
    p, d = capped_load_control(hs._apply_normal, h[None], allowed[None], hs.grid.cell_area, W, H, tol)
    u = hs._apply_normal(p)
    err = np.abs(p.sum(axis=_AX) * hs.grid.cell_area - W) / W
    return {"pressure": p, "displacement": u, "gap": h[None] + u - d[:, None, None], "approach": d,
            "iterations": np.zeros(1, int), "residual": err}


def solve_normal(hs: ElasticHalfSpace, gap, load: float | None = None, approach: float | None = None,
                 *, mask=None, tol: float = 1e-8, max_iter: int = 2000, hardness: float | None = None,
                 initial_pressure=None) -> NormalSolution:
    """Frictionless normal contact of two elastic bodies separated by ``gap``.

    Args:
        hs: half-space operator (defines grid, moduli, periodicity).
        gap: (nx, ny) initial separation h in mm (e.g. ``z.max() - z`` for a rough surface against
            a flat, or the equivalent macro gap of ``coupling.macro_gap``); only differences matter
            in load control.
        load: total normal force W in N (load control, ≥ 0), or
        approach: rigid approach δ in mm (approach control): deformed gap = h + K*p − δ.
        mask: (nx, ny) bool, True where contact is allowed (False e.g. in the bolt hole).
        tol: tolerance of the complementarity/gap error (see module docstring), in (0, 1).
        max_iter: iteration cap; exceeding it raises ConvergenceError with the residual.
        hardness: optional pressure cap H in MPa (perfectly plastic asperities).
        initial_pressure: optional (nx, ny) warm start in MPa.

    Returns:
        NormalSolution.

    Raises:
        ValueError: bad input (names the argument). ConvergenceError: not converged.
    """
    if not isinstance(hs, ElasticHalfSpace):
        raise ValueError(f"hs: expected an ElasticHalfSpace, got {type(hs).__name__}")
    grid = hs.grid
    h = grid.check_field("gap", gap)
    if (load is None) == (approach is None):
        raise ValueError("load/approach: give exactly one of load (N) or approach (mm)")
    if mask is None:
        allowed = np.ones(grid.shape, dtype=bool)
    else:
        allowed = np.asarray(mask)
        if allowed.shape != grid.shape:
            raise ValueError(f"mask: expected shape {grid.shape}, got {allowed.shape}")
        allowed = allowed.astype(bool)
        if not allowed.any():
            raise ValueError("mask: must allow contact on at least one cell")
    tol = positive_scalar("tol", tol, upper=1.0, upper_open=True)
    if int(max_iter) < 1:
        raise ValueError(f"max_iter: must be >= 1, got {max_iter!r}")
    H = None
    if hardness is not None:
        H = positive_scalar("hardness", hardness)
    kw = {}
    if load is not None:
        W = positive_scalar("load", load, allow_zero=True)
        if H is not None and W > H * grid.cell_area * allowed.sum() * (1 - 1e-12):
            raise ValueError(f"load: must be below hardness × allowed area = "
                             f"{H * grid.cell_area * allowed.sum():.6g} N, got {W!r}")
        kw["load"] = np.array([W])
    else:
        d = float(approach)
        if not np.isfinite(d):
            raise ValueError(f"approach: must be finite, got {approach!r}")
        kw["approach"] = np.array([d])
    p0 = None if initial_pressure is None else grid.check_field("initial_pressure", initial_pressure)[None]
    try:
        res = pk_normal_batch(hs._apply_normal, h[None], allowed[None], grid.cell_area, tol=tol,
                              max_iter=int(max_iter), hardness=None if H is None else np.array([H]),
                              p0=p0, **kw)
    except ConvergenceError:
        if H is None or load is None:
            raise
        res = _capped_by_approach(hs, h, allowed, kw["load"], H, tol)
    p = res["pressure"][0]
    contact = p > 0
    return NormalSolution(
        pressure=p, gap=res["gap"][0], displacement=res["displacement"][0],
        approach=float(res["approach"][0]), load=float(p.sum() * grid.cell_area), contact=contact,
        contact_fraction=float(contact.sum() / allowed.sum()), iterations=int(res["iterations"][0]),
        residual=float(res["residual"][0]), mask=allowed, initial_gap=h,
        hardness=float("inf") if H is None else H)
