"""Files the FE stages write for ParaView and for the later stages: the mesh with its tags and the
interface pairs, the preload fields (XDMF; rank 0 writes csv, json and PNG)."""
from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path

import numpy as np

import dolfinx
from dolfinx.io import XDMFFile

from ..model.interface_contact import PreloadResult
from ..report.fe_figures import plot_geometry, plot_pressure_map
from .assembly import SHANK_MARKER, global_node_dofs
from .elasticity import von_mises_dg0
from .mesh import ResonatorFE, mesh_statistics


def write_mesh_artifacts(fe: ResonatorFE, out_dir: Path) -> dict:
    """Write mesh.xdmf (+ .h5: mesh, cell and facet tags), pairs.csv, geometry.png, mesh.json and
    resonator.npz (the gmsh mesh itself, which the fe stage reads).

    Collective (XDMF is written in parallel; csv, png and json by rank 0).

    Args:
        fe: the distributed resonator.
        out_dir: output folder (created).

    Returns:
        :func:`mesh_statistics` plus ``files`` (names written).
    """
    out_dir = Path(out_dir)
    comm = fe.mesh.comm
    if comm.rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    stats = mesh_statistics(fe)
    with dolfinx.io.XDMFFile(comm, str(out_dir / "mesh.xdmf"), "w") as f:
        f.write_mesh(fe.mesh)
        fe.mesh.topology.create_connectivity(fe.mesh.topology.dim - 1, fe.mesh.topology.dim)
        f.write_meshtags(fe.cell_tags)
        f.write_meshtags(fe.facet_tags)
    files = ["mesh.xdmf", "mesh.h5", "pairs.csv", "geometry.png", "mesh.json", "resonator.npz"]
    if comm.rank == 0:
        d = fe.data
        # the mesh the fe stage builds on (fe.mesh.load_resonator_file)
        d.save(out_dir / "resonator.npz")
        table = np.column_stack([np.arange(d.n_pairs), d.pair_xyz, d.pair_area, d.pair_nodes])
        np.savetxt(out_dir / "pairs.csv", table, delimiter=",",
                   fmt=["%d", "%.12g", "%.12g", "%.12g", "%.12g", "%d", "%d"],
                   header="index,x,y,z,area,node_a,node_b", comments="")
        plot_geometry(d, out_dir / "geometry.png")
        meta = {**stats, "params": asdict(d.params), "excitation_node": int(d.excitation_node),
                "response_node": int(d.response_node),
                "excitation_xyz": d.points[d.excitation_node].tolist()}
        (out_dir / "mesh.json").write_text(json.dumps(meta, indent=2))
    comm.barrier()
    stats["files"] = files
    return stats


def write_preload_fields(problem, res: PreloadResult, out_dir: str) -> None:
    """Write displacement, von Mises stress and interface pressure to XDMF and a pressure PNG."""
    comm = problem.V.mesh.comm
    if comm.rank == 0:
        os.makedirs(out_dir, exist_ok=True)
    comm.barrier()
    mesh = problem.V.mesh
    vm = von_mises_dg0(res.displacement, problem.material, res.eigenstrain, SHANK_MARKER, problem.fe.cell_tags)
    # interface pressure as a P2 scalar field on both lap faces
    Q = dolfinx.fem.FunctionSpace(mesh, ("Lagrange", 2))
    pres = dolfinx.fem.Function(Q, name="interface_pressure")
    pairs = np.asarray(problem.fe.data.pair_nodes)
    gd = global_node_dofs(problem.V, pairs.ravel())[:, 0] // 3
    lo, hi = Q.dofmap.index_map.local_range
    vals = np.repeat(res.pair_pressure, 2)
    mine = (gd >= lo) & (gd < hi)
    pres.x.array[gd[mine] - lo] = vals[mine]
    pres.x.scatter_forward()
    # P2 fields on the tet10 mesh: XDMF stores them at the geometry nodes (exact nodal values)
    u1, p1 = res.displacement, pres
    path = os.path.join(out_dir, "preload.xdmf")
    with XDMFFile(comm, path, "w") as xf:
        xf.write_mesh(mesh)
        xf.write_function(u1)
        xf.write_function(p1)
        xf.write_function(vm)
    if comm.rank == 0:
        plot_pressure_map(problem.fe.data, res.pair_pressure, os.path.join(out_dir, "preload_pressure.png"))
