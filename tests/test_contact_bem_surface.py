"""Gaussian surfaces: exact Rq, 10 % correlation-length convention, reproducibility."""
import numpy as np
import pytest

from contact_bem import Grid, gaussian_surface, surface_statistics


def test_rq_exact_and_zero_mean():
    g = Grid((128, 96), (10.0, 7.5))
    z = gaussian_surface(g, rq=0.01, corr_length=0.5, seed=4)
    assert z.shape == (128, 96)
    assert abs(z.mean()) < 1e-15
    assert np.sqrt(np.mean(z ** 2)) == pytest.approx(0.01, rel=1e-12)
    assert surface_statistics(g, z).rq == pytest.approx(0.01, rel=1e-12)


def test_acf_falls_to_ten_percent_at_corr_length():
    # λ = 8 cells so the ACF is read exactly at a grid lag; average over seeds (ACF is random)
    g = Grid((256, 256), (16.0, 16.0))
    vals = []
    for seed in range(6):
        st = surface_statistics(g, gaussian_surface(g, 0.005, 0.5, seed=seed))
        vals += [st.acf_x[8], st.acf_y[8]]
    assert np.mean(vals) == pytest.approx(0.10, abs=0.02)


def test_anisotropic_corr_lengths():
    g = Grid((256, 256), (16.0, 16.0))
    lx, ly = [], []
    for seed in range(4):
        st = surface_statistics(g, gaussian_surface(g, 0.005, (0.5, 1.0), seed=seed))
        lx.append(st.corr_length[0])
        ly.append(st.corr_length[1])
    assert np.mean(lx) == pytest.approx(0.5, rel=0.1)
    assert np.mean(ly) == pytest.approx(1.0, rel=0.1)


def test_same_seed_same_surface_other_seed_differs():
    g = Grid((64, 64), (4.0, 4.0))
    a = gaussian_surface(g, 0.002, 0.3, seed=7)
    b = gaussian_surface(g, 0.002, 0.3, seed=7)
    c = gaussian_surface(g, 0.002, 0.3, seed=8)
    assert np.array_equal(a, b)
    assert np.abs(a - c).max() > 1e-4


def test_psd_integrates_to_rq2():
    g = Grid((128, 128), (8.0, 8.0))
    z = gaussian_surface(g, 0.003, 0.4, seed=1)
    # Parseval with the continuous-FT normalisation of the 2D PSD
    psd2 = np.abs(np.fft.fft2(z)) ** 2 * g.cell_area ** 2 / g.area
    dq = (2 * np.pi / g.size[0]) * (2 * np.pi / g.size[1])
    assert psd2.sum() * dq / (2 * np.pi) ** 2 == pytest.approx(0.003 ** 2, rel=1e-10)
    st = surface_statistics(g, z)
    assert st.psd[0] == pytest.approx(0.0, abs=1e-20)  # zero mean → no DC power


@pytest.mark.parametrize("kw, name", [
    (dict(rq=-1.0, corr_length=0.5), "rq"),
    (dict(rq=float("nan"), corr_length=0.5), "rq"),
    (dict(rq=0.01, corr_length=0.0), "corr_length"),
    (dict(rq=0.01, corr_length=(0.5, -1)), "corr_length"),
])
def test_bad_input(kw, name):
    with pytest.raises(ValueError, match=name):
        gaussian_surface(Grid((16, 16), (1.0, 1.0)), **kw)


def test_grid_validation():
    with pytest.raises(ValueError, match="shape"):
        Grid((0, 4), (1.0, 1.0))
    with pytest.raises(ValueError, match="size"):
        Grid((4, 4), (1.0, float("inf")))
    g = Grid((4, 2), (2.0, 1.0), origin=(-1.0, 0.0))
    assert np.allclose(g.x, [-0.75, -0.25, 0.25, 0.75]) and g.cell_area == pytest.approx(0.25)
