"""Closed-form contact solutions used as independent references (Johnson, Contact Mechanics, 1985).

All for two identical elastic bodies with composite moduli E* = E/(2(1-ν²)) and
G* = G/(2(2-ν)) (``ElasticHalfSpace.e_star`` / ``.g_star``). Units: N, mm, MPa.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import positive_scalar


def composite_moduli(young: float, poisson: float) -> tuple[float, float]:
    """(E*, G*) in MPa of two identical bodies: E/(2(1-ν²)), G/(2(2-ν)) with G = E/(2(1+ν))."""
    g = young / (2.0 * (1.0 + poisson))
    return young / (2.0 * (1.0 - poisson ** 2)), g / (2.0 * (2.0 - poisson))


@dataclass
class Hertz:
    """Hertz sphere-on-flat contact.

    Attributes:
        radius: contact radius a (mm).
        peak_pressure: p0 (MPa).
        approach: rigid approach δ = a²/R (mm).
        stiffness: dP/dδ = 2 a E* (N/mm).
    """

    radius: float
    peak_pressure: float
    approach: float
    stiffness: float

    def pressure(self, r) -> np.ndarray:
        """Pressure p0·sqrt(1 - r²/a²) (MPa) at radii r (mm), 0 outside."""
        r = np.asarray(r, dtype=float)
        return self.peak_pressure * np.sqrt(np.clip(1.0 - (r / self.radius) ** 2, 0.0, None))


def hertz(load: float, sphere_radius: float, e_star: float) -> Hertz:
    """Hertz solution for a sphere of radius R pressed on a flat with load P.

    Args:
        load: P in N (> 0). sphere_radius: R in mm (> 0). e_star: composite modulus in MPa.

    Returns:
        Hertz (a = (3PR/(4E*))^(1/3), p0 = 3P/(2πa²), δ = a²/R).
    """
    P = positive_scalar("load", load)
    R = positive_scalar("sphere_radius", sphere_radius)
    E = positive_scalar("e_star", e_star)
    a = (3.0 * P * R / (4.0 * E)) ** (1.0 / 3.0)
    return Hertz(a, 3.0 * P / (2.0 * np.pi * a * a), a * a / R, 2.0 * a * E)


def cattaneo_stick_radius(q: float, mu: float, p: float, a: float) -> float:
    """Cattaneo–Mindlin stick radius c = a (1 - Q/μP)^(1/3) (mm) for 0 ≤ Q < μP."""
    return a * (1.0 - abs(q) / (mu * p)) ** (1.0 / 3.0)


def mindlin_displacement(q, mu: float, p: float, a: float, g_star: float):
    """Tangential rigid displacement on virgin loading (mm), two identical bodies:

    δ(Q) = 3μP/(16 G* a) · [1 - (1 - Q/μP)^(2/3)] (odd in Q).
    """
    q = np.asarray(q, dtype=float)
    return np.sign(q) * 3.0 * mu * p / (16.0 * g_star * a) * (1.0 - (1.0 - np.abs(q) / (mu * p)) ** (2.0 / 3.0))


def mindlin_deresiewicz(q, q_star: float, mu: float, p: float, a: float, g_star: float,
                        branch: str = "unloading"):
    """Mindlin–Deresiewicz hysteresis loop between ±Q* (constant normal load).

    unloading (from +Q* down): δ = δ(Q*) − 2 δ((Q* − Q)/2);
    reloading (from −Q* up):   δ = −δ(Q*) + 2 δ((Q* + Q)/2), with δ(·) of ``mindlin_displacement``.

    Returns:
        δ in mm at the forces q (N).
    """
    q = np.asarray(q, dtype=float)
    d = lambda x: mindlin_displacement(x, mu, p, a, g_star)  # noqa: E731
    if branch == "unloading":
        return d(q_star) - 2.0 * d((q_star - q) / 2.0)
    if branch == "reloading":
        return -d(q_star) + 2.0 * d((q_star + q) / 2.0)
    raise ValueError(f"branch: must be 'unloading' or 'reloading', got {branch!r}")


def mindlin_dissipation(q_star: float, mu: float, p: float, a: float, g_star: float) -> float:
    """Energy dissipated per Mindlin–Deresiewicz cycle ±Q* (N·mm), two identical bodies.

    W = 9 (μP)² /(10 G* a) · [1 − (1 − Q*/μP)^(5/3) − (5Q*/(6μP)) (1 + (1 − Q*/μP)^(2/3))]
    (the area between the two branches of ``mindlin_deresiewicz``; Johnson eq. 7.60).
    """
    r = q_star / (mu * p)
    return 9.0 * (mu * p) ** 2 / (10.0 * g_star * a) * (
        1.0 - (1.0 - r) ** (5.0 / 3.0) - 5.0 * r / 6.0 * (1.0 + (1.0 - r) ** (2.0 / 3.0)))


def mindlin_initial_stiffness(a: float, g_star: float) -> float:
    """Tangential stiffness of a stuck circle of radius a: 8 G* a (N/mm)."""
    return 8.0 * g_star * a


def mindlin_secant_stiffness(q_star: float, mu: float, p: float, a: float, g_star: float) -> float:
    """Secant 2Q*/Δδ of the Mindlin–Deresiewicz loop ±Q* = Q*/δ(Q*) (N/mm), ``mindlin_displacement``."""
    return q_star / float(mindlin_displacement(q_star, mu, p, a, g_star))


def mindlin_energy_stiffness(q_star: float, mu: float, p: float, a: float, g_star: float) -> float:
    """The Jenkins element through the Mindlin–Deresiewicz loop's tips (±Q*, ±δ(Q*)) with the loop's
    area W (``mindlin_dissipation``): W = 4Q*(δ(Q*) − Q*/k), so k = Q*/(δ(Q*) − W/(4Q*)) (N/mm)."""
    d = float(mindlin_displacement(q_star, mu, p, a, g_star))
    return q_star / (d - mindlin_dissipation(q_star, mu, p, a, g_star) / (4.0 * q_star))


def flat_punch_stiffness(a: float, e_star: float) -> float:
    """Normal stiffness of a rigid circular flat punch of radius a: 2 a E* (N/mm)."""
    return 2.0 * a * e_star


def westergaard_full_contact_pressure(amplitude: float, wavelength: float, e_star: float) -> float:
    """Mean pressure p* = π E* Δ/λ (MPa) that closes a wavy gap Δ(1 - cos 2πx/λ) completely."""
    return np.pi * e_star * amplitude / wavelength


def westergaard_contact_width(mean_pressure: float, amplitude: float, wavelength: float,
                              e_star: float) -> float:
    """Contact width 2a (mm) per wavelength of the Westergaard wavy contact: p̄ = p* sin²(πa/λ)."""
    ps = westergaard_full_contact_pressure(amplitude, wavelength, e_star)
    if mean_pressure >= ps:
        return float(wavelength)
    return float(2.0 * wavelength / np.pi * np.arcsin(np.sqrt(mean_pressure / ps)))


def westergaard_pressure(x, mean_pressure: float, amplitude: float, wavelength: float, e_star: float):
    """Westergaard pressure (MPa) at x (mm, contact centred at x = 0), partial or full contact."""
    x = np.asarray(x, dtype=float)
    ps = westergaard_full_contact_pressure(amplitude, wavelength, e_star)
    if mean_pressure >= ps:
        return mean_pressure + ps * np.cos(2 * np.pi * x / wavelength)
    a = 0.5 * westergaard_contact_width(mean_pressure, amplitude, wavelength, e_star)
    c = np.cos(np.pi * x / wavelength)
    sa = np.sin(np.pi * a / wavelength) ** 2
    val = np.clip(sa - np.sin(np.pi * x / wavelength) ** 2, 0.0, None)
    return 2.0 * ps * np.abs(c) * np.sqrt(val) * (np.abs(np.mod(x + wavelength / 2, wavelength) - wavelength / 2) < a)
