"""Half-space operators: closed forms vs point loads, FFT vs direct sums, periodic multipliers."""
import numpy as np
import pytest

from contact_bem import ElasticHalfSpace, Grid, influence_coefficients

E, NU = 198400.0, 0.3
ES = E / (2 * (1 - NU ** 2))
G = E / (2 * (1 + NU))


def test_far_field_equals_point_loads():
    # a tiny cell seen from far away acts as a point force (Boussinesq / Cerruti, both bodies)
    d = 1e-3
    x, y = 0.7, -0.4
    r = np.hypot(x, y)
    c = influence_coefficients(np.array(x), np.array(y), d, d, E, NU)
    F = d * d
    assert c["zz"] == pytest.approx(F / (np.pi * ES * r), rel=1e-6)
    assert c["xx"] == pytest.approx(F / (np.pi * G) * ((1 - NU) / r + NU * x * x / r ** 3), rel=1e-6)
    assert c["yy"] == pytest.approx(F / (np.pi * G) * ((1 - NU) / r + NU * y * y / r ** 3), rel=1e-6)
    assert c["xy"] == pytest.approx(F * NU / (np.pi * G) * x * y / r ** 3, rel=1e-6)


def test_centre_of_uniformly_loaded_square():
    # Love: centre deflection of a square 2a×2a under p: u = 4 p a ln(1+√2)·2/π /E*... per both bodies
    a = 0.5
    c = influence_coefficients(np.array(0.0), np.array(0.0), 2 * a, 2 * a, E, NU)
    assert c["zz"] == pytest.approx(8 * a * np.log(1 + np.sqrt(2)) / (np.pi * ES), rel=1e-12)


@pytest.mark.parametrize("periodic", [False])
def test_fft_equals_direct_sum(periodic):
    g = Grid((12, 9), (1.2, 0.8))
    hs = ElasticHalfSpace(g, E, NU, periodic=periodic)
    rng = np.random.default_rng(0)
    p = rng.random((2, 12, 9))
    q = rng.random((2, 2, 12, 9))
    X, Y = g.meshgrid()
    c = influence_coefficients(X[:, :, None, None] - X, Y[:, :, None, None] - Y, g.dx, g.dy, E, NU)
    u = np.einsum("ijkl,bkl->bij", c["zz"], p)
    assert np.abs(hs.displacement(p) - u).max() < 1e-12 * np.abs(u).max()
    ut = hs.tangential_displacement(q)
    ux = np.einsum("ijkl,bkl->bij", c["xx"], q[:, 0]) + np.einsum("ijkl,bkl->bij", c["xy"], q[:, 1])
    uy = np.einsum("ijkl,bkl->bij", c["xy"], q[:, 0]) + np.einsum("ijkl,bkl->bij", c["yy"], q[:, 1])
    assert np.abs(ut[:, 0] - ux).max() < 1e-12 * np.abs(ux).max()
    assert np.abs(ut[:, 1] - uy).max() < 1e-12 * np.abs(uy).max()


def test_periodic_sinusoid_response():
    # long-wave limit of the continuous half-space: p = cos(kx): u = 2/(E* k) cos(kx);
    # q_x = cos(kx): u_x = 2(1-ν)/(G k) cos; q_x = cos(ky): u_x = 2/(G k) cos (64 cells per wave)
    g = Grid((64, 32), (1.0, 0.5))
    hs = ElasticHalfSpace(g, E, NU, periodic=True)
    X, Y = g.meshgrid()
    k = 2 * np.pi / 1.0
    p = np.cos(k * X)
    assert np.abs(hs.displacement(p) - 2 / (ES * k) * p).max() < 2e-3 * 2 / (ES * k)
    q = np.zeros((2,) + g.shape)
    q[0] = np.cos(k * X)
    ref = 2 * (1 - NU) / (G * k)
    assert np.abs(hs.tangential_displacement(q)[0] - ref * q[0]).max() < 2e-3 * ref
    q[0] = np.cos(2 * k * Y)
    ref = 2 / (G * 2 * k)
    assert np.abs(hs.tangential_displacement(q)[0] - ref * q[0]).max() < 2e-3 * ref


