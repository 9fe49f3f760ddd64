"""Parametric gmsh (OCC) model of the two-mass bolted lap-joint resonator (docs/design.md, "The resonator").

Pure gmsh + numpy: no dolfinx here, so the model can be built and checked on its own.
Call :func:`build_resonator` on ONE MPI rank; the returned :class:`ResonatorMesh` is plain numpy
and can be broadcast.

Geometry (units mm; x = lap direction, z = bolt axis, interface plane z = 0):

* part A (marker 1): lap plate A (z in [-t, 0], x in [-ov/2 - ext_a, ov/2]), the leaf spring hanging
  under its far (-x) end, and mass A (cube) at the leaf's lower end;
* part B (marker 2): lap plate B (z in [0, t], x in [-ov/2, ov/2 + ext_b]) and mass B (cube, centred
  at z = 0) at its +x end;
* bolt: shank (3) from the nut's lower face to plate B's top face, head (4) on plate B, nut (5)
  under plate A; hole of diameter ``hole_diameter`` through both plates.

Meshing strategy (the gmsh 4.8 traps listed in docs/design.md, "The resonator"):

* two independent fragment groups, {part A} and {part B + bolt}: a face-connected group holding
  the two coincident lap faces fails with "Could not recover boundary mesh";
* the lap faces of A and B are split identically (rectangle minus washer disc + washer annuli) and
  meshed identically with ``setPeriodic`` (identity transform); B's node coordinates are then
  snapped to A's so that pairs coincide exactly;
* the nut (group B) is tied to plate A (group A) through identically meshed annuli whose node pairs
  are merged here, so the returned mesh is one body through the bolt, cut only at the lap interface;
* sizes: ``lap_mesh_size`` on the lap faces growing to ``body_mesh_size`` away from them,
  ``hole_mesh_size`` on the hole and shank surfaces (with the 0.25 mm shank/hole clearance, coarser
  facets of the shank and of plate B's hole intersect and gmsh's boundary recovery fails), and
  ``leaf_mesh_size`` in the leaf spring (its bending is the first mode);
* P2: mid-edge nodes on the geometry, then gmsh's elastic high-order optimisation: the thin
  (0.25 mm) annuli under the head and on the nut otherwise give curved cells with negative
  Jacobians. The build fails with :class:`GeometryError` if any cell stays inverted.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields

import numpy as np

#: Volume markers (cell_markers).
PART_A, PART_B, SHANK, HEAD, NUT = 1, 2, 3, 4, 5
#: Facet markers (facet_markers).
LAP_A, LAP_B, WASHER_HEAD, WASHER_NUT = 11, 12, 13, 14
#: Point marker of the excitation / response point (gmsh physical group only).
EXCITATION_POINT = 21

MARKER_NAMES = {PART_A: "part_a", PART_B: "part_b", SHANK: "shank", HEAD: "head", NUT: "nut"}

# gmsh element type ids
_GMSH_TET = {1: 4, 2: 11}  # order -> tet4 / tet10
_GMSH_TRI = {1: 2, 2: 9}  # order -> tri3 / tri6


class GeometryError(RuntimeError):
    """Raised when gmsh produces a model or mesh that violates the construction's invariants."""


