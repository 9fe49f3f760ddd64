"""Contact-stage variants of the Rq sweep, without FRFs (issue 13, items 6 and 7).

* **Seed statistics**: ``roughness.seeds`` surface realizations per Rq (seeds ``seed`` …
  ``seed + seeds − 1``; the first is the study's own surface). Per realization: the contact
  fraction (over the usable and over the whole overlap), the v2 joint's k_n,eq and k_t,eq
  (patch k_n at N0, Mindlin k_t) and its stuck breathing-mode frequency; per Rq their mean,
  sample standard deviation, min and max.
* **Hardness cap**: the sweep's surfaces (seed ``seed``) solved again with the pressure capped at
  ``roughness.material_hardness`` (perfectly plastic asperities; the patches capped too, k_n the
  unloading stiffness of the flattened contact), the same numbers beside the study's own.

Both are cheap (one global solve, one batch of patches and one shifted eigenproblem per
realization) and written to ``contact/seeds.json`` and ``contact/hardness.json``.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ..model.joint import JointModel, stuck_modes, stuck_stiffness
from .artifacts import rq_label
from .configurations import joint_v2
from .contact import InterfaceSetup, SurfaceContact, contact_area, rough_contact
from .queue import map_ranks

#: the per-realization numbers the variants report (keys of :func:`joint_numbers`)
NUMBERS = ("contact_fraction", "contact_fraction_overlap", "kn_eq", "kt_eq", "stuck_hz",
           "peak_pressure", "capped_share", "loaded_elements")


def stuck_frequency(K: np.ndarray, M: np.ndarray, pair_dofs: np.ndarray, joint: JointModel,
                    f_guess: float) -> float:
    """The stuck breathing-mode frequency (Hz) by one shift-and-invert solve near ``f_guess``.

    The same mode as :func:`~fe_joint.model.joint.stuck_modes` (the first elastic one) at a
    fraction of its cost (one LU instead of a dense tridiagonalisation): the eigenvalue nearest
    σ = (2π f_guess)² is the breathing mode's as long as f_guess is nearer to it than to the
    rigid-body modes (0) and the next elastic mode (on the resonator 245 vs 544 Hz; the
    realizations move it by < 1 %). One eigenvalue, not three: three of them included part of
    the six-fold rigid-body cluster, and ARPACK took ≈ 200 iterations to resolve it (9.3 of the
    contact stage's 23 s, serially; issue 16, session 15).

    Args:
        K, M: (n, n) reduced stiffness (N/mm) without the joint and mass (t).
        pair_dofs: (ne, 2, 3) reduced DOFs of the pairs.
        joint: the configuration (its loaded elements become springs).
        f_guess: Hz, a nearby frequency (e.g. the first realization's, from ``stuck_modes``).
    Returns:
        the frequency of the lowest elastic mode among those nearest the shift, Hz.
    """
    Ks = stuck_stiffness(K, pair_dofs, joint)
    sigma = (2 * np.pi * f_guess) ** 2
    lu = sla.lu_factor(Ks - sigma * M)
    w2 = _inverse_iteration(Ks, M, lu)
    f = float(np.sqrt(max(w2, 0.0)) / (2 * np.pi))
    if not f > 1e-2 * f_guess:
        raise ValueError("stuck joint: no elastic mode near the shift")
    return f


#: inverse iterations of :func:`stuck_frequency` at most, and the relative change of the
#: Rayleigh quotient that ends them (the quotient's error is then about the convergence factor
#: squared times it, < 1e-15) ...
INVERSE_ITERATIONS = 60
INVERSE_TOL = 1e-12
#: ... or, with stiff springs (the layer caps of 1000 k_bulk), where round-off in the quotient
#: is larger than that, a change below this that has stopped falling for 3 iterations
INVERSE_FLOOR = 1e-9


def _inverse_iteration(K: np.ndarray, M: np.ndarray, lu) -> float:
    """The eigenvalue of (K, M) nearest the shift of ``lu`` (an LU of K - sigma M), (rad/s)²:
    inverse iteration from a fixed start (all ones), its Rayleigh quotient after each step.

    It converges by |lambda - sigma| / |lambda' - sigma| per step (lambda' the next nearest): on
    the resonator about 0.02 (the breathing mode within 1 % of the shift, the rigid modes at 0),
    so 5-8 solves of 2 n² each, where ARPACK's Lanczos (k = 1, ncv 20) took 21 products and
    its own set-up: 0.34 → 0.23 s per realization at 2198 DOFs, the LU and the assembly the rest
    (issue 16, session 24). The quotient's error is the square of the vector's. Raises
    ValueError if it has not settled after INVERSE_ITERATIONS.
    """
    Mx = M @ np.ones(K.shape[0])
    lam, least, flat = np.inf, np.inf, 0
    for _ in range(INVERSE_ITERATIONS):
        x = sla.lu_solve(lu, Mx, check_finite=False)
        x /= np.linalg.norm(x)
        Mx = M @ x
        new = float(x @ (K @ x)) / float(x @ Mx)
        change = abs(new - lam) / abs(new)
        if change <= INVERSE_TOL:
            return new
        flat = flat + 1 if change >= least else 0
        least = min(least, change)
        if flat >= 3 and least <= INVERSE_FLOOR:
            return new
        lam = new
    raise ValueError("stuck joint: the inverse iteration near the shift did not settle")


def joint_numbers(setup: InterfaceSetup, rm, sc: SurfaceContact, hardness: float,
                  f_guess: float | None) -> dict:
    """The numbers of one realization's v2 joint.

    Args:
        setup: the interface (grid, mask, smooth pressure).
        rm: the ReducedModel (K, M, pair DOFs).
        sc: the realization's rough contact (its pressure, N0, k_n).
        hardness: the pressure cap of the solve, MPa (0: none; sets ``capped_share``).
        f_guess: Hz, shift of :func:`stuck_frequency`; None: the exact ``stuck_modes``.
    Returns:
        contact fractions (usable, overlap), kn_eq / kt_eq N/mm³, stuck_hz Hz, peak_pressure MPa,
        capped_share (the contact area's share at the cap), loaded_elements.
    """
    ca = contact_area(setup.ig.mask, setup.ig.cell_area, sc.pressure, setup.p_s)
    fr = ca.fractions()
    joint = joint_v2(setup, sc)
    if f_guess is None:
        f = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint).frequency
    else:
        f = stuck_frequency(rm.K, rm.M, rm.pair_dofs, joint, f_guess)
    c = sc.pressure > 0
    capped = float(np.sum(c & (sc.pressure >= hardness * (1 - 1e-9))) / max(c.sum(), 1)) if hardness > 0 else 0.0
    return {"contact_fraction": fr["usable"], "contact_fraction_overlap": fr["overlap"],
            "kn_eq": joint.k_eq("kn"), "kt_eq": joint.k_eq("kt"), "stuck_hz": f,
            "peak_pressure": float(sc.pressure.max()), "capped_share": capped,
            "loaded_elements": int(np.sum(sc.n0 > 0))}


def statistics(values) -> dict:
    """mean, sample standard deviation (0 for one value), min, max and count of ``values``."""
    v = np.asarray(values, float)
    return {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
            "min": float(v.min()), "max": float(v.max()), "n": int(len(v))}


def own_numbers(setup: InterfaceSetup, rm, roughness, surfaces: dict[float, SurfaceContact],
                comm=None) -> dict:
    """:func:`joint_numbers` of the study's own surfaces, {rq: numbers} (one per rank at a
    time): the first seed of :func:`seed_study` and the uncapped side of :func:`hardness_study`."""
    rqs = sorted(surfaces)
    rows = map_ranks(lambda rq: joint_numbers(setup, rm, surfaces[rq], roughness.hardness, None),
                     rqs, comm)
    return dict(zip(rqs, rows))


def seed_study(setup: InterfaceSetup, rm, roughness, surfaces: dict[float, SurfaceContact],
               comm=None, own: dict | None = None) -> dict:
    """Several surface realizations per Rq of the sweep: per-seed numbers and their statistics.

    Args:
        setup: the interface.
        rm: the ReducedModel.
        roughness: the case's Roughness section (rq_um, v_rq_um, corr_length, seed, seeds, hardness).
        surfaces: the study's own surfaces (seed ``roughness.seed``), reused as the first seed.
        comm: MPI communicator (the realizations dealt to the ranks) or None.
        own: :func:`own_numbers` when already computed (else computed here).
    Returns:
        {rq label: {"rq_um", "seeds": [...], "per_seed": {number: [...]}, "stats": {number: stats}}}.
    """
    rqs = sorted(surfaces)
    seeds = [roughness.seed + i for i in range(roughness.seeds)]
    # each realization on one rank (a BEM solve and a stuck frequency: 20 of them took 14 s on
    # both ranks alike); the study's own surface first, whose exact frequency is the others' shift
    own = own_numbers(setup, rm, roughness, surfaces, comm) if own is None else own
    first = [own[rq] for rq in rqs]
    f0 = {rq: row["stuck_hz"] for rq, row in zip(rqs, first)}

    def other(item):
        rq, s = item
        sc = rough_contact(setup, rq, roughness.corr_length, s, hardness=roughness.hardness)
        return joint_numbers(setup, rm, sc, roughness.hardness, f0[rq])
    rest = iter(map_ranks(other, [(rq, s) for rq in rqs for s in seeds[1:]], comm))
    out = {}
    for rq, row in zip(rqs, first):
        rows = [row] + [next(rest) for _ in seeds[1:]]
        per = {k: [r[k] for r in rows] for k in NUMBERS}
        out[rq_label(rq)] = {"rq_um": rq, "seeds": seeds, "per_seed": per,
                             "stats": {k: statistics(v) for k, v in per.items()}}
    return out


def hardness_study(setup: InterfaceSetup, rm, roughness, surfaces: dict[float, SurfaceContact],
                   comm=None, own: dict | None = None) -> dict:
    """The sweep's surfaces with the pressure capped at ``roughness.material_hardness``.

    Args:
        own: :func:`own_numbers` when already computed (the stage shares those of
            :func:`seed_study`: the same four joints' stuck frequencies were solved twice).
    Returns:
        {} when the hardness is 0; else {"hardness_MPa": H, "surfaces": {rq label: {"rq_um",
        "study": numbers of the study's own solve, "capped": numbers with the cap}}}.
    """
    H = roughness.material_hardness
    if H <= 0:
        return {}
    own = own_numbers(setup, rm, roughness, surfaces, comm) if own is None else own

    def one(rq):
        sc = rough_contact(setup, rq, roughness.corr_length, roughness.seed, hardness=H)
        return {"rq_um": rq, "study": own[rq], "capped": joint_numbers(setup, rm, sc, H, own[rq]["stuck_hz"])}
    rqs = sorted(surfaces)
    return {"hardness_MPa": H, "surfaces": {rq_label(rq): r for rq, r in zip(rqs, map_ranks(one, rqs, comm))}}


def write_json(path, data: dict) -> None:
    """Write ``data`` as indented JSON atomically (rank 0)."""
    import json
    import os
    tmp = str(path) + ".tmp"
    with open(tmp, "w") as f:
        json.dump(data, f, indent=1)
    os.replace(tmp, path)


def read_json(path) -> dict | None:
    """What :func:`write_json` wrote, None when the file is missing (runs before the variants)."""
    import json
    from pathlib import Path
    p = Path(path)
    return json.loads(p.read_text()) if p.exists() else None