def test_periodic_equals_image_sum_of_cell_coefficients():
    # zero-mean loads: the periodic operator is the lattice sum of the non-periodic cell
    # coefficients (up to a constant); symmetric image boxes converge like 1/M²
    g = Grid((6, 5), (1.2, 1.0))
    hs = ElasticHalfSpace(g, E, NU, periodic=True, alias_terms=8)
    rng = np.random.default_rng(1)
    p = rng.random(g.shape)
    p -= p.mean()
    q = rng.random((2,) + g.shape)
    q -= q.mean(axis=(1, 2), keepdims=True)
    X, Y = g.meshgrid()
    M = 40
    mx, my = np.meshgrid(np.arange(-M, M + 1) * g.size[0], np.arange(-M, M + 1) * g.size[1], indexing="ij")
    dX = (X[:, :, None, None] - X)[..., None] + mx.ravel()
    dY = (Y[:, :, None, None] - Y)[..., None] + my.ravel()
    c = {k: v.sum(axis=-1) for k, v in influence_coefficients(dX, dY, g.dx, g.dy, E, NU).items()}
    u = np.einsum("ijkl,kl->ij", c["zz"], p)
    up = hs.displacement(p)
    assert np.abs((u - u.mean()) - (up - up.mean())).max() < 2e-3 * np.abs(up).max()
    ux = np.einsum("ijkl,kl->ij", c["xx"], q[0]) + np.einsum("ijkl,kl->ij", c["xy"], q[1])
    upx = hs.tangential_displacement(q)[0]
    assert np.abs((ux - ux.mean()) - (upx - upx.mean())).max() < 2e-3 * np.abs(upx).max()


def test_moduli_and_validation():
    g = Grid((4, 4), (1.0, 1.0))
    hs = ElasticHalfSpace(g, E, NU)
    assert hs.e_star == pytest.approx(ES)
    assert hs.g_star == pytest.approx(G / (2 * (2 - NU)))
    with pytest.raises(ValueError, match="poisson"):
        ElasticHalfSpace(g, E, 0.5)
    with pytest.raises(ValueError, match="young"):
        ElasticHalfSpace(g, -1.0, 0.3)
    with pytest.raises(ValueError, match="pressure"):
        hs.displacement(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="traction"):
        hs.tangential_displacement(np.zeros((4, 4)))


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("shape", [(8, 8), (7, 7), (6, 9), (9, 4)])
@pytest.mark.parametrize("lead", [(), (3,), (2, 3)])
def test_pruned_transposed_fft_equals_plain_convolution(periodic, shape, lead):
    # the operator's FFTs (pruned padding, transposed spectra, 1/N folded into the kernels) give
    # the plain numpy convolution: zero-padded (DC-FFT) with the cell coefficients, or circular
    # with the periodic symbol; odd, even and non-square grids, any batch
    g = Grid(shape, (0.9, 1.3))
    hs = ElasticHalfSpace(g, E, NU, periodic=periodic)
    rng = np.random.default_rng(3)
    p = rng.random(lead + shape)
    q = rng.random(lead + (2,) + shape)
    nx, ny = shape
    if periodic:
        s = {k: getattr(hs, "_" + k).T / hs._inv_size for k in ("zz", "xx", "yy", "xy")}
        conv = lambda k, f: np.fft.irfft2(np.fft.rfft2(f) * s[k], s=shape)  # noqa: E731
    else:
        ix, iy = np.arange(2 * nx), np.arange(2 * ny)
        ox = np.where(ix < nx, ix, ix - 2 * nx) * g.dx
        oy = np.where(iy < ny, iy, iy - 2 * ny) * g.dy
        c = influence_coefficients(ox[:, None], oy[None, :], g.dx, g.dy, E, NU)
        s = {k: np.fft.rfft2(v) for k, v in c.items()}
        conv = lambda k, f: np.fft.irfft2(np.fft.rfft2(f, s=(2 * nx, 2 * ny)) * s[k],  # noqa: E731
                                          s=(2 * nx, 2 * ny))[..., :nx, :ny]
    u = conv("zz", p)
    assert hs.displacement(p).shape == p.shape
    assert np.abs(hs.displacement(p) - u).max() <= 1e-12 * np.abs(u).max()
    ux = conv("xx", q[..., 0, :, :]) + conv("xy", q[..., 1, :, :])
    uy = conv("xy", q[..., 0, :, :]) + conv("yy", q[..., 1, :, :])
    ut = hs.tangential_displacement(q)
    assert ut.shape == q.shape
    assert np.abs(ut[..., 0, :, :] - ux).max() <= 1e-12 * np.abs(ux).max()
    assert np.abs(ut[..., 1, :, :] - uy).max() <= 1e-12 * np.abs(uy).max()
    # a field and a batch of one share a plan; calls do not disturb each other's results
    assert np.array_equal(hs.displacement(p.reshape((-1,) + shape)[:1])[0], hs.displacement(p.reshape((-1,) + shape)[0]))
