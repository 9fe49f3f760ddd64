"""Original (mesh-file) node numbers <-> dolfinx/PETSc degrees of freedom, rank-independent.

Interface quantities must come out in the ORIGINAL pair order whatever the partition, so every
lookup here goes through ``mesh.geometry.input_global_indices`` (the node number given to
``create_mesh``) and returns the same answer on every rank.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import ufl
from mpi4py import MPI

import dolfinx
from dolfinx.io import gmshio


class JointFE(NamedTuple):
    """A distributed joint mesh: dolfinx mesh, cell tags (markers 1-5) and the source mesh data."""

    mesh: "dolfinx.mesh.Mesh"
    cell_tags: "dolfinx.mesh.MeshTags"
    facet_tags: object
    data: object


def load_joint_mesh(data, comm: MPI.Comm = MPI.COMM_WORLD) -> JointFE:
    """Distribute a tet10 joint mesh (``JointMeshData`` / ``ResonatorMesh``) over ``comm``.

    Args:
        data: object with ``points`` (n, 3) mm, ``cells`` (n_cells, 10) gmsh order, ``cell_markers``.
        comm: MPI communicator; every rank must pass the same ``data``.

    Returns:
        JointFE(mesh, cell_tags, None, data).
    """
    cells = np.asarray(data.cells, dtype=np.int64)
    if cells.ndim != 2 or cells.shape[1] != 10:
        raise ValueError(f"data.cells must be (n_cells, 10) tet10 connectivity, got shape {cells.shape}")
    perm = gmshio.cell_perm_array(dolfinx.mesh.CellType.tetrahedron, 10)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, 2))
    if comm.rank == 0:
        c, x = cells[:, perm], np.asarray(data.points, dtype=np.float64)
    else:
        c, x = np.empty((0, 10), dtype=np.int64), np.empty((0, 3))
    mesh = dolfinx.mesh.create_mesh(comm, c, x, domain)
    tdim = mesh.topology.dim
    n_local = mesh.topology.index_map(tdim).size_local
    orig = np.asarray(mesh.topology.original_cell_index)[:n_local]
    markers = np.asarray(data.cell_markers, dtype=np.int32)[orig]
    tags = dolfinx.mesh.meshtags(mesh, tdim, np.arange(n_local, dtype=np.int32), markers)
    return JointFE(mesh, tags, None, data)


def node_to_block(V: "dolfinx.fem.FunctionSpace") -> tuple[np.ndarray, np.ndarray]:
    """Local block index of every local geometry node (P2 space on a P2 geometry).

    Returns:
        (original node number per local geometry node, local block index per local geometry node).
    """
    mesh = V.mesh
    nn = len(mesh.geometry.dofmap.links(0))
    gdm = mesh.geometry.dofmap.array.reshape(-1, nn)
    vdm = V.dofmap.list.array.reshape(-1, V.dofmap.cell_dofs(0).size)
    if vdm.shape[1] != nn:
        raise ValueError("node_to_block needs a function space of the geometry's degree (P2 on tet10)")
    blk = np.empty(mesh.geometry.x.shape[0], dtype=np.int32)
    blk[gdm.ravel()] = vdm.ravel()
    return np.asarray(mesh.geometry.input_global_indices, dtype=np.int64), blk


def global_node_dofs(V: "dolfinx.fem.FunctionSpace", nodes: np.ndarray) -> np.ndarray:
    """Global PETSc DOF numbers (x, y, z) of original nodes, identical on every rank.

    Args:
        V: vector P2 space (block size 3) on the tet10 mesh.
        nodes: (n,) original node numbers.

    Returns:
        (n, 3) int64 global DOF indices; raises ValueError if a node is not in the mesh.
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    orig, blk = node_to_block(V)
    imap = V.dofmap.index_map
    bs = V.dofmap.index_map_bs
    n_owned = imap.size_local
    owned = blk < n_owned  # each node is owned by exactly one rank
    order = np.argsort(orig[owned])
    so, sb = orig[owned][order], blk[owned][order]
    pos = np.searchsorted(so, nodes)
    pos = np.minimum(pos, max(len(so) - 1, 0))
    found = (len(so) > 0) & (so[pos] == nodes) if len(so) else np.zeros(len(nodes), bool)
    gblk = np.where(found, sb[pos] + imap.local_range[0], -1).astype(np.int64)
    comm = V.mesh.comm
    if comm.size > 1:
        out = np.empty_like(gblk)
        comm.Allreduce(gblk, out, op=MPI.MAX)
        gblk = out
    if np.any(gblk < 0):
        bad = nodes[gblk < 0][:5]
        raise ValueError(f"nodes {bad.tolist()} are not nodes of the mesh (check pair_nodes / excitation_node)")
    return gblk[:, None] * bs + np.arange(bs)[None, :]
