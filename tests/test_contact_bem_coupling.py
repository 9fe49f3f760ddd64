"""FE → BEM coupling: the equivalent macro gap reproduces the smooth pressure; patches; averages."""
import numpy as np
import pytest

from contact_bem import (ElasticHalfSpace, Grid, cell_average, extract_patches, gaussian_surface,
                         macro_gap, solve_normal)

E, NU = 198400.0, 0.3


def test_macro_gap_without_roughness_returns_smooth_pressure():
    g = Grid((64, 64), (20.0, 20.0), origin=(-10.0, -10.0))
    X, Y = g.meshgrid()
    r = np.hypot(X, Y)
    # a smooth FE-like field: pressure on an annulus (bolt hole masked), gap opening outside it
    hole = r < 4.25
    ps = np.where((r < 8.0) & ~hole, 150.0 * np.sqrt(np.clip(1 - ((r - 6.0) / 2.0) ** 2, 0, None)) + 5.0, 0.0)
    gs = np.where(ps > 0, 0.0, 1e-4 * np.clip(r - 8.0, 0, None) ** 2 + 1e-6)
    gs[hole] = 0.0
    hs = ElasticHalfSpace(g, E, NU)
    h0 = macro_gap(hs, ps, gs, None)
    load = ps.sum() * g.cell_area
    ns = solve_normal(hs, h0, load=load, mask=~hole, tol=1e-12, max_iter=5000)
    assert np.abs(ns.pressure - ps).max() <= 1e-6 * ps.max()
    assert abs(ns.approach) < 1e-9


def test_macro_gap_adds_roughness_and_validates():
    g = Grid((16, 16), (2.0, 2.0))
    hs = ElasticHalfSpace(g, E, NU)
    z = gaussian_surface(g, 1e-3, 0.3, seed=0)
    ps = np.zeros(g.shape)
    assert np.allclose(macro_gap(hs, ps, np.ones(g.shape), z), 1.0 - z)
    with pytest.raises(ValueError, match="pressure_smooth"):
        macro_gap(hs, -np.ones(g.shape), ps, z)
    with pytest.raises(ValueError, match="gap_smooth"):
        macro_gap(hs, ps, np.ones((3, 3)), z)
    with pytest.raises(ValueError, match="roughness"):
        macro_gap(hs, ps, ps, np.full(g.shape, np.inf))


def test_extract_patches_on_grid_points_and_wrap():
    g = Grid((64, 48), (6.4, 4.8), origin=(-3.2, -2.4))
    z = gaussian_surface(g, 1e-3, 0.4, seed=1)
    c = [[(g.x[9] + g.x[10]) / 2, (g.y[19] + g.y[20]) / 2], [g.x[0] - g.dx / 2, g.y[0] - g.dy / 2]]
    P = extract_patches(z, g, c, (4, 4))
    assert np.allclose(P[0], z[8:12, 18:22], atol=1e-15)
    wrapped = np.roll(np.roll(z, 2, 0), 2, 1)[:4, :4]       # periodic wrap at the corner
    assert np.allclose(P[1], wrapped, atol=1e-15)
    # half-cell shift = average of neighbours (bilinear)
    P2 = extract_patches(z, g, [[g.x[10], (g.y[19] + g.y[20]) / 2]], (2, 2))
    assert P2[0, 0, 0] == pytest.approx(0.5 * (z[9, 19] + z[10, 19]), abs=1e-15)


def test_cell_average_conserves_integral():
    g = Grid((40, 30), (4.0, 3.0))
    f = np.random.default_rng(0).random(g.shape)
    # 4 × 3 tiles of 1 mm² covering the grid: Σ avg·area = ∫ f
    cx, cy = np.meshgrid(np.arange(4) + 0.5, np.arange(3) + 0.5, indexing="ij")
    c = np.c_[cx.ravel(), cy.ravel()]
    avg = cell_average(f, g, c, np.full_like(c, 0.5))
    assert avg.sum() * 1.0 == pytest.approx(f.sum() * g.cell_area, rel=1e-12)
    assert avg[0] == pytest.approx(f[:10, :10].mean(), rel=1e-12)
    # a rectangle cutting cells in half weights them by overlap
    a = cell_average(f, g, [[0.1, 0.15]], [[0.1, 0.15]])[0]
    assert a == pytest.approx(f[:2, :3].mean(), rel=1e-12)
