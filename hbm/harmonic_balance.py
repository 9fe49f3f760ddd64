"""Multiharmonic balance of a linear structure with 3D friction contacts.

Formulation (condensed on the contacts)
--------------------------------------
The unknowns are the harmonics U (n_H x n_c) of the contact relative displacements u = B q only
(n_c = 3 n_e); the response of every structure DOF follows afterwards from the receptance. With the
linear base K~ = K + B^T diag(k0) B (the contacts closed at rest, stuck), the balance per harmonic is

    R(U, w) = U - U_lin(w) + G(w) g(U) = 0,      g = F_nl(U) - k0 U,

where G is the base receptance (modal + static residual flexibility, see ``structure``) and g the
nonlinear *correction* force. Elements stuck all cycle (from rest) or open all cycle (when open at
rest) have dg/dU = 0, so the Newton matrix J = I + G dg/dU has identity columns there: the linear
system is solved exactly on the nonlinear elements only (size 3 k n_H, k = number of elements that
slip or separate somewhere in the cycle), and the other unknowns follow by one receptance product.
Open-all-cycle elements thus carry no unknowns in the solve and stuck-all-cycle ones are linear.

Linear solver (what we chose and why)
-------------------------------------
* k small (3 k n_H <= ``dense_limit`` = 400): the reduced Jacobian is formed and LU-factorized
  (about a millisecond; the bordered determinant then also orients the continuation tangent).
* k large: the dense 3 k n_H system (7140 for 340 elements, H = 3; ~6 s per LU here) is
  factorized only for a determinant's sign at corner folds and where GMRES fails, in mixed
  precision (``dense.lu_solve_sign``). Otherwise GMRES runs on it matrix-free (one receptance product per iteration: modal low rank
  + the dense static residual block), preconditioned by ``preconditioner.PatchPreconditioner``
  (issue 16, session 28): each element's own block I + G_ee D_e (all harmonics coupled)
  inverted exactly (``ElementBlockPreconditioner``), then a coarse correction on patches of
  about 15 elements (their uniform motion per direction and harmonic row, Z^T J Z by one LU,
  reused like the other preconditioners' factors; switched on where the element blocks alone
  need more than ``COARSE_ON`` iterations): 17 GMRES iterations per solve on the default
  model's top-level baseline sweep where the element blocks alone needed 41. The element blocks
  replaced (session 7)
  the harmonic-averaged one, the exact inverse of I + G_h k_bar (one real LU of I + R k_bar and a
  rank-m Woodbury correction per harmonic, reused while the nonlinear set stays the same and
  GMRES does not slow down, ``_PreconditionerCache``): on the default model's curves the element
  blocks took 1.3-1.7 times less time for the same points and peaks. The module
  ``preconditioner`` has the numbers, the mean-coupled and two-level alternatives.

Newton uses a backtracking line search on ||R|| and raises ``ConvergenceError`` with the residual
reached when it stalls.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.linalg as sla
from numpy.lib.stride_tricks import as_strided
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .continuation import ContinuationSettings, FRFResult, continue_frf
from .dense import MIXED_SIZE, lu_solve, lu_solve_sign
from .errors import ConvergenceError, CycleNotClosed
from .fourier import Fourier
from .friction import FrictionContacts, once
from .preconditioner import (PRECONDITIONERS, CoarseFactor, ElementBlockPreconditioner,
                             PatchPreconditioner, PatchSpace, TwoLevelPreconditioner)
from .structure import LinearStructure


class Solution:
    """A periodic solution at one frequency.

    Attributes:
        omega: excitation frequency, rad/s.
        coefficients: (2H+1, n) displacement harmonics of every DOF, mm ([a0, a1, b1, ...]);
            recovered from the contact harmonics on first access (cached).
        contact: (ne, 3, 2H+1) harmonics of the element relative displacements (t1, t2, n), mm.
        residual: relative residual norm reached.
        iterations: Newton iterations used.
        n_nonlinear: number of elements that slip or separate somewhere in the cycle.
    """

    def __init__(self, omega: float, coefficients, contact: np.ndarray, residual: float,
                 iterations: int, n_nonlinear: int, recover=None) -> None:
        self.omega = float(omega)
        self._coefficients = None if coefficients is None else np.asarray(coefficients)
        self.contact = contact
        self.residual = residual
        self.iterations = iterations
        self.n_nonlinear = n_nonlinear
        self._recover = recover            # (hb, y) to recover structure DOFs lazily
        self._jac = None

    @property
    def coefficients(self) -> np.ndarray:
        if self._coefficients is None:
            hb, y = self._recover
            self._coefficients = hb._recover_dofs(self.omega, y, None)
        return self._coefficients

    def dof_coefficients(self, dof: int) -> np.ndarray:
        """Harmonics (2H+1,) of one DOF (cheap: does not recover the whole structure)."""
        if self._coefficients is not None:
            return self._coefficients[:, dof]
        hb, y = self._recover
        return hb._recover_dofs(self.omega, y, dof)

    def amplitude(self, dof: int, harmonic: int = 1) -> float:
        """Amplitude sqrt(a_h^2 + b_h^2) of harmonic ``harmonic`` (default the first) at ``dof``, mm."""
        X = self.dof_coefficients(dof)
        if harmonic == 0:
            return float(abs(X[0]))
        return float(np.hypot(X[2 * harmonic - 1], X[2 * harmonic]))


@dataclass
class ElementResults:
    """Per-element results over one period of a solution (ne elements, nt samples).

    Attributes:
        status: (ne,) 0 stuck, 1 stick–slip, 2 gross slip (slipping >= 90 % of the cycle),
            3 partly open, 4 open.
        energy: (ne,) energy dissipated per cycle, N·mm (work of the retained force harmonics,
            the quantity that balances the input power in the HBM).
        mean_normal: (ne,) cycle-mean normal force N(t), N.
        slip_fraction: (ne,) fraction of the samples spent slipping.
        u_t: (ne, 2, nt) tangential relative displacement, mm.
        T: (ne, 2, nt) tangential force, N.
        N: (ne, nt) total normal force, N.
        time: (nt,) sample times over one period, s.
    """

    status: np.ndarray
    energy: np.ndarray
    mean_normal: np.ndarray
    slip_fraction: np.ndarray
    u_t: np.ndarray
    T: np.ndarray
    N: np.ndarray
    time: np.ndarray


def _contact_operator(dofs: np.ndarray, n: int) -> sp.csr_matrix:
    ne = dofs.shape[0]
    rows, cols, vals = [], [], []
    for body, sign in ((0, 1.0), (1, -1.0)):
        d = dofs[:, body, :].ravel()
        r = np.arange(3 * ne)
        keep = d >= 0
        rows.append(r[keep]); cols.append(d[keep]); vals.append(np.full(keep.sum(), sign))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(3 * ne, n))



def _blocks_times(D: np.ndarray, x: np.ndarray) -> np.ndarray:
    """D_k x_k for blocks D (k, a, b) and rows x (k, b): (k, a). numpy's batched matmul, 1.8x
    faster than einsum for the friction elements' 21 x 21 blocks (37 against 68 us for 353)."""
    return np.matmul(D, x[:, :, None])[:, :, 0]