@dataclass(frozen=True)
class ResonatorParams:
    """Parameters of the resonator; all lengths in mm, defaults = docs/design.md, "The resonator"."""

    plate_width: float = 20.0  # y
    plate_thickness: float = 8.0
    overlap: float = 20.0  # lap length in x, lap at x in [-overlap/2, overlap/2]
    plate_a_extension: float = 20.0  # plate A beyond the overlap in -x
    plate_b_extension: float = 15.0  # plate B beyond the overlap in +x
    leaf_thickness: float = 8.0  # x
    leaf_length: float = 40.0  # free length, z
    mass_a_size: float = 50.0  # cube edge
    mass_b_size: float = 50.0
    hole_diameter: float = 8.5
    shank_diameter: float = 8.0
    head_diameter: float = 13.0
    head_height: float = 5.3
    nut_diameter: float = 13.0
    nut_height: float = 6.5
    lap_mesh_size: float = 2.8  # element size on the lap faces
    body_mesh_size: float = 6.0  # far-field element size
    hole_mesh_size: float = 1.8  # element size on the hole / shank surfaces (0.25 mm clearance)
    refine_distance: float = 20.0  # distance from the lap faces over which sizes grow to body size
    hole_grading_distance: float = 3.0  # distance from the hole over which sizes grow to lap size
    leaf_mesh_size: float = 3.0  # element size in the leaf spring (first mode = leaf bending)
    order: int = 2  # P2 tetrahedra (order 1 allowed for tests)
    seed: int = 1  # gmsh Mesh.RandomSeed: same seed, same mesh

    def validate(self) -> None:
        """Check ranges; raise ``ValueError`` naming the field and the allowed range."""
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("order", "seed"):
                continue
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ValueError(f"{f.name} = {v!r} must be a finite number (mm)")
            if v <= 0:
                raise ValueError(f"{f.name} = {v} must be > 0 (mm)")
        if self.order not in (1, 2) or isinstance(self.order, bool):
            raise ValueError(f"order = {self.order!r} must be 1 or 2")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"seed = {self.seed!r} must be an integer >= 0")
        lap_min = min(self.overlap, self.plate_width)
        if not self.shank_diameter < self.hole_diameter:
            raise ValueError(f"shank_diameter = {self.shank_diameter} must be < hole_diameter "
                             f"({self.hole_diameter})")
        for name in ("head_diameter", "nut_diameter"):
            v = getattr(self, name)
            if not self.hole_diameter < v < lap_min:
                raise ValueError(f"{name} = {v} must be > hole_diameter ({self.hole_diameter}) and "
                                 f"< overlap and < plate_width ({lap_min})")
        if not self.hole_diameter < lap_min:
            raise ValueError(f"hole_diameter = {self.hole_diameter} must be < overlap and < "
                             f"plate_width ({lap_min})")
        if not self.leaf_thickness <= self.plate_a_extension:
            raise ValueError(f"leaf_thickness = {self.leaf_thickness} must be <= plate_a_extension "
                             f"({self.plate_a_extension})")
        if not self.mass_a_size >= max(self.leaf_thickness, self.plate_width):
            raise ValueError(f"mass_a_size = {self.mass_a_size} must be >= leaf_thickness and "
                             f">= plate_width ({max(self.leaf_thickness, self.plate_width)})")
        if not self.mass_b_size >= max(self.plate_width, 2 * self.plate_thickness):
            raise ValueError(f"mass_b_size = {self.mass_b_size} must be >= plate_width and >= 2*"
                             f"plate_thickness ({max(self.plate_width, 2 * self.plate_thickness)})")
        if not self.leaf_length > self.nut_height:
            raise ValueError(f"leaf_length = {self.leaf_length} must be > nut_height "
                             f"({self.nut_height}) so that mass A clears the nut")
        g = _Layout(self)
        if not (g.mass_a_x[1] < g.mass_b_x[0] or g.mass_a_z[1] < g.mass_b_z[0]):
            raise ValueError(f"mass_a_size = {self.mass_a_size}, mass_b_size = {self.mass_b_size}: "
                             f"the masses overlap; reduce them or increase leaf_length")
        if not self.hole_mesh_size <= self.lap_mesh_size <= self.body_mesh_size:
            raise ValueError(f"mesh sizes must satisfy hole_mesh_size ({self.hole_mesh_size}) <= "
                             f"lap_mesh_size ({self.lap_mesh_size}) <= body_mesh_size "
                             f"({self.body_mesh_size})")
        if self.lap_mesh_size > lap_min / 2:
            raise ValueError(f"lap_mesh_size = {self.lap_mesh_size} must be <= half the lap "
                             f"({lap_min / 2})")


class _Layout:
    """Derived coordinates of the parts (mm)."""

    def __init__(self, p: ResonatorParams):
        self.t = p.plate_thickness
        self.w = p.plate_width
        self.x_lap = (-p.overlap / 2, p.overlap / 2)
        self.x_a0 = -p.overlap / 2 - p.plate_a_extension  # far end of plate A
        self.x_b1 = p.overlap / 2 + p.plate_b_extension  # far end of plate B
        xc_leaf = self.x_a0 + p.leaf_thickness / 2
        self.mass_a_x = (xc_leaf - p.mass_a_size / 2, xc_leaf + p.mass_a_size / 2)
        self.mass_a_z = (-self.t - p.leaf_length - p.mass_a_size, -self.t - p.leaf_length)
        self.mass_b_x = (self.x_b1, self.x_b1 + p.mass_b_size)
        self.mass_b_z = (-p.mass_b_size / 2, p.mass_b_size / 2)
        self.r_hole = p.hole_diameter / 2
        self.r_shank = p.shank_diameter / 2
        self.r_head = p.head_diameter / 2
        self.r_nut = p.nut_diameter / 2
        # radii at which both lap plates are split (identical partitions of lap A and lap B)
        self.radii = sorted({self.r_hole, self.r_head, self.r_nut})
        self.excitation = (self.mass_a_x[0], 0.0, 0.5 * (self.mass_a_z[0] + self.mass_a_z[1]))


