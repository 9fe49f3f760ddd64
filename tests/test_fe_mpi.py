"""Same numbers on any number of ranks: COMM_WORLD (mpirun -n 2) vs COMM_SELF in the same process."""
from dataclasses import dataclass

import numpy as np
import pytest
from mpi4py import MPI

from fe_joint.fe.box_joint import build_box_joint
from fe_joint.case import Material
from fe_joint.fe.mesh import mesh_from_data
from fe_joint.fe.reduction import build_reduced_model_from_fe


def _run(comm):
    data = build_box_joint(half=6.0, thickness=4.0, cell=2.0, shank_half=2.0, hole_half=4.0)
    return build_reduced_model_from_fe(mesh_from_data(data, comm), Material(), 30000.0, 1e-3, 150000.0)


@pytest.mark.mpi
def test_preload_and_frequencies_independent_of_partition():
    par = _run(MPI.COMM_WORLD)
    ser = _run(MPI.COMM_SELF)
    assert par.metadata["n_ranks"] == MPI.COMM_WORLD.size and ser.metadata["n_ranks"] == 1
    assert par.metadata["n_modes"] == ser.metadata["n_modes"] > 0
    assert np.array_equal(par.preload_status, ser.preload_status)
    f_ser = ser.preload_normal_force
    assert np.abs(par.preload_normal_force - f_ser).max() <= 1e-8 * np.abs(f_ser).max()
    assert np.abs(par.preload_gap - ser.preload_gap).max() <= 1e-8 * np.abs(ser.preload_gap).max()
    el = slice(6, 16)
    assert np.abs(par.full_frequencies[el] / ser.full_frequencies[el] - 1).max() <= 1e-8
    assert np.abs(par.reduced_frequencies[el] / ser.reduced_frequencies[el] - 1).max() <= 1e-8
    assert np.abs(par.K - ser.K).max() <= 1e-8 * np.abs(ser.K).max()
    # the fixed-interface modes come with a canonical sign (reduction.canonical_mode_signs), so the
    # modal blocks of M and C agree too, not only the physics (measured: M 5e-13, C 7e-11 on the
    # quick resonator; without the canonical sign M's coupling rows differ by O(1))
    assert np.abs(par.M - ser.M).max() <= 1e-9 * np.abs(ser.M).max()
    assert np.abs(par.C - ser.C).max() <= 1e-7 * np.abs(ser.C).max()


@pytest.mark.mpi
def test_column_split_condensation_equals_a_superlu_schur_complement():
    """On several ranks each rank condenses a share of the boundary columns on its own serial
    copy of K and M (``BoundaryCondensation._condense_split``): K_BB, M_BB and the modes'
    coupling M_PB equal the Schur complement and the projected mass of a SuperLU factorization."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    from petsc4py import PETSc

    from fe_joint.fe.assembly import assemble_joint
    from fe_joint.fe.condensation import BoundaryCondensation

    comm = MPI.COMM_WORLD
    data = build_box_joint(half=6.0, thickness=4.0, cell=2.0, shank_half=2.0, hole_half=4.0)
    prob = assemble_joint(mesh_from_data(data, comm), Material())
    b = prob.layout.dofs
    n = prob.K.getSize()[0]
    interior = np.setdiff1d(np.arange(n), b)
    cond = BoundaryCondensation(prob.K, prob.M, b)
    # two interior "modes", known functions of the global DOF number
    modes = []
    for k in range(2):
        v = cond.KII.createVecRight()
        lo, hi = v.getOwnershipRange()
        v.getArray()[:] = np.sin(0.37 * interior[lo:hi] + k)
        modes.append(v)
    blocks = cond.condense(modes, chunk=100)
    everything = PETSc.IS().createStride(n, 0, 1, comm=PETSc.COMM_SELF)

    def scipy_copy(A):
        ai, aj, av = A.createSubMatrices(everything)[0].getValuesCSR()
        return sp.csr_matrix((av, aj, ai), shape=(n, n))
    K, M = scipy_copy(prob.K), scipy_copy(prob.M)
    lu = spla.splu(K[interior][:, interior].tocsc())
    psi = -lu.solve(K[interior][:, b].toarray())
    schur = K[b][:, b].toarray() + K[b][:, interior] @ psi
    mi = M[interior][:, b].toarray() + M[interior][:, interior] @ psi
    mr = M[b][:, b].toarray() + M[b][:, interior] @ psi + psi.T @ mi
    phi = np.stack([np.sin(0.37 * interior + k) for k in range(2)], axis=1)
    assert comm.size == 1 or cond.mpi.size > 1
    assert np.abs(blocks["K_BB"] - schur).max() < 1e-9 * np.abs(schur).max()
    assert np.abs(blocks["M_BB"] - mr).max() < 1e-9 * np.abs(mr).max()
    assert np.abs(blocks["M_PB"] - phi.T @ mi).max() < 1e-9 * np.abs(phi.T @ mi).max()
    cond.destroy()


@dataclass(frozen=True)
class _Build:
    """A job of the queue (sent to another rank: a module-level class pickles)."""
    name: str


@pytest.mark.mpi
def test_serial_builds_inside_the_job_queue_equal_one_outside(tmp_path) -> None:
    """The speed stage builds its coarser FE models inside its job queue, each on the rank that
    runs the job (COMM_SELF), while rank 0's server thread deals the jobs over COMM_WORLD: every
    build equals one made outside the queue, and both ranks built."""
    from fe_joint.study.queue import run_jobs

    ref = _run(MPI.COMM_SELF).reduced_frequencies
    got = {}

    def run(job):
        return {"f": _run(MPI.COMM_SELF).reduced_frequencies, "rank": MPI.COMM_WORLD.rank}

    run_jobs(run, lambda folder, job, r: got.__setitem__(job.name, r),
             [_Build(f"b{i}") for i in range(4)], tmp_path, comm=MPI.COMM_WORLD, skip_done=False)
    if MPI.COMM_WORLD.rank == 0:
        assert sorted(got) == ["b0", "b1", "b2", "b3"]
        assert all(np.array_equal(r["f"], ref) for r in got.values())
        assert {r["rank"] for r in got.values()} == set(range(MPI.COMM_WORLD.size))


class _Unpicklable:
    """A job that cannot be sent to another rank."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __reduce__(self):
        raise TypeError("this job does not pickle")


@pytest.mark.mpi
def test_a_job_the_queue_cannot_send_fails_every_rank(tmp_path) -> None:
    """When rank 0's server cannot hand a job over, every rank raises JobFailed (exit class 1)
    naming the queue, instead of waiting for ever."""
    from fe_joint.errors import JobFailed
    from fe_joint.study.queue import run_jobs
    if MPI.COMM_WORLD.size == 1:
        pytest.skip("needs a second rank to send a job to")
    import time

    def run(job):       # long enough for rank 1 to ask while rank 0 is still in its first job
        time.sleep(1.0)
        return {"ok": 1.0}
    with pytest.raises(JobFailed, match="does not pickle"):
        run_jobs(run, lambda folder, job, r: None,
                 [_Unpicklable(f"u{i}") for i in range(3)], tmp_path, comm=MPI.COMM_WORLD,
                 skip_done=False)