def _blocks_transposed_times(D: np.ndarray, x: np.ndarray) -> np.ndarray:
    """D_kᵀ x_k for blocks D (k, a, b) and rows x (k, a): (k, b)."""
    return np.matmul(x[:, None, :], D)[:, 0, :]


def _modal_apply(Psi: np.ndarray, Ls, v: np.ndarray) -> np.ndarray:
    """Modal part of the receptance on real harmonic rows: (n_H, n) -> (n_H, n).

    Row 0 is the mean, rows 2h-1, 2h the cosine and sine of harmonic h (complex amplitude
    c_h = x - i y); Ls[h] the modal factors of harmonic h, (m,) diagonal or (m, m), or their
    :class:`_DiagonalFactors`. The two products with the real mode shapes Psi (n, m) run once on
    all real rows: complex products per harmonic converted Psi to complex on every call, which
    cost more than the products.
    """
    W = Psi.T @ v.T                                                   # (m, n_H)
    if not isinstance(Ls, _DiagonalFactors):
        Ls = _DiagonalFactors.of(Ls) or Ls
    if isinstance(Ls, _DiagonalFactors):
        return (Psi @ Ls.times(W)).T
    S = np.empty_like(W)
    for h, L in enumerate(Ls):
        if h == 0:
            S[:, 0] = (L * W[:, 0]).real if L.ndim == 1 else (L @ W[:, 0]).real
        elif L.ndim == 1:
            a, b, x, y = L.real, L.imag, W[:, 2 * h - 1], W[:, 2 * h]
            S[:, 2 * h - 1] = a * x + b * y
            S[:, 2 * h] = a * y - b * x
        else:
            z = L @ (W[:, 2 * h - 1] - 1j * W[:, 2 * h])
            S[:, 2 * h - 1], S[:, 2 * h] = z.real, -z.imag
    return (Psi @ S).T


class _DiagonalFactors:
    """Diagonal modal factors of harmonics 0..H as real arrays, so that a product with them is
    five array operations instead of four per harmonic (it ran in every GMRES iteration:
    90 us a call, most of it the Python loop over harmonics)."""

    def __init__(self, Ls: list) -> None:
        self.L0 = np.ascontiguousarray(Ls[0].real)
        self.a = np.stack([L.real for L in Ls[1:]], axis=1)          # (m, H)
        self.b = np.stack([L.imag for L in Ls[1:]], axis=1)

    @classmethod
    def of(cls, Ls) -> "_DiagonalFactors | None":
        """The factors of Ls when each is diagonal (m,), else None."""
        return cls(Ls) if all(np.ndim(L) == 1 for L in Ls) else None

    def times(self, W: np.ndarray) -> np.ndarray:
        """The factors applied to the modal rows W (m, n_H): (a + ib)(x - iy) in real
        arithmetic, row 0 the mean (numpy's complex product may contract to FMA on some paths
        and not on others, which made two equal runs differ in the last bit)."""
        x, y = W[:, 1::2], W[:, 2::2]
        S = np.empty_like(W)
        S[:, 0] = self.L0 * W[:, 0]
        S[:, 1::2] = self.a * x + self.b * y
        S[:, 2::2] = self.a * y - self.b * x
        return S

#: Newton gives up when its residual has not halved in this many iterations (see ``newton``) ...
STALL_ITERATIONS = 10
#: ... or after this many line searches in a row found no decrease (10 trials each) ...
STALL_LINE_SEARCHES = 3
#: ... once its best relative residual is below this: the end game, where a stall is a kink of
#: the sampled friction law; far from the solution damped Newton may crawl before it converges
#: (the friction demo's oscillator: 3 failed line searches at 0.68, then converged)
STALL_BELOW = 1e-5


#: a Newton step's GMRES stops once its linear residual is below this fraction of the Newton
#: tolerance's absolute residual (tol x scale), not at ``krylov_tol`` relative to the right-hand
#: side: after the step the residual is that linear residual plus the step's quadratic error, so
#: solving further buys nothing (the "forcing term" of inexact Newton, Eisenstat & Walker 1996;
#: Kelley 2003, ch. 3). The first corrector step from a residual of 1e-3 then stops at 1e-5
#: relative instead of 1e-8, the last one at 1e-2 or so. Never looser than ``krylov_tol``
#: relative when the right-hand side is large, never looser than KRYLOV_ETA_MAX when it is small
#: (a residual just above the tolerance still gets a step that clears it).
KRYLOV_FORCING = 0.1
KRYLOV_ETA_MAX = 1e-2


#: after GMRES failed on two reduced systems in a row (its restarts exhausted, then the dense
#: LU), the next this many systems of at least DENSE_FALLBACK_SIZE times the last one's size go to
#: the LU directly: where the preconditioner fails it keeps failing (the stiff layer joint's
#: backbone on the default model: 12 of 13 Newton systems at 321 elements each paid 600 GMRES
#: iterations before the LU). One failure is not enough: on the forced top-level curves a
#: failure is isolated, and ten 7413-unknown LUs (6 s each) instead of GMRES solves (0.3 s)
#: made the default baseline@L2 curve 8 % slower.
DENSE_AFTER_FALLBACK = 10
DENSE_FALLBACK_SIZE = 0.9

#: GMRES's Krylov space before a restart, and its restart cycles (scipy's ``maxiter``): after
#: GMRES_MAXITER cycles GMRES has failed and the dense LU takes over. Restarted at 150, the stiff
#: layer joint's Newton systems (6743 unknowns) lost their convergence at each restart and had
#: reached 1e-9 ... 1e-6 of the right-hand side after 600 iterations: its backbone took 14 dense
#: fallbacks, then DENSE_AFTER_FALLBACK sent 28 more systems to the LU (2.4 s each), 163 s in all;
#: with 300 it took 55 s, the same points to 1e-8 (one process, issue 16, session 16). The cycles
#: are also scipy's outer loop, where it checks the true residual after the preconditioned one
#: met its tolerance: with 2 cycles of 300 (or one of 600) a default-model curve whose systems
#: need < 150 iterations sent 24 (255) of them to the LU. Systems that converge within 150
#: iterations (most on the forced curves) are solved exactly as with 150.
GMRES_RESTART = 300
GMRES_MAXITER = 4

#: the "patches" preconditioner's coarse level is switched on when a solve with the element
#: blocks alone took more than COARSE_ON GMRES iterations, and off again when a solve with it
#: took fewer than COARSE_OFF: an application costs about a quarter of an iteration more
#: (0.25 ms at 353 elements) and a new coarse factor about one element-block set-up (7 ms),
#: which a third fewer iterations do not repay. On the default model the top-level curves
#: (41-49 iterations per solve with the element blocks alone, 16-23 with the patches) keep it;
#: the middle level's (14-19 against 10-14) were 0.5-1 s slower each with it switched on at
#: 20 iterations (two whole studies: +4 and +7 s over the eight middle-level curves)
COARSE_ON = 30
COARSE_OFF = 8


