"""Linear structure and its receptance in contact (relative) coordinates.

The receptance is written about a *linear base*: the structure plus the stuck stiffness of every
contact element that is closed at rest (``K~ = K + B^T diag(k0) B``). Its low modes are computed
once (the lowest ``n_modes`` pairs of (K~, M): block Lanczos on the factor of K~ - shift M,
:mod:`hbm.lanczos`) and the contribution of the discarded modes is kept as static residual
flexibility, so that

    G(h w) = Psi (Omega^2 - (h w)^2 + i h w C_m)^-1 Psi^T + R,        Psi = B Phi,
    R = B P (K~ - shift M)^-1 P^T B^T - Psi_el (Omega_el^2 - shift)^-1 Psi_el^T,

(P = I - Phi_r Phi_r^T M removes the rigid-body modes, el: the kept elastic modes)

is exact at h w = 0 (to shift / lambda_discarded, below 1e-8) and accurate below the cut-off.
The shift is a small negative number (``RIGID_TOL`` of the largest diag K~ / diag M), so that
K~ - shift M is positive definite for a free-free structure. Rigid-body modes are detected by
their zero eigenvalue; they enter the dynamic harmonics (h >= 1) through the modal sum and are
removed from the static one (h = 0): the 0th harmonic only sees self-equilibrated contact
forces. They are among the kept modes and P keeps them out of R.
"""
from __future__ import annotations

import hashlib

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from . import lanczos


#: an eigenvalue of (K~, M) below RIGID_TOL · max(diag K~ / diag M) belongs to a rigid-body mode.
#: max(diag K~ / diag M) is a lower bound of the largest eigenvalue, and a rigid mode's
#: eigenvalue is round-off of it, ~1e-16 of it (1.0 and 0.4 (rad/s)² on the default and quick
#: models, whose bound is 5.8e14 and 2.7e14); the first elastic one is 2.4e6. 1e-12 sits between
#: the two by three orders of magnitude each way; the former 1e-9 put the default model's
#: threshold at 5.8e5, a factor 4 below its breathing mode, which a finer mesh (stiffer
#: boundary DOFs) would have made rigid (issue 16, session 24)
RIGID_TOL = 1e-12


#: the receptance's shift is -SHIFT max(diag K~ / diag M), the rigid-mode threshold mirrored:
#: K~ - shift M is positive definite for any positive semi-definite K~, and the static residual
#: flexibility found about the shift, Sum phi phi^T / (lambda - shift) over the discarded modes,
#: is within shift / lambda_(m+1) of the one about zero: 580 (rad/s)² on the default model,
#: 6e-9 of its 61st mode's 9.8e10. The factor's condition number (3e12 there) spoils only the
#: rigid-body directions, which the loads and solutions are projected off (``Receptance``)
SHIFT = RIGID_TOL


