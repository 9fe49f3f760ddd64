"""FE → BEM coupling helpers: equivalent macro gap, patch extraction, element averages.

Equivalent macro gap (docs/design.md, "Rough contact"): the smooth FE solution gives the interface pressure p_s and gap
g_s. Taking the initial separation

    h0 = g_s − K*p_s − z

(K the half-space operator, z the roughness heights, positive towards the other face) makes the BEM
solve with total load Σ p_s·A reproduce p_s exactly when z = 0: the deformed gap is then
h0 + K*p_s = g_s, zero where p_s > 0 and ≥ 0 elsewhere. The original design map wrote "+ z" with z the roughness'
contribution to the separation; with heights that is −z (identical in distribution for a Gaussian
surface).
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from .errors import finite_array, positive_scalar
from .grid import Grid
from .halfspace import ElasticHalfSpace


def macro_gap(hs: ElasticHalfSpace, pressure_smooth, gap_smooth, roughness=None) -> np.ndarray:
    """Initial separation h0 = g_s − K*p_s − z for the rough BEM solve.

    Args:
        hs: half-space operator of the interface grid.
        pressure_smooth: (nx, ny) smooth FE contact pressure p_s (MPa, ≥ 0).
        gap_smooth: (nx, ny) smooth FE gap g_s (mm, ≥ 0 up to round-off).
        roughness: (nx, ny) roughness heights z (mm), or None for a smooth interface.

    Returns:
        (nx, ny) h0 in mm, to pass as ``gap`` to ``solve_normal`` with load = Σ p_s·A.
    """
    g = hs.grid
    ps = g.check_field("pressure_smooth", pressure_smooth)
    if np.any(ps < 0):
        raise ValueError("pressure_smooth: must be >= 0 MPa")
    gs = g.check_field("gap_smooth", gap_smooth)
    z = np.zeros(g.shape) if roughness is None else g.check_field("roughness", roughness)
    return gs - hs.displacement(ps) - z


def extract_patches(heights, grid: Grid, centers, patch_shape=(16, 16), patch_size=None) -> np.ndarray:
    """Local surface patches around points, by bilinear interpolation of a periodic surface.

    Args:
        heights: (nx, ny) surface heights on ``grid`` (mm).
        grid: grid of the surface.
        centers: (ne, 2) patch centres (mm, same frame as ``grid.x``/``grid.y``).
        patch_shape: cells (n, m) of each patch.
        patch_size: (lx, ly) mm of each patch; default n·dx × m·dy (the surface's own resolution).

    Returns:
        (ne, n, m) heights (mm), cell-centred on the patch grid.
    """
    z = grid.check_field("heights", heights)
    c = finite_array("centers", centers, (None, 2))
    n, m = (int(v) for v in patch_shape)
    if n < 2 or m < 2:
        raise ValueError(f"patch_shape: cell counts must be >= 2, got {patch_shape!r}")
    if patch_size is None:
        lx, ly = n * grid.dx, m * grid.dy
    else:
        lx, ly = (positive_scalar("patch_size", v) for v in patch_size)
    ox = (np.arange(n) + 0.5) * lx / n - lx / 2
    oy = (np.arange(m) + 0.5) * ly / m - ly / 2
    X = c[:, 0, None, None] + ox[None, :, None]
    Y = c[:, 1, None, None] + oy[None, None, :]
    # fractional cell indices (cell i is centred at origin + (i + 0.5) d)
    fi = (X - grid.origin[0]) / grid.dx - 0.5
    fj = (Y - grid.origin[1]) / grid.dy - 0.5
    fi, fj = np.broadcast_arrays(fi, fj)
    return ndimage.map_coordinates(z, [fi.ravel(), fj.ravel()], order=1, mode="grid-wrap").reshape(fi.shape)


def cell_average(field, grid: Grid, centers, half_sizes) -> np.ndarray:
    """Average of a grid field over axis-aligned rectangles (e.g. tributary cells of elements).

    Cells are weighted by their overlap area with each rectangle (exact for piecewise-constant
    fields), so Σ average·area is conserved when the rectangles tile the grid.

    Args:
        field: (nx, ny) values (e.g. pressure MPa or gap mm).
        grid: grid of the field.
        centers: (ne, 2) rectangle centres (mm).
        half_sizes: (ne, 2) rectangle half widths (mm, > 0).

    Returns:
        (ne,) averages (nan for rectangles entirely outside the grid).
    """
    f = grid.check_field("field", field)
    c = finite_array("centers", centers, (None, 2))
    hw = finite_array("half_sizes", half_sizes, (c.shape[0], 2))
    if np.any(hw <= 0):
        raise ValueError("half_sizes: must be > 0 mm")
    xe = grid.origin[0] + np.arange(grid.shape[0] + 1) * grid.dx
    ye = grid.origin[1] + np.arange(grid.shape[1] + 1) * grid.dy
    # 1D overlaps (ne, nx) and (ne, ny); the 2D weights are their outer product
    wx = np.clip(np.minimum(xe[None, 1:], (c[:, 0] + hw[:, 0])[:, None])
                 - np.maximum(xe[None, :-1], (c[:, 0] - hw[:, 0])[:, None]), 0.0, None)
    wy = np.clip(np.minimum(ye[None, 1:], (c[:, 1] + hw[:, 1])[:, None])
                 - np.maximum(ye[None, :-1], (c[:, 1] - hw[:, 1])[:, None]), 0.0, None)
    num = np.einsum("ei,ij,ej->e", wx, f, wy)
    den = wx.sum(axis=1) * wy.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
