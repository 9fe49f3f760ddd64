#!/usr/bin/env python3
"""Demo 5 — the multiscale loop: FE preload → rough BEM → friction elements → HBM → BEM loops.

The paper's idea in one page: the FE model gives the smooth contact pressure; the BEM solver puts
the roughness back (the equivalent macro gap h0 = g_s − K*p_s − z) and gives every friction
element its normal load and contact stiffness; the harmonic balance gives the loads each element
carries over a vibration cycle; and those loads give, on the same rough patch, the tangential
stiffness (slope of the hysteresis loop at load reversal), which goes back into the dynamics.
To stay under a minute the dynamics is solved at one frequency near resonance instead of a sweep
(``fe-joint run`` does the sweeps).

Run: ``.venv/bin/python scripts/demo_multiscale.py [--rq 10]``
"""
# %% [markdown]
# ## 1. FE: preload and reduced model (coarse mesh)
# %%
import argparse
import tempfile

import numpy as np

from fe_joint.study import contact as ms
from fe_joint.study.configurations import joint_v2
from fe_joint.case import load_case
from fe_joint.study.frf import contacts, structure
from fe_joint.model.joint import JointModel, stuck_modes
from fe_joint.fe.reduction import build_reduced_model
from hbm import HarmonicBalance

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--rq", type=float, default=10.0, help="composite RMS roughness, µm")
args = ap.parse_args()
case = load_case(preset="quick")
rm = build_reduced_model(case.geometry, case.material,
                         case.preload.bolt_force, case.reduction.damping_ratio,
                         case.reduction.cutoff_hz, out_dir=tempfile.mkdtemp(), n_full_elastic=0)
print(f"reduced model: {rm.n_dofs} DOFs, {rm.n_pairs} pairs")

# %% [markdown]
# ## 2. BEM: from the smooth FE pressure to the rough contact
# With z = 0 the equivalent macro gap must give back the FE pressure exactly.
# %%
setup = ms.interface_setup(rm, case.geometry, case.material, case.roughness)
flat = ms.rough_contact(setup, 0.0, 0.5, 0, stiffness=False, tol=1e-12)
coupling = np.abs(flat.pressure - setup.p_s).max() / setup.p_s.max()
sc = ms.rough_contact(setup, args.rq, case.roughness.corr_length, case.roughness.seed)
print(f"Rq = {args.rq:g} µm: real contact {100 * sc.contact_fraction:.2f} % of the lap; "
      f"{np.sum(sc.n0 > 0)} of {rm.n_pairs} elements loaded; k_n mean {sc.kn.mean():.3g} N/mm³")

# %% [markdown]
# ## 3. Dynamics with k_t by Mindlin (the paper's 'v2')
# %%
joint = joint_v2(setup, sc)
f_lin = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint).frequency
level = 20.0                                    # N on mass A, in x
force = np.zeros(rm.n_dofs)
force[rm.excitation_dof] = level
omega = 2 * np.pi * 0.995 * f_lin


def response(j: JointModel):
    c, _ = contacts(rm, j, case.contact.mu)
    hb = HarmonicBalance(structure(rm), c, harmonics=1, samples=64)
    sol = hb.solve(omega, force)
    return hb, sol


hb, sol = response(joint)
er = hb.element_results(sol)
print(f"v2 at {omega / 2 / np.pi:.2f} Hz: amplitude {1e3 * sol.amplitude(rm.response_dof):.3f} µm, "
      f"{np.sum(er.status > 0)} elements slip or open")

# %% [markdown]
# ## 4. Back to the BEM: k_t from each element's hysteresis loop ('v3', one pass)
# %%
act = np.nonzero((joint.kn > 0) & (joint.kt > 0))[0]
n_mean = np.zeros(rm.n_pairs)
q_amp = np.zeros((rm.n_pairs, 2))
n_mean[act] = np.maximum(er.mean_normal, 0.0)
q_amp[act] = 0.5 * (er.T.max(axis=2) - er.T.min(axis=2))
kn, kt = ms.element_loop_stiffness(setup, sc.z, n_mean, q_amp, case.contact.mu)
loaded = sc.n0 > 0
v3 = JointModel("v3", n0=sc.n0, gap=sc.gap_el, kn=np.where(loaded, kn, 0), kt=np.where(loaded, kt, 0),
                area=setup.area, rq_um=args.rq)
_, sol3 = response(v3)
print(f"k_t,eq: Mindlin {joint.k_eq('kt'):.3g} → loops {v3.k_eq('kt'):.3g} N/mm³; amplitude "
      f"{1e3 * sol3.amplitude(rm.response_dof):.3f} µm")
# the number the test checks: zero roughness reproduces the FE pressure
print(f"RESULT coupling_error = {coupling:.3e}")
