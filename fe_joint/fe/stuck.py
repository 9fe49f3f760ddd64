"""The stuck joint on the full FE mesh: interface pair springs in PETSc and the modes near a target.

The reduced model's stuck linear limit (``model.joint.stuck_modes``) ties every loaded pair by a
normal spring k_n·A and two tangential springs k_t·A in the pair's local frame. Here the same
springs go into the full (free–free) stiffness, so the stuck resonance of the Craig–Bampton model
can be checked against the full model (docs/design.md, "Reduction").

Spring of pair p between its nodes A and B, in global components, with the frame R_p (rows t1,
t2, n) and D_p = R_pᵀ diag(k_t, k_t, k_n) R_p (N/mm):

    [f_A; f_B] = [[D_p, -D_p], [-D_p, D_p]] [u_A; u_B]

Collective: every rank passes the same pair data (global DOFs, identical on every rank, as in
:class:`fe_joint.fe.assembly.BoundaryLayout`) and sets only the rows it owns.
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from .modal import ModalResult, rayleigh_ritz, shift_invert, to_hz, vec_values_at


def _pair_blocks(frames: np.ndarray, kn: np.ndarray, kt: np.ndarray) -> np.ndarray:
    """D_p = R_pᵀ diag(k_t, k_t, k_n) R_p for every pair, (m, 3, 3) N/mm."""
    R = np.asarray(frames, float)
    k = np.stack([kt, kt, kn], axis=1)
    return np.einsum("pki,pk,pkj->pij", R, k, R)


def _check_pairs(pair_dofs: np.ndarray, frames: np.ndarray, kn, kt, n: int):
    """Validate and broadcast the pair data; return (dofs (m, 2, 3) int64, frames, kn, kt)."""
    d = np.asarray(pair_dofs, dtype=np.int64)
    if d.ndim != 3 or d.shape[1:] != (2, 3):
        raise ValueError(f"pair_dofs must be (n_pairs, 2, 3) global DOFs, got shape {d.shape}")
    m = len(d)
    if m and (d.min() < 0 or d.max() >= n):
        raise ValueError(f"pair_dofs must be global DOFs in [0, {n})")
    if len(np.unique(d)) != d.size:
        raise ValueError("pair_dofs repeats a DOF: each node belongs to one pair side")
    R = np.broadcast_to(np.asarray(frames, float), (m, 3, 3))
    if m and np.abs(np.einsum("pik,pjk->pij", R, R) - np.eye(3)).max() > 1e-9:
        raise ValueError("pair frames must be orthonormal (rows t1, t2, n)")
    kn = np.broadcast_to(np.asarray(kn, float), (m,))
    kt = np.broadcast_to(np.asarray(kt, float), (m,))
    for name, k in (("kn", kn), ("kt", kt)):
        if not np.all(np.isfinite(k)) or np.any(k < 0):
            raise ValueError(f"{name} must be finite spring stiffnesses >= 0 N/mm")
    return d, R, kn, kt


def pair_spring_stiffness(K: PETSc.Mat, pair_dofs: np.ndarray, frames: np.ndarray,
                          kn: np.ndarray, kt: np.ndarray) -> PETSc.Mat:
    """Sparse stiffness of the interface pair springs in the global DOF numbering of K.

    Collective; the matrix has K's row/column layout and each rank fills the rows it owns.

    Args:
        K: full stiffness whose layout (sizes, communicator) the result takes.
        pair_dofs: (m, 2, 3) global DOFs of node A and node B of each pair, components (x, y, z);
            identical on every rank.
        frames: (m, 3, 3) or (3, 3) pair frames, rows t1, t2, n in global components.
        kn: (m,) or scalar normal spring stiffness per pair, N/mm (k_n·A; 0 = no spring).
        kt: (m,) or scalar tangential spring stiffness per pair, N/mm (same in t1 and t2).

    Returns:
        S, assembled symmetric AIJ matrix, N/mm.
    """
    n = K.getSize()[0]
    d, R, kn, kt = _check_pairs(pair_dofs, frames, kn, kt, n)
    lo, hi = K.getOwnershipRange()
    D = _pair_blocks(R, kn, kt)
    # element matrix on [u_A, u_B]: [[D, -D], [-D, D]], (m, 6, 6)
    E = np.block([[D, -D], [-D, D]]) if len(d) else np.zeros((0, 6, 6))
    cols = d.reshape(-1, 6)                                            # (m, 6) x_A y_A z_A x_B ...
    rows_loc = np.zeros(hi - lo, dtype=PETSc.IntType)
    o_loc = np.zeros(hi - lo, dtype=PETSc.IntType)
    own = (cols >= lo) & (cols < hi)
    n_diag = own.sum(axis=1)
    pr, pc = np.nonzero(own)                                          # (pair, local slot) owned rows
    rows_loc[cols[pr, pc] - lo] = n_diag[pr]
    o_loc[cols[pr, pc] - lo] = 6 - n_diag[pr]
    S = PETSc.Mat().createAIJ(K.getSizes(), nnz=(rows_loc, o_loc), comm=K.getComm())
    for p, s in zip(pr, pc):
        S.setValues([int(cols[p, s])], cols[p].astype(PETSc.IntType), E[p, s], addv=PETSc.InsertMode.ADD_VALUES)
    S.assemble()
    S.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return S


def with_pair_springs(K: PETSc.Mat, pair_dofs: np.ndarray, frames: np.ndarray,
                      kn: np.ndarray, kt: np.ndarray) -> PETSc.Mat:
    """A new matrix K + S with the interface pair springs of :func:`pair_spring_stiffness` added.

    Args:
        K: full stiffness, N/mm (left unchanged).
        pair_dofs, frames, kn, kt: see :func:`pair_spring_stiffness`.

    Returns:
        K + S, N/mm (collective; the caller destroys it).
    """
    S = pair_spring_stiffness(K, pair_dofs, frames, kn, kt)
    Ks = K.copy()
    Ks.axpy(1.0, S, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    S.destroy()
    Ks.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return Ks


def eigenpairs_near(K: PETSc.Mat, M: PETSc.Mat, target_hz: float, nev: int = 4,
                    tol: float = 1e-10, max_it: int = 300) -> tuple[np.ndarray, list]:
    """The ``nev`` eigenpairs of K phi = lambda M phi nearest (2 pi target_hz)².

    Shift-and-invert at the target with a MUMPS LDLᵀ factorization of K - sigma M (symmetric
    indefinite: MUMPS' general symmetric mode), then one Rayleigh–Ritz step (M-orthonormal).

    Args:
        K, M: assembled symmetric stiffness N/mm and mass t.
        target_hz: frequency near which the modes are wanted, Hz (> 0, not itself an eigenfrequency).
        nev: number of eigenpairs.
        tol: SLEPc relative residual tolerance (eigenvalue error ~ tol²).
        max_it: Krylov–Schur restarts.

    Returns:
        (eigenvalues (rad/s)² ascending, list of M-normalized Vecs).

    Raises:
        ConvergenceError: fewer than ``nev`` pairs converged.
    """
    from slepc4py import SLEPc

    if not (np.isfinite(target_hz) and target_hz > 0):
        raise ValueError(f"target_hz must be a finite frequency > 0 Hz, got {target_hz}")
    if nev < 1:
        raise ValueError(f"nev must be >= 1, got {nev}")
    sigma = (2 * np.pi * target_hz) ** 2

    def nearest(vals: np.ndarray) -> np.ndarray:     # the nev nearest sigma, ascending
        near = np.argsort(np.abs(vals - sigma), kind="stable")[:nev]
        return near[np.argsort(vals[near])]

    vecs = shift_invert(K, M, sigma, nev, tol, max_it, SLEPc.EPS.Which.TARGET_MAGNITUDE, nearest,
                        f"near {target_hz:g} Hz")
    return rayleigh_ritz(K, M, vecs)


def stuck_free_modes(K: PETSc.Mat, M: PETSc.Mat, pair_dofs: np.ndarray, frames: np.ndarray,
                     kn: np.ndarray, kt: np.ndarray, target_hz: float, nev: int = 4,
                     probe_dofs: np.ndarray | None = None, tol: float = 1e-10) -> ModalResult:
    """Modes of the full free–free model with the interface pairs tied by springs, near a target.

    Collective.

    Args:
        K, M: full free–free stiffness N/mm and mass t (unchanged).
        pair_dofs, frames, kn, kt: the springs, see :func:`pair_spring_stiffness`.
        target_hz: frequency near which the modes are wanted, Hz (e.g. the reduced model's).
        nev: number of modes.
        probe_dofs: (k,) global DOFs whose modal values are returned in ``probe`` (same on every
            rank), e.g. the reduced model's boundary DOFs to identify a mode by its shape.
        tol: SLEPc relative residual tolerance.

    Returns:
        ModalResult (frequencies Hz ascending, M-normalized modes; ``probe`` (nev, k) if asked;
        ``n_rigid`` = 0 and ``breathing_index`` = -1: the modes are not the lowest ones).
    """
    Ks = with_pair_springs(K, pair_dofs, frames, kn, kt)
    try:
        vals, vecs = eigenpairs_near(Ks, M, target_hz, nev, tol)
    finally:
        Ks.destroy()
    res = ModalResult(frequencies=to_hz(vals), eigenvalues=vals, modes=vecs)
    if probe_dofs is not None:
        res.probe = vec_values_at(vecs, np.asarray(probe_dofs, dtype=np.int64))
    return res


def mode_match(shape: np.ndarray, candidates: np.ndarray) -> tuple[int, np.ndarray]:
    """The candidate most alike a mode shape by the modal assurance criterion.

    Args:
        shape: (k,) reference mode at k DOFs.
        candidates: (n, k) modes at the same DOFs.

    Returns:
        (index of the best candidate, MAC of every candidate in [0, 1]).
    """
    a = np.asarray(shape, float)
    C = np.asarray(candidates, float)
    mac = (C @ a) ** 2 / np.maximum(np.einsum("ij,ij->i", C, C) * (a @ a), 1e-300)
    return int(np.argmax(mac)), mac


def compare_stuck_resonance(problem, rm, joint, nev: int = 4, tol: float = 1e-10) -> dict:
    """The reduced model's stuck resonance checked against the full FE model with the same springs.

    The reduced side is the study's own (:func:`fe_joint.model.joint.stuck_modes`: first elastic
    mode of the Craig–Bampton K plus the springs k·A of the loaded elements). The full side adds
    the same springs, in the pairs' frames, to the full K and solves near the reduced frequency;
    the full mode matched to the reduced one is the one with the largest MAC at the boundary
    DOFs (the reduced model's physical DOFs). Collective.

    Args:
        problem: JointProblem (full K, M and the boundary layout the reduced model was built on).
        rm: ReducedModel of that problem.
        joint: JointModel (per-element k_n, k_t N/mm³, area mm², N0 N; loaded = N0 > 0).
        nev: full-model modes computed near the target.
        tol: SLEPc relative residual tolerance.

    Returns:
        dict: ``f_reduced``, ``f_full`` (Hz), ``rel_diff`` (f_reduced / f_full - 1), ``mac`` (of
        the matched mode), ``mode_index`` (of the reduced stuck mode), ``full_frequencies`` (Hz),
        ``reduced_s`` and ``full_s`` (wall times of the two eigen solves, s; the full one
        includes adding the springs).
    """
    import time

    from ..model.joint import stuck_modes

    lay = problem.layout
    if lay.size != rm.n_boundary or len(lay.pair_a) != rm.n_pairs:
        raise ValueError("the reduced model was not built on this problem's boundary layout")
    t = time.perf_counter()
    lin = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint)
    reduced_s = time.perf_counter() - t
    c = joint.closed
    gdofs = np.asarray(lay.dofs)[np.asarray(rm.pair_dofs)]          # (m, 2, 3) global DOFs
    t = time.perf_counter()
    res = stuck_free_modes(problem.K, problem.M, gdofs[c], np.asarray(rm.pair_frame)[c],
                           (joint.kn * joint.area)[c], (joint.kt * joint.area)[c],
                           lin.frequency, nev=nev, probe_dofs=lay.dofs, tol=tol)
    full_s = time.perf_counter() - t
    i, mac = mode_match(lin.modes[:rm.n_boundary, lin.mode_index], res.probe)
    for v in res.modes:
        v.destroy()
    f_full = float(res.frequencies[i])
    return dict(f_reduced=lin.frequency, f_full=f_full, rel_diff=lin.frequency / f_full - 1,
                mac=float(mac[i]), mode_index=lin.mode_index,
                full_frequencies=res.frequencies.tolist(), reduced_s=reduced_s, full_s=full_s)
