#!/usr/bin/env python
"""Benchmark of the FE chain (mesh -> preload -> Craig–Bampton ReducedModel) vs mesh size and ranks.

Prints markdown tables (rank 0):
1. per mesh size and rank count: DOFs, pairs, boundary DOFs, modes kept, time of each stage
   (assembly, K_II factorization, fixed-interface modes, constraint modes + projection, preload,
   full-model modes), total, peak memory (sum over ranks), breathing-mode frequency (untied and
   with the closed pairs stuck at k = 6e4 N/mm³) and the preload pressure at a fixed point;
2. with ``--degree-study``: P1 vs P2 breathing frequency vs DOFs (the element-degree choice);
3. with ``--stuck`` (instead of table 1): the stuck resonance of the reduced model (baseline
   springs k_n = k_t = k_ref on the loaded pairs, as the study computes it) against the full FE
   model with the same springs (``fe_joint.fe.stuck``), with the time of each.

Usage:
    scripts/bench_fe.py                       # coarse + default, 1 and 2 ranks
    scripts/bench_fe.py --sizes coarse default fine --ranks 1 2 --degree-study
    scripts/bench_fe.py --stuck --sizes quick default --ranks 1
The parent process launches ``mpirun -n R`` workers and gathers their JSON lines.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

SIZES = {
    "quick": dict(lap_mesh_size=4.0, body_mesh_size=14.0),  # the quick preset's mesh
    "coarse": dict(lap_mesh_size=4.0, body_mesh_size=14.0, leaf_mesh_size=6.0),
    "medium": dict(lap_mesh_size=3.4, body_mesh_size=9.0, leaf_mesh_size=5.0),
    "default": dict(),
    "fine": dict(lap_mesh_size=2.0, body_mesh_size=5.0, hole_mesh_size=1.2, leaf_mesh_size=3.0),
    "refined": dict(body_mesh_size=3.3, leaf_mesh_size=2.4),  # ~200k DOFs, same lap mesh as default
    "xfine": dict(lap_mesh_size=1.6, body_mesh_size=3.6, hole_mesh_size=1.0, leaf_mesh_size=2.4),
}
PROBE_XY = (0.0, 6.0)  # fixed point for the pressure convergence column, mm


def worker(size: str, cutoff: float, chunk: int) -> None:
    """Run the chain on one mesh size with the current communicator; rank 0 prints one JSON line."""
    import resource

    import numpy as np
    from mpi4py import MPI

    from fe_joint.case import Material
    from fe_joint.fe.mesh import load_resonator
    from fe_joint.fe.reduction import build_reduced_model_from_fe
    from geometry.resonator import ResonatorParams

    comm = MPI.COMM_WORLD
    t = time.perf_counter()
    fe = load_resonator(ResonatorParams(**SIZES[size]), comm)
    t_mesh = time.perf_counter() - t
    cpu0 = time.process_time()
    rm = build_reduced_model_from_fe(fe, Material(), 30000.0, 1e-3, cutoff, chunk=chunk or None)
    cpu = comm.allreduce(time.process_time() - cpu0, op=MPI.SUM)  # what a quiet machine would need
    peak = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, op=MPI.SUM)
    if comm.rank == 0:
        from matplotlib.tri import LinearTriInterpolator, Triangulation

        from fe_joint.model.interface_contact import lap_triangles
        tri6 = lap_triangles(fe.data)
        sub = np.vstack([tri6[:, [0, 3, 5]], tri6[:, [3, 1, 4]], tri6[:, [5, 4, 2]], tri6[:, [3, 4, 5]]])
        xyz = rm.pair_xyz
        p_probe = float(LinearTriInterpolator(Triangulation(xyz[:, 0], xyz[:, 1], sub),
                                              rm.preload_pressure)(*PROBE_XY))
        N, y = rm.preload_normal_force, xyz[:, 1]
        half_asym = abs(N[y > 1e-9].sum() / N[y < -1e-9].sum() - 1)
        m = rm.metadata
        out = dict(cpu_s=cpu, half_asym=float(half_asym), shank_force=m["shank_force"],
                   size=size, ranks=comm.size, dofs=m["n_dofs_full"], pairs=m["n_pairs"],
                   boundary=m["n_boundary"], modes=m["n_modes"], mesh_s=t_mesh, peak_mb=peak,
                   f_breathing=m["breathing_frequency_hz"], f_stuck=float(rm.tied_frequencies(6e4, n=8)[6]),
                   p_probe=p_probe, n_closed=m["n_closed"], n_toggled=m["n_toggled"],
                   max_cb_err=float(np.abs(rm.reduced_frequencies[6:16] / rm.full_frequencies[6:16] - 1).max()),
                   **m["timings"])
        print("JSON " + json.dumps(out), flush=True)


def degree_worker(size: str, degree: int) -> None:
    """Free–free breathing frequency of the structure (no contact) for P1/P2; rank 0 prints JSON."""
    from mpi4py import MPI

    from fe_joint.case import Material
    from fe_joint.fe.elasticity import assemble_mass, assemble_stiffness, vector_space
    from fe_joint.fe.assembly import global_node_dofs
    from fe_joint.fe.mesh import load_resonator
    from fe_joint.fe.modal import free_modes
    from geometry.resonator import ResonatorParams

    comm = MPI.COMM_WORLD
    fe = load_resonator(ResonatorParams(order=degree, **SIZES[size]), comm)
    V = vector_space(fe.mesh, degree)
    t = time.perf_counter()
    K, M = assemble_stiffness(V, Material()), assemble_mass(V, Material())
    probe = global_node_dofs(V, [fe.data.excitation_node])[0]
    res = free_modes(K, M, 4, probe_dofs=probe)
    if comm.rank == 0:
        print("JSON " + json.dumps(dict(size=size, degree=degree, dofs=K.getSize()[0],
                                        f_breathing=float(res.frequencies[res.breathing_index]),
                                        time_s=time.perf_counter() - t)), flush=True)


def stuck_worker(size: str, cutoff: float, chunk: int) -> None:
    """Reduced vs full stuck resonance (baseline springs) on one mesh size; rank 0 prints JSON."""
    import dataclasses

    from mpi4py import MPI

    from fe_joint.case import load_case
    from fe_joint.fe.assembly import assemble_joint
    from fe_joint.fe.mesh import load_resonator
    from fe_joint.fe.reduction import build_reduced_model_from_fe
    from fe_joint.fe.stuck import compare_stuck_resonance
    from fe_joint.study.configurations import joint_baseline
    from fe_joint.study.contact import interface_setup

    comm = MPI.COMM_WORLD
    case = load_case()
    geo = dataclasses.replace(case.geometry, **SIZES[size])
    fe = load_resonator(geo, comm)
    t = time.perf_counter()
    rm = build_reduced_model_from_fe(fe, case.material, case.preload.bolt_force,
                                     case.reduction.damping_ratio, cutoff, chunk=chunk or None,
                                     n_full_elastic=0)
    reduction_s = time.perf_counter() - t
    t = time.perf_counter()
    problem = assemble_joint(fe, case.material)
    assembly_s = time.perf_counter() - t
    joint = joint_baseline(interface_setup(rm, geo, case.material, case.roughness), case.contact.k_ref)
    cmp = compare_stuck_resonance(problem, rm, joint)
    if comm.rank == 0:
        print("JSON " + json.dumps(dict(size=size, ranks=comm.size, dofs=problem.n_dofs, pairs=rm.n_pairs,
                                        loaded=int(joint.closed.sum()), reduced_dofs=rm.n_dofs,
                                        reduction_s=reduction_s, assembly_s=assembly_s, **cmp)), flush=True)


def launch(ranks: int, args: list[str]) -> dict:
    """Run this script as a worker under mpirun; return its JSON result."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = ["mpirun", "-n", str(ranks), sys.executable, os.path.abspath(__file__)] + args
    t = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, env=env)
    for line in res.stdout.splitlines():
        if line.startswith("JSON "):
            out = json.loads(line[5:])
            out["wall_s"] = time.perf_counter() - t
            return out
    raise RuntimeError(f"worker {' '.join(args)} failed:\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}")


