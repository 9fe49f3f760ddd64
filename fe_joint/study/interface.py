"""The lap interface seen by the contact solver: global BEM grid, FE → BEM fields, element cells.

Choices (docs/design.md, "Rough contact" and "Configurations"; named here because the paper is silent on them):

* **Global grid** — ``n × n`` cells over the nominal overlap (x ∈ [−L/2, L/2], y ∈ [−W/2, W/2]);
  cells whose centre lies in the bolt hole are masked (no contact possible).
* **FE → grid** — the smooth FE pressure and gap, known at the pair nodes, are interpolated
  piecewise-linearly (Delaunay of the pair nodes; nearest node outside their hull). The pressure
  is then scaled so that it integrates to the bolt force exactly (the interpolation error is a
  few per mille; the factor is reported), so that the "equivalent macro gap" with zero roughness
  gives back this pressure exactly.
* **Element cells** — each grid cell belongs to its nearest pair node (a Voronoi partition of the
  interface). An element's normal load is its tributary area × the mean BEM pressure over its
  cell: the same weighting the FE uses for the P2 nodal split (vertex A/12, mid-edge A/4), so a
  uniform pressure gives the FE's own nodal loads. The loads are then rescaled so that
  Σ N0 = bolt force holds exactly (the factor is reported). An element with no contact in its
  cell gets N0 = 0 and gap = the smallest BEM separation over its cell; loaded elements have gap 0.
* **Patches** — every element gets a square patch of the *same* side s = √(interface area /
  n_pairs) centred on its node, cut out of the same surface realization (bilinear resampling to
  ``patch × patch`` points, ``contact_bem.extract_patches``). Contact stiffness per unit area is intensive, so one patch size for
  all elements, loaded by the element's mean pressure × s², gives k_n [N/mm³]; the element's
  stiffness is k_n × its tributary area. One size means one batched half-space operator.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator
from scipy.spatial import cKDTree

from contact_bem import Grid


@dataclass
class InterfaceGrid:
    """Global BEM grid over the lap face and its partition into element cells.

    Attributes:
        grid: the contact_bem grid (cell-centred, mm, origin at the overlap's corner).
        mask: (n, n) bool, True where contact is possible (outside the bolt hole).
        owner: (n, n) int, index of the pair whose cell this grid cell belongs to.
        xc, yc: (n, n) cell-centre coordinates, mm.
    """
    grid: Grid
    mask: np.ndarray
    owner: np.ndarray
    xc: np.ndarray
    yc: np.ndarray

    @property
    def cell_area(self) -> float:
        return self.grid.cell_area


def interface_grid(pair_xy: np.ndarray, overlap: float, width: float, hole_diameter: float,
                   n: int) -> InterfaceGrid:
    """Build the global grid over the overlap and assign its cells to the nearest pair node.

    Args:
        pair_xy: (n_pairs, 2) pair coordinates in the interface plane, mm.
        overlap: lap length in x, mm (grid spans [−overlap/2, overlap/2]).
        width: plate width in y, mm.
        hole_diameter: bolt hole (centred at the origin), mm; cells inside are masked.
        n: cells per side.
    Returns:
        The :class:`InterfaceGrid`.
    """
    pair_xy = np.asarray(pair_xy, float)
    if pair_xy.ndim != 2 or pair_xy.shape[1] != 2 or len(pair_xy) == 0:
        raise ValueError(f"pair_xy: expected shape (n_pairs, 2), got {pair_xy.shape}")
    if not (n >= 4):
        raise ValueError(f"n = {n}: must be ≥ 4")
    x0, y0 = -overlap / 2, -width / 2
    grid = Grid(shape=(n, n), size=(overlap, width), origin=(x0, y0))
    xs = x0 + (np.arange(n) + 0.5) * overlap / n
    ys = y0 + (np.arange(n) + 0.5) * width / n
    xc, yc = np.meshgrid(xs, ys, indexing="ij")
    mask = np.hypot(xc, yc) >= hole_diameter / 2
    _, owner = cKDTree(pair_xy).query(np.column_stack([xc.ravel(), yc.ravel()]))
    return InterfaceGrid(grid=grid, mask=mask, owner=owner.reshape(n, n),
                         xc=xc, yc=yc)


def to_grid(ig: InterfaceGrid, pair_xy: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Interpolate nodal values to the grid cell centres (linear, nearest outside the hull)."""
    pts = np.column_stack([ig.xc.ravel(), ig.yc.ravel()])
    lin = LinearNDInterpolator(pair_xy, values)(pts)
    bad = ~np.isfinite(lin)
    if bad.any():
        lin[bad] = NearestNDInterpolator(pair_xy, values)(pts[bad])
    return lin.reshape(ig.xc.shape)


def smooth_fields(ig: InterfaceGrid, pair_xy: np.ndarray, pressure: np.ndarray, gap: np.ndarray,
                  bolt_force: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Smooth FE pressure and gap on the grid, pressure scaled to integrate to the bolt force.

    Returns:
        (p_s, g_s, scale): grid pressure (MPa, 0 in the hole), grid gap (mm, ≥ 0) and the factor
        applied to the interpolated pressure.
    """
    p = np.clip(to_grid(ig, pair_xy, pressure), 0.0, None) * ig.mask
    g = np.clip(to_grid(ig, pair_xy, gap), 0.0, None)
    g[p > 0] = 0.0                      # where the FE pressure is positive the surfaces touch
    total = p.sum() * ig.cell_area
    if not total > 0:
        raise ValueError("preload pressure: no pair carries load; the FE preload has no contact")
    scale = bolt_force / total
    return p * scale, g, scale


def element_loads(ig: InterfaceGrid, pressure: np.ndarray, gap: np.ndarray, area: np.ndarray,
                  bolt_force: float) -> dict[str, np.ndarray | float]:
    """Per-element normal load, gap and real-contact fraction from a global BEM solution.

    Args:
        ig: the interface grid.
        pressure, gap: (n, n) BEM pressure (MPa) and separation (mm).
        area: (n_pairs,) tributary areas, mm².
        bolt_force: the total normal load, N (Σ N0 is scaled to it).
    Returns:
        dict with ``n0`` (N), ``gap`` (mm), ``pressure`` (mean over the cell, MPa),
        ``contact_fraction`` (of the cell's unmasked area), ``scale`` (the Σ N0 correction).
    """
    ne = len(area)
    own = ig.owner.ravel()
    m = ig.mask.ravel()
    cnt = np.bincount(own[m], minlength=ne).astype(float)
    psum = np.bincount(own[m], weights=pressure.ravel()[m], minlength=ne)
    csum = np.bincount(own[m], weights=(pressure.ravel()[m] > 0).astype(float), minlength=ne)
    pmean = np.divide(psum, cnt, out=np.zeros(ne), where=cnt > 0)
    n0 = pmean * area
    total = n0.sum()
    scale = bolt_force / total if total > 0 else 1.0
    n0 = n0 * scale
    gmin = np.full(ne, np.inf)
    np.minimum.at(gmin, own[m], gap.ravel()[m])
    gmin[~np.isfinite(gmin)] = 0.0
    g = np.where(n0 > 0, 0.0, np.maximum(gmin, 0.0))
    return {"n0": n0, "gap": g, "pressure": pmean * scale,
            "contact_fraction": np.divide(csum, cnt, out=np.zeros(ne), where=cnt > 0),
            "scale": float(scale)}


def patch_side(area: np.ndarray) -> float:
    """Side of the common element patch: √(interface area / number of elements), mm."""
    return float(np.sqrt(np.sum(area) / len(area)))