class _PreconditionerCache:
    """A preconditioner kept between GMRES solves, with the conditions of its reuse.

    It is reused for the same receptance and nonlinear set, within ``REUSE_OMEGA`` (relative)
    of the frequency it was built at, while the solves it serves need at most
    ``REUSE_GROWTH`` times (plus ``REUSE_SLACK``) the GMRES iterations of its first solve: the
    friction Jacobians it was built from change from Newton step to Newton step and from point
    to point, but on the resonator's sweeps a preconditioner 17 solves old did as well as a
    fresh one (``preconditioner``), and its set-up costs several solves' worth of iterations.
    """

    REUSE_OMEGA = 1e-2
    REUSE_GROWTH = 1.5
    REUSE_SLACK = 5

    def __init__(self, G, nl: np.ndarray, omega: float, R: np.ndarray, Psi: np.ndarray,
                 apply) -> None:
        self.G, self.nl, self.omega, self.R, self.Psi, self.apply = G, nl.copy(), omega, R, Psi, apply
        self.first = None          # GMRES iterations of the first solve served
        self.worn = False

    def usable(self, G, nl: np.ndarray, omega: float) -> bool:
        return (G is self.G and not self.worn and np.array_equal(nl, self.nl)
                and abs(omega - self.omega) <= self.REUSE_OMEGA * self.omega)

    def observe(self, iterations: int) -> None:
        """Record a solve's GMRES iterations; a preconditioner that needs many more than on its
        first solve is rebuilt at the next one."""
        if self.first is None:
            self.first = iterations
        elif iterations > self.REUSE_GROWTH * self.first + self.REUSE_SLACK:
            self.worn = True


