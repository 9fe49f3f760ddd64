"""The hand-over from FE to BEM/HBM: a small dense reduced model with the interface pairs (HDF5).

Pure numpy/h5py: ``ReducedModel.load`` works without dolfinx or PETSc.

DOF order: ``[boundary DOFs, fixed-interface modal coordinates]`` where the boundary DOFs are
``[pair A nodes (x, y, z) in pair order, pair B nodes (x, y, z), excitation/response node (x, y, z)]``.
Pair local frame: rows (t1, t2, n) = (x, y, z); the normal n points from A (below) to B (above), so
the relative displacement u = q_A - q_B has u_n > 0 when the contact closes (docs/design.md, "Units and conventions").
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

_ARRAYS = ("K", "M", "C", "pair_xyz", "pair_area", "pair_frame", "pair_dofs", "preload_normal_force",
           "preload_pressure", "preload_gap", "preload_status", "full_frequencies", "reduced_frequencies")


def add_pair_springs(K: np.ndarray, pair_dofs: np.ndarray, k: np.ndarray) -> np.ndarray:
    """A copy of K with a spring between the A and B DOFs of each pair and direction.

    Args:
        K: (n, n) stiffness.
        pair_dofs: (m, 2, 3) DOFs of sides A and B for (t1, t2, n).
        k: (m, 3) spring stiffness per pair and direction, N/mm.
    Returns:
        (n, n) stiffness with the springs added.
    """
    Ks = np.array(K, dtype=float, copy=True)
    a, b, kv = pair_dofs[:, 0, :].ravel(), pair_dofs[:, 1, :].ravel(), np.asarray(k, float).ravel()
    np.add.at(Ks, (a, a), kv)
    np.add.at(Ks, (b, b), kv)
    np.add.at(Ks, (a, b), -kv)
    np.add.at(Ks, (b, a), -kv)
    return Ks


#: below this many DOFs (or when more than a quarter of the modes are wanted) ``lowest_modes``
#: is LAPACK's dense subset eigh: a Krylov method needs k << n
LANCZOS_MIN_DOFS = 200
#: the shift of ``lowest_modes``' Lanczos, (rad/s)²: below the rigid-body modes' zero, so that
#: K - sigma M of a free-free structure is positive definite (a Cholesky), as in fe.modal
LANCZOS_SHIFT = -(2 * np.pi * 1.0) ** 2
#: M's Cholesky factor for the last mass matrix seen (by identity: a study's joints share the
#: reduced model's M, and the factor is 0.1 s of a 0.2 s solve at 2198 DOFs)
_CHOL_M: list = []


def mass_cholesky(M: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of M, kept for the last M seen (by identity; M is never modified)."""
    if not (_CHOL_M and _CHOL_M[0] is M):
        _CHOL_M[:] = [M, np.linalg.cholesky(M)]
    return _CHOL_M[1]


