"""Rules between keys of a case, and the physical bounds of the geometry.

Each rule raises :class:`CaseError` with one line naming *one* key and what it must satisfy.
When a rule ties two keys, the line names the one the case file wrote (``sources``): a user who
wrote ``hole_diameter = 14`` hears about ``hole_diameter``, not about the ``head_diameter`` it
now exceeds. The geometry's own ``ResonatorParams.validate`` runs afterwards as a backstop.

The mesh guard estimates the gmsh cell count from the mesh-size fields of
``geometry.resonator`` (sizes graded linearly from a surface over a distance), so that a case
that would mesh for hours (``hole_mesh_size = 0.01``) is rejected before gmsh runs.
"""
from __future__ import annotations

import math
from typing import Any

from geometry.resonator import ResonatorParams

from ..errors import CaseError
from .schema import Case, check_range

#: where each key's value came from ("default", "preset quick", "file"); "section.key" → label
Sources = dict[str, str]

#: physical bounds of the geometry keys, mm (the dataclass lives in ``geometry``, which knows
#: nothing about cases): lengths of a bench-size joint, mesh sizes down to what the cell guard
#: then judges as a whole
_LENGTH = {"lo": 0.1, "hi": 1e4, "unit": "mm"}
_SIZE = {"lo": 0.01, "hi": 1e4, "unit": "mm"}
GEOMETRY_RANGES: dict[str, dict] = {
    **{k: _LENGTH for k in ("plate_width", "plate_thickness", "overlap", "plate_a_extension",
                            "plate_b_extension", "leaf_thickness", "leaf_length", "mass_a_size",
                            "mass_b_size", "hole_diameter", "shank_diameter", "head_diameter",
                            "head_height", "nut_diameter", "nut_height")},
    **{k: _SIZE for k in ("lap_mesh_size", "body_mesh_size", "hole_mesh_size", "refine_distance",
                          "hole_grading_distance", "leaf_mesh_size")},
    "order": {"choices": (1, 2)},
    "seed": {"lo": 0, "hi": 2**31 - 1},
}

#: largest estimated cell count accepted (the default mesh has 13 000 tets, the finest of the
#: README's table 22 000; 1e6 tets are ≈ 5 million P2 DOFs, hours on a workstation)
MAX_CELLS = 1.0e6
#: tetrahedra per h³ of volume meshed at size h: fitted to the four meshes of the README's mesh
#: table (quick, default, fine, coarse), which it reproduces within −30 % … +40 %
_TETS_PER_H3 = 8.0


def _is_file(sources: Sources, key: str) -> bool:
    return sources.get(key, "default") == "file"


def _blame(sources: Sources, first: str, *others: str) -> str:
    """The key to name for a rule over ``first`` and ``others``: the first one the case file
    wrote, else ``first``."""
    for k in (first, *others):
        if _is_file(sources, k):
            return k
    return first


def _src(sources: Sources, key: str) -> str:
    """`` [default]`` / `` [preset quick]`` after a value the case file did not write."""
    s = sources.get(key, "default")
    return "" if s == "file" else f" [{s}]"


def check_geometry_ranges(table: dict[str, Any]) -> None:
    """Physical bounds of each geometry key written (types are already checked)."""
    for k, v in table.items():
        md = GEOMETRY_RANGES.get(k)
        if md is not None:
            check_range(f"geometry.{k}", v, md)


