"""Nonlinear modes (EPMC backbones) of the study's joints, their synthesized peaks, and their files.

One backbone per fixed configuration and one per v3 surface (at its converged k_n, k_t): the
mode of interest (the stuck mode the FRF bands are built on, ``f_lin``) continued in amplitude
from 0.3 × its slip onset up to 1.2 × the largest peak amplitude the study's forced curves of that
joint reach (scaled to the top level where only a lower level was swept). The HarmonicBalance is
built exactly as the FRFs' (``frf._setup``), so the two compare one to one. From each backbone the
forced peak at every study level is synthesized (SNMS with the off-resonant background,
``hbm.synthesize``).

A :class:`BackboneResult` is saved as ``dynamics/backbones/<name>.npz`` (plain arrays; the
synthesis needs only the shape and the background at the excitation and response DOFs, which are
kept) and exported as ``<name>.csv`` in the fields tmdsimpy publishes its backbones in
(``TMDSIMPY_FIELDS``).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from hbm import synthesize
from hbm.nonlinear_mode import Backbone, LinearBackground, NonlinearModeProblem

from .artifacts import BackboneKey, check_files, digest, save_dataclass_npz
from .frf import OPEN, SWEEP_TOLERANCES, SweepSettings, _setup

#: bump when a backbone's result changes for the same inputs (its cache key changes with it)
BACKBONE_VERSION = "1"
#: backbone points (log-spaced modal amplitudes; the slip onset is added as one more)
BACKBONE_POINTS = 35
#: first amplitude, relative to the slip onset of the linear mode
START_OF_ONSET = 0.3
#: last amplitude, relative to the largest forced peak amplitude at the top level
END_OF_TOP_PEAK = 1.2
#: the CSV export's columns, named as tmdsimpy publishes its Brake–Reuß backbones
TMDSIMPY_FIELDS = ("modal_amplitude", "displacement_amplitude", "frequency_rad_per_s",
                   "damping_factor_frac_crit")


@dataclass
class BackboneResult:
    """One joint's backbone, the peaks it predicts at the study's levels, and its cost.

    Arrays over the p backbone points unless noted; amplitudes of the first harmonic.

    Attributes:
        config, rq_um: the joint (``BackboneKey`` fields; rq_um NaN for the fixed configurations).
        mode: elastic mode index of the linear base (the one nearest ``f_lin_hz``).
        f_lin_hz: the study's stuck frequency of the joint, Hz.
        linear_hz, linear_zeta: the linear base mode's frequency (Hz) and damping ratio.
        onset_modal: modal amplitude of the first steady slip / separation, mm·t^0.5.
        modal_amplitude: imposed coordinate of the mass-normalized linear mode, mm·t^0.5.
        mass_amplitude: ||eta_1||, tmdsimpy's "modal amplitude", mm·t^0.5.
        displacement_amplitude: at the response DOF, mm; displacement: its complex phasor, mm.
        omega: rad/s; xi: EPMC damping, 1/s; zeta: xi / (2 omega); zeta_energy: from the
            dissipated energy per cycle; xi_viscous: viscous part of xi, 1/s.
        friction_energy, viscous_energy, kinetic: N·mm per cycle / kinetic measure, N·mm.
        element_status, element_energy: (p, ne) over all pairs (OPEN and 0 for unmodelled ones).
        shape: (p, 2) mass-normalized first-harmonic shape at (excitation, response) DOF.
        bg_lam, bg_c, bg_row: (m,) the base's eigenvalues (rad/s)², modal damping (1/s) and mode
            shapes at the response DOF without the mode of interest (``hbm.LinearBackground``).
        bg_phi: (2, m) mode shapes at (excitation, response); bg_static: (2,) static residual
            flexibility between them and the response DOF, mm/N.
        levels: (L,) the study's levels, N; snms_hz, snms_amplitude: (L,) synthesized peak, Hz
            and mm at the response DOF (NaN where the peak is beyond the backbone).
        zeta_doubled_amplitude: response amplitude where ζ first reaches twice its stuck value,
            mm (NaN if it never does); zeta_doubled_modal: the same as a modal amplitude.
        seconds: wall time of the continuation (and synthesis), s; newton_iterations: total.
        complete: False when the continuation stopped before the top amplitude (a step that
            Newton could not complete even after halvings); stop_reason says where.
    """
    config: str
    rq_um: float
    mode: int
    f_lin_hz: float
    linear_hz: float
    linear_zeta: float
    onset_modal: float
    modal_amplitude: np.ndarray
    mass_amplitude: np.ndarray
    displacement_amplitude: np.ndarray
    displacement: np.ndarray
    omega: np.ndarray
    xi: np.ndarray
    zeta: np.ndarray
    zeta_energy: np.ndarray
    xi_viscous: np.ndarray
    friction_energy: np.ndarray
    viscous_energy: np.ndarray
    kinetic: np.ndarray
    element_status: np.ndarray
    element_energy: np.ndarray
    shape: np.ndarray
    bg_lam: np.ndarray
    bg_c: np.ndarray
    bg_row: np.ndarray
    bg_phi: np.ndarray
    bg_static: np.ndarray
    levels: np.ndarray
    snms_hz: np.ndarray
    snms_amplitude: np.ndarray
    zeta_doubled_amplitude: float
    zeta_doubled_modal: float
    seconds: float
    newton_iterations: int
    complete: bool = True
    stop_reason: str = ""

    @property
    def key(self) -> BackboneKey:
        """The backbone's typed key (stored inside its file)."""
        return BackboneKey.from_fields(self.config, self.rq_um)

    @property
    def frequency_hz(self) -> np.ndarray:
        """(p,) backbone frequency, Hz."""
        return self.omega / (2 * np.pi)

    def backbone(self) -> Backbone:
        """The hbm Backbone restricted to (excitation, response) DOFs: ``synthesize`` takes a
        force of shape (2,) on [excitation, response] (the response DOF is index 1)."""
        p = self.omega.size
        bg = LinearBackground(self.bg_lam, self.bg_c, self.bg_row, self.bg_phi, self.bg_static)
        return Backbone(
            mode=self.mode, dof=1, modal_amplitude=self.modal_amplitude,
            mass_amplitude=self.mass_amplitude, displacement_amplitude=self.displacement_amplitude,
            omega=self.omega, xi=self.xi, zeta=self.zeta, zeta_energy=self.zeta_energy,
            xi_viscous=self.xi_viscous, friction_energy=self.friction_energy,
            viscous_energy=self.viscous_energy, kinetic=self.kinetic,
            element_status=self.element_status, element_energy=self.element_energy,
            shape=self.shape, contact=np.zeros((p, 0)), residual=np.zeros(p),
            iterations=np.zeros(p, int), linear_omega=2 * np.pi * self.linear_hz,
            linear_zeta=self.linear_zeta, onset_amplitude=self.onset_modal,
            displacement=self.displacement, background=bg)

    def save(self, path: Path) -> None:
        save_dataclass_npz(self, path)

    @classmethod
    def load(cls, path: Path) -> "BackboneResult":
        with np.load(path, allow_pickle=False) as d:
            kw = {k: d[k] for k in d.files}
        # (a field with a default may be missing from an older file: it keeps its default)
        kinds = {f.name: f.type for f in fields(cls) if f.name in kw}
        for k, t in kinds.items():
            if t == "str":
                kw[k] = str(kw[k])
            elif t == "float":
                kw[k] = float(kw[k])
            elif t == "int":
                kw[k] = int(kw[k])
            elif t == "bool":
                kw[k] = bool(kw[k])
        return cls(**kw)

    def write_csv(self, path: Path) -> None:
        """The tmdsimpy-style export (``TMDSIMPY_FIELDS``); units in the header comment."""
        cols = np.column_stack([self.mass_amplitude, self.displacement_amplitude, self.omega,
                                self.zeta])
        np.savetxt(path, cols, delimiter=",", fmt="%.12e", header=",".join(TMDSIMPY_FIELDS),
                   comments="")
        # units: a sidecar line would break plain CSV readers, so they are documented in the
        # README ("Backbones"): mm·t^0.5, mm (response DOF), rad/s, fraction of critical