def lowest_modes(K: np.ndarray, M: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The m lowest eigenpairs of K phi = lambda M phi (K symmetric positive semi-definite,
    free-free allowed; M symmetric positive definite), ascending, phi M-normalized.

    Block shift-invert Lanczos about ``LANCZOS_SHIFT`` on one dense Cholesky of K - sigma M
    (``hbm.lanczos``, the receptance's: every pair to a backward error of 1e-9, from a fixed
    start). On the default model's stuck joints (2198 DOFs, m = 10) 0.21 s against 0.29 s for
    ARPACK's single-vector Lanczos (sessions 20-26) and 0.72 s for LAPACK's subset eigh (a
    tridiagonalization of the whole matrix); the breathing mode's frequency equal to ARPACK's
    within 3.2e-9. Small problems, many modes of one, or no convergence: the dense eigh.

    Args:
        K, M: (n, n) stiffness (N/mm) and mass (t).
        m: number of modes, 1 <= m <= n.
    Returns:
        (lambda (m,) (rad/s)², phi (n, m)).
    """
    from hbm import lanczos
    n = K.shape[0]
    if not 1 <= m <= n:
        raise ValueError(f"m must be in [1, {n}], got {m}")
    modes = None
    if n >= LANCZOS_MIN_DOFS and 4 * m <= n:
        try:
            modes = lanczos.lowest_modes(K, M, m, LANCZOS_SHIFT, mass_cholesky(M))
        except np.linalg.LinAlgError:      # K not positive semi-definite: no Cholesky
            modes = None
    if modes is None:
        return sla.eigh(K, M, subset_by_index=[0, m - 1])
    return modes.lam, modes.Phi


def check_damping_ratio(damping_ratio: float) -> float:
    """Return the ratio if it is finite and in [0, 1), else raise ValueError."""
    if not (isinstance(damping_ratio, (int, float)) and np.isfinite(damping_ratio) and 0 <= damping_ratio < 1):
        raise ValueError(f"damping_ratio must be in [0, 1), got {damping_ratio}")
    return float(damping_ratio)


def modal_damping_matrix(K: np.ndarray, M: np.ndarray, damping_ratio: float,
                         rigid_tol: float = 1e-13) -> tuple[np.ndarray, np.ndarray]:
    """Viscous damping with the same ratio in every elastic mode: C = M Φ diag(2 ζ ω) Φᵀ M.

    Args:
        K, M: (n, n) reduced stiffness (N/mm) and mass (t).
        damping_ratio: modal damping ratio ζ in [0, 1).
        rigid_tol: modes with |ω²| below rigid_tol * max(ω²) are rigid and get no damping (the
            reduced model keeps boundary DOFs up to ~1e7 Hz, so round-off in the rigid eigenvalues
            is ~1e-16 max(ω²); 1e-13 puts the threshold at a few Hz).

    Returns:
        (C (n, n) N·s/mm, frequencies (n,) Hz signed sqrt of the eigenvalues / 2π).
    """
    zeta = check_damping_ratio(damping_ratio)
    lam, phi = sla.eigh(K, M)
    omega = np.sqrt(np.clip(lam, 0.0, None))
    elastic = lam > rigid_tol * lam.max()
    Mp = M @ phi[:, elastic]
    C = (Mp * (2 * zeta * omega[elastic])) @ Mp.T
    freq = np.sign(lam) * np.sqrt(np.abs(lam)) / (2 * np.pi)
    return 0.5 * (C + C.T), freq


@dataclass
class ReducedModel:
    """Craig–Bampton model of the preloaded joint.

    Attributes:
        K, M, C: (n, n) reduced stiffness N/mm, mass t, modal damping N·s/mm.
        damping_ratio: modal damping ratio used for C.
        dof_labels: (n,) labels ("pair12.A.x", "excitation.x", "mode3", ...).
        pair_xyz: (n_pairs, 3) pair coordinates, mm.
        pair_area: (n_pairs,) tributary areas, mm².
        pair_frame: (n_pairs, 3, 3) rows t1, t2, n (global components).
        pair_dofs: (n_pairs, 2, 3) reduced DOF indices of A and B for (t1, t2, n).
        preload_normal_force: (n_pairs,) N (sum = bolt force).
        preload_pressure: (n_pairs,) MPa.
        preload_gap: (n_pairs,) mm (0 where closed).
        preload_status: (n_pairs,) 0 open, 1 closed tied, 2 closed untied, 3 closed vertex pair
            inside the contact zone (see :mod:`fe_joint.model.interface_contact`); closed = status != 0.
        excitation_dof, response_dof: reduced indices (x direction on mass A).
        full_frequencies: (n_full,) free–free frequencies of the full FE model, Hz (rigid ≈ 0).
        reduced_frequencies: (n,) free–free frequencies of (K, M), Hz.
        n_boundary: number of boundary (physical) DOFs; the rest are modal coordinates.
        metadata: dict (bolt force, mesh stats, hashes, timings).
    """

    K: np.ndarray
    M: np.ndarray
    C: np.ndarray
    damping_ratio: float
    dof_labels: list
    pair_xyz: np.ndarray
    pair_area: np.ndarray
    pair_frame: np.ndarray
    pair_dofs: np.ndarray
    preload_normal_force: np.ndarray
    preload_pressure: np.ndarray
    preload_gap: np.ndarray
    preload_status: np.ndarray
    excitation_dof: int
    response_dof: int
    full_frequencies: np.ndarray
    reduced_frequencies: np.ndarray
    n_boundary: int
    metadata: dict = field(default_factory=dict)

    @property
    def n_dofs(self) -> int:
        """Number of reduced DOFs."""
        return self.K.shape[0]

    @property
    def n_pairs(self) -> int:
        """Number of interface pairs."""
        return len(self.pair_area)

    def tied_frequencies(self, k_normal: float, k_tangential: float | None = None, n: int = 12) -> np.ndarray:
        """Free–free frequencies with every closed pair tied by springs, Hz (stuck-joint check).

        Args:
            k_normal: normal contact stiffness per area, N/mm³ (element stiffness = k * area).
            k_tangential: tangential stiffness per area, N/mm³ (default = k_normal).
            n: number of lowest frequencies returned.
        """
        kt = k_normal if k_tangential is None else k_tangential
        closed = self.preload_status != 0
        k = np.array([kt, kt, k_normal])[None, :] * self.pair_area[closed, None]
        K = add_pair_springs(self.K, self.pair_dofs[closed], k)
        lam = lowest_modes(K, self.M, min(n, self.n_dofs))[0]
        return np.sign(lam) * np.sqrt(np.abs(lam)) / (2 * np.pi)

    def save(self, path: str) -> None:
        """Write to HDF5 (call on one rank only)."""
        import h5py
        with h5py.File(path, "w") as f:
            for name in _ARRAYS:
                f.create_dataset(name, data=np.asarray(getattr(self, name)))
            f.create_dataset("dof_labels", data=np.array(self.dof_labels, dtype="S"))
            f.attrs["damping_ratio"] = self.damping_ratio
            f.attrs["excitation_dof"] = self.excitation_dof
            f.attrs["response_dof"] = self.response_dof
            f.attrs["n_boundary"] = self.n_boundary
            f.attrs["metadata"] = json.dumps(self.metadata, default=_jsonable)
            f.attrs["format"] = "fe-joint ReducedModel 1"

    @classmethod
    def load(cls, path: str) -> "ReducedModel":
        """Read a model written by :meth:`save` (h5py + numpy only)."""
        import h5py
        with h5py.File(path, "r") as f:
            kw = {name: f[name][()] for name in _ARRAYS}
            kw["dof_labels"] = [s.decode() for s in f["dof_labels"][()]]
            kw["damping_ratio"] = float(f.attrs["damping_ratio"])
            kw["excitation_dof"] = int(f.attrs["excitation_dof"])
            kw["response_dof"] = int(f.attrs["response_dof"])
            kw["n_boundary"] = int(f.attrs["n_boundary"])
            kw["metadata"] = json.loads(f.attrs["metadata"])
        return cls(**kw)


def _jsonable(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return str(obj)
