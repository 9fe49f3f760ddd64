"""The multiscale study: FE preload → rough BEM → friction elements → HBM, configurations of the paper.

Configurations (paper Table 1, DESIGN §4.6):

============  ==========================  ==============================  ==========================
name          N0, gap                     k_n                             k_t
============  ==========================  ==============================  ==========================
baseline      smooth FE preload           k_ref                           k_ref
smooth-ms     smooth FE preload           BEM patches, Rq = smooth_rq     = k_n
v1            BEM, rough (Rq = v_rq)      k_ref                           k_ref
v2            BEM, rough                  BEM patches at N0               Mindlin ratio · k_n
v3            BEM, rough                  BEM patches at cycle-mean N     BEM loop at resonance
============  ==========================  ==============================  ==========================

v3 is a fixed point: it starts from v2, computes the FRF at the chosen level, takes every element's
cycle-mean normal load and tangential force amplitude at resonance, recomputes k_n and k_t on the
element's patch (k_t = slope of the hysteresis loop at load reversal, paper Fig. 4) and repeats
until the resonance frequency and the peak change by less than ``contact.kt_tol`` (the paper did
one pass). Elements without real contact in their cell get k_n = 0, as in the paper: they carry no
force and are left out of the dynamics (model only what the analysis needs).

All functions here are collective when given a communicator: BEM patches are split over ranks
(each patch is solved independently, so the split does not change its result) and FRF curves are
distributed one per rank.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from contact_bem import (ElasticHalfSpace, extract_patches, gaussian_surface, macro_gap,
                         mindlin_ratio, patch_normal_stiffness, patch_stiffness, solve_normal)

from .interface import InterfaceGrid, element_loads, interface_grid, patch_side, smooth_fields
from .joint import JointModel

CONFIGURATIONS = ("baseline", "smooth-ms", "v1", "v2", "v3")


# ---------------------------------------------------------------------------------------------
# MPI helpers
# ---------------------------------------------------------------------------------------------
def _split(n: int, comm) -> slice:
    """Contiguous block of range(n) owned by this rank."""
    if comm is None or comm.size == 1:
        return slice(0, n)
    r, s = comm.rank, comm.size
    lo = (n * r) // s
    hi = (n * (r + 1)) // s
    return slice(lo, hi)


def _gather_concat(local: np.ndarray, comm) -> np.ndarray:
    """Concatenate each rank's block in rank order (every rank gets the whole array)."""
    if comm is None or comm.size == 1:
        return local
    return np.concatenate(comm.allgather(local), axis=0)


# ---------------------------------------------------------------------------------------------
# Contact: global rough solve and element patches
# ---------------------------------------------------------------------------------------------
@dataclass
class InterfaceSetup:
    """Everything the contact analyses share: pairs, grid, smooth FE fields on the grid."""
    pair_xy: np.ndarray          # (ne, 2) mm
    area: np.ndarray             # (ne,) mm²
    n0_fe: np.ndarray            # (ne,) N, smooth FE preload
    gap_fe: np.ndarray           # (ne,) mm
    bolt_force: float            # N
    ig: InterfaceGrid
    p_s: np.ndarray              # (n, n) smooth pressure on the grid, MPa (integrates to bolt_force)
    g_s: np.ndarray              # (n, n) smooth gap on the grid, mm
    pressure_scale: float        # interpolation correction applied to p_s
    side: float                  # element patch side, mm
    patch: int                   # patch cells per side
    young: float
    poisson: float


def interface_setup(rm, geometry, material, roughness) -> InterfaceSetup:
    """Global BEM grid over the overlap with the FE preload interpolated onto it.

    Args:
        rm: the ReducedModel (pair coordinates, areas, preload forces and gaps).
        geometry: ResonatorParams (overlap, plate width, hole diameter).
        material: Material (young, poisson).
        roughness: Roughness section (grid, patch).
    """
    xy = np.asarray(rm.pair_xyz)[:, :2]
    area = np.asarray(rm.pair_area, float)
    n0 = np.asarray(rm.preload_normal_force, float)
    gap = np.asarray(rm.preload_gap, float)
    bolt = float(n0.sum())
    ig = interface_grid(xy, geometry.overlap, geometry.plate_width, geometry.hole_diameter,
                        roughness.grid)
    pressure = np.divide(n0, area, out=np.zeros_like(n0), where=area > 0)
    p_s, g_s, scale = smooth_fields(ig, xy, pressure, gap, bolt)
    return InterfaceSetup(pair_xy=xy, area=area, n0_fe=n0, gap_fe=gap, bolt_force=bolt, ig=ig,
                          p_s=p_s, g_s=g_s, pressure_scale=scale, side=patch_side(area),
                          patch=roughness.patch, young=material.young, poisson=material.poisson)


