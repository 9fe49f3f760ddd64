"""The numba warm-up (hbm.warmup, run by scripts/setup) exercises what a study's joints do, and
its plain repetition closes the same cycles as the Newton restarts."""
import numpy as np

from hbm import PARTLY_OPEN, STICK_SLIP
from hbm import warmup


def test_warmup_problem_slips_opens_and_repetition_matches_newton():
    hb, force, w0 = warmup.problem()
    res = hb.frf(0.8 * w0, 1.2 * w0, force, dof=0, max_points=60)
    sol = res.solutions[int(np.argmax(res.amplitude))]
    status = hb.element_results(sol).status
    # the kernels' paths: partial opening and stick-slip both present at the peak
    assert np.sum(status == PARTLY_OPEN) >= 2 and np.sum(status == STICK_SLIP) >= 2
    u = sol.contact @ hb.fourier.E.T
    idx = np.arange(hb.c.ne)
    T, N = hb.c.march(u, idx, newton=False)[:2]
    Tn, Nn = hb.c.march(u, idx)[:2]
    scale = hb.c.mu.max() * Nn.max()
    assert np.abs(T - Tn).max() <= 1e-7 * scale and np.abs(N - Nn).max() <= 1e-9 * Nn.max()
    # 2D slip: the tangential force turns (its direction is not constant over the cycle)
    ang = np.arctan2(Tn[:, 1], Tn[:, 0])
    slipping = status == STICK_SLIP
    assert np.ptp(np.unwrap(ang[slipping], axis=1), axis=1).max() > 0.5
    # the nonlinear mode softens with amplitude (friction), from the stuck frequency
    bb = hb.nonlinear_mode(0, (1e-6, 1e-3), dof=0, n_points=6, partial=True)
    assert bb.complete and bb.omega[-1] < 0.98 * bb.omega[0]
