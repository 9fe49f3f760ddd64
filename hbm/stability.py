"""Stability of harmonic-balance solutions.

* Hill's method (small systems): the Floquet exponents are approximated by the eigenvalues of the
  quadratic Hill problem  (J_q + l (C~ + 2 w M~ nabla) + l^2 M~) p = 0  built on the harmonic
  Jacobian J_q of the full structure (linear part + friction Jacobian); of its 2 n_H n eigenvalues
  the 2n with the smallest |Im| are kept (Lazarus & Thomas sorting). Unstable if one has a real
  part > ``tol`` * w. Rigid-body modes give zero exponents and count as stable.
* Fold parity (large reduced models, where the 2 n_H n eigenproblem is out of reach): along a
  continuation branch that starts stable, stability flips at each turning point (saddle-node).
  This misses Neimark–Sacker bifurcations — documented limitation.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

#: largest 2 n_H n for which Hill's eigenproblem is solved
HILL_LIMIT = 1200


def hill_available(hb) -> bool:
    """True if Hill's method can be run for this solver (small size and a physical damping matrix)."""
    s = hb.s
    has_c = s.C is not None or s.damping_ratio is None or hb.G.complete
    return 2 * hb.nH * s.n <= HILL_LIMIT and has_c


def _physical_damping(hb) -> np.ndarray:
    s = hb.s
    if s.C is not None:
        return s.C
    if s.damping_ratio is None:
        return np.zeros((s.n, s.n))
    MP = s.M @ hb.G.Phi                       # complete modal basis: C = M Phi C_m Phi^T M
    return MP @ hb.G.Cm @ MP.T


def floquet_exponents(hb, sol) -> np.ndarray:
    """Approximate Floquet exponents (2n,) of solution ``sol`` by Hill's method, 1/s."""
    s, nH, n, w = hb.s, hb.nH, hb.s.n, sol.omega
    jac = getattr(sol, "_jac", None)
    if jac is None:
        U = hb.from_contact(sol.contact)
        _, _, nl, Dg = hb.residual(U, w, hb.ulin(w, np.zeros(n)), jacobian=True)
    else:
        nl, Dg = jac
    nab = hb.fourier.nabla
    Kb, M, C = hb.G.Kb, s.M, _physical_damping(hb)
    I = np.eye(nH)
    # harmonic-major layout: d/dt -> w nabla, d2/dt2 -> w^2 nabla^2
    Jq = np.kron(I, Kb) + w * w * np.kron(nab @ nab, M) + w * np.kron(nab, C)
    if nl.size:
        nc = hb.nc
        Dc = np.zeros((nH * nc, nH * nc))
        cn = (3 * nl[:, None] + np.arange(3)).ravel()          # contact coordinates of nl
        # element layout (e, d*nH + h) -> global contact layout h*nc + c
        e = np.arange(nl.size)[:, None, None]
        d = np.arange(3)[None, :, None]
        h = np.arange(nH)[None, None, :]
        gidx = (h * nc + 3 * nl[e] + d).reshape(nl.size, 3 * nH)
        Dc[gidx[:, :, None], gidx[:, None, :]] = Dg
        Bh = sp.kron(sp.eye(nH), hb.B).toarray()
        Jq = Jq + Bh.T @ Dc @ Bh
    Mt = np.kron(I, M)
    C1 = np.kron(I, C) + 2.0 * w * np.kron(nab, M)
    N = nH * n
    Minv = np.linalg.inv(Mt)
    A = np.zeros((2 * N, 2 * N))
    A[:N, N:] = np.eye(N)
    A[N:, :N] = -Minv @ Jq
    A[N:, N:] = -Minv @ C1
    lam = sla.eigvals(A)
    order = np.argsort(np.abs(lam.imag))
    return lam[order[:2 * n]]


def is_stable_hill(hb, sol, tol: float = 1e-6) -> bool:
    """Hill stability of ``sol``: all retained Floquet exponents have Re <= tol * omega."""
    lam = floquet_exponents(hb, sol)
    return bool(np.max(lam.real) <= tol * sol.omega)
