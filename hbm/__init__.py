"""hbm — multiharmonic balance with 3D friction elements (numpy/scipy only).

Public API (docs/design.md, "Public API")::

    from hbm import LinearStructure, FrictionContacts, HarmonicBalance
    s = LinearStructure(M, K, C)                 # or damping_ratio=0.001
    c = FrictionContacts(dofs, kt=, kn=, mu=, n0=, gap=)
    hb = HarmonicBalance(s, c, harmonics=3, samples=128)
    sol = hb.solve(omega, force); sol.coefficients; sol.amplitude(dof)
    frf = hb.frf(omega_start, omega_end, force, dof=d); frf.omega, frf.amplitude, frf.stable
    frf = hb.frf(..., settings=ContinuationSettings(max_points=500, max_domega=0.1))  # or the same
                                                 # fields as keywords (max_points=500, ...), not both
    er = hb.element_results(sol)                 # status, energy, mean_normal, u_t, T, N
    bb = hb.nonlinear_mode(mode=0, amplitudes=(a0, a1), dof=d, n_points=40)   # EPMC backbone
    bb.omega, bb.zeta, bb.displacement_amplitude, bb.friction_energy, bb.element_status
    sr = synthesize(bb, force); sr.peak_omega, sr.peak_amplitude, sr.omega_low, sr.omega_high
                                                 # mode + off-resonant background (bb.background)
"""
from .errors import ConvergenceError, CycleNotClosed
from .fourier import Fourier
from .friction import FrictionContacts, STUCK, STICK_SLIP, GROSS_SLIP, PARTLY_OPEN, OPEN
from .structure import LinearStructure
from .harmonic_balance import HarmonicBalance, Solution, ElementResults
from .continuation import ContinuationSettings, FRFResult
from .nonlinear_mode import Backbone, LinearBackground
from .synthesis import SynthesizedResponse, synthesize

__all__ = ["ConvergenceError", "CycleNotClosed", "Fourier", "FrictionContacts", "LinearStructure", "HarmonicBalance",
           "Solution", "ElementResults", "FRFResult", "ContinuationSettings", "STUCK", "STICK_SLIP",
           "GROSS_SLIP", "PARTLY_OPEN", "OPEN", "Backbone", "LinearBackground", "SynthesizedResponse",
           "synthesize"]