def check_geometry(p: ResonatorParams, sources: Sources) -> None:
    """The geometry's relations, each naming the key the file wrote (see the module doc)."""
    g = {f: getattr(p, f) for f in p.__dataclass_fields__}

    def need(ok: bool, keys: tuple[str, ...], rule: str) -> None:
        if not ok:
            k = _blame(sources, *(f"geometry.{x}" for x in keys))
            short = k.split(".", 1)[1]
            others = ", ".join(f"{x} = {g[x]:g}{_src(sources, 'geometry.' + x)}"
                               for x in keys if x != short)
            raise CaseError(f"{k} = {g[short]:g}: {rule} ({others})")

    lap_min = min(p.overlap, p.plate_width)
    need(p.shank_diameter < p.hole_diameter, ("shank_diameter", "hole_diameter"),
         "the shank must be narrower than the hole: shank_diameter < hole_diameter")
    need(p.hole_diameter < lap_min, ("hole_diameter", "overlap", "plate_width"),
         "the hole must fit in the lap: hole_diameter < overlap and < plate_width")
    for name in ("head_diameter", "nut_diameter"):
        need(p.hole_diameter < getattr(p, name) < lap_min, (name, "hole_diameter", "overlap", "plate_width"),
             f"must satisfy hole_diameter < {name} < overlap and plate_width")
    need(p.leaf_thickness <= p.plate_a_extension, ("leaf_thickness", "plate_a_extension"),
         "the leaf must fit under plate A: leaf_thickness ≤ plate_a_extension")
    need(p.mass_a_size >= max(p.leaf_thickness, p.plate_width), ("mass_a_size", "leaf_thickness", "plate_width"),
         "must be ≥ leaf_thickness and ≥ plate_width")
    need(p.mass_b_size >= max(p.plate_width, 2 * p.plate_thickness), ("mass_b_size", "plate_width", "plate_thickness"),
         "must be ≥ plate_width and ≥ 2 plate_thickness")
    need(p.leaf_length > p.nut_height, ("leaf_length", "nut_height"),
         "mass A must clear the nut: leaf_length > nut_height")
    # the masses' boxes (geometry.resonator._Layout): they overlap when their x ranges meet and
    # mass A's top (z = −t − leaf_length) is above mass B's bottom (z = −mass_b_size/2)
    x_a0 = -p.overlap / 2 - p.plate_a_extension
    a_x1 = x_a0 + p.leaf_thickness / 2 + p.mass_a_size / 2
    b_x0 = p.overlap / 2 + p.plate_b_extension
    if a_x1 >= b_x0:
        need_l = p.mass_b_size / 2 - p.plate_thickness
        need(p.leaf_length > need_l, ("leaf_length", "mass_b_size", "plate_thickness", "mass_a_size"),
             f"the masses overlap: needs leaf_length > mass_b_size/2 − plate_thickness "
             f"= {need_l:g}, or smaller masses")
    need(p.hole_mesh_size <= p.lap_mesh_size, ("hole_mesh_size", "lap_mesh_size"),
         "must satisfy hole_mesh_size ≤ lap_mesh_size")
    need(p.lap_mesh_size <= p.body_mesh_size, ("lap_mesh_size", "body_mesh_size"),
         "must satisfy lap_mesh_size ≤ body_mesh_size")
    need(p.lap_mesh_size <= lap_min / 2, ("lap_mesh_size", "overlap", "plate_width"),
         f"must be ≤ half the lap ({lap_min / 2:g})")


def _graded(area: float, h0: float, h1: float, dist: float, thick: float) -> float:
    """∫ dV / h³ over a layer of ``thick`` on a surface of ``area``, the size growing linearly
    from ``h0`` on it to ``h1`` at distance ``dist`` (gmsh's Threshold field), then ``h1``."""
    s = min(thick, dist)
    k = (h1 - h0) / dist
    v = (1 / h0**2 - 1 / (h0 + k * s) ** 2) / (2 * k) if k > 0 else s / h0**3
    return area * (v + max(thick - dist, 0.0) / h1**3)


