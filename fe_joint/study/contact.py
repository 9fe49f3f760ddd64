"""Rough contact of the interface: FE preload → BEM grid → global rough solve → element loads and
patch stiffnesses (k_n at a load; k_n and k_t at a cycle-mean load and tangential amplitude).

All functions here are collective when given a communicator: BEM patches are split over ranks
(each patch is solved independently, so the split does not change its result).
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from contact_bem import (ElasticHalfSpace, extract_patches, gaussian_surface, macro_gap,
                         mindlin_ratio, patch_normal_stiffness, patch_stiffness, solve_normal)

from .interface import InterfaceGrid, element_loads, interface_grid, patch_side, smooth_fields


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
    kn = (element_normal_stiffness(setup, z, el["n0"], comm=comm, hardness=hardness) if stiffness
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
                             comm=None, hardness: float = 0.0) -> np.ndarray:
    """k_n (N/mm³) of every element at its load; patches split over the ranks.

    ``hardness`` > 0 caps the patch pressures too (MPa); k_n is then the unloading stiffness of
    the whole contact set (``contact_bem.patch_normal_stiffness``)."""
    P = element_patches(setup, z)
    sl = _split(len(n0), comm)
    cell = (setup.side / setup.patch, setup.side / setup.patch)
    k = patch_normal_stiffness(P[sl], cell, setup.young, setup.poisson, patch_loads(setup, n0)[sl],
                               hardness=hardness if hardness > 0 else None)
    return _gather_concat(k, comm)


@dataclass(frozen=True)
class ContactArea:
    """The real contact area of a global solve over three nominal areas (all in mm²).

    Attributes:
        real: area of the cells with p > 0 (outside the bolt hole).
        usable: the overlap without the bolt-hole cells: where contact is possible (our fraction).
        overlap: the whole overlap, hole included: the square the paper's 256² grid covers, its
            "total potential contact area" (the paper's fraction).
        fe_loaded: where the smooth FE preload pressure is positive (the region the bolt clamps).
    """
    real: float
    usable: float
    overlap: float
    fe_loaded: float

    def fractions(self) -> dict[str, float]:
        """real / usable (ours), real / overlap (the paper's) and real / fe_loaded."""
        return {"usable": self.real / self.usable, "overlap": self.real / self.overlap,
                "fe_loaded": self.real / self.fe_loaded if self.fe_loaded > 0 else float("nan")}


def contact_area(mask: np.ndarray, cell_area: float, pressure: np.ndarray,
                 p_smooth: np.ndarray) -> ContactArea:
    """The contact area of a pressure field on the global grid over the three nominal areas.

    Args:
        mask: (n, n) bool, True outside the bolt hole.
        cell_area: mm².
        pressure: (n, n) MPa, the rough solve's pressure.
        p_smooth: (n, n) MPa, the smooth FE pressure on the grid.
    Returns:
        the ContactArea (mm²).
    """
    real = float(((pressure > 0) & mask).sum() * cell_area)
    return ContactArea(real=real, usable=float(mask.sum() * cell_area),
                       overlap=float(mask.size * cell_area),
                       fe_loaded=float(((p_smooth > 0) & mask).sum() * cell_area))


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


def save_surfaces(path, surfaces: dict[float, SurfaceContact], extra: dict | None = None) -> None:
    """Write surface contacts and extra arrays to one ``.npz`` (rank 0).

    Surface i is stored under ``surface<i>/<field>``; its Rq is the ``rq_um`` field inside, so
    :func:`load_surfaces` keys the surfaces by the stored value, never by a formatted name.
    """
    out = {}
    for i, sc in enumerate(surfaces.values()):
        for k, v in asdict(sc).items():
            out[f"surface{i}/{k}"] = np.asarray(json.dumps(v) if k == "seconds" else v)
    for k, v in (extra or {}).items():
        out[f"extra/{k}"] = np.asarray(v)
    tmp = str(path) + ".tmp.npz"
    np.savez(tmp, **out)
    os.replace(tmp, path)


def load_surfaces(path) -> tuple[dict[float, SurfaceContact], dict]:
    """Read what :func:`save_surfaces` wrote: ({rq_um: SurfaceContact}, extra arrays)."""
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
    for head in sorted(raw, key=lambda h: int(h.removeprefix("surface"))):
        kw = {k: v for k, v in raw[head].items() if k in names}
        kw["seconds"] = json.loads(str(kw["seconds"]))
        for k in ("rq_um", "contact_fraction", "load_scale"):
            kw[k] = float(kw[k])
        kw["iterations"] = int(kw["iterations"])
        surfaces[kw["rq_um"]] = SurfaceContact(**kw)
    return surfaces, extra
