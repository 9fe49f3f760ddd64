"""Static condensation on a set of boundary DOFs with constraint modes computed in chunks.

Partition the DOFs into boundary B (given, in a canonical rank-independent order) and interior I.
The constraint modes are Psi = -K_II^{-1} K_IB; they are never stored whole: for each chunk of
boundary columns we solve with the MUMPS factorization of K_II (dense multi-RHS solve) and
accumulate the small dense blocks

    K_r,BB = K_BB + K_BI Psi                       (the cheap identity, no Psiᵀ K Psi product)
    M_r,BB = M_BB + M_BI Psi + Psiᵀ (M_IB + M_II Psi),   with Psiᵀ X = -K_BI K_II^{-1} X
    M_r,PhiB = Phi_Iᵀ (M_IB + M_II Psi)            (fixed-interface modes Phi_I)

so memory is bounded by a few (n_I x chunk) dense blocks. Results are gathered on every rank in
the canonical boundary order, hence identical for any number of ranks (to round-off).

On several ranks the columns are split instead of the matrix (issue 16, session 12): every rank
takes a sequential copy of K and M, factorizes its own K_II serially and condenses its share of
the boundary columns with sparse right-hand sides; the column blocks are then gathered. The
distributed MUMPS solve needs dense right-hand sides (MUMPS rejects sparse ones in parallel) and
was no faster on 2 ranks than one rank alone (the default model's 2121 columns: 29.7 s on 2 ranks,
29 s serially); the split halves it. The distributed factor stays for the preload's solves.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .modal import mumps_cholesky


class BoundaryCondensation:
    """Boundary/interior split of assembled K (and M) with a factorized K_II.

    Args:
        K: assembled stiffness (free, N/mm).
        M: assembled mass (t) or None (static condensation only).
        boundary_dofs: (n_B,) global DOF numbers in canonical order, identical on all ranks.
    """

    def __init__(self, K: PETSc.Mat, M: PETSc.Mat | None, boundary_dofs: np.ndarray):
        self.K, self.M = K, M
        self.comm = K.getComm()
        self.mpi = self.comm.tompi4py()
        bd = np.asarray(boundary_dofs, dtype=np.int64)
        if len(np.unique(bd)) != len(bd):
            raise ValueError("boundary_dofs must not repeat a DOF")
        self.n_b = len(bd)
        lo, hi = K.getOwnershipRange()
        mine = (bd >= lo) & (bd < hi)
        # PETSc's parallel createSubMatrix needs sorted local indices: keep my boundary rows in
        # increasing global order and remember the canonical position of each
        order = np.argsort(bd[mine], kind="stable")
        self.bd = bd
        self.b_canon_local = np.nonzero(mine)[0][order]  # canonical positions of my boundary rows
        # sub-matrix row order is rank-major; remember the canonical index of every sub row
        self.b_canon_all = np.concatenate(self.mpi.allgather(self.b_canon_local))
        interior = np.setdiff1d(np.arange(lo, hi), bd[mine])
        self.isB = PETSc.IS().createGeneral(bd[self.b_canon_local].astype(PETSc.IntType), comm=self.comm)
        self.isI = PETSc.IS().createGeneral(interior.astype(PETSc.IntType), comm=self.comm)
        self.n_i_local = len(interior)
        self.KII = K.createSubMatrix(self.isI, self.isI)
        self.KIB = K.createSubMatrix(self.isI, self.isB)
        self.KBI = K.createSubMatrix(self.isB, self.isI)
        self.KBB = K.createSubMatrix(self.isB, self.isB)
        if M is not None:
            self.MII = M.createSubMatrix(self.isI, self.isI)
            self.MIB = M.createSubMatrix(self.isI, self.isB)
            self.MBI = M.createSubMatrix(self.isB, self.isI)
            self.MBB = M.createSubMatrix(self.isB, self.isB)
        for A in (self.KII,) + ((self.MII,) if M is not None else ()):
            A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        self._ksp = None  # factorized lazily: the fixed-interface eigen solve runs first with its own

    @property
    def ksp(self) -> PETSc.KSP:
        """MUMPS Cholesky solver of K_II (factorized on first use)."""
        if self._ksp is None:
            self._ksp = mumps_cholesky(PETSc.KSP().create(self.comm))
            self._ksp.setOperators(self.KII)
            self._ksp.setUp()
        return self._ksp

    @property
    def factor(self) -> PETSc.Mat:
        """The factored K_II."""
        return self.ksp.getPC().getFactorMatrix()

    def release_factor(self) -> None:
        """Free the factorization (the condensed blocks stay available)."""
        if self._ksp is not None:
            self._ksp.destroy()
            self._ksp = None

    # ---- helpers -------------------------------------------------------------------------
    def _gather_b_rows(self, local: np.ndarray) -> np.ndarray:
        """Rows of a boundary-distributed array (local rows in sub order) -> canonical full array."""
        parts = self.mpi.allgather(np.ascontiguousarray(local))
        stacked = np.concatenate(parts, axis=0)
        out = np.empty_like(stacked)
        out[self.b_canon_all] = stacked
        return out

    def _dense(self, rows_local: int, rows_global: int, ncols: int) -> PETSc.Mat:
        A = PETSc.Mat().createDense([(rows_local, rows_global), (PETSc.DECIDE, ncols)], comm=self.comm)
        A.setUp()
        return A

    def _selection(self, cols: np.ndarray) -> PETSc.Mat:
        """Dense n_B x len(cols) matrix with E[b, j] = 1 where canonical b == cols[j] (contiguous cols)."""
        E = self._dense(len(self.b_canon_local), self.n_b, len(cols))
        arr = E.getDenseArray()
        arr[:] = 0.0
        rows = np.nonzero((self.b_canon_local >= cols[0]) & (self.b_canon_local <= cols[-1]))[0]
        arr[rows, self.b_canon_local[rows] - cols[0]] = 1.0  # cols is a contiguous range
        E.assemble()
        return E

    def solve_interior(self, B: PETSc.Mat) -> PETSc.Mat:
        """X = K_II^{-1} B for a dense block B (MUMPS multi-RHS solve)."""
        X = B.duplicate()
        self.factor.matSolve(B, X)
        return X

    def _solve_coupling(self, cols: np.ndarray, E: PETSc.Mat) -> PETSc.Mat:
        """K_II^{-1} K_IB[:, cols] as a dense block.

        Serially the right-hand side goes to MUMPS as a sparse matrix (a transpose view of the
        K_BI rows; MUMPS prunes the forward elimination, measured 2x faster); MUMPS rejects a
        sparse RHS in parallel, so there it is the dense product K_IB E.
        """
        if self.mpi.size == 1:
            rows = PETSc.IS().createGeneral(self.bd[cols].astype(PETSc.IntType), comm=self.comm)
            Bt = self.K.createSubMatrix(rows, self.isI)
            T = PETSc.Mat().createTranspose(Bt)
            P = self._dense(self.n_i_local, self.KII.getSize()[0], len(cols))
            self.factor.matSolve(T, P)
            for A in (T, Bt, rows):
                A.destroy()
            return P
        R = self.KIB.matMult(E)
        P = self.solve_interior(R)
        R.destroy()
        return P

    # ---- condensation --------------------------------------------------------------------
    def auto_chunk(self, budget_mb: float = 1000.0, max_chunk: int = 256) -> int:
        """Chunk size keeping the ~5 dense (n_I x chunk) work blocks within ``budget_mb`` per run."""
        n_i = self.KII.getSize()[0]
        return int(max(16, min(max_chunk, budget_mb * 1e6 / (5 * 8 * max(n_i, 1)))))

    def condense(self, modes_interior: list | None = None, chunk: int | None = None) -> dict:
        """Reduced boundary blocks, computed chunk by chunk.

        Args:
            modes_interior: fixed-interface modes (PETSc Vecs on the interior layout) or None.
            chunk: boundary columns per block (memory ~ 5 * n_I * chunk * 8 bytes); None: auto
                (:meth:`auto_chunk`, <= 256 columns and ~1 GB).

        Returns:
            dict with ``K_BB`` (n_B, n_B) N/mm, and if M was given ``M_BB`` (n_B, n_B) t and
            ``M_PB`` (n_modes, n_B) t (coupling of modal and boundary coordinates).
        """
        chunk = self.auto_chunk() if chunk is None else chunk
        if chunk < 1:
            raise ValueError(f"chunk must be >= 1, got {chunk}")
        phi = None
        if self.M is not None:
            phi = (np.stack([v.getArray(readonly=True) for v in modes_interior], axis=1)
                   if modes_interior else np.zeros((self.n_i_local, 0)))
        if self.mpi.size == 1:
            blocks = self._condense_columns(0, self.n_b, phi, chunk)
        else:
            blocks = self._condense_split(phi, chunk)
        out = {"K_BB": 0.5 * (blocks["K_BB"] + blocks["K_BB"].T)}
        if self.M is not None:
            out["M_BB"] = 0.5 * (blocks["M_BB"] + blocks["M_BB"].T)
            out["M_PB"] = blocks["M_PB"]
        self.condensed = out
        return out

    def _condense_split(self, phi: np.ndarray | None, chunk: int) -> dict:
        """:meth:`condense`'s column blocks on several ranks: each rank condenses a contiguous
        share of the boundary columns on its own sequential copy of K and M (module docstring),
        then the shares are gathered on every rank (unsymmetrized)."""
        size, rank = self.mpi.size, self.mpi.rank
        n = self.K.getSize()[0]
        everything = PETSc.IS().createStride(n, 0, 1, comm=PETSc.COMM_SELF)
        K = self.K.createSubMatrices(everything)[0]
        M = self.M.createSubMatrices(everything)[0] if self.M is not None else None
        everything.destroy()
        serial = BoundaryCondensation(K, M, self.bd)
        if phi is not None:
            # the interior in increasing global order: the ranks' interiors one after the other
            phi = np.concatenate(self.mpi.allgather(np.ascontiguousarray(phi)), axis=0)
        edges = np.linspace(0, self.n_b, size + 1).round().astype(int)
        mine = serial._condense_columns(edges[rank], edges[rank + 1], phi, chunk)
        serial.destroy()
        K.destroy()
        if M is not None:
            M.destroy()
        return {name: np.concatenate(self.mpi.allgather(block), axis=1) for name, block in mine.items()}

    def _condense_columns(self, lo: int, hi: int, phi: np.ndarray | None, chunk: int) -> dict:
        """The condensed blocks' canonical columns lo..hi-1 (``K_BB``, and with M ``M_BB`` and
        ``M_PB``; (n_B, hi - lo) and (n_modes, hi - lo)), chunk by chunk; ``phi`` the
        fixed-interface modes' interior values on this rank (n_I local, n_modes) or None."""
        nb = self.n_b
        KBBr = np.zeros((nb, hi - lo))
        with_mass = self.M is not None
        if with_mass:
            MBBr = np.zeros((nb, hi - lo))
            MPB = np.zeros((phi.shape[1], hi - lo))
        for start in range(lo, hi, chunk):
            cols = np.arange(start, min(start + chunk, hi))
            put = cols - lo
            E = self._selection(cols)
            P = self._solve_coupling(cols, E)        # K_II^{-1} K_IB E = -Psi chunk
            S = self.KBB.matMult(E)
            T = self.KBI.matMult(P)
            KBBr[:, put] = self._gather_b_rows(S.getDenseArray() - T.getDenseArray())
            S.destroy(); T.destroy()
            if with_mass:
                X = self.MIB.matMult(E)
                MP = self.MII.matMult(P)
                Xa = X.getDenseArray()
                Xa -= MP.getDenseArray()             # X = M_IB E + M_II Psi
                MP.destroy()
                Y = self.solve_interior(X)
                A1 = self.MBB.matMult(E)
                A2 = self.MBI.matMult(P)
                A3 = self.KBI.matMult(Y)
                MBBr[:, put] = self._gather_b_rows(A1.getDenseArray() - A2.getDenseArray()
                                                   - A3.getDenseArray())
                loc = phi.T @ X.getDenseArray()
                self.mpi.Allreduce(MPI.IN_PLACE, loc, op=MPI.SUM)
                MPB[:, put] = loc
                for A in (X, Y, A1, A2, A3):
                    A.destroy()
            P.destroy(); E.destroy()
        out = {"K_BB": KBBr}
        if with_mass:
            out["M_BB"], out["M_PB"] = MBBr, MPB
        return out

    def condense_load(self, f: PETSc.Vec) -> np.ndarray:
        """Condensed load f_B + Psiᵀ f_I = f_B - K_BI K_II^{-1} f_I, canonical order (N)."""
        fI = f.getSubVector(self.isI)
        fB = f.getSubVector(self.isB)
        x = fI.duplicate()
        self.ksp.solve(fI, x)
        y = fB.duplicate()
        self.KBI.mult(x, y)
        out = self._gather_b_rows(fB.getArray(readonly=True) - y.getArray(readonly=True))
        f.restoreSubVector(self.isI, fI)
        f.restoreSubVector(self.isB, fB)
        return out

    def expand(self, u_b: np.ndarray, f: PETSc.Vec | None = None) -> PETSc.Vec:
        """Full displacement from boundary values: u_I = K_II^{-1} (f_I - K_IB u_B).

        Args:
            u_b: (n_B,) boundary displacements, canonical order, mm.
            f: full load vector (N) or None.

        Returns:
            full displacement Vec (mm).
        """
        u = self.K.createVecRight()
        uB = u.getSubVector(self.isB)
        uB.getArray()[:] = np.asarray(u_b)[self.b_canon_local]
        rhs = self.KII.createVecLeft()
        self.KIB.mult(uB, rhs)
        rhs.scale(-1.0)
        if f is not None:
            fI = f.getSubVector(self.isI)
            rhs.axpy(1.0, fI)
            f.restoreSubVector(self.isI, fI)
        u.restoreSubVector(self.isB, uB)
        uI = u.getSubVector(self.isI)
        self.ksp.solve(rhs, uI)
        u.restoreSubVector(self.isI, uI)
        return u

    def interior_pair(self) -> tuple[PETSc.Mat, PETSc.Mat]:
        """(K_II, M_II) for the fixed-interface eigenproblem."""
        return self.KII, self.MII

    def destroy(self):
        """Free the factorization and sub-matrices."""
        self.release_factor()
        for name in ("KII", "KIB", "KBI", "KBB", "MII", "MIB", "MBI", "MBB"):
            if hasattr(self, name):
                getattr(self, name).destroy()