def stuck_table(a: argparse.Namespace) -> None:
    """Run the stuck-resonance workers and print their markdown table."""
    rows = []
    for size in a.sizes:
        for r in a.ranks:
            rows.append(launch(r, ["--worker", size, "--stuck-worker", "--cutoff", str(a.cutoff),
                                   "--chunk", str(a.chunk)]))
            print(f"<!-- done {size} x{r}: {rows[-1]['wall_s']:.1f} s -->", flush=True)
    print("Stuck resonance (baseline: k_n = k_t = k_ref on the loaded pairs): Craig–Bampton reduced "
          "model vs the full FE model with the same pair springs (SLEPc shift-invert at the reduced "
          "frequency, mode matched by MAC at the boundary DOFs)")
    print()
    print("| mesh | ranks | DOFs | pairs (loaded) | reduced DOFs | f reduced Hz | f full Hz | "
          "reduced / full − 1 | MAC | reduction s | reduced eigen s | full assembly s | "
          "full springs + eigen s |")
    print("|" + "---|" * 13)
    for o in rows:
        print(f"| {o['size']} | {o['ranks']} | {o['dofs']} | {o['pairs']} ({o['loaded']}) | "
              f"{o['reduced_dofs']} | {o['f_reduced']:.6f} | {o['f_full']:.6f} | {o['rel_diff']:.1e} | "
              f"{o['mac']:.6f} | {o['reduction_s']:.1f} | {o['reduced_s']:.2f} | {o['assembly_s']:.1f} | "
              f"{o['full_s']:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", nargs="+", default=["coarse", "default"], choices=list(SIZES))
    ap.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--cutoff", type=float, default=60000.0, help="fixed-interface mode cut-off, Hz")
    ap.add_argument("--chunk", type=int, default=0, help="constraint modes per block (0: auto, ~1 GB)")
    ap.add_argument("--degree-study", action="store_true", help="also tabulate P1 vs P2 convergence")
    ap.add_argument("--degree-sizes", nargs="+", default=["coarse", "medium", "default", "fine"],
                    choices=list(SIZES))
    ap.add_argument("--stuck", action="store_true",
                    help="only the stuck-resonance table: reduced vs full FE model with the baseline springs")
    ap.add_argument("--stuck-worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--worker", choices=list(SIZES), help=argparse.SUPPRESS)
    ap.add_argument("--degree-worker", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker and a.degree_worker:
        return degree_worker(a.worker, a.degree_worker)
    if a.worker and a.stuck_worker:
        return stuck_worker(a.worker, a.cutoff, a.chunk)
    if a.worker:
        return worker(a.worker, a.cutoff, a.chunk)
    if a.stuck:
        return stuck_table(a)

    rows = []
    for size in a.sizes:
        for r in a.ranks:
            rows.append(launch(r, ["--worker", size, "--cutoff", str(a.cutoff), "--chunk", str(a.chunk)]))
            print(f"<!-- done {size} x{r}: {rows[-1]['total_s']:.1f} s -->", flush=True)
    print("| mesh | ranks | DOFs | pairs | boundary DOFs | modes | assembly s | factor s | FI modes s | "
          "constraint modes s | preload s | full modes s | projection s | total s | CPU s (all ranks) | "
          "peak MB (all ranks) | "
          "f breathing untied Hz | f breathing stuck Hz | p(0, 6) MPa | closed pairs | max CB error | "
          "shank force N | y-half load asymmetry |")
    print("|" + "---|" * 23)
    for o in rows:
        print(f"| {o['size']} | {o['ranks']} | {o['dofs']} | {o['pairs']} | {o['boundary']} | {o['modes']} | "
              f"{o['assembly_s']:.1f} | {o['factorization_s']:.1f} | {o['fixed_interface_modes_s']:.1f} | "
              f"{o['constraint_modes_s']:.1f} | {o['preload_s']:.1f} | {o.get('full_modes_s', 0):.1f} | "
              f"{o['projection_s']:.1f} | {o['total_s']:.1f} | {o['cpu_s']:.1f} | {o['peak_mb']:.0f} | {o['f_breathing']:.2f} | "
              f"{o['f_stuck']:.2f} | {o['p_probe']:.1f} | {o['n_closed']}/{o['pairs']} | {o['max_cb_err']:.1e} | "
              f"{o['shank_force']:.0f} | {o['half_asym']:.1e} |")
    if a.degree_study:
        drows = [launch(1, ["--worker", s, "--degree-worker", str(d)]) for s in a.degree_sizes for d in (1, 2)]
        ref = max((o for o in drows if o["degree"] == 2), key=lambda o: o["dofs"])
        print()
        print(f"Breathing mode of the free structure (no contact) vs element degree; reference = P2 "
              f"{ref['size']} ({ref['dofs']} DOFs, {ref['f_breathing']:.2f} Hz)")
        print()
        print("| mesh | degree | DOFs | f breathing Hz | error vs reference | time s |")
        print("|---|---|---|---|---|---|")
        for o in drows:
            print(f"| {o['size']} | P{o['degree']} | {o['dofs']} | {o['f_breathing']:.2f} | "
                  f"{o['f_breathing'] / ref['f_breathing'] - 1:+.2e} | {o['time_s']:.1f} |")


if __name__ == "__main__":
    main()