@dataclass
class ResonatorMesh:
    """Plain-numpy description of the meshed resonator (identical on every rank after broadcast).

    Attributes:
        points: (n_nodes, 3) float64 node coordinates, mm (nut-annulus duplicates merged).
        cells: (n_cells, 10) int64 tet10 in gmsh node ordering ((n_cells, 4) for order 1).
        cell_markers: (n_cells,) int32: 1 part A, 2 part B, 3 shank, 4 head, 5 nut.
        facets: (n_facets, 6) int64 tri6 ((n, 3) for order 1), gmsh ordering.
        facet_markers: (n_facets,) int32: 11 lap face A, 12 lap face B, 13 head/plate B washer,
            14 nut/plate A washer.
        pair_nodes: (n_pairs, 2) int64 node on lap A, matched node on lap B (identical xyz).
        pair_xyz: (n_pairs, 3) float64 pair coordinates, mm (z = 0).
        pair_area: (n_pairs,) float64 tributary area, mm² (vertex A/12, mid-edge A/4 per triangle).
        excitation_node: node at the centre of mass A's outer (-x) face.
        response_node: node on mass A (same point as the excitation).
        params: the parameters the mesh was built from.
        build_time: wall time of the gmsh build, s.
    """

    points: np.ndarray
    cells: np.ndarray
    cell_markers: np.ndarray
    facets: np.ndarray
    facet_markers: np.ndarray
    pair_nodes: np.ndarray
    pair_xyz: np.ndarray
    pair_area: np.ndarray
    excitation_node: int
    response_node: int
    params: ResonatorParams
    build_time: float = field(default=0.0)

    @property
    def n_pairs(self) -> int:
        """Number of matched interface node pairs."""
        return int(self.pair_nodes.shape[0])

    #: the arrays and integers :meth:`save` writes (everything but the parameters and the time)
    _SAVED = ("points", "cells", "cell_markers", "facets", "facet_markers", "pair_nodes", "pair_xyz",
              "pair_area", "excitation_node", "response_node")

    def save(self, path) -> None:
        """Write the mesh as ``.npz`` (bit-exact; the parameters are the case's, not stored).

        A later stage builds its FE model from this file rather than meshing again: gmsh's
        high-order node placement is not repeatable to the last bit (README, "In parallel")."""
        np.savez(path, **{k: np.asarray(getattr(self, k)) for k in self._SAVED})

    @classmethod
    def load(cls, path, params: ResonatorParams) -> "ResonatorMesh":
        """Read a mesh written by :meth:`save`; ``params`` are the geometry it was built from."""
        with np.load(path, allow_pickle=False) as d:
            kw = {k: d[k] for k in cls._SAVED}
        for k in ("excitation_node", "response_node"):
            kw[k] = int(kw[k])
        return cls(params=params, **kw)


def nominal_volumes(params: ResonatorParams) -> dict[str, float]:
    """Analytic volumes of the parts, mm³.

    Args:
        params: resonator parameters.

    Returns:
        ``{"part_a", "part_b", "shank", "head", "nut", "total"}`` -> volume (mm³); the keys match
        :data:`MARKER_NAMES`.
    """
    p = params
    p.validate()
    hole = math.pi * (p.hole_diameter / 2) ** 2 * p.plate_thickness
    plate_a = (p.overlap + p.plate_a_extension) * p.plate_width * p.plate_thickness - hole
    plate_b = (p.overlap + p.plate_b_extension) * p.plate_width * p.plate_thickness - hole
    vol = {
        "part_a": plate_a + p.leaf_thickness * p.plate_width * p.leaf_length + p.mass_a_size ** 3,
        "part_b": plate_b + p.mass_b_size ** 3,
        "shank": math.pi * (p.shank_diameter / 2) ** 2 * (2 * p.plate_thickness + p.nut_height),
        "head": math.pi * (p.head_diameter / 2) ** 2 * p.head_height,
        "nut": math.pi * ((p.nut_diameter / 2) ** 2 - (p.shank_diameter / 2) ** 2) * p.nut_height,
    }
    vol["total"] = sum(vol.values())
    return vol


def nominal_interface_area(params: ResonatorParams) -> float:
    """Nominal lap interface area minus the hole, mm²."""
    return params.overlap * params.plate_width - math.pi * (params.hole_diameter / 2) ** 2


# ----------------------------------------------------------------------------------------------
# gmsh model
# ----------------------------------------------------------------------------------------------

def _ring(occ, z0: float, h: float, r_in: float, r_out: float) -> int:
    """OCC annulus r in [r_in, r_out], z in [z0, z0 + h]; returns the volume tag."""
    outer = occ.addCylinder(0, 0, z0, 0, 0, h, r_out)
    inner = occ.addCylinder(0, 0, z0, 0, 0, h, r_in)
    out, _ = occ.cut([(3, outer)], [(3, inner)])
    return out[0][1]