class HarmonicBalance:
    """Harmonic balance solver for ``s`` with friction contacts ``c``.

    Args:
        s: the linear structure.
        c: the friction contacts (DOF indices must be < s.n).
        harmonics: highest harmonic H (0..H are kept).
        samples: AFT time samples per period.
        tol: Newton tolerance on ||R|| relative to the response norm.
        max_iter: Newton iteration limit.
        dense_limit: largest reduced system size factorized directly (else GMRES).
        krylov_tol: relative GMRES tolerance of the reduced Newton systems, the tightest a
            Newton step uses (it stops at the residual the step needs when that is looser,
            :data:`KRYLOV_FORCING`; a Newton tolerance of 1e-7 needs no more than 1e-8; 1e-11
            keeps Newton quadratic down to 1e-9).
        preconditioner: GMRES preconditioner, a key of ``preconditioner.PRECONDITIONERS``:
            "patches" (the default since issue 16's session 28, ``PatchPreconditioner``:
            the element blocks and a coarse space of patches of elements), "element"
            (``ElementBlockPreconditioner``, the default before), "averaged", "mean-coupled"
            or "two-level" (see the module ``preconditioner``).
    """

    def __init__(self, s: LinearStructure, c: FrictionContacts, harmonics: int = 3,
                 samples: int = 128, tol: float = 1e-9, max_iter: int = 40,
                 dense_limit: int = 400, krylov_tol: float = 1e-11,
                 preconditioner: str = "patches") -> None:
        if not isinstance(s, LinearStructure) or not isinstance(c, FrictionContacts):
            raise ValueError("HarmonicBalance(s, c): s must be a LinearStructure and c FrictionContacts")
        c.check_dofs(s.n)
        if not (0 < tol < 1):
            raise ValueError(f"tol must be in (0, 1), got {tol}")
        if not (0 < krylov_tol < 1):
            raise ValueError(f"krylov_tol must be in (0, 1), got {krylov_tol}")
        if preconditioner not in PRECONDITIONERS:
            raise ValueError(f"preconditioner must be one of {'|'.join(PRECONDITIONERS)}, "
                             f"got {preconditioner!r}")
        self.preconditioner = preconditioner
        self.s, self.c = s, c
        self.fourier = Fourier(harmonics, samples)
        self.H, self.nH = self.fourier.H, self.fourier.nH
        self.tol, self.max_iter, self.dense_limit = float(tol), int(max_iter), int(dense_limit)
        self.B = _contact_operator(c.dofs, s.n)
        self.k0 = c.base_stiffness().ravel()
        self.G = s.receptance(self.B, self.k0)
        self.ne, self.nc = c.ne, 3 * c.ne
        self._pre = None          # cached preconditioner (GMRES path)
        self._patches = None      # (contact rows, PatchSpace) of the "patches" preconditioner
        self._coarse_on = False   # its coarse level in use (COARSE_ON, COARSE_OFF)
        self._coarse_used = False # ... in the current solve
        self._rows = None         # (G, nonlinear set, R and Psi on its coordinates)
        self._dense_left, self._dense_size = 0, 0     # dense solves owed to the last fallbacks
        self._gmres_failed = False                    # the last GMRES solve failed
        self.krylov_tol = float(krylov_tol)
        self.stats = {"residuals": 0, "jacobians": 0, "linear_solves": 0, "gmres_iterations": 0,
                      "sign_factorizations": 0, "unsigned_restarts": 0, "dense_fallbacks": 0,
                      "dense_after_fallback": 0, "preconditioners": 0, "lu_single": 0,
                      "lu_double": 0}

    # ------------------------------------------------------------------ layouts
    def to_contact(self, U: np.ndarray) -> np.ndarray:
        """Unknowns in the element layout of ``Solution.contact`` (a view when U is contiguous).

        Args:
            U: (n_H, n_c) contact relative harmonics, n_c = 3 n_e (t1, t2, n per element), mm.

        Returns:
            (n_e, 3, n_H) array: per element and direction, the harmonics [a0, a1, b1, ...], mm.
        """
        return U.reshape(self.nH, self.ne, 3).transpose(1, 2, 0)

    def from_contact(self, X: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_contact`: (n_e, 3, n_H) element layout -> (n_H, n_c) unknowns, mm."""
        return X.transpose(2, 0, 1).reshape(self.nH, -1)

    def check_force(self, force) -> np.ndarray:
        """Validated force amplitude: a finite float array of shape (n,), N (else ValueError)."""
        f = np.asarray(force, dtype=float)
        if f.shape != (self.s.n,):
            raise ValueError(f"force must have shape ({self.s.n},), got {f.shape}")
        if not np.all(np.isfinite(f)):
            raise ValueError("force must be finite")
        return f

    @staticmethod
    def check_omega(omega) -> float:
        """Validated excitation frequency as a float, rad/s: finite and > 0 (else ValueError)."""
        if not np.isfinite(omega) or omega <= 0:
            raise ValueError(f"omega must be a finite frequency > 0 rad/s, got {omega!r}")
        return float(omega)

    # ------------------------------------------------------------------ linear operators
    def ulin(self, omega: float, force: np.ndarray) -> np.ndarray:
        """Contact response (n_H, n_c) of the linear base to force·cos(wt)."""
        U = np.zeros((self.nH, self.nc))
        u = self.G.force_response(1, omega, force.astype(complex))
        U[1], U[2] = u.real, -u.imag
        return U

    def gapply(self, omega: float, g: np.ndarray, transpose: bool = False,
               factors: list[np.ndarray] | None = None, static: bool = True) -> np.ndarray:
        """Receptance times correction-force harmonics, (n_H, n_c) -> (n_H, n_c).

        transpose=True applies the transpose of the real harmonic-block operator (G is complex
        symmetric, so that is the block operator of conj(G)).

        Args:
            factors: modal factors per harmonic h = 0..H to use instead of ``G.modal(h, omega)``
                (the nonlinear-mode solver applies their derivatives in omega and xi this way).
            static: add the static residual flexibility (False for such derivatives: it does not
                depend on omega)."""
        G = self.G
        # static residual flexibility is real and the same for every harmonic: one real product
        # (R is symmetric: g R is (R gᵀ)ᵀ, :func:`_operator`)
        out = g @ G.R if static else np.zeros_like(g)
        Ls = [G.modal(h, omega) if factors is None else factors[h] for h in range(self.H + 1)]
        # transposed blocks [[a, -b], [b, a]] act as conj(G) = a - i b on c = x - i y
        out += _modal_apply(G.Psi, [L.conj() for L in Ls] if transpose else Ls, g)
        return out

    # ------------------------------------------------------------------ residual
    def residual(self, U: np.ndarray, omega: float, Ul: np.ndarray, jacobian: bool = True,
                 deferred: bool = False):
        """R = U - U_lin + G g(U); returns R, g, nonlinear element indices, their dg/dU blocks.

        With ``deferred`` the blocks come as a function computing them on its first call
        (``FrictionContacts.evaluate``): what line searches use for their trials."""
        self.stats["residuals"] += 1
        F, nl, DF = self.c.evaluate(self.to_contact(U), self.fourier, jacobian, deferred=True)
        g = self.from_contact(F) - self.k0[None, :] * U
        R = U - Ul + self.gapply(omega, g)
        if not (jacobian and nl.size):
            return R, g, nl, None
        Dg = once(lambda: self._dg_blocks(nl, DF()))
        return R, g, nl, (Dg if deferred else Dg())

    def _dg_blocks(self, nl: np.ndarray, DF: np.ndarray) -> np.ndarray:
        """dg/dU = dF/dU - k0 of the elements nl (DF overwritten), element layout d*nH + h."""
        self.stats["jacobians"] += 1
        k0 = self.k0.reshape(self.ne, 3)[nl]                   # (k, 3)
        diag = np.repeat(k0, self.nH, axis=1)
        i = np.arange(3 * self.nH)
        DF[:, i, i] -= diag
        return DF

    def r_omega(self, omega: float, force: np.ndarray, g: np.ndarray) -> np.ndarray:
        """dR/dw at fixed U (central difference of the linear operators only, no AFT)."""
        eps = 1e-6 * omega
        rp = -self.ulin(omega + eps, force) + self.gapply(omega + eps, g)
        rm = -self.ulin(omega - eps, force) + self.gapply(omega - eps, g)
        return (rp - rm) / (2 * eps)

    # ------------------------------------------------------------------ linear solve
    def _elidx(self, k: int) -> np.ndarray:
        """Reduced-layout index (h * 3k + 3e + d) of element-layout entry (e, d*nH + h)."""
        nH = self.nH
        e = np.arange(k)[:, None, None]
        d = np.arange(3)[None, :, None]
        h = np.arange(nH)[None, None, :]
        return (h * 3 * k + 3 * e + d).reshape(k, 3 * nH)

    def _dense_jacobian(self, omega: float, cn: np.ndarray, Dg: np.ndarray,
                        out: np.ndarray | None = None) -> np.ndarray:
        """The reduced Jacobian J = I + G D (reduced layout), formed densely.

        G's harmonic blocks (the real form of the complex G_h: only the cosine and sine rows of
        one harmonic couple) times D's element blocks, one batched product per pair of coupled
        row blocks: a 7413-unknown J (the default model's top level) took 4-6 s through the
        whole real receptance and its element columns, 1.2 s so.

        Args:
            cn: contact coordinates of the k nonlinear elements (3k,).
            Dg: (k, 3 n_H, 3 n_H) element Jacobians, element layout d n_H + h.
            out: (P, P) array to fill (may be a view, e.g. the top left of a bordered matrix).
        Returns:
            J, (P, P) with P = n_H 3k.
        """
        nH, p = self.nH, cn.size
        k, P = p // 3, nH * p
        J = np.empty((P, P)) if out is None else out      # every block is written once below
        # a single-precision ``out`` (the mixed-precision LU's matrix, ``dense.lu_solve_sign``)
        # is formed in single precision: its entries are those of the double product to a few
        # ulps, which the LU's refinement against the double-precision operator and its sign
        # certificate (the backward error) see as they saw the rounding; 0.20 s against 1.17 s
        # at 7413 unknowns (the products and the strided copies move half the bytes)
        dt = J.dtype
        D5 = Dg.reshape(k, 3, nH, 3, nH).astype(dt, copy=False)
        for h in range(self.H + 1):
            Gh = self.G.matrix(h, omega, cn, cn)
            re, im = Gh.real.astype(dt, copy=False), Gh.imag.astype(dt, copy=False)
            if h == 0:
                rows = [(0, [(0, re)])]
            else:
                a, b = 2 * h - 1, 2 * h
                rows = [(a, [(a, re), (b, im)]), (b, [(a, -im), (b, re)])]
            for r, terms in rows:
                acc = 0.0
                for c, Gm in terms:       # Gm times blockdiag_e(D5[e, :, c, :, :]): (k, p, 3 n_H)
                    acc = acc + np.matmul(Gm.reshape(p, k, 3).transpose(1, 0, 2),
                                          D5[:, :, c, :, :].reshape(k, 3, 3 * nH))
                # entry (e, i, d, col) is J[r p + i, col p + 3e + d]: one strided copy into a
                # view of J in acc's layout (a copy per column block took 4 times as long)
                s0, s1 = J.strides
                view = as_strided(J[r * p:(r + 1) * p], shape=(k, p, 3, nH),
                                  strides=(3 * s1, s0, s1, p * s1))
                view[...] = acc.reshape(k, p, 3, nH)
        J[np.diag_indices(P)] += 1.0
        return J

    def _reduced(self, omega: float, nl: np.ndarray, Dg: np.ndarray, dense: bool = False,
                 out: np.ndarray | None = None):
        """Reduced Newton operator on the nonlinear elements: (cn, idx, matvec, J or None, prec).

        J is formed (dense path) up to ``dense_limit``, or at any size when ``dense`` is True
        (into ``out`` when given)."""
        cn, idx = self._coords(nl)
        P = self.nH * cn.size
        if dense or P <= self.dense_limit or self._after_fallback(P):
            J = self._dense_jacobian(omega, cn, Dg, out)
            return cn, idx, (lambda x: J @ x), J, None
        matvec, prec = self._gmres_ops(omega, nl, cn, idx, Dg)
        return cn, idx, matvec, None, prec

    def _coords(self, nl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact coordinates (3k,) of the elements nl and their reduced-layout index (k, 3 n_H)."""
        return (3 * nl[:, None] + np.arange(3)).ravel(), self._elidx(nl.size)

    def _expand(self, omega, nl, cn, idx, Dg, xN):
        """G (dg/dU x_N) on all contact coordinates for a reduced vector x_N."""
        k, nH = nl.size, self.nH
        ge = _blocks_times(Dg, xN[idx])
        gfull = np.zeros((nH, self.nc))
        gfull[:, cn] = self.from_contact(ge.reshape(k, 3, nH))
        return self.gapply(omega, gfull)

    def krylov_rtol(self, b_norm: float, atol: float | None) -> float:
        """GMRES tolerance relative to ||b|| for a right-hand side of norm ``b_norm``.

        ``atol`` None: ``krylov_tol``. Else the Newton step's linear residual only has to stay
        below ``atol`` (see :data:`KRYLOV_FORCING`): the relative tolerance is atol / ||b||, at
        least ``krylov_tol`` and at most :data:`KRYLOV_ETA_MAX`.
        """
        if atol is None or not atol > 0 or not b_norm > 0:
            return self.krylov_tol
        return float(min(max(self.krylov_tol, atol / b_norm), KRYLOV_ETA_MAX))

    def _krylov(self, matvec, prec, B, P, atol=None):
        Aop = spla.LinearOperator((P, P), matvec=matvec)
        Mop = spla.LinearOperator((P, P), matvec=prec)
        X = np.empty_like(B)
        most = 0
        for i in range(B.shape[1]):
            it = [0]

            def cb(_):
                it[0] += 1
            bn = float(np.linalg.norm(B[:, i]))
            rtol = self.krylov_rtol(bn, None if atol is None else atol[i])
            x, info = spla.gmres(Aop, B[:, i], M=Mop, tol=rtol, atol=0.0, restart=GMRES_RESTART,
                                 maxiter=GMRES_MAXITER, callback=cb, callback_type="pr_norm")
            self.stats["gmres_iterations"] += it[0]
            most = max(most, it[0])
            if info != 0:
                res = np.linalg.norm(matvec(x) - B[:, i]) / max(bn, 1e-300)
                if not np.isfinite(res) or res > max(1e-7, rtol):
                    if self._pre is not None:
                        self._pre.worn = True      # a fresh one at the next solve
                    self._coarse_on = True         # ("patches") with its coarse level
                    raise ConvergenceError("GMRES did not converge on the reduced Newton system", res)
            X[:, i] = x
        patches = self.preconditioner == "patches"
        if self._pre is not None and (self._coarse_used or not patches):
            self._pre.observe(most)
        if patches:
            self._coarse_on = most >= COARSE_OFF if self._coarse_used else most > COARSE_ON
        self._gmres_failed = False
        return X

    def linsolve(self, omega: float, nl: np.ndarray, Dg, rhs: list[np.ndarray],
                 atol: list | None = None, direct: bool = False) -> list[np.ndarray]:
        """Solve J x = rhs (each (n_H, n_c)) with J = I + G dg/dU, reduced on the nonlinear elements.

        Args:
            atol: per right-hand side, the linear residual a Newton step needs (None: none,
                ``krylov_tol`` relative; see :meth:`krylov_rtol`); GMRES path only.
            direct: the dense LU whatever the size, as after a failed GMRES run (a fallback).
        """
        self.stats["linear_solves"] += 1
        if nl.size == 0:
            return [r.copy() for r in rhs]
        if direct:
            cn, idx = self._coords(nl)
            J = self._dense_fallback(omega, nl, Dg)
        else:
            cn, idx, matvec, J, prec = self._reduced(omega, nl, Dg)
        B = np.stack([r[:, cn].ravel() for r in rhs], axis=1)   # (P, nrhs) reduced layout
        if J is None:
            try:
                X = self._krylov(matvec, prec, B, B.shape[0], atol)
            except ConvergenceError:
                J = self._dense_fallback(omega, nl, Dg)
        if J is not None:
            X = lu_solve(J, B, self.stats)
            self._check_singular(X)
        return [r - self._expand(omega, nl, cn, idx, Dg, X[:, i]) for i, r in enumerate(rhs)]

    def linsolve_bordered(self, omega: float, nl: np.ndarray, Dg, cols: list[np.ndarray],
                          rows: list[np.ndarray], S: np.ndarray, R: np.ndarray, r: np.ndarray,
                          row_scale: float = 1.0, atol: float | None = None):
        """One GMRES run on a Newton system with m borders (the nonlinear modes' frequency and
        damping), where ``linsolve`` would take m + 1 runs:

            dU + G D dU + sum_k cols[k] s_k = -R,   rows[j] . (D dU) + sum_k S[j, k] s_k = -r[j],

        with D = dg/dU (nonzero on the nonlinear elements only), reduced on them as ``linsolve``
        does. The border rows are multiplied by ``row_scale`` (the weight of their residual
        against R's in the caller's merit).

        Args:
            cols: m arrays (n_H, n_c), the residual's derivatives in the border unknowns.
            rows: m arrays (n_H, n_c): the border equations' functionals of D dU.
            S: (m, m) the border equations' derivatives in the border unknowns.
            R: (n_H, n_c) residual; r: (m,) border residuals.
            atol: the linear residual the step needs (in the scaled rows; None: ``krylov_tol``
                relative, see :meth:`krylov_rtol`).
        Returns:
            (dU (n_H, n_c), s (m,)), or None where the dense path applies (``dense_limit``,
            after GMRES failures): the caller then solves the m + 1 right-hand sides with
            ``linsolve``. Raises ConvergenceError where GMRES fails (then ``linsolve`` with
            ``direct``, as ``linsolve`` itself falls back).
        """
        k, m = nl.size, len(cols)
        P = self.nH * 3 * k
        if k == 0 or P <= self.dense_limit or self._after_fallback(P, count=False):
            return None
        self.stats["linear_solves"] += 1
        cn, idx, matvec, _, prec = self._reduced(omega, nl, Dg)
        C = np.stack([c[:, cn].ravel() for c in cols], axis=1)              # (P, m)
        V = np.empty((m, P))
        for j, row in enumerate(rows):                  # rows . (D x) = (D^T rows) . x
            rN = row[:, cn].ravel()
            V[j, idx] = _blocks_transposed_times(Dg, rN[idx])
        V *= row_scale
        Ss = row_scale * np.asarray(S, float)

        def mv(z):
            return np.concatenate([matvec(z[:P]) + C @ z[P:], V @ z[:P] + Ss @ z[P:]])

        def pc(z):
            return np.concatenate([prec(z[:P]), np.linalg.solve(Ss, z[P:])])
        b = np.concatenate([-R[:, cn].ravel(), -row_scale * np.asarray(r, float)])
        z = self._krylov(mv, pc, b[:, None], P + m, None if atol is None else [atol])[:, 0]
        s_ = z[P:]
        dU = -R - sum(c * sk for c, sk in zip(cols, s_)) - self._expand(omega, nl, cn, idx, Dg, z[:P])
        return dU, s_

    def _dense_fallback(self, omega, nl, Dg, out=None):
        """The reduced Jacobian formed for an LU solve where GMRES stalled: a preconditioner can
        be poor where a few elements' Jacobians are stiff (e.g. slip starting right at a
        closing, where the slip law is singular, or a stiff contact), and the exact solve costs a
        factorization of the reduced system instead of a failed continuation step."""
        self.stats["dense_fallbacks"] += 1
        P = self.nH * 3 * nl.size
        if self._gmres_failed:
            self._dense_left, self._dense_size = DENSE_AFTER_FALLBACK, P
        self._gmres_failed = True
        return self._reduced(omega, nl, Dg, dense=True, out=out)[3]

    def _check_singular(self, X: np.ndarray) -> None:
        """After an LU solve: a non-finite solution means the system is singular (a zero pivot),
        so a GMRES failure on it was not the preconditioner's: the systems after it go back to
        GMRES instead of ``DENSE_AFTER_FALLBACK`` LUs. (With the secant predictor, 22b's model's
        baseline@L2 met a corner-restart predictor whose bordered systems were singular: its
        corrector's and its tangent's GMRES failed, and the ten LUs after them took 60 of 125 s.)
        The caller sees the non-finite solution and fails the step."""
        if not np.all(np.isfinite(X)):
            self._gmres_failed, self._dense_left = False, 0

    def _after_fallback(self, P: int, count: bool = True) -> bool:
        """True for a system solved directly by LU because GMRES failed on two in a row, about
        as large, shortly before (``DENSE_AFTER_FALLBACK``); ``count``: the system is solved so
        now (once per system)."""
        if self._dense_left > 0 and P >= DENSE_FALLBACK_SIZE * self._dense_size:
            if count:
                self._dense_left -= 1
                self.stats["dense_after_fallback"] += 1
            return True
        return False

    def linsolve_aug(self, omega, nl, Dg, Rw, tU, tw, rhs, exact_sign: bool = False,
                     atol: list | None = None):
        """Bordered Newton solves of pseudo-arc-length continuation (nonsingular at folds).

        Solves [[J, Rw], [tU^T, tw]] [dU; dw] = [-R; -c] for each (R, c) in ``rhs`` (tU, tw
        already scaled), reduced on the nonlinear elements: with dU_R = -R_R - Rw_R dw - J_RN dU_N
        the last row becomes (tU_N - J_RN^T tU_R) . dU_N + (tw - tU_R . Rw_R) dw = -c + tU_R . R_R.

        Args:
            exact_sign: factorize the bordered system by LU even above ``dense_limit``, so that
                the sign of its determinant is known (the continuation asks for it at corner
                folds only; counted in ``stats["sign_factorizations"]``).
            atol: per right-hand side, the linear residual a corrector step needs (None:
                ``krylov_tol`` relative; see :meth:`krylov_rtol`); GMRES path only.

        Returns:
            list of (dU (n_H, n_c), dw), and the sign of the bordered determinant (0 if unknown,
            i.e. on the GMRES path).
        """
        self.stats["linear_solves"] += 1
        if nl.size == 0:
            den = tw - np.sum(tU * Rw)
            out = []
            for R, c in rhs:
                dw = (-c + np.sum(tU * R)) / den
                out.append((-R - Rw * dw, dw))
            return out, int(np.sign(den))
        P = self.nH * 3 * nl.size
        # the bordered matrix, J formed in place on the dense path (a 7413-unknown J is 440 MB);
        # above dense.MIXED_SIZE in single precision, as it is factorized (the refinement's
        # residuals use the matrix-free operator in double)
        single = P + 1 >= MIXED_SIZE
        A = np.empty((P + 1, P + 1), np.float32 if single else float)
        cn, idx, matvec, J, prec = self._reduced(omega, nl, Dg, dense=exact_sign, out=A[:P, :P])
        if exact_sign and prec is None and self.nH * cn.size > self.dense_limit:
            self.stats["sign_factorizations"] += 1
        tR = tU.copy()
        tR[:, cn] = 0.0
        y = self.gapply(omega, tR, transpose=True)[:, cn].ravel()
        v = tU[:, cn].ravel().copy()
        v[idx] -= _blocks_transposed_times(Dg, y[idx])
        beta = tw - np.sum(tR * Rw)
        RwN = Rw[:, cn].ravel()
        Bm = np.stack([np.concatenate([-R[:, cn].ravel(), [-c + np.sum(tR * R)]]) for R, c in rhs], axis=1)
        if J is None:
            def mv(z):
                return np.concatenate([matvec(z[:P]) + RwN * z[P], [v @ z[:P] + beta * z[P]]])

            def pc(z):
                return np.concatenate([prec(z[:P]), [z[P] / beta if beta != 0 else z[P]]])
            try:
                Z = self._krylov(mv, pc, Bm, P + 1, atol)
                sign = 0
            except ConvergenceError:
                J = self._dense_fallback(omega, nl, Dg, out=A[:P, :P])
        if J is not None:
            A[:P, P], A[P, :P], A[P, P] = RwN, v, beta
            # mixed precision above dense.MIXED_SIZE, the sign only where certified
            if single:
                op = self._operator(omega, nl, cn, idx, Dg)

                def mv64(z):
                    return np.concatenate([op(z[:P]) + RwN * z[P], [v @ z[:P] + beta * z[P]]])

                def rebuild():
                    A64 = np.empty((P + 1, P + 1))
                    self._dense_jacobian(omega, cn, Dg, out=A64[:P, :P])
                    A64[:P, P], A64[P, :P], A64[P, P] = RwN, v, beta
                    return A64
                Z, sign = lu_solve_sign(A, Bm, self.stats, matvec=mv64, rebuild=rebuild)
            else:
                Z, sign = lu_solve_sign(A, Bm, self.stats)
            self._check_singular(Z)
        out = []
        for i, (R, c) in enumerate(rhs):
            xN, dw = Z[:P, i], Z[P, i]
            out.append((-R - Rw * dw - self._expand(omega, nl, cn, idx, Dg, xN), dw))
        return out, sign

    # ------------------------------------------------------------------ GMRES operators
    def _gmres_ops(self, omega, nl, cn, idx, Dg):
        """Matrix-free reduced Jacobian and its preconditioner (``preconditioner``), the latter
        reused from an earlier solve while that is worth it (``_PreconditionerCache``); the
        element blocks (``element``, and in ``two-level``) are built for every solve."""
        nH, p = self.nH, cn.size
        P = nH * p
        Ls = [self.G.modal(h, omega) for h in range(self.H + 1)]
        kind = PRECONDITIONERS[self.preconditioner]
        R, Psi = self._contact_rows(nl, cn)
        pre = self._pre
        if getattr(kind, "fresh", False):
            pre = None
        elif pre is None or not pre.usable(self.G, nl, omega):
            pre = self._pre = _PreconditionerCache(self.G, nl, omega, R, Psi, kind(R, Psi, Ls, Dg))
            self.stats["preconditioners"] += 1

        matvec = self._operator(omega, nl, cn, idx, Dg, R, Psi, Ls)
        self._coarse_used = self.preconditioner == "patches" and self._coarse_on
        if self.preconditioner == "patches" and not self._coarse_on:
            return matvec, ElementBlockPreconditioner(R, Psi, Ls, Dg)
        if self.preconditioner == "patches":
            # the element blocks fresh, the coarse factor reused as the other kinds are
            space = self._patch_space()
            pre = self._pre
            if pre is None or not pre.usable(self.G, nl, omega):
                pre = self._pre = _PreconditionerCache(self.G, nl, omega, R, Psi,
                                                       CoarseFactor(space, Psi, Ls, Dg))
                self.stats["preconditioners"] += 1
            return matvec, PatchPreconditioner(space, R, Psi, Ls, Dg, coarse=pre.apply)
        if pre is None:
            return matvec, kind(R, Psi, Ls, Dg)
        if self.preconditioner == "two-level":
            return matvec, TwoLevelPreconditioner(pre.apply, ElementBlockPreconditioner(R, Psi, Ls, Dg),
                                                  matvec)
        return matvec, pre.apply

    def _operator(self, omega, nl, cn, idx, Dg, R=None, Psi=None, Ls=None) -> Callable:
        """The reduced Jacobian J = I + G D as a matrix-free product x -> J x (double precision;
        R, Psi and Ls are found when not given)."""
        nH, p = self.nH, cn.size
        P = nH * p
        if R is None:
            R, Psi = self._contact_rows(nl, cn)
        if Ls is None:
            Ls = [self.G.modal(h, omega) for h in range(self.H + 1)]
        factors = _DiagonalFactors.of(Ls) or Ls

        def matvec(x):
            ge = _blocks_times(Dg, x[idx])
            gv = np.empty(P)
            gv[idx] = ge
            v = gv.reshape(nH, p)
            # R is symmetric (LinearStructure makes it so exactly): v R is (R vᵀ)ᵀ, and
            # OpenBLAS computes the (n_H, p) x (p, p) product 1.6x faster than the (p, p) x
            # (p, n_H) one (0.63 against 1.03 ms at p = 1059, n_H = 7: the R product was 30 %
            # of a top-level curve)
            return x + (v @ R + _modal_apply(Psi, factors, v)).ravel()
        return matvec

    def _patch_space(self) -> PatchSpace:
        """The coarse space of the current nonlinear set (``_contact_rows``'s), kept with it."""
        rows = self._rows
        if self._patches is None or self._patches[0] is not rows:
            self._patches = (rows, PatchSpace(rows[2], rows[3], self.nH))
        return self._patches[1]

    def _contact_rows(self, nl: np.ndarray, cn: np.ndarray):
        """R and Psi restricted to the nonlinear elements' coordinates cn, kept while the
        receptance and the nonlinear set stay the same (the set changes at a few points per
        curve, the solves happen at every Newton step)."""
        rows = self._rows
        if rows is None or rows[0] is not self.G or not np.array_equal(rows[1], nl):
            rows = self._rows = (self.G, nl.copy(), self.G.R[np.ix_(cn, cn)], self.G.Psi[cn])
        return rows[2], rows[3]

    # ------------------------------------------------------------------ Newton
    def _scale(self, U, Ul):
        return max(np.linalg.norm(U), np.linalg.norm(Ul), 1e-300)

    def step_atol(self, scale: float) -> float:
        """The linear residual a Newton step needs at response norm ``scale`` (the norm its
        convergence test multiplies ``tol`` by), absolute (:data:`KRYLOV_FORCING`)."""
        return KRYLOV_FORCING * self.tol * scale

    def converged(self, r: float, scale: float, step: float) -> bool:
        """Convergence test: ||R|| <= tol * scale, or (at a kink of the nonsmooth contact law,
        where Newton can stagnate) ||R|| <= 10 tol * scale with a last step below 10 tol * scale."""
        return r <= self.tol * scale or (r <= 10 * self.tol * scale and step <= 10 * self.tol * scale)

    def _line_search(self, omega: float, Ul: np.ndarray, U: np.ndarray, dU: np.ndarray, r: float):
        """Halve alpha (at most 10 times) while ||R(U + alpha dU)|| does not decrease enough.

        A trial whose friction march does not close (CycleNotClosed) counts as a rejected one.

        Returns:
            (alpha, residual() at U + alpha dU) of the accepted trial, or of the last one that
            could be evaluated when none decreased ||R||; (alpha, None) when none could be.
        """
        alpha, last = 1.0, (1.0, None)
        for _ in range(10):
            try:
                trial = self.residual(U + alpha * dU, omega, Ul, deferred=True)
            except CycleNotClosed:
                alpha *= 0.5
                continue
            last = (alpha, trial)
            if np.linalg.norm(trial[0]) <= (1 - 1e-4 * alpha) * r:
                break
            alpha *= 0.5
        return last

    def newton(self, omega: float, force: np.ndarray, U0: np.ndarray):
        """Damped Newton at fixed omega from U0; returns (U, residual, iterations, nonlinear
        elements).

        Gives up (ConvergenceError with the best iterate as ``best``) after ``max_iter``
        iterations, or, once the relative residual has been below ``STALL_BELOW``, as soon as it
        has not halved in ``STALL_ITERATIONS`` or ``STALL_LINE_SEARCHES`` line searches in a row
        found no decrease: at a kink of the sampled friction law Newton can sit at one residual,
        line search after failed line search (the quick model's top-level peaks: 1e-8 … 4e-6
        for 30 iterations of ~7 trials each), and the caller's fallbacks are cheaper than
        waiting."""
        Ul = self.ulin(omega, force)
        U = U0.copy()
        R, g, nl, Dg = self.residual(U, omega, Ul)
        r = np.linalg.norm(R)
        step = np.inf
        best = (np.inf, None)            # (relative residual, (U, g, nl, iteration)) of the best
        mark = (np.inf, 0)               # the last residual that halved the one before, iteration
        no_descent = 0                   # line searches in a row that found no decrease
        for it in range(1, self.max_iter + 1):
            rel = r / self._scale(U, Ul)
            if self.converged(r, self._scale(U, Ul), step):
                self._last = (g, (nl, Dg))
                return U, rel, it - 1, nl.size
            if rel < best[0]:
                best = (rel, (U, g, nl, it - 1))
            if rel <= 0.5 * mark[0]:
                mark = (rel, it - 1)
            elif best[0] <= STALL_BELOW and (it - 1 - mark[1] >= STALL_ITERATIONS
                                             or no_descent >= STALL_LINE_SEARCHES):
                raise ConvergenceError(
                    f"Newton stalled at omega = {omega:.6g} rad/s: the residual did not halve in "
                    f"{it - 1 - mark[1]} iterations ({no_descent} line searches in a row without "
                    "descent)", best[0], self._best(omega, force, best))
            (dU,) = self.linsolve(omega, nl, Dg, [-R], atol=[self.step_atol(self._scale(U, Ul))])
            alpha, trial = self._line_search(omega, Ul, U, dU, r)
            if trial is None:
                raise ConvergenceError(f"Newton at omega = {omega:.6g} rad/s: the friction march "
                                       "did not close at any line-search trial", best[0],
                                       self._best(omega, force, best))
            step = alpha * np.linalg.norm(dU)
            r_new = np.linalg.norm(trial[0])
            no_descent = no_descent + 1 if r_new > (1 - 1e-4 * alpha) * r else 0
            U, (R, g, nl, Dg), r = U + alpha * dU, trial, r_new
            Dg = Dg() if callable(Dg) else Dg
        rel = r / self._scale(U, Ul)
        if self.converged(r, self._scale(U, Ul), step):
            self._last = (g, (nl, Dg))
            return U, rel, self.max_iter, nl.size
        if rel < best[0]:
            best = (rel, (U, g, nl, self.max_iter))
        raise ConvergenceError(f"Newton did not converge at omega = {omega:.6g} rad/s in "
                               f"{self.max_iter} iterations", best[0], self._best(omega, force, best))

    def _best(self, omega: float, force: np.ndarray, best) -> Solution | None:
        """The Solution of Newton's best iterate (``best`` as kept by :meth:`newton`)."""
        rel, it = best
        if it is None:
            return None
        U, g, nl, k = it
        return self.make_solution(omega, force, U, rel, k, nl.size, g=g)

    def make_solution(self, omega: float, force: np.ndarray, U: np.ndarray, res: float,
                      it: int, nnl: int, g: np.ndarray | None = None, jac=None) -> Solution:
        """Solution object; structure DOFs are recovered from the contact harmonics on demand."""
        if g is None:
            F, _, _ = self.c.evaluate(self.to_contact(U), self.fourier, jacobian=False)
            g = self.from_contact(F) - self.k0[None, :] * U
        y = -(self.B.T @ g.T).T                                 # (nH, n) forces on the structure
        y[1] += force
        sol = Solution(omega, None, self.to_contact(U).copy(), res, it, nnl, recover=(self, y))
        sol._jac = jac
        return sol

    def _recover_dofs(self, omega: float, y: np.ndarray, dof: int | None) -> np.ndarray:
        """Displacement harmonics q_h = H(h w) y_h of all DOFs (dof None) or of one DOF."""
        G = self.G
        yc = np.concatenate([y[:1], y[1::2] - 1j * y[2::2]]).T          # (n, H+1) complex
        PtY = G.Phi.T @ yc
        for h in range(self.H + 1):
            L = G.modal(h, omega)
            PtY[:, h] = L * PtY[:, h] if L.ndim == 1 else L @ PtY[:, h]
        if dof is None:
            z = G.Phi @ PtY
            if not G.complete:
                r = G.residual_full(np.concatenate([yc.real, yc.imag], axis=1))
                z = z + r[:, :self.H + 1] + 1j * r[:, self.H + 1:]
        else:
            z = G.Phi[dof] @ PtY
            if not G.complete:
                z = z + G.residual_row(dof) @ yc
        q = np.zeros((self.nH,) + z.shape[:-1])
        q[0] = z[..., 0].real
        q[1::2] = np.moveaxis(z[..., 1:].real, -1, 0)
        q[2::2] = -np.moveaxis(z[..., 1:].imag, -1, 0)
        return q

    def solve(self, omega: float, force, guess: Solution | None = None) -> Solution:
        """Periodic response to force·cos(omega t).

        Args:
            omega: excitation frequency, rad/s (> 0).
            force: (n,) force amplitude per DOF, N.
            guess: optional starting solution (default: the linear-base response).

        Returns:
            Solution (raises ConvergenceError if Newton fails).
        """
        omega = self.check_omega(omega)
        force = self.check_force(force)
        U0 = self.ulin(omega, force) if guess is None else self.from_contact(guess.contact)
        U, res, it, nnl = self.newton(omega, force, U0)
        g, jac = self._last
        return self.make_solution(omega, force, U, res, it, nnl, g=g, jac=jac)

    # ------------------------------------------------------------------ post-processing
    def element_results(self, sol: Solution) -> ElementResults:
        """Per-element status, dissipated energy, mean normal load and load histories at ``sol``."""
        U = sol.contact
        F, _, _ = self.c.evaluate(U, self.fourier, jacobian=False)
        hist = self.c.histories(U, self.fourier)
        h = self.fourier.orders[1::2]
        # W = Int f . du = pi Sum_h h (b_u a_f - a_u b_f)
        W = np.pi * np.sum(h * (U[:, :, 2::2] * F[:, :, 1::2] - U[:, :, 1::2] * F[:, :, 2::2]), axis=(1, 2))
        t = self.fourier.theta / sol.omega
        return ElementResults(hist["status"], W, hist["N"].mean(axis=1), hist["slip_fraction"],
                              hist["u_t"], hist["T"], hist["N"], t)

    def frf(self, omega_start: float, omega_end: float, force, dof: int, *,
            settings: ContinuationSettings | None = None, guess: Solution | None = None,
            stop: Callable[[list], bool] | None = None, **options) -> FRFResult:
        """Frequency response by pseudo-arc-length continuation (``continuation.continue_frf``).

        The step and stopping settings come either from ``settings`` or from keyword ``options``
        named like its fields (``max_points=``, ``ds=``, ``ds_max=``, ``ds_min=``,
        ``max_corrector=``, ``stability=``, ``max_domega=``, ``max_damp=``; None means the
        default), never from both: giving both raises TypeError, so no setting is silently
        overridden. Either way they are validated by :class:`ContinuationSettings`.

        Args:
            omega_start, omega_end: frequency range, rad/s (either order).
            force: (n,) amplitude of force·cos(wt), N.
            dof: response DOF of ``FRFResult.amplitude``.
            settings: a ContinuationSettings.
            guess: optional Solution (or object with ``.contact``) to start Newton from at
                omega_start; default the linear-base response.
            stop: optional callable(amplitudes so far, mm) -> bool; True ends the branch there.
            **options: ContinuationSettings fields, when ``settings`` is not given.

        Returns:
            FRFResult (ConvergenceError if the step falls below ds_min).
        """
        if settings is not None and options:
            raise TypeError("frf: give either settings= or the keyword options "
                            f"({', '.join(sorted(options))}), not both")
        if settings is None:
            settings = ContinuationSettings.from_options(**options)
        return continue_frf(self, omega_start, omega_end, force, dof, settings, guess=guess, stop=stop)

    def nonlinear_mode(self, mode: int, amplitudes: tuple[float, float], dof: int, *,
                       n_points: int = 40, tol: float | None = None, max_iter: int | None = None,
                       max_halvings: int = 8, partial: bool = False):
        """Nonlinear mode (EPMC backbone) by continuation in log amplitude
        (``nonlinear_mode.continue_backbone``; the formulation is in that module's docstring).

        Args:
            mode: elastic mode of the linear base (0 = lowest non-rigid mode).
            amplitudes: (a0, a1), the first and last modal amplitude (coordinate of that
                mass-normalized linear mode, first harmonic), mm·t^0.5, 0 < a0 < a1.
            dof: response DOF of ``Backbone.displacement_amplitude``.
            n_points: log-spaced points from a0 to a1 (>= 2).
            tol, max_iter: Newton settings (default: this solver's).
            max_halvings: step halvings allowed between two output points.
            partial: when a step cannot be completed, return the points reached so far
                (``Backbone.complete`` False) instead of raising.

        Returns:
            Backbone (ConvergenceError if a step cannot be completed and not ``partial``).
        """
        from .nonlinear_mode import continue_backbone
        return continue_backbone(self, mode, amplitudes, dof, n_points=n_points, tol=tol,
                                 max_iter=max_iter, max_halvings=max_halvings, partial=partial)
