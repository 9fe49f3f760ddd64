"""The gmsh resonator in dolfinx: distributed mesh, tags, original-node -> dof lookup, artifacts.

``geometry.build_resonator`` runs on rank 0 only (gmsh is serial); the resulting numpy description
(:class:`geometry.ResonatorMesh`) is broadcast so every rank holds the same pair list and node
numbering, and the dolfinx mesh is created from it with ``create_mesh`` (rank 0 passes the cells,
the partitioner distributes them). Node numbers of the ``ResonatorMesh`` ("original" numbers) are
what ``mesh.geometry.input_global_indices`` returns, which is how interface pairs are found again
in any partition (:func:`original_node_dofs`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from mpi4py import MPI

import dolfinx
from dolfinx import cpp as _cpp
from dolfinx.io import gmshio
from geometry.resonator import (MARKER_NAMES, ResonatorMesh, ResonatorParams, build_resonator,
                                nominal_interface_area)

_GMSH_TET = {4: 4, 10: 11}  # nodes per cell -> gmsh element type


@dataclass
class ResonatorFE:
    """The distributed resonator.

    Attributes:
        mesh: dolfinx mesh (tet10 or tet4 geometry), coordinates in mm.
        cell_tags: cell markers 1 part A, 2 part B, 3 shank, 4 head, 5 nut.
        facet_tags: facet markers 11 lap A, 12 lap B, 13 head washer, 14 nut washer.
        data: the numpy description (identical on all ranks).
    """

    mesh: dolfinx.mesh.Mesh
    cell_tags: dolfinx.mesh.MeshTags
    facet_tags: dolfinx.mesh.MeshTags
    data: ResonatorMesh


def mesh_from_data(data: ResonatorMesh, comm: MPI.Comm = MPI.COMM_WORLD) -> ResonatorFE:
    """Create the distributed dolfinx mesh and tags from a ``ResonatorMesh`` held by every rank.

    Args:
        data: numpy mesh description (same on all ranks; only rank 0's cells are used).
        comm: communicator.

    Returns:
        The :class:`ResonatorFE`.
    """
    nn = data.cells.shape[1]
    if nn not in _GMSH_TET:
        raise ValueError(f"data.cells must have 4 or 10 nodes per cell, got {nn}")
    domain = gmshio.ufl_mesh(_GMSH_TET[nn], 3)
    cell_type = dolfinx.mesh.CellType.tetrahedron
    cperm = gmshio.cell_perm_array(cell_type, nn)
    nf = data.facets.shape[1]
    fperm = gmshio.cell_perm_array(dolfinx.mesh.CellType.triangle, nf)
    if comm.rank == 0:
        cells = np.ascontiguousarray(data.cells[:, cperm], dtype=np.int64)
        x = np.ascontiguousarray(data.points, dtype=np.float64)
        cvals = np.asarray(data.cell_markers, dtype=np.int32)
        facets = np.ascontiguousarray(data.facets[:, fperm], dtype=np.int64)
        fvals = np.asarray(data.facet_markers, dtype=np.int32)
    else:
        cells = np.empty((0, nn), dtype=np.int64)
        x = np.empty((0, 3), dtype=np.float64)
        cvals = np.empty(0, dtype=np.int32)
        facets = np.empty((0, nf), dtype=np.int64)
        fvals = np.empty(0, dtype=np.int32)
    mesh = dolfinx.mesh.create_mesh(comm, cells, x, domain)
    tdim = mesh.topology.dim

    # same recipe as dolfinx.io.gmshio.model_to_mesh (0.5.2): entities given in input numbering
    ents, vals = _cpp.io.distribute_entity_data(mesh._mesh, tdim, cells, cvals)
    mesh.topology.create_connectivity(tdim, 0)
    ct = dolfinx.mesh.meshtags_from_entities(mesh, tdim, _cpp.graph.AdjacencyList_int32(ents),
                                             vals.astype(np.int32))
    ct.name = "cell_tags"
    ents, vals = _cpp.io.distribute_entity_data(mesh._mesh, tdim - 1, facets, fvals)
    mesh.topology.create_connectivity(tdim - 1, tdim)
    ft = dolfinx.mesh.meshtags_from_entities(mesh, tdim - 1, _cpp.graph.AdjacencyList_int32(ents),
                                             vals.astype(np.int32))
    ft.name = "facet_tags"
    mesh.name = "resonator"
    return ResonatorFE(mesh=mesh, cell_tags=ct, facet_tags=ft, data=data)


def load_resonator_file(path, params: ResonatorParams, comm: MPI.Comm = MPI.COMM_WORLD) -> ResonatorFE:
    """The resonator from a mesh the mesh stage saved (``ResonatorMesh.save``). Collective.

    Rank 0 reads the file and broadcasts it, as :func:`load_resonator` does with gmsh's output:
    the fe stage builds on the very mesh the mesh stage wrote, so rerunning it gives the same
    bits (gmsh's high-order node placement does not, README "In parallel").

    Args:
        path: the ``.npz`` file.
        params: the geometry the mesh was built from.
        comm: communicator.
    """
    return mesh_from_data(_on_rank0(lambda: ResonatorMesh.load(path, params), comm), comm)


def load_resonator(params: ResonatorParams, comm: MPI.Comm = MPI.COMM_WORLD) -> ResonatorFE:
    """Build the resonator with gmsh on rank 0, broadcast it and distribute it in dolfinx.

    Collective. Invalid parameters raise ``ValueError`` on every rank (checked before gmsh runs).

    Args:
        params: geometry and mesh parameters (mm).
        comm: communicator.

    Returns:
        The :class:`ResonatorFE` (``data`` identical on every rank).
    """
    params.validate()  # every rank raises the same error; nobody waits on a failed rank 0
    return mesh_from_data(_on_rank0(lambda: build_resonator(params), comm), comm)


def _on_rank0(make, comm: MPI.Comm):
    """``make()`` on rank 0, its result broadcast; its exception raised on every rank (forwarded,
    so that the other ranks do not hang in bcast). Collective."""
    err, data = None, None
    if comm.rank == 0:
        try:
            data = make()
        except Exception as e:
            err = e
    err = comm.bcast(err, root=0)
    if err is not None:
        raise err
    return comm.bcast(data, root=0)


def _node_to_block(V: dolfinx.fem.FunctionSpace) -> np.ndarray:
    """Local block index of the dof at each local geometry node (-1 if V has no dof there)."""
    mesh = V.mesh
    gdm = mesh.geometry.dofmap
    nn = gdm.links(0).size
    g = gdm.array.reshape(-1, nn)
    nd = V.dofmap.cell_dofs(0).size
    v = V.dofmap.list.array.reshape(-1, nd)
    # Lagrange layouts agree column by column for equal degree; vertices come first in both,
    # so with unequal degrees (P1 space on P2 mesh or vice versa) the 4 vertex columns agree
    k = nn if nn == nd else 4
    if nn != nd and 4 not in (nn, nd):
        raise ValueError(f"V has {nd} dofs per cell, geometry {nn} nodes: need P1/P2 Lagrange")
    blk = np.full(mesh.geometry.x.shape[0], -1, dtype=np.int64)
    blk[g[:, :k].ravel()] = v[:, :k].ravel()
    return blk


def original_node_dofs(V: dolfinx.fem.FunctionSpace, original_nodes: np.ndarray,
                       return_owned: bool = False):
    """Local block (node) index of the dof at each ORIGINAL node (``ResonatorMesh`` numbering).

    Not collective: every rank answers for its own local (owned + ghost) dofs.

    Args:
        V: (vector) Lagrange P1/P2 space on the resonator mesh.
        original_nodes: (n,) int node indices of the ``ResonatorMesh``.
        return_owned: also return the mask of nodes whose dof this rank owns.

    Returns:
        (n,) int64 local block index (dof index for a scalar space; multiply by ``bs`` and add the
        component for a vector space) or -1 if this rank does not hold the node; with
        ``return_owned`` a tuple (blocks, owned) where ``owned`` is (n,) bool (each node is owned
        by exactly one rank).
    """
    nodes = np.asarray(original_nodes)
    if nodes.ndim != 1 or (nodes.size and not np.issubdtype(nodes.dtype, np.integer)):
        raise ValueError(f"original_nodes must be a 1-D integer array, got shape {nodes.shape} "
                         f"dtype {nodes.dtype}")
    nodes = nodes.astype(np.int64)
    blk = _node_to_block(V)
    orig = np.asarray(V.mesh.geometry.input_global_indices, dtype=np.int64)
    keep = blk >= 0
    orig, blk = orig[keep], blk[keep]
    order = np.argsort(orig)
    so, sb = orig[order], blk[order]
    out = np.full(nodes.shape, -1, dtype=np.int64)
    if so.size:
        pos = np.minimum(np.searchsorted(so, nodes), so.size - 1)
        hit = so[pos] == nodes
        out[hit] = sb[pos[hit]]
    if return_owned:
        owned = (out >= 0) & (out < V.dofmap.index_map.size_local)
        return out, owned
    return out


def _volumes(fe: ResonatorFE) -> dict[str, float]:
    """Volume per marker and total from dolfinx forms, mm³ (collective)."""
    # det J of a P2 map is cubic: degree 3 integrates curved cells exactly (the default is lower)
    dx = ufl.Measure("dx", domain=fe.mesh, subdomain_data=fe.cell_tags,
                     metadata={"quadrature_degree": 3})
    one = dolfinx.fem.Constant(fe.mesh, 1.0)
    out = {}
    for m, name in MARKER_NAMES.items():
        loc = dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * dx(m)))
        out[name] = fe.mesh.comm.allreduce(loc, op=MPI.SUM)
    out["total"] = sum(out.values())
    return out


def mesh_statistics(fe: ResonatorFE) -> dict:
    """Mesh statistics (collective): nodes, cells, P2-vector dofs, pairs, interface area, volumes.

    Returns:
        dict with n_nodes, n_cells, n_dofs (P2 vector space), n_pairs, interface_area (mm², Σ pair
        tributary areas), nominal_interface_area (mm²), volumes (mm³ per marker name, from dolfinx
        forms), build_time_s (gmsh, rank 0).
    """
    mesh = fe.mesh
    tdim = mesh.topology.dim
    if fe.data.cells.shape[1] == 10:
        n_dofs = 3 * mesh.geometry.index_map().size_global
    else:
        V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 2))
        n_dofs = V.dofmap.index_map.size_global * V.dofmap.index_map_bs
    return {
        "n_nodes": int(mesh.geometry.index_map().size_global),
        "n_cells": int(mesh.topology.index_map(tdim).size_global),
        "n_dofs": int(n_dofs),
        "n_pairs": int(fe.data.n_pairs),
        "interface_area": float(fe.data.pair_area.sum()),
        "nominal_interface_area": float(nominal_interface_area(fe.data.params)),
        "volumes": {k: float(v) for k, v in _volumes(fe).items()},
        "build_time_s": float(fe.data.build_time),
    }