def _lap_plate(occ, g: _Layout, z0: float) -> list[int]:
    """Lap (overlap) part of a plate, split at the washer radii: [outer, ring1, ring2, ...]."""
    box = occ.addBox(g.x_lap[0], -g.w / 2, z0, g.x_lap[1] - g.x_lap[0], g.w, g.t)
    cyl = occ.addCylinder(0, 0, z0, 0, 0, g.t, g.radii[-1])
    out, _ = occ.cut([(3, box)], [(3, cyl)])
    vols = [out[0][1]]
    for r0, r1 in zip(g.radii[:-1], g.radii[1:]):
        vols.append(_ring(occ, z0, g.t, r0, r1))
    return vols


def _fragment(occ, groups: dict[int, list[int]]) -> dict[int, list[int]]:
    """Fragment all volumes of ``groups`` (marker -> input tags) together; marker -> output tags."""
    inputs = [(m, v) for m, vs in groups.items() for v in vs]
    dimtags = [(3, v) for _, v in inputs]
    _, out_map = occ.fragment(dimtags[:1], dimtags[1:])
    res: dict[int, list[int]] = {m: [] for m in groups}
    for (m, _), children in zip(inputs, out_map):
        res[m].extend(t for d, t in children if d == 3)
    # the pieces never overlap, so every output volume has exactly one owner
    flat = [t for ts in res.values() for t in ts]
    if len(flat) != len(set(flat)):
        raise GeometryError("overlapping input volumes in a fragment group")
    return res


def _surfaces_in_box(gmsh, box, vols: set[int]) -> list[int]:
    """Surfaces inside the bounding box ``box`` that bound at least one volume of ``vols``."""
    eps = 1e-6
    lo = np.asarray(box[:3]) - eps
    hi = np.asarray(box[3:]) + eps
    found = gmsh.model.getEntitiesInBoundingBox(*lo, *hi, dim=2)
    res = []
    for _, s in found:
        up, _ = gmsh.model.getAdjacencies(2, s)
        if vols.intersection(int(u) for u in up):
            res.append(s)
    return sorted(res)


def _surface_key(gmsh, s: int) -> tuple:
    """Geometric signature of a planar surface (bounding box rounded), to pair coincident faces."""
    bb = gmsh.model.getBoundingBox(2, s)
    return tuple(np.round(bb, 6))


def _threshold(fld, faces: list[int], size_min: float, size_max: float, dist_max: float,
               stop_at_dist_max: bool = False) -> int:
    """Distance-to-``faces`` threshold field: size_min on the faces growing linearly to size_max
    at dist_max (mm); with ``stop_at_dist_max`` it does not constrain beyond dist_max."""
    dist = fld.add("Distance")
    fld.setNumbers(dist, "FacesList", faces)
    thr = fld.add("Threshold")
    fld.setNumber(thr, "InField", dist)
    fld.setNumber(thr, "SizeMin", size_min)
    fld.setNumber(thr, "SizeMax", size_max)
    fld.setNumber(thr, "DistMin", 0.0)
    fld.setNumber(thr, "DistMax", dist_max)
    fld.setNumber(thr, "StopAtDistMax", int(stop_at_dist_max))
    return thr