def rigid_modes(lam: np.ndarray, K: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Which eigenvalues ``lam`` of (K, M) belong to rigid-body modes (:data:`RIGID_TOL`), (m,) bool."""
    scale = max(np.max(np.diag(K) / np.diag(M)), 1e-300)
    return np.asarray(lam) < RIGID_TOL * scale


def _check_square(name: str, A, n: int | None) -> np.ndarray:
    A = np.asarray(A.toarray() if sp.issparse(A) else A, dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1] or (n is not None and A.shape[0] != n):
        want = f"({n}, {n})" if n is not None else "square"
        raise ValueError(f"{name} must be a {want} matrix, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError(f"{name} must be finite (no NaN/inf)")
    # reduced models (Phi^T K Phi) are symmetric to round-off only: allow 1e-8 of the largest entry
    if np.abs(A - A.T).max() > 1e-8 * max(np.abs(A).max(), 1e-300):
        raise ValueError(f"{name} must be symmetric (|A - A^T| <= 1e-8 max|A|)")
    return 0.5 * (A + A.T)


def lowest_modes_and_factor(K: np.ndarray, M: np.ndarray, m: int,
                            chol_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple, float]:
    """The m lowest eigenpairs of (K, M), m < n, and the factor of K - shift M they came from.

    Block Lanczos (:mod:`hbm.lanczos`, 0.8 against 1.3 s for LAPACK's subset eigh and a
    Cholesky at 2198 DOFs), LAPACK's subset eigh where that does not converge. The shift
    (:data:`SHIFT`) makes K - shift M positive definite for a free-free structure.

    Args:
        K, M: (n, n) stiffness (K positive semi-definite) and mass (positive definite).
        m: pairs wanted.
        chol_m: lower Cholesky factor of M.
    Returns:
        (lam (m,) ascending, Phi (n, m) M-orthonormal, ``cho_factor`` of K - shift M, shift).
    Raises:
        numpy.linalg.LinAlgError: K - shift M is not positive definite.
    """
    shift = -SHIFT * max(np.max(np.diag(K) / np.diag(M)), 1e-300)
    factor = lanczos.shifted_factor(K, M, shift)
    modes = lanczos.lowest_modes(K, M, m, shift, chol_m, factor=factor)
    if modes is None:
        return (*sla.eigh(K, M, subset_by_index=[0, m - 1]), factor, shift)
    return modes.lam, modes.Phi, factor, shift


def discarded_static_response(M: np.ndarray, factor: tuple, shift: float, lam: np.ndarray,
                              Phi: np.ndarray, rigid: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Static response of the modes not kept to forces y (n,) or (n, k), about the shift:
    Sum_discarded phi phi^T y / (lam - shift), found as P (K - shift M)^-1 P^T y less the kept
    elastic modes' part, with P = I - Phi_r Phi_r^T M removing the rigid-body modes (the factor
    resolves them only to eps lambda_max / |shift|). The shift changes a discarded mode's
    1 / lam by shift / lam, below 1e-8 of it (:data:`SHIFT`).

    Args:
        M: (n, n) mass; factor, shift: from :func:`lowest_modes_and_factor`.
        lam, Phi, rigid: the kept modes (m,), (n, m), (m,) bool (rigid ones with lam 0).
        y: forces, N.
    Returns:
        displacements with y's shape, mm.
    """
    el = ~rigid
    Pr, MPr = Phi[:, rigid], M @ Phi[:, rigid]
    x = sla.cho_solve(factor, y - MPr @ (Pr.T @ y), check_finite=False)
    x = x - Pr @ (MPr.T @ x)
    d = lam[el] - shift
    return x - Phi[:, el] @ ((Phi[:, el].T @ y) / (d[:, None] if y.ndim == 2 else d))


class LinearStructure:
    """Linear structure M q'' + C q' + K q = f (units tonne, N/mm, N·s/mm).

    Args:
        M: mass matrix (n, n), symmetric positive definite.
        K: stiffness matrix (n, n), symmetric positive semi-definite (free–free allowed).
        C: viscous damping matrix (n, n), optional.
        damping_ratio: modal damping ratio applied to the modes of the linear base (the structure
            with the contacts closed at rest stuck, i.e. the low-amplitude assembled structure),
            an alternative to C; at most one of C / damping_ratio.
        n_modes: number of modes kept in the receptance (the rest is static residual
            flexibility). Default: all if n <= 300, else 60.
    """

    def __init__(self, M, K, C=None, damping_ratio: float | None = None,
                 n_modes: int | None = None) -> None:
        self.M = _check_square("M", M, None)
        n = self.M.shape[0]
        self.n = n
        self.K = _check_square("K", K, n)
        if C is not None and damping_ratio is not None:
            raise ValueError("give either C or damping_ratio, not both")
        self.C = None if C is None else _check_square("C", C, n)
        if damping_ratio is not None:
            if not np.isfinite(damping_ratio) or not (0.0 <= damping_ratio < 1.0):
                raise ValueError(f"damping_ratio must be in [0, 1), got {damping_ratio!r}")
        self.damping_ratio = damping_ratio
        if n_modes is None:
            n_modes = n if n <= 300 else 60
        if int(n_modes) != n_modes or not (1 <= n_modes <= n):
            raise ValueError(f"n_modes must be an integer in [1, {n}], got {n_modes!r}")
        self.n_modes = int(n_modes)
        try:
            # kept: the receptances' Lanczos works in the standard form it gives
            self.chol_m = np.linalg.cholesky(self.M)
        except np.linalg.LinAlgError:
            raise ValueError("M must be positive definite") from None
        self._receptances: list = []       # [(key, Receptance)], most recent first

    #: receptances a structure keeps (``receptance``) at most ...
    RECEPTANCES_KEPT = 12
    #: ... and within this many bytes together (about 90 MB each at 2198 DOFs). A rank of the
    #: study's job queue meets about a dozen joints (curves, v3 passes, backbones, speed rows):
    #: keeping 3 had it build 41 receptances in the default study, keeping 12 (or all) 34-35,
    #: each a dense eigh of about 1 s (issue 16, session 24)
    RECEPTANCE_BYTES = 1.5e9

    def receptance(self, B: sp.csr_matrix, k0: np.ndarray) -> "Receptance":
        """The receptance about the base stiffness ``k0`` with contact map ``B``
        (:class:`Receptance`), kept for the last ``RECEPTANCES_KEPT`` bases (equal B and k0)
        that fit in ``RECEPTANCE_BYTES`` together (the latest is always kept).

        Its set-up is a dense generalized eigh and a Cholesky solve (1.0 s at 2198 DOFs, most
        of a middle-level curve's set-up); the curves of one joint at several levels, its
        backbone and the speed stage's rows share one. A Receptance is not changed after its
        set-up (its caches are keyed by their inputs), so sharing it is safe.
        """
        B = sp.csr_matrix(B)
        k0 = np.ascontiguousarray(k0, dtype=float)
        h = hashlib.sha256()
        for a in (np.asarray(B.shape), B.indptr, B.indices, B.data, k0):
            h.update(np.ascontiguousarray(a).tobytes())
        key = h.hexdigest()
        hit = [G for k, G in self._receptances if k == key]
        G = hit[0] if hit else Receptance(self, B, k0)
        kept, size = [(key, G)], G.nbytes
        for k, g in self._receptances:
            if k != key and len(kept) < self.RECEPTANCES_KEPT and size + g.nbytes <= self.RECEPTANCE_BYTES:
                kept.append((k, g))
                size += g.nbytes
        self._receptances = kept
        return G


class Receptance:
    """Receptance of the linear base in contact coordinates u = B q (see module docstring).

    Args:
        s: the linear structure.
        B: sparse (nc, n) map from structure DOFs to contact relative coordinates.
        k0: (nc,) stiffness of the linear base at each contact coordinate, N/mm.
    """

    def __init__(self, s: LinearStructure, B: sp.csr_matrix, k0: np.ndarray) -> None:
        self.s = s
        self.B = B
        n, m = s.n, s.n_modes
        Kb = s.K + (B.T @ sp.diags(k0) @ B).toarray()
        self.complete = m == n
        self.Kb = Kb
        self._factor = None
        lam, Phi = self._modes(Kb, m)
        rigid = rigid_modes(lam, Kb, s.M)
        lam = np.where(rigid, 0.0, lam)
        self.lam, self.Phi, self.rigid = lam, Phi, rigid
        if s.C is not None:
            Cm = Phi.T @ s.C @ Phi
        elif s.damping_ratio is not None:
            Cm = np.diag(2.0 * s.damping_ratio * np.sqrt(lam))
        else:
            Cm = np.zeros((m, m))
        off = Cm - np.diag(np.diag(Cm))
        self.diag_damping = not np.any(np.abs(off) > 1e-12 * max(np.abs(Cm).max(), 1e-300))
        self.Cm = Cm
        self.cvec = np.diag(Cm).copy()
        self.Psi = np.asarray(B @ Phi)                       # (nc, m)
        if self.complete:
            self.R = np.zeros((B.shape[0], B.shape[0]))
        else:
            # B P (K~ - shift M)^-1 P^T B^T = Y^T Y, Y = L^-1 P^T B^T with L the shifted pencil's
            # factor and P = I - Phi_r Phi_r^T M: the loads' rigid-body part removed before the
            # solve, as the factor resolves it only to eps lambda_max / |shift|
            el = ~rigid
            Bt = B.T.toarray() - (s.M @ Phi[:, rigid]) @ self.Psi[:, rigid].T
            Y = sla.solve_triangular(self._factor[0], Bt, lower=True, check_finite=False)
            Pe = self.Psi[:, el]
            R = Y.T @ Y - (Pe / (lam[el] - self.shift)) @ Pe.T
            self.R = 0.5 * (R + R.T)

    def _modes(self, Kb: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
        """The m lowest eigenpairs of (K~, M): all of them (m = n) by LAPACK's eigh, else by
        :func:`lowest_modes_and_factor` (which sets the shifted pencil's factor)."""
        if self.complete:
            return sla.eigh(Kb, self.s.M)
        lam, Phi, self._factor, self.shift = lowest_modes_and_factor(Kb, self.s.M, m, self.s.chol_m)
        return lam, Phi

    @property
    def nbytes(self) -> int:
        """Memory of the arrays the receptance keeps (its base, modes, factor and R), bytes."""
        arrays = [self.Kb, self.Phi, self.Psi, self.R, self.lam, self.Cm]
        if self._factor is not None:
            arrays.append(self._factor[0])
        return int(sum(a.nbytes for a in arrays))

    # ------------------------------------------------------------------ modal factors
    def modal(self, h: int, omega: float) -> np.ndarray:
        """Modal receptance Lambda_h (m,) if diagonal damping else (m, m), complex; h = 0 drops rigid modes."""
        lam = self.lam
        if h == 0:
            out = np.where(self.rigid, 0.0, 1.0 / np.where(self.rigid, 1.0, lam))
            return out.astype(complex) if self.diag_damping else np.diag(out).astype(complex)
        w = h * omega
        if self.diag_damping:
            return 1.0 / (lam - w * w + 1j * w * self.cvec)
        return np.linalg.inv(np.diag(lam - w * w) + 1j * w * self.Cm)

    def _mul(self, L: np.ndarray, X: np.ndarray) -> np.ndarray:
        if L.ndim == 1:
            return L[:, None] * X if X.ndim == 2 else L * X
        return L @ X

    def matrix(self, h: int, omega: float, rows=None, cols=None) -> np.ndarray:
        """Dense receptance block G_h[rows, cols] (complex), mm/N."""
        Pr = self.Psi if rows is None else self.Psi[rows]
        Pc = self.Psi if cols is None else self.Psi[cols]
        R = self.R if rows is None and cols is None else self.R[np.ix_(
            np.arange(self.R.shape[0]) if rows is None else rows,
            np.arange(self.R.shape[0]) if cols is None else cols)]
        return Pr @ self._mul(self.modal(h, omega), Pc.T) + R

    def apply(self, h: int, omega: float, c: np.ndarray) -> np.ndarray:
        """G_h c for complex contact forces c (nc,) or (nc, k)."""
        return self.Psi @ self._mul(self.modal(h, omega), self.Psi.T @ c) + self.R @ c

    def force_response(self, h: int, omega: float, f: np.ndarray):
        """Contact response u = B H_h f to an external force f (n,) (complex)."""
        key = f.tobytes()
        cached = getattr(self, "_fcache", None)
        if cached is None or cached[0] != key:
            # the modal projection and the static residual response do not depend on omega
            res = None if self.complete else (self.B @ self.residual_full(f.real)
                                              + 1j * (self.B @ self.residual_full(f.imag)))
            self._fcache = cached = (key, self.Phi.T @ f, res)
        L = self.modal(h, omega)
        u = self.Psi @ self._mul(L, cached[1])
        if cached[2] is not None:
            u = u + cached[2]
        return u

    def residual_full(self, y: np.ndarray) -> np.ndarray:
        """Static response of the discarded modes to forces y (n,) or (n, k)
        (:func:`discarded_static_response`)."""
        if self.complete:
            return np.zeros_like(y)
        return discarded_static_response(self.s.M, self._factor, self.shift, self.lam, self.Phi,
                                         self.rigid, y)

    def residual_row(self, dof: int) -> np.ndarray:
        """Row ``dof`` of the static residual flexibility (n,), cached (one solve per DOF)."""
        rows = self.__dict__.setdefault("_rows", {})
        if dof not in rows:
            e = np.zeros(self.s.n)
            e[dof] = 1.0
            rows[dof] = self.residual_full(e)          # symmetric: column = row
        return rows[dof]

    def response_full(self, h: int, omega: float, y: np.ndarray) -> np.ndarray:
        """Structure displacement harmonic q_h = H_h y for complex forces y (n,)."""
        L = self.modal(h, omega)
        q = self.Phi @ self._mul(L, self.Phi.T @ y)
        if not self.complete:
            q = q + self.residual_full(y.real) + 1j * self.residual_full(y.imag)
        return q
