"""The friction march repeats to the bit.

With numpy's complex products in the cycle matrix, the Newton-closed march gave different last
bits for the same inputs between calls, and a curve's continuation path differed between runs
of one job (issue 16, session 20; what chose numpy's path was not pinned down).
``friction._cmul`` rounds each real operation on its own.
"""
import numpy as np

from hbm import friction as fr


def _placed(a: np.ndarray, offset: int) -> np.ndarray:
    """A copy of ``a`` whose data start ``offset`` bytes past a 64-byte boundary."""
    buf = np.empty(a.nbytes + 128, dtype=np.uint8)
    start = (-buf.ctypes.data) % 64 + offset
    out = buf[start:start + a.nbytes].view(a.dtype).reshape(a.shape)
    out[...] = a
    return out


def test_complex_products_are_rounded_per_operation() -> None:
    """_cmul equals the real-arithmetic product exactly (each real multiply and add rounded
    once), and so does numpy's complex product up to an ulp (the FMA it may use)."""
    rng = np.random.default_rng(3)
    a = rng.standard_normal(1000) + 1j * rng.standard_normal(1000)
    b = rng.standard_normal(1000) + 1j * rng.standard_normal(1000)
    got = fr._cmul(a, b)
    re = a.real * b.real - a.imag * b.imag
    im = a.real * b.imag + a.imag * b.real
    assert np.array_equal(got.real, re) and np.array_equal(got.imag, im)
    assert np.allclose(got, a * b, rtol=1e-15, atol=1e-15)


def test_the_period_composition_does_not_depend_on_memory_placement() -> None:
    """_compose (the period's slope of a 2D stick-slip cycle, strided products over the steps)
    equals the maps composed one by one, and gives the same bits for operands placed at every
    8-byte offset (numpy's own product did too in this test: placement alone was not the cause)."""
    rng = np.random.default_rng(4)
    k, nt = 37, 32
    P = rng.standard_normal((k, nt)) + 1j * rng.standard_normal((k, nt))
    Q = 0.3 * (rng.standard_normal((k, nt)) + 1j * rng.standard_normal((k, nt)))
    outs = {off: fr._compose(_placed(P, off), _placed(Q, off)) for off in range(0, 64, 8)}
    ref = outs[0]
    for off, (p, q) in outs.items():
        assert np.array_equal(p, ref[0]) and np.array_equal(q, ref[1]), off
    # and it is the composition: later maps on the left, dv -> P dv + Q conj(dv)
    v = 0.7 - 0.2j
    x = v
    for j in range(nt):
        x = P[0, j] * x + Q[0, j] * np.conj(x)
    assert abs(ref[0][0] * v + ref[1][0] * np.conj(v) - x) <= 1e-10 * abs(x)


def test_the_newton_closed_march_is_repeatable() -> None:
    """The march with Newton-closed cycles (``FrictionContacts._forward``) on the same step tables,
    called again and again with other evaluations in between, ends on the same sliders to the
    bit. The case (tests/data/march_case.npz: 189 elements of a quick-preset joint at the top
    level, H = 1, 32 samples, 38 of them Newton-restarted) returned two different slider sets
    in 12 such calls before the cycle matrix's products were rounded per operation."""
    from pathlib import Path

    from hbm.fourier import Fourier
    d = np.load(Path(__file__).parent / "data" / "march_case.npz")
    ne = d["U"].shape[0]
    c = fr.FrictionContacts(np.arange(6 * ne).reshape(ne, 2, 3), kt=d["kt"], kn=d["kn"],
                            mu=d["mu"], n0=d["n0"], gap=d["gap"])
    four = Fourier(int(d["H"]), int(d["nt"]))
    U = d["U"]
    u = four.to_time(U)
    open_all, stuck_all, _, _ = c._classify(u, U, np.arange(ne))
    m = np.nonzero(~(open_all | stuck_all))[0]
    ends = set()
    for _ in range(12):
        c.evaluate(d["U_other"], four, False)          # other work in between
        tab = fr._StepTables(u[m], c.kt[m], c.mu[m], c.kn[m], c.n0[m], c.gap[m])
        final, _, _, _, jumped = c._forward(tab, True, c.max_cycles, False)
        ends.add(final.wend.tobytes())
    assert jumped.sum() > 0                           # Newton restarts happen in this case
    assert len(ends) == 1
