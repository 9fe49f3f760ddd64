"""Craig–Bampton reduction of the joint and the whole FE chain (mesh -> preload -> ReducedModel).

Boundary DOFs: all nodes of both lap faces (the matched pairs) plus the excitation/response node;
fixed-interface modes of (K_II, M_II) up to a cut-off frequency. The constraint-mode blocks come
from :class:`fe_joint.fe.condensation.BoundaryCondensation` chunk by chunk (bounded memory) and
K_r,BB = K_BB + K_BI Psi (no dense Psiᵀ K Psi). The same condensed stiffness serves the preload
contact problem, so the preload costs almost nothing on top of the reduction.
"""
from __future__ import annotations

import hashlib
import os
import resource
import time

import numpy as np
from petsc4py import PETSc

from .condensation import BoundaryCondensation
from .block_lanczos import lowest_modes
from .modal import free_modes, mumps_cholesky, rayleigh_ritz, solve_eigenproblem, to_hz
from ..model.reduced_model import ReducedModel, check_damping_ratio, modal_damping_matrix


def _peak_mb() -> float:
    """Peak resident memory of this process, MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def count_modes_below(K, M, cutoff_hz: float) -> int:
    """Number of eigenvalues of (K, M) below (2 pi cutoff_hz)² from the inertia of K - sigma M.

    Sylvester's law of inertia: the negative pivots of an LDLᵀ factorization (MUMPS, ICNTL(13)=1 so
    the root node is not handed to ScaLAPACK, which reports no inertia) count the eigenvalues
    below the shift. One factorization instead of a guess-and-double eigen solve.
    """
    sigma = (2 * np.pi * cutoff_hz) ** 2
    A = K.copy()
    A.axpy(-sigma, M)
    ksp = mumps_cholesky(PETSc.KSP().create(K.getComm()))
    ksp.setOperators(A)
    pc = ksp.getPC()
    pc.setFactorSetUpSolverType()
    F = pc.getFactorMatrix()
    F.setMumpsIcntl(13, 1)
    F.setMumpsIcntl(24, 1)  # null-pivot detection: MatGetInertia needs it (nzero)
    ksp.setUp()
    nneg, _, _ = F.getInertia()
    ksp.destroy()
    A.destroy()
    return int(nneg)


def fixed_interface_modes(cond: BoundaryCondensation, cutoff_hz: float,
                          max_modes: int = 2000) -> tuple[np.ndarray, list]:
    """Fixed-interface modes of (K_II, M_II) with frequency <= cutoff_hz.

    The number of modes is counted first (:func:`count_modes_below`), then block Lanczos on
    K_II's factor, which the condensation keeps for the constraint modes
    (:func:`~fe_joint.fe.block_lanczos.lowest_modes`). Its Ritz values are upper bounds of the
    eigenvalues: when all ``n`` lie below the cut-off they are the ``n`` modes the count found.
    Otherwise (a mode missed, the basis over its memory budget, no convergence) SLEPc's
    Krylov–Schur solves the problem (:func:`~fe_joint.fe.modal.solve_eigenproblem`), with the
    factor released first (one factor alive at a time).

    Returns:
        (frequencies Hz ascending, list of M_II-normalized interior Vecs).
    """
    if not (np.isfinite(cutoff_hz) and cutoff_hz > 0):
        raise ValueError(f"cutoff_hz must be a finite frequency > 0 Hz, got {cutoff_hz}")
    KII, MII = cond.interior_pair()
    n = count_modes_below(KII, MII, cutoff_hz)
    if n > max_modes:
        raise ValueError(f"cutoff_hz = {cutoff_hz} keeps {n} fixed-interface modes (> {max_modes}); lower it")
    if n == 0:
        return np.zeros(0), []
    found = lowest_modes(KII, MII, cond.factor, n)
    if found is not None:
        vals, vecs = rayleigh_ritz(KII, MII, found[1])
        if to_hz(vals)[-1] <= cutoff_hz:
            return to_hz(vals), vecs
        for v in vecs:
            v.destroy()
    cond.release_factor()
    vals, vecs = solve_eigenproblem(KII, MII, n, sigma=0.0)
    f = to_hz(vals)
    keep = f <= cutoff_hz
    return f[keep], [v for v, k in zip(vecs, keep) if k]


def dof_labels(layout, n_modes: int) -> list[str]:
    """Labels of the reduced DOFs (boundary in canonical order, then modes)."""
    npair = len(layout.pair_a)
    lab = np.empty(layout.size, dtype=object)
    for side, idx in (("A", layout.pair_a), ("B", layout.pair_b)):
        for c, ax in enumerate("xyz"):
            lab[idx[:, c]] = [f"pair{p}.{side}.{ax}" for p in range(npair)]
    for name, idx in reversed(list(layout.extra.items())):  # shared node: 'excitation' wins
        for c, ax in enumerate("xyz"):
            lab[idx[c]] = f"{name}.{ax}"
    names = list(lab)
    return names + [f"mode{k}" for k in range(n_modes)]


def craig_bampton(problem, cutoff_hz: float, damping_ratio: float = 1e-3, preload=None,
                  condensation: BoundaryCondensation | None = None, chunk: int | None = None,
                  full_modes=None, timings: dict | None = None, interface_modes=None) -> ReducedModel:
    """Craig–Bampton reduced model of an assembled joint.

    Args:
        problem: JointProblem (K, M, layout) from ``fe_joint.fe.assembly.assemble_joint``.
        cutoff_hz: fixed-interface modes up to this frequency are kept, Hz.
        damping_ratio: modal damping ratio of the reduced model, in [0, 1).
        preload: PreloadResult (fills the pair preload fields) or None (zeros, all closed).
        condensation: a BoundaryCondensation with mass on ``problem.layout.dofs`` (else built).
        chunk: constraint modes per block.
        full_modes: ModalResult of the full model (stored frequencies) or None.
        timings: dict receiving stage timings (s) and peak memory (MB).
        interface_modes: (frequencies, Vecs) already computed with ``condensation.condense`` (reused).

    Returns:
        ReducedModel (identical on every rank).
    """
    zeta = check_damping_ratio(damping_ratio)
    timings = {} if timings is None else timings
    layout = problem.layout
    if condensation is None:
        condensation = BoundaryCondensation(problem.K, problem.M, layout.dofs)
    if interface_modes is None:
        t = time.perf_counter()
        fm, modes = fixed_interface_modes(condensation, cutoff_hz)
        timings["fixed_interface_modes_s"] = time.perf_counter() - t
    else:
        fm, modes = interface_modes
    blocks = getattr(condensation, "condensed", {})
    if "M_PB" not in blocks or blocks["M_PB"].shape[0] != len(modes):
        t = time.perf_counter()
        blocks = condensation.condense(modes, chunk)
        timings["constraint_modes_s"] = time.perf_counter() - t
    t = time.perf_counter()
    nb, nm = layout.size, len(modes)
    blocks = dict(blocks, M_PB=blocks["M_PB"] * canonical_mode_signs(blocks["M_PB"])[:, None])
    K, M = _reduced_matrices(blocks, fm)
    C, fr = modal_damping_matrix(K, M, zeta)
    timings["projection_s"] = time.perf_counter() - t
    npair = len(layout.pair_a)
    data = problem.fe.data
    frame = np.broadcast_to(np.eye(3), (npair, 3, 3)).copy()
    (pn, pp, pg, ps), meta_pre = _preload_fields(preload, npair)
    meta = _metadata(problem, nb, nm, cutoff_hz, fm, full_modes)
    meta.update(meta_pre)
    meta["timings"] = timings
    return ReducedModel(K=K, M=M, C=C, damping_ratio=zeta, dof_labels=dof_labels(layout, nm),
                        pair_xyz=np.asarray(data.pair_xyz, float), pair_area=np.asarray(data.pair_area, float),
                        pair_frame=frame, pair_dofs=np.stack([layout.pair_a, layout.pair_b], axis=1),
                        preload_normal_force=pn, preload_pressure=pp, preload_gap=pg, preload_status=ps,
                        excitation_dof=int(layout.extra["excitation"][0]),
                        response_dof=int(layout.extra["response"][0]),
                        full_frequencies=(full_modes.frequencies if full_modes is not None else np.zeros(0)),
                        reduced_frequencies=fr, n_boundary=nb, metadata=meta)


def canonical_mode_signs(m_pb: np.ndarray, rel_tie: float = 1e-6) -> np.ndarray:
    """Signs that make the fixed-interface mode basis canonical.

    An eigensolver returns each mode with an arbitrary sign (it differs between runs and rank
    counts), and with it the sign of the mode's row of the mass coupling M_PB and of the
    corresponding rows and columns of the reduced M and C. The model is the same either way, but
    the matrices are not comparable. Each mode's sign is fixed by its coupling row, which is in
    the canonical boundary order (independent of the partition): the entry of largest magnitude
    is made positive, the first in boundary order among entries within ``rel_tie`` of the largest
    (so a round-off difference between two nearly equal entries, e.g. mirror-symmetric DOFs,
    cannot swap the choice).

    Rotations within a cluster of equal frequencies are not fixed: Rayleigh–Ritz returns the
    Ritz vectors of the converged subspace, unique for distinct Ritz values, and the resonator's
    fixed-interface spectrum has no multiple eigenvalues (smallest relative gap on the quick
    preset 7e-4).

    Args:
        m_pb: (n_modes, n_B) mass coupling of the modes and the boundary DOFs, t.

    Returns:
        (n_modes,) +1.0 / -1.0.
    """
    a = np.abs(m_pb)
    if a.size == 0:
        return np.ones(m_pb.shape[0])
    big = a >= (1.0 - rel_tie) * a.max(axis=1, keepdims=True)
    j = np.argmax(big, axis=1)                        # first True in boundary order
    return np.where(m_pb[np.arange(len(j)), j] < 0, -1.0, 1.0)


def _reduced_matrices(blocks: dict, fm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Craig–Bampton K and M (boundary DOFs first, then the fixed-interface modes, mass-normalized).

    Args:
        blocks: condensed K_BB, M_BB and the modal coupling M_PB (modes × boundary).
        fm: fixed-interface frequencies, Hz.
    """
    nb, nm = blocks["K_BB"].shape[0], len(fm)
    K = np.zeros((nb + nm, nb + nm))
    M = np.zeros_like(K)
    K[:nb, :nb] = blocks["K_BB"]
    K[nb:, nb:] = np.diag((2 * np.pi * fm) ** 2)
    M[:nb, :nb] = blocks["M_BB"]
    M[nb:, :nb] = blocks["M_PB"]
    M[:nb, nb:] = blocks["M_PB"].T
    M[nb:, nb:] = np.eye(nm)
    return K, M