def zeta_doubled(modal: np.ndarray, disp: np.ndarray, zeta: np.ndarray, zeta0: float):
    """First amplitude where ζ reaches 2 ζ0 (log-linear interpolation between the points).

    Returns:
        (response amplitude mm, modal amplitude), NaN each when ζ stays below 2 ζ0.
    """
    above = np.nonzero(zeta >= 2 * zeta0)[0]
    if not above.size or above[0] == 0:
        return (float("nan"),) * 2 if not above.size else (float(disp[0]), float(modal[0]))
    i = int(above[0])
    t = (2 * zeta0 - zeta[i - 1]) / (zeta[i] - zeta[i - 1])
    lm = np.log(modal[i - 1]) + t * np.log(modal[i] / modal[i - 1])
    ld = np.log(disp[i - 1]) + t * np.log(disp[i] / disp[i - 1])
    return float(np.exp(ld)), float(np.exp(lm))


def compute_backbone(key: BackboneKey, rm, joint, f_lin: float, peak_amplitude_top: float,
                     levels: list, settings: SweepSettings,
                     n_points: int = BACKBONE_POINTS) -> BackboneResult:
    """The backbone of one joint and its synthesized peaks at ``levels``.

    Args:
        key: the backbone's key (stored in the result).
        rm: ReducedModel.
        joint: the joint (JointModel).
        f_lin: the study's stuck frequency of the joint, Hz (picks the mode).
        peak_amplitude_top: the largest forced peak amplitude expected at the top level, mm at
            the response DOF (the backbone ends at END_OF_TOP_PEAK times it).
        levels: the study's excitation levels, N.
        settings: the study's sweep settings (harmonics, samples, μ).
        n_points: log-spaced backbone points.

    Returns:
        BackboneResult.
    """
    t0 = time.perf_counter()
    # the FRFs' solver, at hbm's strict tolerances (the backbone is compared with polished peaks)
    hb, force, act = _setup(rm, joint, 1.0, settings, SWEEP_TOLERANCES[1])
    G = hb.G
    elastic = np.nonzero(~G.rigid)[0]
    f_el = np.sqrt(G.lam[elastic]) / (2 * np.pi)
    mode = int(np.argmin(np.abs(f_el - f_lin)))
    prob = NonlinearModeProblem(hb, mode)
    onset = prob.onset_amplitude()
    phi_r = abs(G.Phi[rm.response_dof, elastic[mode]])
    a1 = END_OF_TOP_PEAK * peak_amplitude_top / phi_r
    a0 = START_OF_ONSET * onset if np.isfinite(onset) and onset < a1 else 1e-3 * a1
    # a continuation that cannot go on keeps the points it reached (warned about by the stage):
    # one joint's backbone must not stop the study
    bb = hb.nonlinear_mode(mode, (a0, a1), dof=rm.response_dof, n_points=n_points, partial=True)
    exc, resp = rm.excitation_dof, rm.response_dof
    snms_hz, snms_amp = [], []
    for lv in levels:
        sr = synthesize(bb, np.asarray(force) * lv)
        snms_hz.append(sr.peak_omega / (2 * np.pi))
        snms_amp.append(sr.peak_amplitude)
    ne, p = len(joint.area), bb.omega.size
    status = np.full((p, ne), OPEN, dtype=np.int64)
    status[:, act] = bb.element_status
    energy = np.zeros((p, ne))
    energy[:, act] = bb.element_energy
    dz, dm = zeta_doubled(bb.modal_amplitude, bb.displacement_amplitude, bb.zeta, bb.linear_zeta)
    bg = bb.background.restrict([exc, resp])
    return BackboneResult(
        **key.to_fields(), mode=mode, f_lin_hz=float(f_lin),
        linear_hz=bb.linear_omega / (2 * np.pi), linear_zeta=bb.linear_zeta,
        onset_modal=float(onset), modal_amplitude=bb.modal_amplitude,
        mass_amplitude=bb.mass_amplitude, displacement_amplitude=bb.displacement_amplitude,
        displacement=bb.displacement, omega=bb.omega, xi=bb.xi, zeta=bb.zeta,
        zeta_energy=bb.zeta_energy, xi_viscous=bb.xi_viscous,
        friction_energy=bb.friction_energy, viscous_energy=bb.viscous_energy, kinetic=bb.kinetic,
        element_status=status, element_energy=energy, shape=bb.shape[:, [exc, resp]],
        bg_lam=bg.lam, bg_c=bg.c, bg_row=bg.row, bg_phi=bg.Phi, bg_static=bg.static,
        levels=np.asarray(levels, float), snms_hz=np.asarray(snms_hz),
        snms_amplitude=np.asarray(snms_amp), zeta_doubled_amplitude=dz, zeta_doubled_modal=dm,
        seconds=time.perf_counter() - t0, newton_iterations=int(bb.iterations.sum()),
        complete=bb.complete, stop_reason=bb.stop_reason)


def backbone_key(rm_key: str, joint, f_lin: float, peak_amplitude_top: float, levels: list,
                 settings: SweepSettings) -> str:
    """Cache key of a backbone: the digest of everything :func:`compute_backbone` reads.

    Args:
        rm_key: ``jobs.rm_digest`` of the reduced model.
        joint, f_lin, peak_amplitude_top, levels, settings: as for :func:`compute_backbone`.
    """
    return digest(BACKBONE_VERSION, rm_key, joint, float(f_lin), float(peak_amplitude_top),
                  [float(x) for x in levels], settings)


def is_cached(folder: Path, name: str, key: str) -> bool:
    """A backbone ``folder/<name>`` on disk whose ``.json`` record has this key and whose recorded
    files are intact (rank 0)."""
    try:
        rec = json.loads((Path(folder) / f"{name}.json").read_text())
    except (OSError, ValueError):
        return False
    return (isinstance(rec, dict) and rec.get("key") == key and "files" in rec
            and check_files(Path(folder), rec["files"]) is None)
