"""Friction damping at the FRF peaks as an energy-equivalent modal damping ratio (issue 13, item 1).

Definition: a linear viscous damper of modal ratio ζ on a mode φ (mass-normalized) that moves with
modal amplitude a at ω dissipates 2π ζ ω² a² per cycle (at resonance, ω = the mode's frequency).
So the friction energy per cycle E_fric at a peak corresponds to

    ζ_fric = E_fric / (2π ω² a²),   ζ_total = ζ_struct + ζ_fric,   η = 2 ζ_total (loss factor),

with ω the peak's angular frequency, φ the configuration's stuck mode of interest and a its
first-harmonic modal amplitude. The curves store the response amplitude X at the excitation DOF,
not the whole state, so a = X / |φ_e|: the projection φᵀMq₁ when the response is that one mode,
which at a resonance with ζ = 0.1 % it is (the other modes add an in-phase part of relative size
O(ζ), which changes |q₁| at second order).

Check (``zeta_from_amplitude``): at a peak the force works in quadrature with the response, so the
input per cycle is π F X = π F |φ_e| a and the energy balance π F |φ_e| a = 2π ζ_total ω² a² gives
ζ_total = F |φ_e| / (2 ω² a) independently of the friction energy; on the linear check curve it
is the structural ζ (the curves' own numbers, not the definition, are then tested).
"""
from __future__ import annotations

import numpy as np

from ..model.joint import JointModel, LinearJoint, stuck_modes
from ..study.artifacts import rq_label
from ..study.frf import CurveResult
from .data import ReportData
from .stiffness import configuration_joints, rq_joints

#: share of the clamping load (Σ N0) whose slip onset sets the "slip onset" amplitude
SLIP_SHARE = 0.1


def modal_amplitude(response_amplitude: float, phi_e: float) -> float:
    """First-harmonic modal amplitude a = X / |φ_e| (mm·√t for a mass-normalized φ, 1/√t)."""
    return float(response_amplitude / abs(phi_e))


def friction_damping_ratio(energy: float, omega: float, a: float) -> float:
    """ζ_fric = E / (2π ω² a²): E N·mm per cycle, ω rad/s, a the modal amplitude."""
    return float(energy / (2 * np.pi * omega ** 2 * a ** 2))


def amplitude_damping_ratio(force: float, phi_e: float, omega: float, a: float) -> float:
    """ζ_total from the peak's energy balance in quadrature: F |φ_e| / (2 ω² a)."""
    return float(force * abs(phi_e) / (2 * omega ** 2 * a))


def curve_damping(cr: CurveResult, lin: LinearJoint, dof: int, zeta_struct: float) -> dict:
    """The damping numbers of one curve at its peak.

    Args:
        cr: the curve (peak frequency, response amplitude, friction energy, level).
        lin: the stuck modes of the curve's joint (mode of interest at ``lin.mode_index``).
        dof: the excitation (= response) DOF.
        zeta_struct: the structural modal damping ratio.
    Returns:
        zeta_fric, zeta_total (= ζ_struct + ζ_fric), loss_factor (2 ζ_total), zeta_from_amplitude
        (the check), modal_amplitude.
    """
    phi_e = lin.modes[dof, lin.mode_index]
    w = 2 * np.pi * cr.peak_hz
    a = modal_amplitude(cr.peak_amplitude, phi_e)
    zf = friction_damping_ratio(cr.dissipated, w, a)
    return {"zeta_fric": zf, "zeta_total": zeta_struct + zf, "loss_factor": 2 * (zeta_struct + zf),
            "zeta_from_amplitude": amplitude_damping_ratio(cr.level, phi_e, w, a),
            "modal_amplitude": a}


def slip_onset_amplitude(rm, joint: JointModel, lin: LinearJoint, mu: float,
                         share: float = SLIP_SHARE) -> float:
    """Response amplitude (mm) at which ``share`` of the clamping load would slip in the stuck mode.

    In the stuck mode φ an element carries T = k_t A |u_t| per unit modal amplitude and slips once
    T a ≥ μ N0; ordered by that onset, the elements holding the first ``share`` of Σ N0 slip by
    a response amplitude X = a |φ_e|. A linear estimate (friction caps the real response), used
    only to compare how early each joint starts to slip.
    """
    phi = lin.modes[:, lin.mode_index]
    pd = np.asarray(rm.pair_dofs)
    ut = phi[pd[:, 0, :2]] - phi[pd[:, 1, :2]]
    t = joint.kt * joint.area * np.hypot(ut[:, 0], ut[:, 1])
    c = (joint.n0 > 0) & (t > 0)
    x = mu * joint.n0[c] / t[c] * abs(phi[rm.excitation_dof])
    order = np.argsort(x)
    cum = np.cumsum(joint.n0[c][order]) / joint.n0[c].sum()
    return float(x[order][min(np.searchsorted(cum, share), len(order) - 1)])


def _joint_of_curve(key, joints: dict, rqj: dict, v_rq: float):
    """The JointModel behind a curve: its configuration's, v3 of another Rq from the sweep, the
    baseline for the linear check."""
    if key.level_index is None:
        return "baseline", joints["baseline"]
    if key.rq_um is not None and key.rq_um != v_rq:
        return f"v3-rq{key.rq_um}", rqj[key.rq_um]
    return key.config, joints[key.config]


def damping_by_curve(data: ReportData, stuck: dict[str, LinearJoint | None]) -> dict:
    """{curve name: curve_damping(...)} for every curve whose joint has a stuck mode."""
    rm, zs = data.rm, data.rm.damping_ratio
    joints, rqj = configuration_joints(data), rq_joints(data)
    modes = dict(stuck)
    out = {}
    for key, cr in sorted(data.curves.items(), key=lambda kv: kv[0].name):
        name, joint = _joint_of_curve(key, joints, rqj, data.v_rq)
        if name not in modes:
            try:
                modes[name] = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint)
            except ValueError:
                modes[name] = None
        if modes[name] is not None:
            out[key.name] = curve_damping(cr, modes[name], rm.excitation_dof, zs)
    return out


def slip_onsets(data: ReportData, stuck: dict[str, LinearJoint | None]) -> dict:
    """Slip-onset response amplitude (mm) per configuration and per Rq of the sweep (its v3 joint,
    or v2 when the fixed point is missing)."""
    rm, mu = data.rm, data.case.contact.mu
    out = {"configurations": {}, "rq": {}}
    for name, joint in configuration_joints(data).items():
        if stuck.get(name) is not None:
            out["configurations"][name] = slip_onset_amplitude(rm, joint, stuck[name], mu)
    for rq, joint in rq_joints(data).items():
        try:
            lin = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint)
        except ValueError:      # no elastic mode among the lowest: nothing to compare
            continue
        out["rq"][rq_label(rq)] = slip_onset_amplitude(rm, joint, lin, mu)
    return out
