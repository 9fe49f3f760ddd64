"""The joint's state in numbers: stuck modes per configuration, how the interface moves in them,
and the cycle-mean shear at the top level (summary.json and report.md read these)."""
from __future__ import annotations

import numpy as np

from ..model.interface_motion import decompose, relative_motion
from ..model.joint import LinearJoint, stuck_modes
from .data import ReportData
from .loops import loop_area
from .stiffness import configuration_joints


def stuck_modes_by_configuration(data: ReportData) -> dict[str, LinearJoint | None]:
    """Each configuration's stuck modes (v3 with its converged k_n, k_t); None where the model has
    no elastic mode among its lowest ten."""
    rm, out = data.rm, {}
    for name, joint in configuration_joints(data).items():
        try:
            out[name] = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint)
        except ValueError:
            out[name] = None
    return out


def interface_motions(data: ReportData, stuck: dict[str, LinearJoint | None]) -> dict[str, dict]:
    """Per configuration: the stuck mode's frequency (Hz), the shares of its interface motion
    (:class:`~fe_joint.model.interface_motion.InterfaceMotion`) and mean/rms of u_x."""
    rm, out = data.rm, {}
    for name, lin in stuck.items():
        if lin is None:
            continue
        im = decompose(relative_motion(lin.modes[:, lin.mode_index], rm.pair_dofs, rm.pair_frame),
                       rm.pair_xyz, rm.pair_area)
        out[name] = {"frequency_hz": float(lin.frequencies[lin.mode_index]), **im.as_dict(),
                     "mean_over_rms_ux": float(im.mean_over_rms[0])}
    return out


def joint_shear(data: ReportData) -> dict[str, dict]:
    """Per configuration at the top level's peak: cycle-mean Σ T_x (N; the bolt shank carries
    −Σ T_x), its share of μ × bolt force, the mean relative u_x (mm), the area of Σ T_x against the
    mean u_x (N·mm) and the dissipated energy (N·mm)."""
    mu_n = data.case.contact.mu * data.case.preload.bolt_force
    out = {}
    for cfg in data.configs:
        cr = data.curve(cfg, data.top)
        if cr is not None:
            shear = float(np.mean(cr.loop_T))
            out[cfg] = {"mean_shear_N": shear, "share_of_mu_bolt_force": shear / mu_n,
                        "mean_slip_mm": float(np.mean(cr.loop_u)),
                        "mean_slip_loop_area": loop_area(cr.loop_u, cr.loop_T),
                        "dissipated": cr.dissipated}
    return out