def _preload_fields(preload, npair: int) -> tuple[tuple, dict]:
    """Per-pair preload arrays (normal force N, pressure MPa, gap mm, status) and their metadata;
    zeros and 'all closed' without a preload."""
    if preload is None:
        return (np.zeros(npair), np.zeros(npair), np.zeros(npair), np.ones(npair, dtype=int)), {}
    meta = dict(bolt_force=preload.bolt_force, shank_force=preload.shank_force,
                eigenstrain=preload.eigenstrain, n_closed=int(np.sum(preload.closed)),
                n_toggled=preload.n_toggled, active_set_iterations=preload.iterations,
                max_support_reaction=float(np.abs(preload.support_reactions).max()))
    return (preload.pair_normal_force, preload.pair_pressure, preload.pair_gap,
            preload.pair_status), meta


def _metadata(problem, nb: int, nm: int, cutoff_hz: float, fm: np.ndarray, full_modes) -> dict:
    """What the reduced model records about its origin: sizes, mesh hash, material, full modes."""
    data = problem.fe.data
    h = hashlib.sha256()
    for arr in (data.points, data.cells, data.pair_nodes):
        h.update(np.ascontiguousarray(arr).tobytes())
    meta = dict(n_dofs_full=problem.n_dofs, n_pairs=len(problem.layout.pair_a), n_boundary=nb,
                n_modes=nm, cutoff_hz=cutoff_hz, fixed_interface_frequencies=fm,
                mesh_sha256=h.hexdigest(), material=vars(problem.material)
                if hasattr(problem.material, "__dict__") else str(problem.material),
                n_ranks=problem.K.getComm().getSize())
    if full_modes is not None:
        meta["breathing_index"] = full_modes.breathing_index
        meta["breathing_frequency_hz"] = (float(full_modes.frequencies[full_modes.breathing_index])
                                          if full_modes.breathing_index >= 0 else None)
        meta["n_rigid_full"] = full_modes.n_rigid
    return meta