@dataclass
class SurfaceContact:
    """Global and per-element contact of one rough surface realization under the bolt load."""
    rq_um: float
    z: np.ndarray                 # (n, n) heights, mm
    pressure: np.ndarray          # (n, n) MPa
    gap: np.ndarray               # (n, n) mm, deformed separation
    contact_fraction: float       # real contact area / usable nominal area
    iterations: int
    n0: np.ndarray                # (ne,) N
    gap_el: np.ndarray            # (ne,) mm
    pressure_el: np.ndarray       # (ne,) MPa, mean over the element cell
    contact_fraction_el: np.ndarray
    kn: np.ndarray                # (ne,) N/mm³ at the element load
    kt_mindlin: np.ndarray        # (ne,) N/mm³
    load_scale: float             # Σ N0 correction (element cells vs tributary areas)
    seconds: dict = field(default_factory=dict)


def surface(setup: InterfaceSetup, rq_um: float, corr_length: float, seed: int) -> np.ndarray:
    """The seeded Gaussian realization on the global grid (same seed → same shape, scaled by Rq)."""
    return gaussian_surface(setup.ig.grid, rq=rq_um * 1e-3, corr_length=corr_length, seed=seed)


def patch_loads(setup: InterfaceSetup, element_force: np.ndarray) -> np.ndarray:
    """Load on an element's patch: the element's mean pressure × the patch area, N."""
    return element_force / setup.area * setup.side ** 2


def rough_contact(setup: InterfaceSetup, rq_um: float, corr_length: float, seed: int,
                  hardness: float = 0.0, comm=None, tol: float = 1e-8,
                  stiffness: bool = True) -> SurfaceContact:
    """Global rough contact with the equivalent macro gap, then k_n per element from its patch.

    With ``rq_um = 0`` the global solve returns the smooth FE pressure (the coupling test).
    ``stiffness=False`` skips the element patches (k_n, k_t are then zero).
    """
    t0 = time.perf_counter()
    ig = setup.ig
    z = surface(setup, rq_um, corr_length, seed) if rq_um > 0 else np.zeros(ig.grid.shape)
    hs = ElasticHalfSpace(ig.grid, young=setup.young, poisson=setup.poisson, periodic=False)
    h0 = macro_gap(hs, setup.p_s, setup.g_s, z)
    ns = solve_normal(hs, gap=h0, load=setup.bolt_force, mask=ig.mask, tol=tol,
                      hardness=hardness if hardness > 0 else None)
    t1 = time.perf_counter()
    el = element_loads(ig, ns.pressure, ns.gap, setup.area, setup.bolt_force)
    kn = (element_normal_stiffness(setup, z, el["n0"], comm=comm) if stiffness
          else np.zeros(len(setup.area)))
    t2 = time.perf_counter()
    usable = ig.mask.sum()
    return SurfaceContact(
        rq_um=rq_um, z=z, pressure=ns.pressure, gap=ns.gap,
        contact_fraction=float(((ns.pressure > 0) & ig.mask).sum() / usable),
        iterations=int(ns.iterations), n0=el["n0"], gap_el=el["gap"], pressure_el=el["pressure"],
        contact_fraction_el=el["contact_fraction"], kn=kn,
        kt_mindlin=kn * mindlin_ratio(setup.poisson), load_scale=el["scale"],
        seconds={"global": t1 - t0, "patches_normal": t2 - t1})


def element_patches(setup: InterfaceSetup, z: np.ndarray) -> np.ndarray:
    """(ne, patch, patch) heights of every element's patch, cut from the global realization."""
    return extract_patches(z, setup.ig.grid, setup.pair_xy, (setup.patch, setup.patch),
                           (setup.side, setup.side))


def element_normal_stiffness(setup: InterfaceSetup, z: np.ndarray, n0: np.ndarray,
                             comm=None) -> np.ndarray:
    """k_n (N/mm³) of every element at its load; patches split over the ranks."""
    P = element_patches(setup, z)
    sl = _split(len(n0), comm)
    cell = (setup.side / setup.patch, setup.side / setup.patch)
    k = patch_normal_stiffness(P[sl], cell, setup.young, setup.poisson, patch_loads(setup, n0)[sl])
    return _gather_concat(k, comm)


