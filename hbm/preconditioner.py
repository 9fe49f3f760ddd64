"""Preconditioner of the reduced Newton systems of the harmonic balance (GMRES path).

The reduced Newton matrix on the k nonlinear elements (p = 3k contact coordinates, n_H = 2H + 1
harmonic rows, layout row h, column 3e + d) is

    J = I + G D,    G_h = R + Psi L_h Psi^T,

with R the static residual flexibility (real, the same at every harmonic), Psi the contact rows
of the kept modes, L_h their modal factors at harmonic h (complex; L_0 real and independent of
the frequency) and D the friction Jacobian, block-diagonal over elements but coupling all
harmonics of an element (3 n_H x 3 n_H per element).

What it keeps of D, and why (measured on 31 Newton systems of the quick model's top-level
baseline sweep, 201 nonlinear elements, GMRES to 1e-8):

* The first preconditioner replaced each element's D by its mean 3x3 diagonal block over the
  dynamic harmonics, k_bar, which decouples the harmonics: 63-88 iterations per solve on that
  sweep. Replacing parts of D in the *system* by that average located what it misses: with the
  mean (h = 0) row and column of D averaged the same preconditioner needs 20 iterations, with the
  t-n coupling averaged 66, with the normal-normal block averaged 65. The coupling of the mean
  displacement to the vibration (the static shear in a slipping joint moves with the slip
  phases) is what matters most; a time-collocation of D at 2H + 1 instants (one LU per instant)
  captured it poorly (75 iterations).
* The mean block is therefore solved exactly: J_00 = I + G_0 D_00 with G_0 = R + Psi L_0 Psi^T,
  one real p x p LU, and coupled to the vibration by one block Gauss-Seidel sweep (the dynamic
  harmonics first, then the mean with their force D_0h x_h on its right-hand side).
* Each dynamic harmonic h keeps the element's complex stiffness K_h = (D_cc + D_ss)/2 +
  i (D_cs - D_sc)/2, the part of the harmonic's cosine/sine block that commutes with complex
  multiplication: its imaginary part is the friction's hysteresis (damping), which k_bar
  dropped. (I + G_h K_h)^-1 is one complex LU of I + R K_h and a rank-m Woodbury correction for
  the modes. The couplings between different dynamic harmonics are left to GMRES.

Together: 18-30 iterations per solve instead of 63-88 on those systems. The set-up costs H
complex LUs and one real LU of size p (about three times the averaged one's), so the
preconditioner is kept and reused while the nonlinear set does not change
(``HarmonicBalance``): a preconditioner from 17 solves earlier on the same sweep needed
the same number of iterations as a fresh one.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla


def _times_blockdiag(X: np.ndarray, K: np.ndarray) -> np.ndarray:
    """X @ blockdiag(K) for X (p, p) and K (k, 3, 3), p = 3k, without forming blockdiag(K)."""
    p, k = X.shape[0], K.shape[0]
    Y = np.matmul(X.reshape(p, k, 3).transpose(1, 0, 2), K)          # (k, p, 3)
    return Y.transpose(1, 0, 2).reshape(p, p)


class HarmonicBlockPreconditioner:
    """Approximate inverse of J = I + G D on the nonlinear elements (module docstring).

    Args:
        R: (p, p) static residual flexibility on the elements' contact coordinates, mm/N.
        Psi: (p, m) contact rows of the kept modes.
        Ls: modal factors L_h for h = 0..H, each (m,) or (m, m), complex.
        Dg: (k, 3 n_H, 3 n_H) element Jacobians of the correction force, element layout
            d n_H + h, N/mm.
    """

    def __init__(self, R: np.ndarray, Psi: np.ndarray, Ls: list, Dg: np.ndarray) -> None:
        k = Dg.shape[0]
        H = len(Ls) - 1
        nH, p, m = 2 * H + 1, 3 * k, Psi.shape[1]
        self.H, self.nH, self.p, self.k = H, nH, p, k
        D5 = Dg.reshape(k, 3, nH, 3, nH)
        L0 = Ls[0].real
        self.G0 = R + ((Psi * L0) if L0.ndim == 1 else Psi @ L0) @ Psi.T
        A0 = _times_blockdiag(self.G0, np.ascontiguousarray(D5[:, :, 0, :, 0]))
        A0[np.diag_indices(p)] += 1.0
        self.lu0 = sla.lu_factor(A0, check_finite=False)
        # force at the mean row from the dynamic displacements: D_0h, (k, 3, 3, nH - 1)
        self.D0d = np.ascontiguousarray(D5[:, :, 0, :, 1:].transpose(3, 0, 1, 2))  # (nH-1, k, 3, 3)
        self.dyn = [self._harmonic(R, Psi, Ls[h], D5, h) for h in range(1, H + 1)]

    @staticmethod
    def _harmonic(R, Psi, L, D5, h):
        """Factors of (I + G_h K_h)^-1 for harmonic h >= 1: LU of I + R K_h, A^-1 Psi,
        Psi^T K_h and the Woodbury capacitance I + L Psi^T K_h A^-1 Psi."""
        c, s = 2 * h - 1, 2 * h
        K = (0.5 * (D5[:, :, c, :, c] + D5[:, :, s, :, s])
             + 0.5j * (D5[:, :, c, :, s] - D5[:, :, s, :, c]))                  # (k, 3, 3)
        p, m = Psi.shape
        A = _times_blockdiag(R.astype(complex), K)
        A[np.diag_indices(p)] += 1.0
        lu = sla.lu_factor(A, check_finite=False)
        AU = sla.lu_solve(lu, Psi.astype(complex), check_finite=False)          # (p, m)
        VtK = np.einsum("kam,kab->mkb", Psi.reshape(-1, 3, m), K).reshape(m, p)  # Psi^T K
        Lm = np.diag(L) if L.ndim == 1 else L
        cap = sla.lu_factor(np.eye(m) + Lm @ (VtK @ AU), check_finite=False)
        return lu, AU, VtK, cap, Lm

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Approximate J^-1 x for x (n_H p,) in the reduced layout (row h, column 3e + d)."""
        nH, p, k = self.nH, self.p, self.k
        r = x.reshape(nH, p)
        out = np.empty((nH, p))
        for h, (lu, AU, VtK, cap, Lm) in enumerate(self.dyn, start=1):
            y = sla.lu_solve(lu, r[2 * h - 1] - 1j * r[2 * h], check_finite=False)
            y = y - AU @ sla.lu_solve(cap, Lm @ (VtK @ y), check_finite=False)
            out[2 * h - 1], out[2 * h] = y.real, -y.imag
        # Gauss-Seidel: the mean row with the force D_0h x_h of the dynamic harmonics moved right
        f0 = np.einsum("hkab,hkb->ka", self.D0d, out[1:].reshape(nH - 1, k, 3)).ravel()
        out[0] = sla.lu_solve(self.lu0, r[0] - self.G0 @ f0, check_finite=False)
        return out.ravel()