def _build_gmsh_model(gmsh, p: ResonatorParams) -> dict:
    """Create the OCC model, physical groups, periodic constraints and size fields."""
    g = _Layout(p)
    occ = gmsh.model.occ
    gmsh.model.add("resonator")

    # --- group A: plate A (far part + lap part split at washer radii), leaf, mass A
    far_a = occ.addBox(g.x_a0, -g.w / 2, -g.t, p.plate_a_extension, g.w, g.t)
    lap_a = _lap_plate(occ, g, -g.t)
    leaf = occ.addBox(g.x_a0, -g.w / 2, -g.t - p.leaf_length, p.leaf_thickness, g.w, p.leaf_length)
    mass_a = occ.addBox(g.mass_a_x[0], -p.mass_a_size / 2, g.mass_a_z[0],
                        p.mass_a_size, p.mass_a_size, p.mass_a_size)
    # --- group B: plate B, mass B, bolt
    lap_b = _lap_plate(occ, g, 0.0)
    far_b = occ.addBox(g.x_lap[1], -g.w / 2, 0.0, p.plate_b_extension, g.w, g.t)
    mass_b = occ.addBox(g.mass_b_x[0], -p.mass_b_size / 2, g.mass_b_z[0],
                        p.mass_b_size, p.mass_b_size, p.mass_b_size)
    z_nut = -g.t - p.nut_height
    shank = occ.addCylinder(0, 0, z_nut, 0, 0, 2 * g.t + p.nut_height, g.r_shank)
    head = occ.addCylinder(0, 0, g.t, 0, 0, p.head_height, g.r_head)
    # the nut is split at the same radii as plate A so its top annulus matches plate A's bottom
    nut_radii = [g.r_shank] + [r for r in g.radii if r < g.r_nut] + [g.r_nut]
    nut = [_ring(occ, z_nut, p.nut_height, r0, r1) for r0, r1 in zip(nut_radii[:-1], nut_radii[1:])]
    occ.synchronize()

    vol_a = _fragment(occ, {PART_A: [far_a, *lap_a, leaf, mass_a]})
    vol_b = _fragment(occ, {PART_B: [*lap_b, far_b, mass_b], SHANK: [shank], HEAD: [head],
                            NUT: nut})
    exc = occ.addPoint(*g.excitation)
    occ.synchronize()
    vols = {**vol_a, **vol_b}
    set_a = set(vol_a[PART_A])
    set_b = set(t for m in (PART_B, SHANK, HEAD, NUT) for t in vol_b[m])

    # --- lap faces: same partition on A and B; pair them by geometry
    lap_box = (g.x_lap[0], -g.w / 2, 0.0, g.x_lap[1], g.w / 2, 0.0)
    lap_a_s = _surfaces_in_box(gmsh, lap_box, set_a)
    lap_b_s = _surfaces_in_box(gmsh, lap_box, set_b)
    if len(lap_a_s) != len(g.radii) or len(lap_b_s) != len(g.radii):
        raise GeometryError(f"lap faces: expected {len(g.radii)} surfaces per side, got "
                            f"{len(lap_a_s)} (A) and {len(lap_b_s)} (B)")
    key_a = {_surface_key(gmsh, s): s for s in lap_a_s}
    lap_master = [key_a[_surface_key(gmsh, s)] for s in lap_b_s]

    # --- washer faces
    rh = g.r_head
    head_box = (-rh, -rh, g.t, rh, rh, g.t)
    head_set = set(vols[HEAD])
    plate_b_set = set(vols[PART_B])
    washer_head = [s for s in _surfaces_in_box(gmsh, head_box, head_set)
                   if plate_b_set.intersection(int(u) for u in gmsh.model.getAdjacencies(2, s)[0])]
    rn = g.r_nut
    nut_box = (-rn, -rn, -g.t, rn, rn, -g.t)
    nut_top = [s for s in _surfaces_in_box(gmsh, nut_box, set(vols[NUT]))
               if gmsh.model.getBoundingBox(2, s)[3] > g.r_hole + 1e-6]
    plate_a_bottom = _surfaces_in_box(gmsh, nut_box, set_a)
    key_pa = {_surface_key(gmsh, s): s for s in plate_a_bottom}
    try:
        nut_master = [key_pa[_surface_key(gmsh, s)] for s in nut_top]
    except KeyError as exc_:
        raise GeometryError("nut top annulus does not match plate A's bottom annulus") from exc_
    if not washer_head or not nut_top:
        raise GeometryError("washer faces not found")

    # --- excitation point embedded in mass A's -x face
    x0 = g.mass_a_x[0]
    face = _surfaces_in_box(gmsh, (x0, -p.mass_a_size / 2, g.mass_a_z[0],
                                   x0, p.mass_a_size / 2, g.mass_a_z[1]), set_a)
    if len(face) != 1:
        raise GeometryError(f"mass A -x face: found {len(face)} surfaces")
    gmsh.model.mesh.embed(0, [exc], 2, face[0])

    # --- physical groups (gmsh 4.8: no name= argument)
    for m, tags in vols.items():
        gmsh.model.addPhysicalGroup(3, tags, m)
    gmsh.model.addPhysicalGroup(2, lap_a_s, LAP_A)
    gmsh.model.addPhysicalGroup(2, lap_b_s, LAP_B)
    gmsh.model.addPhysicalGroup(2, washer_head, WASHER_HEAD)
    gmsh.model.addPhysicalGroup(2, nut_master, WASHER_NUT)
    gmsh.model.addPhysicalGroup(0, [exc], EXCITATION_POINT)

    # --- identical meshes on the coincident faces (identity transform)
    ident = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    gmsh.model.mesh.setPeriodic(2, lap_b_s, lap_master, ident)
    gmsh.model.mesh.setPeriodic(2, nut_top, nut_master, ident)

    # --- sizes: lap faces -> lap size growing to body size over refine_distance
    fld = gmsh.model.mesh.field
    t_lap = _threshold(fld, lap_a_s + lap_b_s, p.lap_mesh_size, p.body_mesh_size,
                       p.refine_distance)
    # the clearance: every surface within the hole radius (hole and shank cylinders, inner nut ring),
    # so that the shank and hole surfaces, meshed in one connected component of group B, do not
    # intersect (gmsh then fails in boundary recovery with "A segment and a facet intersect").
    # Beyond hole_grading_distance this field stops constraining, so the pair count depends on the
    # lap and hole sizes only, not on body_mesh_size.
    r_in = g.r_hole + 1e-6
    bolt_box = (-r_in, -r_in, z_nut - 1e-3, r_in, r_in, g.t + p.head_height + 1e-3)
    faces = [c for _, c in gmsh.model.getEntitiesInBoundingBox(*bolt_box, dim=2)]
    t_hole = _threshold(fld, faces, p.hole_mesh_size, p.lap_mesh_size, p.hole_grading_distance,
                        stop_at_dist_max=True)
    # the leaf carries the first (bending) mode: keep a few P2 elements through its thickness
    b_leaf = fld.add("Box")
    fld.setNumber(b_leaf, "VIn", p.leaf_mesh_size)
    fld.setNumber(b_leaf, "VOut", p.body_mesh_size)
    for key, val in zip(("XMin", "YMin", "ZMin", "XMax", "YMax", "ZMax"),
                        (g.x_a0, -g.w / 2, g.mass_a_z[1], g.x_a0 + p.leaf_thickness, g.w / 2, -g.t)):
        fld.setNumber(b_leaf, key, val)
    f_min = fld.add("Min")
    fld.setNumbers(f_min, "FieldsList", [t_lap, t_hole, b_leaf])
    fld.setAsBackgroundMesh(f_min)

    return {"vols": vols, "lap_a": lap_a_s, "lap_b": lap_b_s, "nut_top": nut_top,
            "nut_master": nut_master, "washer_head": washer_head, "excitation": exc}


