"""The assembled FE problem of a bolted joint: space, K, M, bolt eigenstrain load, boundary layout.

Boundary DOFs (kept by the condensation and the Craig–Bampton reduction) in canonical order:
``[pair A nodes (x, y, z) in pair order, pair B nodes (x, y, z), extra nodes (x, y, z)]`` where
the extra nodes are the excitation and response nodes (deduplicated, skipped if already a pair
node). The order depends only on the mesh data, never on the MPI partition.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import ufl
from mpi4py import MPI

from .elasticity import (Material, assemble_eigenstrain_load, assemble_mass, assemble_stiffness,
                                 vector_space)
from .mesh import original_node_dofs

SHANK_MARKER = 3


def global_node_dofs(V, nodes: np.ndarray) -> np.ndarray:
    """Global PETSc DOF numbers (x, y, z) of ORIGINAL nodes, identical on every rank (collective).

    Args:
        V: vector P2 space on the tet10 mesh.
        nodes: (n,) original node numbers.

    Returns:
        (n, 3) int64 global DOF indices.
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    blk, owned = original_node_dofs(V, nodes, return_owned=True)
    imap = V.dofmap.index_map
    gblk = np.where(owned, blk + imap.local_range[0], -1).astype(np.int64)
    out = np.empty_like(gblk)
    V.mesh.comm.Allreduce(gblk, out, op=MPI.MAX)
    if np.any(out < 0):
        raise ValueError(f"nodes {nodes[out < 0][:5].tolist()} are not nodes of the mesh "
                         "(check pair_nodes / excitation_node)")
    bs = V.dofmap.index_map_bs
    return out[:, None] * bs + np.arange(bs)[None, :]


@dataclass
class BoundaryLayout:
    """Canonical boundary DOF layout.

    Attributes:
        nodes: (n_nodes,) original node numbers, canonical order.
        dofs: (n_nodes * 3,) global PETSc DOFs, canonical order.
        pair_a, pair_b: (n_pairs, 3) boundary indices of the A / B node of each pair (x, y, z).
        extra: dict name -> (3,) boundary indices of the excitation / response node.
    """

    nodes: np.ndarray
    dofs: np.ndarray
    pair_a: np.ndarray
    pair_b: np.ndarray
    extra: dict = field(default_factory=dict)

    @property
    def size(self) -> int:
        """Number of boundary DOFs."""
        return len(self.dofs)


def check_mesh_data(data) -> None:
    """Validate the interface data of a joint mesh; raise ValueError naming the problem."""
    pairs = np.asarray(getattr(data, "pair_nodes", np.empty((0, 2))))
    if pairs.ndim != 2 or pairs.shape[1] != 2 or len(pairs) == 0:
        raise ValueError("mesh has no matched lap faces: pair_nodes must be a non-empty (n_pairs, 2) array")
    pts = np.asarray(data.points)
    if not np.all(np.isfinite(pts)):
        raise ValueError("mesh points contain NaN or inf")
    if pairs.min() < 0 or pairs.max() >= len(pts):
        raise ValueError(f"pair_nodes must index points (0..{len(pts) - 1})")
    gap = np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1)
    scale = np.ptp(pts, axis=0).max()
    if gap.max() > 1e-8 * scale:
        raise ValueError(f"lap faces are not matched: pair nodes up to {gap.max():.3g} mm apart (must coincide)")
    if len(np.unique(pairs)) != pairs.size:
        raise ValueError("pair_nodes repeats a node: each lap node belongs to exactly one pair")
    area = np.asarray(data.pair_area, dtype=float)
    if area.shape != (len(pairs),) or not np.all(np.isfinite(area)) or np.any(area <= 0):
        raise ValueError("pair_area must be (n_pairs,) finite and > 0 (tributary areas, mm²)")
    cm = np.asarray(data.cell_markers)
    if not np.any(cm == SHANK_MARKER):
        raise ValueError(f"mesh has no bolt shank cells (cell marker {SHANK_MARKER}) to carry the pretension")


def boundary_layout(V, data) -> BoundaryLayout:
    """Build the canonical boundary layout of a joint (see module docstring)."""
    pairs = np.asarray(data.pair_nodes, dtype=np.int64)
    npair = len(pairs)
    nodes = [pairs[:, 0], pairs[:, 1]]
    extra, seen, k = {}, {int(n): i for i, n in enumerate(np.r_[pairs[:, 0], pairs[:, 1]])}, 2 * npair
    for name in ("excitation_node", "response_node"):
        n = int(getattr(data, name))
        if n not in seen:
            seen[n] = k
            nodes.append(np.array([n]))
            k += 1
        extra[name.replace("_node", "")] = 3 * seen[n] + np.arange(3)
    nodes = np.concatenate(nodes)
    dofs = global_node_dofs(V, nodes).ravel()
    ar = np.arange(3)
    return BoundaryLayout(nodes=nodes, dofs=dofs, pair_a=3 * np.arange(npair)[:, None] + ar,
                          pair_b=3 * (npair + np.arange(npair))[:, None] + ar, extra=extra)