def element_loop_stiffness(setup: InterfaceSetup, z: np.ndarray, n_mean: np.ndarray,
                           q_amp: np.ndarray, mu: float, comm=None) -> tuple[np.ndarray, np.ndarray]:
    """k_n and k_t (N/mm³) of every element at its cycle-mean normal load and tangential amplitude.

    Args:
        n_mean: (ne,) cycle-mean normal force, N.
        q_amp: (ne, 2) tangential force amplitude per direction, N.
    Returns:
        (k_n, k_t): k_t is the slope of the patch's hysteresis loop at load reversal.
    """
    P = element_patches(setup, z)
    sl = _split(len(n_mean), comm)
    cell = (setup.side / setup.patch, setup.side / setup.patch)
    scale = setup.side ** 2 / setup.area
    ps = patch_stiffness(P[sl], cell, setup.young, setup.poisson, mu, (n_mean * scale)[sl],
                         (q_amp * scale[:, None])[sl], secant=False)
    return _gather_concat(ps.k_n, comm), _gather_concat(ps.k_t, comm)


# ---------------------------------------------------------------------------------------------
# Configurations
# ---------------------------------------------------------------------------------------------
def joint_baseline(setup: InterfaceSetup, k_ref: float) -> JointModel:
    ne = len(setup.area)
    return JointModel("baseline", n0=setup.n0_fe, gap=setup.gap_fe, kn=np.full(ne, k_ref),
                      kt=np.full(ne, k_ref), area=setup.area)


def joint_smooth_ms(setup: InterfaceSetup, smooth: SurfaceContact, comm=None) -> JointModel:
    """FE loads; k_n from the nearly smooth surface's patches at the FE element loads; k_t = k_n."""
    kn = element_normal_stiffness(setup, smooth.z, setup.n0_fe, comm=comm)
    return JointModel("smooth-ms", n0=setup.n0_fe, gap=setup.gap_fe, kn=kn, kt=kn.copy(),
                      area=setup.area, rq_um=smooth.rq_um)


def joint_v1(setup: InterfaceSetup, sc: SurfaceContact, k_ref: float) -> JointModel:
    ne = len(setup.area)
    return JointModel("v1", n0=sc.n0, gap=sc.gap_el, kn=np.full(ne, k_ref), kt=np.full(ne, k_ref),
                      area=setup.area, rq_um=sc.rq_um)


def joint_v2(setup: InterfaceSetup, sc: SurfaceContact, name: str = "v2") -> JointModel:
    return JointModel(name, n0=sc.n0, gap=sc.gap_el, kn=sc.kn, kt=sc.kt_mindlin, area=setup.area,
                      rq_um=sc.rq_um)


def active(joint: JointModel) -> np.ndarray:
    """Elements the dynamics needs: those with a contact stiffness (k_n, k_t > 0)."""
    return (joint.kn > 0) & (joint.kt > 0)


def save_surfaces(path, surfaces: dict[float, SurfaceContact], extra: dict | None = None) -> None:
    """Write surface contacts (keyed by Rq in µm) and extra arrays to one ``.npz`` (rank 0)."""
    import json
    from dataclasses import asdict
    out = {}
    for rq, sc in surfaces.items():
        for k, v in asdict(sc).items():
            out[f"{rq:g}/{k}"] = np.asarray(json.dumps(v) if k == "seconds" else v)
    for k, v in (extra or {}).items():
        out[f"extra/{k}"] = np.asarray(v)
    tmp = str(path) + ".tmp.npz"
    np.savez(tmp, **out)
    import os
    os.replace(tmp, path)


def load_surfaces(path) -> tuple[dict[float, SurfaceContact], dict]:
    """Read what :func:`save_surfaces` wrote: ({rq_um: SurfaceContact}, extra arrays)."""
    import json
    from dataclasses import fields
    names = {f.name for f in fields(SurfaceContact)}
    raw: dict[str, dict] = {}
    extra = {}
    with np.load(path) as d:
        for key in d.files:
            head, k = key.split("/", 1)
            if head == "extra":
                extra[k] = d[key]
                continue
            raw.setdefault(head, {})[k] = d[key]
    surfaces = {}
    for head, kw in raw.items():
        kw = {k: v for k, v in kw.items() if k in names}
        kw["seconds"] = json.loads(str(kw["seconds"]))
        for k in ("rq_um", "contact_fraction", "load_scale"):
            kw[k] = float(kw[k])
        kw["iterations"] = int(kw["iterations"])
        surfaces[float(head)] = SurfaceContact(**kw)
    return surfaces, extra