# ----------------------------------------------------------------------------------------------
# mesh extraction
# ----------------------------------------------------------------------------------------------

def _elements(gmsh, dim: int, tags: list[int], etype: int) -> np.ndarray:
    """Node tags (uint64) of elements of type ``etype`` on entities ``tags``, one row each."""
    name, edim, order, nn, *_ = gmsh.model.mesh.getElementProperties(etype)
    rows = []
    for t in tags:
        types, _, ntags = gmsh.model.mesh.getElements(dim, t)
        for ty, nt in zip(types, ntags):
            if ty != etype:
                raise GeometryError(f"unexpected gmsh element type {ty} on entity ({dim}, {t})")
            rows.append(np.asarray(nt, dtype=np.int64).reshape(-1, nn))
    return np.concatenate(rows) if rows else np.empty((0, nn), dtype=np.int64)


def _match_nodes(xa: np.ndarray, xb: np.ndarray, tol: float) -> np.ndarray:
    """For each point of ``xb`` the index of the coincident point of ``xa`` (all must match).

    Sort-based nearest match (no scipy in geometry/): points are ordered lexicographically after
    rounding to ``tol``; coincident points get the same key.
    """
    if xa.shape != xb.shape:
        raise GeometryError(f"node sets of coincident faces differ in size: {len(xa)} vs {len(xb)}")
    ka = np.round(xa / tol).astype(np.int64)
    kb = np.round(xb / tol).astype(np.int64)
    oa = np.lexsort(ka.T[::-1])
    ob = np.lexsort(kb.T[::-1])
    idx = np.empty(len(xb), dtype=np.int64)
    idx[ob] = oa
    dist = np.max(np.abs(xa[idx] - xb), axis=1) if len(xb) else np.zeros(0)
    if dist.size and dist.max() > 10 * tol:
        raise GeometryError(f"coincident faces are not meshed identically: max node distance "
                            f"{dist.max():.3e} mm")
    return idx


