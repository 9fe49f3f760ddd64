#!/usr/bin/env python3
"""Benchmark the resonator mesh: size, pairs, gmsh build and dolfinx load times, accuracy.

    .venv/bin/python scripts/bench_geometry.py [--fine]
    mpirun -n 2 .venv/bin/python scripts/bench_geometry.py

Prints a markdown table (rank 0).
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from mpi4py import MPI

from fe_joint.fe.mesh import load_resonator, mesh_statistics
from geometry import ResonatorParams, nominal_interface_area, nominal_volumes, scaled_jacobian

PRESETS = {
    "coarse": ResonatorParams(lap_mesh_size=4.0, body_mesh_size=14.0, leaf_mesh_size=6.0),
    "default": ResonatorParams(),
    "fine": ResonatorParams(lap_mesh_size=2.0, body_mesh_size=5.0, hole_mesh_size=1.2,
                            leaf_mesh_size=3.0),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fine", action="store_true", help="also run the fine preset (slower)")
    args = ap.parse_args()
    comm = MPI.COMM_WORLD
    names = ["coarse", "default"] + (["fine"] if args.fine else [])
    rows = []
    for name in names:
        p = PRESETS[name]
        comm.barrier()
        t0 = time.perf_counter()
        fe = load_resonator(p, comm)
        t_load = time.perf_counter() - t0
        st = mesh_statistics(fe)
        d = fe.data
        vol_err = abs(st["volumes"]["total"] / nominal_volumes(p)["total"] - 1)
        area_err = abs(st["interface_area"] / nominal_interface_area(p) - 1)
        rows.append((name, p.lap_mesh_size, p.body_mesh_size, p.hole_mesh_size, st["n_nodes"],
                     st["n_cells"], st["n_dofs"], st["n_pairs"], d.build_time, t_load,
                     vol_err, area_err, float(np.min(scaled_jacobian(d.points, d.cells)))))
    if comm.rank == 0:
        print(f"resonator mesh benchmark, {comm.size} MPI rank(s)\n")
        print("| mesh | lap h | body h | hole h | nodes | tets | P2 DOFs | pairs | gmsh build [s] "
              "| build + dolfinx load [s] | volume err | Σ area err | min scaled J |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {r[5]} | {r[6]} | {r[7]} | "
                  f"{r[8]:.1f} | {r[9]:.1f} | {r[10]:.1e} | {r[11]:.1e} | {r[12]:.2f} |")


if __name__ == "__main__":
    main()