def build_reduced_model_from_fe(fe, material, preload_force: float, damping_ratio: float = 1e-3,
                                cutoff_hz: float = 10000.0, out_dir: str | None = None,
                                chunk: int | None = None,
                                n_full_elastic: int = 12) -> ReducedModel:
    """The whole FE chain on a distributed joint mesh: assemble, preload, modes, Craig–Bampton.

    Collective. Writes ``reduced_model.h5``, ``preload.xdmf`` and ``preload_pressure.png`` into
    ``out_dir`` if given (rank 0 writes the HDF5/PNG).

    Args:
        fe: ResonatorFE / JointFE.
        material: elasticity.Material.
        preload_force: bolt force, N (> 0).
        damping_ratio: modal damping ratio, [0, 1).
        cutoff_hz: fixed-interface mode cut-off, Hz (> 0).
        out_dir: output folder or None.
        chunk: constraint modes per block (memory ~ 5 n_I chunk 8 bytes); None = auto (~1 GB).
        n_full_elastic: elastic modes of the full model computed for checking (0 to skip).

    Returns:
        ReducedModel (identical on every rank).
    """
    from .assembly import assemble_joint
    from .preload import solve_preload

    if not (np.isfinite(preload_force) and preload_force > 0):
        raise ValueError(f"preload_force must be a finite bolt force > 0 N, got {preload_force}")
    check_damping_ratio(damping_ratio)
    if not (np.isfinite(cutoff_hz) and cutoff_hz > 0):
        raise ValueError(f"cutoff_hz must be a finite frequency > 0 Hz, got {cutoff_hz}")
    timings: dict = {}
    t0 = t = time.perf_counter()
    problem = assemble_joint(fe, material)
    timings["assembly_s"] = time.perf_counter() - t
    cond = BoundaryCondensation(problem.K, problem.M, problem.layout.dofs)
    t = time.perf_counter()
    fm, modes = fixed_interface_modes(cond, cutoff_hz)  # factorizes K_II (its block Lanczos)
    timings["fixed_interface_modes_s"] = time.perf_counter() - t
    t = time.perf_counter()
    cond.ksp  # factorize K_II (done unless SLEPc had to solve the modes)
    timings["factorization_s"] = time.perf_counter() - t
    t = time.perf_counter()
    cond.condense(modes, chunk)
    timings["constraint_modes_s"] = time.perf_counter() - t
    for v in modes:  # only their number is needed from here on
        v.destroy()
    t = time.perf_counter()
    pre = solve_preload(fe, material, preload_force, out_dir=out_dir, problem=problem, condensation=cond)
    timings["preload_s"] = time.perf_counter() - t
    cond.release_factor()  # before the full-model factorization
    full = None
    if n_full_elastic > 0:
        t = time.perf_counter()
        ex = problem.layout.dofs[problem.layout.extra["excitation"]]
        full = free_modes(problem.K, problem.M, n_full_elastic, probe_dofs=ex)
        timings["full_modes_s"] = time.perf_counter() - t
    rm = craig_bampton(problem, cutoff_hz, damping_ratio, pre, cond, chunk, full, timings,
                       interface_modes=(fm, modes))
    timings["total_s"] = time.perf_counter() - t0
    timings["peak_memory_mb_rank0"] = _peak_mb()
    cond.destroy()
    if out_dir is not None and fe.mesh.comm.rank == 0:
        os.makedirs(out_dir, exist_ok=True)
        rm.save(os.path.join(out_dir, "reduced_model.h5"))
    fe.mesh.comm.barrier()
    return rm


def build_reduced_model(params, material, preload_force: float, damping_ratio: float = 1e-3,
                        cutoff_hz: float = 10000.0, comm=None, out_dir: str | None = None,
                        **kw) -> ReducedModel:
    """Mesh the resonator (gmsh, rank 0) and run :func:`build_reduced_model_from_fe`. Collective.

    Args:
        params: geometry.resonator.ResonatorParams.
        material, preload_force, damping_ratio, cutoff_hz, out_dir, kw: see
            :func:`build_reduced_model_from_fe`.
        comm: MPI communicator (default COMM_WORLD).
    """
    from mpi4py import MPI

    from .mesh import load_resonator
    fe = load_resonator(params, MPI.COMM_WORLD if comm is None else comm)
    return build_reduced_model_from_fe(fe, material, preload_force, damping_ratio, cutoff_hz, out_dir, **kw)