def _p2_triangle_areas(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Areas of (curved) triangles, mm²: tri3 exact; tri6 by a degree-2-exact rule (|J| of a
    planar P2 map is quadratic, so the rule is exact for planar faces)."""
    v = x[tri[:, :3]]
    if tri.shape[1] == 3:
        return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    xe = x[tri]  # (n, 6, 3) gmsh tri6: v0 v1 v2, m01 m12 m20
    qp = np.array([[1 / 6, 1 / 6], [2 / 3, 1 / 6], [1 / 6, 2 / 3]])
    area = np.zeros(len(tri))
    for r, s in qp:
        dr = np.array([4 * r + 4 * s - 3, 4 * r - 1, 0, 4 - 8 * r - 4 * s, 4 * s, -4 * s])
        ds = np.array([4 * r + 4 * s - 3, 0, 4 * s - 1, -4 * r, 4 * r, 4 - 4 * r - 8 * s])
        jr = np.einsum("k,nkd->nd", dr, xe)
        js = np.einsum("k,nkd->nd", ds, xe)
        area += np.linalg.norm(np.cross(jr, js), axis=1) / 6.0
    return area


# gmsh tet10 node order: v0..v3, then the mid-edge nodes of edges 01, 12, 20, 30, 32, 31
_TET10_EDGES = ((0, 1), (1, 2), (2, 0), (3, 0), (3, 2), (3, 1))
_DLAMBDA = np.array([[-1, -1, -1], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)


def _tet10_grad(r: float, s: float, t: float) -> np.ndarray:
    """(10, 3) reference gradients of the gmsh-ordered P2 tet shape functions at (r, s, t)."""
    lam = np.array([1 - r - s - t, r, s, t])
    dn = np.zeros((10, 3))
    for i in range(4):
        dn[i] = (4 * lam[i] - 1) * _DLAMBDA[i]
    for k, (i, j) in enumerate(_TET10_EDGES):
        dn[4 + k] = 4 * (lam[i] * _DLAMBDA[j] + lam[j] * _DLAMBDA[i])
    return dn


def scaled_jacobian(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Minimum over the 10 nodes and the centroid of det J / det J_straight for tet10 cells.

    1 for straight cells; <= 0 means the curved cell is (partly) inverted and unusable.

    Args:
        points: (n_nodes, 3) coordinates, mm.
        cells: (n_cells, 10) gmsh tet10 (tet4 cells return ones).

    Returns:
        (n_cells,) float64.
    """
    if cells.shape[1] == 4:
        return np.ones(len(cells))
    xe = points[cells]
    d = xe[:, 1:4] - xe[:, :1]
    lin = np.einsum("ni,ni->n", np.cross(d[:, 0], d[:, 1]), d[:, 2])
    ref = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (.5, 0, 0), (.5, .5, 0), (0, .5, 0),
           (0, 0, .5), (0, .5, .5), (.5, 0, .5), (.25, .25, .25)]
    out = np.full(len(cells), np.inf)
    for r, s_, t in ref:
        jac = np.einsum("kd,nke->ned", _tet10_grad(r, s_, t), xe)
        out = np.minimum(out, np.linalg.det(jac) / lin)
    return out