@dataclass
class JointProblem:
    """Assembled operators of the joint.

    Attributes:
        V: vector Lagrange space; K (N/mm), M (t) free–free PETSc matrices; f_eig: load (N) of a unit
        axial shortening eigenstrain in the shank; layout: boundary layout; shank_length: mm;
        dx_shank: UFL measure restricted to the shank.
    """

    fe: object
    material: Material
    V: object
    K: object
    M: object
    f_eig: object
    layout: BoundaryLayout
    shank_length: float
    dx_shank: object
    degree: int = 2

    @property
    def n_dofs(self) -> int:
        """Global number of DOFs."""
        return self.K.getSize()[0]


def assemble_joint(fe, material: Material, degree: int = 2, with_mass: bool = True) -> JointProblem:
    """Assemble K, M and the bolt eigenstrain load of a distributed joint mesh.

    Args:
        fe: JointFE / ResonatorFE with ``mesh``, ``cell_tags`` and ``data``.
        material: elastic material.
        degree: Lagrange degree (2: the nodes of the tet10 mesh are the DOF nodes).
        with_mass: also assemble M.
    """
    check_mesh_data(fe.data)
    if degree != 2:
        raise ValueError("the joint chain uses P2 (matched pairs live on tet10 nodes); degree must be 2")
    V = vector_space(fe.mesh, degree)
    K = assemble_stiffness(V, material)
    M = assemble_mass(V, material) if with_mass else None
    dx = ufl.Measure("dx", domain=fe.mesh, subdomain_data=fe.cell_tags)
    f = assemble_eigenstrain_load(V, material, dx(SHANK_MARKER))
    pts = np.asarray(fe.data.points)
    shank_nodes = np.unique(np.asarray(fe.data.cells)[np.asarray(fe.data.cell_markers) == SHANK_MARKER])
    length = float(np.ptp(pts[shank_nodes, 2]))
    return JointProblem(fe=fe, material=material, V=V, K=K, M=M, f_eig=f,
                        layout=boundary_layout(V, fe.data), shank_length=length,
                        dx_shank=dx(SHANK_MARKER), degree=degree)


def shank_axial_force(problem: JointProblem, u, eigenstrain: float) -> float:
    """Axial force in the free span of the shank, N: A_shank * mean(sigma_zz) over the shank cells
    whose centroid lies between the nut (marker 5) and the head (marker 4).

    The shank sides are traction-free between head and nut, so the section force is the same on
    every cross-section there; the volume mean of sigma_zz over that span times the section area
    (shank volume / length) measures it independently of the contact forces. The parts of the
    shank inside the nut/head are excluded (the force is handed over there).
    """
    from .elasticity import axial_eigenstrain, strain, stress
    import dolfinx.fem as fem

    mesh = problem.V.mesh
    comm = mesh.comm
    tags = problem.fe.cell_tags
    cells = tags.indices[tags.values == SHANK_MARKER]
    data = problem.fe.data
    pts, cm = np.asarray(data.points), np.asarray(data.cell_markers)
    z_lo = pts[np.unique(np.asarray(data.cells)[cm == 5]), 2].max() if np.any(cm == 5) else -np.inf
    z_hi = pts[np.unique(np.asarray(data.cells)[cm == 4]), 2].min() if np.any(cm == 4) else np.inf
    W = fem.FunctionSpace(mesh, ("DG", 0))
    zc = fem.Function(W)
    zc.interpolate(lambda x: x[2])
    slab = cells[(zc.x.array[cells] > z_lo) & (zc.x.array[cells] < z_hi)]
    ind = fem.Function(W)
    ind.x.array[:] = 0.0
    ind.x.array[slab] = 1.0
    sig = stress(strain(u) - eigenstrain * axial_eigenstrain(), problem.material)
    dx = problem.dx_shank

    def total(expr):
        return comm.allreduce(fem.assemble_scalar(fem.form(expr)), op=MPI.SUM)

    vol_shank = total(fem.Constant(mesh, 1.0) * dx)
    return total(ind * sig[2, 2] * dx) / total(ind * dx) * vol_shank / problem.shank_length