def estimate_cells(p: ResonatorParams) -> dict[str, float]:
    """Estimated tetrahedra by the mesh-size key that drives them (sum = the whole mesh).

    The size fields of ``geometry.resonator``: hole and shank surfaces at ``hole_mesh_size``
    grading to ``lap_mesh_size`` over ``hole_grading_distance``; the lap faces at
    ``lap_mesh_size`` grading to ``body_mesh_size`` over ``refine_distance`` (through the plates'
    thickness in the overlap, along the extensions beyond it); the leaf at ``leaf_mesh_size``; the
    masses at ``body_mesh_size``.

    Returns:
        {"hole_mesh_size": n, "lap_mesh_size": n, "leaf_mesh_size": n, "body_mesh_size": n}
    """
    t, w = p.plate_thickness, p.plate_width
    lap, body, hole = p.lap_mesh_size, p.body_mesh_size, p.hole_mesh_size
    a_hole = (2 * math.pi * p.hole_diameter / 2 * 2 * t
              + 2 * math.pi * p.shank_diameter / 2 * (2 * t + p.head_height + p.nut_height))
    n_hole = _graded(a_hole, hole, lap, p.hole_grading_distance, p.hole_grading_distance)
    n_lap = _graded(2 * p.overlap * w, lap, body, p.refine_distance, t)
    for ext in (p.plate_a_extension, p.plate_b_extension):
        n_lap += _graded(w * t, lap, body, p.refine_distance, ext)
    h_bolt = lap + (body - lap) * min(1.0, (t + p.head_height / 2) / p.refine_distance)
    n_lap += math.pi / 4 * (p.head_diameter**2 * p.head_height + p.nut_diameter**2 * p.nut_height) / h_bolt**3
    n_leaf = p.leaf_thickness * w * p.leaf_length / min(p.leaf_mesh_size, body) ** 3
    n_body = (p.mass_a_size**3 + p.mass_b_size**3) / body**3
    return {k: _TETS_PER_H3 * v for k, v in (("hole_mesh_size", n_hole), ("lap_mesh_size", n_lap),
                                              ("leaf_mesh_size", n_leaf), ("body_mesh_size", n_body))}


def check_mesh_size(p: ResonatorParams) -> None:
    """Reject a mesh estimated above :data:`MAX_CELLS`, naming the size that drives it."""
    est = estimate_cells(p)
    total = sum(est.values())
    if total > MAX_CELLS:
        key = max(est, key=est.get)
        raise CaseError(f"geometry.{key} = {getattr(p, key):g}: the mesh would have about "
                        f"{total:.1e} cells (limit {MAX_CELLS:.0e}); use a larger {key}")


#: excitation levels, N (a level beyond the joint's gross slip is judged by the dynamics stage)
LEVEL_RANGE = {"lo": 1e-6, "hi": 1e7, "unit": "N"}


def check_cross(case: Case, sources: Sources) -> None:
    """Rules between sections and list-valued keys (after every section is valid)."""
    r, d = case.roughness, case.dynamics
    if r.patch > r.grid:
        k = _blame(sources, "roughness.patch", "roughness.grid")
        other = "roughness.grid" if k == "roughness.patch" else "roughness.patch"
        raise CaseError(f"{k} = {getattr(r, k.split('.')[1])}: needs roughness.patch ≤ roughness.grid "
                        f"({other} = {getattr(r, other.split('.')[1])}{_src(sources, other)})")
    if len(d.band) != 2 or not d.band[0] < d.band[1]:
        raise CaseError(f"dynamics.band = {d.band!r}: must be [low, high] with low < high "
                        "(fractions of the stuck linear frequency)")
    need = 2 * (2 * d.harmonics + 1)
    if d.samples < need:
        if _blame(sources, "dynamics.samples", "dynamics.harmonics") == "dynamics.harmonics":
            raise CaseError(f"dynamics.harmonics = {d.harmonics}: needs dynamics.samples ≥ 2(2H+1) = "
                            f"{need} (samples = {d.samples}{_src(sources, 'dynamics.samples')}; aliasing)")
        raise CaseError(f"dynamics.samples = {d.samples}: must be ≥ 2(2H+1) = {need} for harmonics = "
                        f"{d.harmonics}{_src(sources, 'dynamics.harmonics')} (aliasing)")
    if len(set(d.configurations)) != len(d.configurations):
        raise CaseError(f"dynamics.configurations = {d.configurations!r}: each configuration at most once")
    lv = d.levels
    if isinstance(lv, str):
        if lv != "auto":
            raise CaseError(f"dynamics.levels = {lv!r}: must be \"auto\" or a list of forces in N")
    elif isinstance(lv, list) and lv:
        for v in lv:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise CaseError(f"dynamics.levels: {v!r} must be a force in N")
            check_range("dynamics.levels", v, LEVEL_RANGE)
    else:
        raise CaseError(f"dynamics.levels = {lv!r}: must be \"auto\" or a non-empty list of forces in N")