def cell_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Volumes of tet4 / tet10 cells (gmsh ordering), mm³.

    tet10: the Jacobian determinant of a P2 map is a cubic, integrated exactly with the 5-point
    degree-3 rule (Keast); tet4: exact.

    Args:
        points: (n_nodes, 3) coordinates, mm.
        cells: (n_cells, 4) or (n_cells, 10) node indices.

    Returns:
        (n_cells,) volumes (positive for positively oriented cells).
    """
    xe = points[cells]
    if cells.shape[1] == 4:
        d = xe[:, 1:] - xe[:, :1]
        return np.einsum("ni,ni->n", np.cross(d[:, 0], d[:, 1]), d[:, 2]) / 6.0
    if cells.shape[1] != 10:
        raise ValueError(f"cells must have 4 or 10 nodes, got {cells.shape[1]}")
    a, b = 1 / 6, 1 / 2
    qp = [(0.25, 0.25, 0.25, -4 / 5), (a, a, a, 9 / 20), (b, a, a, 9 / 20), (a, b, a, 9 / 20),
          (a, a, b, 9 / 20)]
    vol = np.zeros(len(cells))
    for r, s_, t, w in qp:
        jac = np.einsum("kd,nke->ned", _tet10_grad(r, s_, t), xe)  # (n, 3 phys, 3 ref)
        vol += w * np.linalg.det(jac) / 6.0
    return vol


def _tributary(tri: np.ndarray, area: np.ndarray, n_nodes: int) -> np.ndarray:
    """Nodal area split: P1 -> A/3 per vertex; P2 -> A/12 per vertex, A/4 per mid-edge node."""
    w = np.full(3, 1 / 3) if tri.shape[1] == 3 else np.array([1, 1, 1, 3, 3, 3]) / 12.0
    out = np.zeros(n_nodes)
    np.add.at(out, tri.ravel(), (area[:, None] * w[None, :]).ravel())
    return out


def build_resonator(params: ResonatorParams, verbose: bool = False) -> ResonatorMesh:
    """Build and mesh the resonator with gmsh (call on one rank only).

    Args:
        params: resonator parameters (validated first).
        verbose: print gmsh messages to the terminal.

    Returns:
        The plain-numpy :class:`ResonatorMesh`.

    Raises:
        ValueError: invalid parameters.
        GeometryError: gmsh produced a model violating the construction (unmatched faces ...).
    """
    import gmsh

    params.validate()
    t0 = time.perf_counter()
    # gmsh 4.8 has no isInitialized(): this function owns one gmsh session from start to end
    # (interruptible=False, where available, keeps gmsh from taking over SIGINT)
    if _has_interruptible(gmsh):
        gmsh.initialize(interruptible=False)
    else:
        gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 1 if verbose else 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", params.seed)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", params.body_mesh_size)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.option.setNumber("Mesh.SecondOrderLinear", 0)
        info = _build_gmsh_model(gmsh, params)
        gmsh.model.mesh.generate(3)
        if params.order == 2:
            gmsh.model.mesh.setOrder(2)
            # thin features (0.25 mm shank/hole clearance annuli under the head and on the nut)
            # give P2 cells with negative Jacobians when curved; the elastic analogy fixes them
            gmsh.model.mesh.optimize("HighOrderElastic")
        data = _extract(gmsh, params, info)
        gmsh.model.remove()
        q = scaled_jacobian(data.points, data.cells)
        if q.min() <= 0:
            raise GeometryError(f"{int((q <= 0).sum())} curved cells have a non-positive Jacobian "
                                f"(min scaled Jacobian {q.min():.3f}); reduce hole_mesh_size")
    finally:
        gmsh.finalize()
    data.build_time = time.perf_counter() - t0
    return data


def _has_interruptible(gmsh) -> bool:
    import inspect
    try:
        return "interruptible" in inspect.signature(gmsh.initialize).parameters
    except (TypeError, ValueError):
        return False


def _extract(gmsh, p: ResonatorParams, info: dict) -> ResonatorMesh:
    """Read the gmsh mesh into numpy, merge the nut annulus, build the matched lap pairs."""
    order = p.order
    tet, tri = _GMSH_TET[order], _GMSH_TRI[order]
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    node_tags = np.asarray(node_tags, dtype=np.int64)
    x_all = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    tag2row = np.full(node_tags.max() + 1, -1, dtype=np.int64)
    tag2row[node_tags] = np.arange(len(node_tags))

    cells, markers = [], []
    for m, tags in info["vols"].items():
        c = _elements(gmsh, 3, tags, tet)
        cells.append(tag2row[c])
        markers.append(np.full(len(c), m, dtype=np.int32))
    cells = np.concatenate(cells)
    markers = np.concatenate(markers)

    def facets_of(tags):
        return tag2row[_elements(gmsh, 2, tags, tri)]

    lap_a = facets_of(info["lap_a"])
    lap_b = facets_of(info["lap_b"])
    w_head = facets_of(info["washer_head"])
    w_nut_a = facets_of(info["nut_master"])
    w_nut_b = facets_of(info["nut_top"])
    scale = float(np.max(np.abs(x_all)))
    tol = 1e-9 * scale

    # lap pairs: B nodes snapped onto A's coordinates (exact coincidence of each pair)
    na = np.unique(lap_a)
    nb = np.unique(lap_b)
    ia = _match_nodes(x_all[nb], x_all[na], tol)  # A node k <-> B node nb[ia[k]]
    nb_of_a = nb[ia]
    x_all[nb_of_a] = x_all[na]

    # nut annulus: nut-side duplicates replaced by plate A's nodes
    nna = np.unique(w_nut_a)
    nnb = np.unique(w_nut_b)
    jb = _match_nodes(x_all[nnb], x_all[nna], tol)
    replace = np.arange(len(x_all))
    replace[nnb[jb]] = nna
    cells = replace[cells]

    # compact numbering over the nodes used by cells (drops merged duplicates and free points)
    used = np.unique(cells)
    new = np.full(len(x_all), -1, dtype=np.int64)
    new[used] = np.arange(len(used))
    points = x_all[used]
    cells = new[cells]
    facets = np.concatenate([lap_a, lap_b, w_head, w_nut_a])
    facets = new[replace[facets]]
    facet_markers = np.concatenate([np.full(len(f), m, dtype=np.int32) for f, m in
                                    ((lap_a, LAP_A), (lap_b, LAP_B), (w_head, WASHER_HEAD),
                                     (w_nut_a, WASHER_NUT))])
    if (facets < 0).any() or (cells < 0).any():
        raise GeometryError("facet or cell node not in the volume mesh")

    pa = new[na]
    pb = new[nb_of_a]
    lap_a_new = new[lap_a]
    area = _tributary(lap_a_new, _p2_triangle_areas(points, lap_a_new), len(points))
    xyz = points[pa]
    order_ = np.lexsort((np.round(xyz[:, 1], 9), np.round(xyz[:, 0], 9)))
    pa, pb = pa[order_], pb[order_]

    exc_nodes = gmsh.model.mesh.getNodes(0, info["excitation"])[0]
    if len(exc_nodes) != 1:
        raise GeometryError("excitation point has no mesh node")
    exc = int(new[tag2row[int(exc_nodes[0])]])
    if exc < 0:
        raise GeometryError("excitation point is not connected to the volume mesh")

    return ResonatorMesh(
        points=points, cells=cells.astype(np.int64), cell_markers=markers,
        facets=facets.astype(np.int64), facet_markers=facet_markers,
        pair_nodes=np.stack([pa, pb], axis=1).astype(np.int64), pair_xyz=points[pa].copy(),
        pair_area=area[pa], excitation_node=exc, response_node=exc, params=p)
