"""Guards on a run's results: typed warnings where a result is suspect, errors where it is absurd.

A stage that finds something suspect records a :class:`RunWarning` (``StageContext.warn``); the
runner keeps a stage's warnings in its manifest (so a cached stage still reports them), the report
puts them into ``summary.json`` (``"warnings"``) and on top of ``report.md``, and the command line
ends with ``done with N warnings: …`` (docs/design.md, "Guards").

The guards:

* **cutoff** — the Craig–Bampton model must reproduce the full FE model in and around the
  dynamics band: every free–free elastic mode the ``fe`` stage compared, up to
  :data:`CUTOFF_MARGIN` × the top of the band, within :data:`CUTOFF_REL_TOL`, and the
  fixed-interface cut-off itself at least :data:`CUTOFF_MARGIN` × the top of the band.
* **gross slip** — a level above the joint's gross-slip estimate (μ·ΣN0 reached by the net
  tangential force of the stuck joint at resonance, :func:`fe_joint.model.joint.slip_onset`) is
  warned; above :data:`GROSS_SLIP_REJECT` × the estimate it is rejected (CaseError, exit 2).
* **v3 unconverged** — a v3 fixed point that stopped at ``contact.kt_max_passes``.
* **unstable** — a curve with continuation points that Hill's method finds unstable.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..errors import CaseError

#: the reduced model must match the full one up to this multiple of the band's top frequency
CUTOFF_MARGIN = 2.0
#: largest relative frequency error, reduced vs full, accepted in that range
CUTOFF_REL_TOL = 1e-3
#: a level above this multiple of the gross-slip estimate is rejected (warned above 1×)
GROSS_SLIP_REJECT = 100.0


@dataclass(frozen=True)
class RunWarning:
    """One suspect result.

    Attributes:
        kind: "cutoff", "gross-slip", "v3-unconverged", "unstable" or "backbone-incomplete".
        subject: what it is about (a curve or job name, a case key).
        message: one line for the console and the report.
        value: the number behind it (relative error, level / estimate, change, unstable points).
        limit: the bound it crossed (same unit as ``value``).
    """
    kind: str
    subject: str
    message: str
    value: float | None = None
    limit: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "RunWarning":
        return cls(**{k: d.get(k) for k in ("kind", "subject", "message", "value", "limit")})


def cutoff_guard(full_hz: list[float], reduced_hz: list[float], cutoff_hz: float,
                 band_top_hz: float) -> list[RunWarning]:
    """Does the reduced model cover the dynamics band with margin?

    Args:
        full_hz: the full FE model's free–free elastic frequencies, ascending, Hz.
        reduced_hz: the reduced model's, same modes, Hz.
        cutoff_hz: the fixed-interface mode cut-off, Hz.
        band_top_hz: the highest frequency the FRFs sweep, Hz.
    Returns:
        at most one warning (kind "cutoff").
    """
    top = CUTOFF_MARGIN * band_top_hz
    full, red = np.asarray(full_hz, float), np.asarray(reduced_hz, float)
    n = min(len(full), len(red))
    full, red = full[:n], red[:n]
    # the modes up to the margin; at least the first, which the band is built around
    sel = (full <= top) | (np.arange(n) == 0)
    err = np.abs(red[sel] - full[sel]) / full[sel]
    worst = float(err.max()) if len(err) else None
    if worst is not None and worst > CUTOFF_REL_TOL:
        i = int(np.flatnonzero(sel)[np.argmax(err)])
        return [RunWarning(
            "cutoff", "reduction.cutoff_hz",
            f"reduction.cutoff_hz = {cutoff_hz:g} Hz: the reduced model misses the dynamics band: "
            f"elastic mode {i + 1} at {red[i]:.5g} Hz against the full model's {full[i]:.5g} Hz "
            f"({worst:.1e} relative > {CUTOFF_REL_TOL:g}, modes up to {top:.4g} Hz = "
            f"{CUTOFF_MARGIN:g}× the band's top); raise the cut-off", worst, CUTOFF_REL_TOL)]
    if cutoff_hz < top:
        return [RunWarning(
            "cutoff", "reduction.cutoff_hz",
            f"reduction.cutoff_hz = {cutoff_hz:g} Hz is below {CUTOFF_MARGIN:g}× the dynamics "
            f"band's top ({top:.4g} Hz): raise the cut-off", cutoff_hz / top, 1.0)]
    return []


def gross_slip_guard(levels: list[float], macroslip_n: float, mu: float,
                     clamp_n: float) -> list[RunWarning]:
    """Levels beyond the joint's gross-slip estimate: warned, or rejected when absurd.

    Args:
        levels: the excitation levels, N.
        macroslip_n: the gross-slip estimate, N (the excitation at which the stuck joint's net
            tangential force at resonance reaches μ·ΣN0).
        mu: friction coefficient.
        clamp_n: ΣN0, the clamping force of the joint, N.
    Returns:
        one warning (kind "gross-slip") per level above the estimate.
    Raises:
        CaseError (exit 2) naming ``dynamics.levels`` when a level exceeds
        :data:`GROSS_SLIP_REJECT` × the estimate.
    """
    out = []
    for i, lv in enumerate(levels):
        r = lv / macroslip_n
        if r > GROSS_SLIP_REJECT:
            raise CaseError(
                f"dynamics.levels: {lv:.4g} N is {r:.3g}× the joint's gross-slip estimate "
                f"{macroslip_n:.4g} N (μ·ΣN0 = {mu * clamp_n:.4g} N; allowed: up to "
                f"{GROSS_SLIP_REJECT:g}× the estimate, warned above 1×)")
        if r > 1.0:
            out.append(RunWarning(
                "gross-slip", f"L{i}",
                f"dynamics.levels: L{i} = {lv:.4g} N is {r:.3g}× the joint's gross-slip estimate "
                f"{macroslip_n:.4g} N (μ·ΣN0 = {mu * clamp_n:.4g} N reached by the stuck joint at "
                "resonance): the joint slides as a whole, its response is suspect", r, 1.0))
    return out


def v3_guard(name: str, record: dict, kt_tol: float) -> list[RunWarning]:
    """A v3 fixed point that did not converge (``record``: its job record with the history)."""
    if record.get("converged", True):
        return []
    h = record.get("history") or []
    change = h[-1].get("change") if h else None
    return [RunWarning(
        "v3-unconverged", name,
        f"{name}: the v3 fixed point did not converge in {max(len(h) - 1, 0)} passes (last change "
        f"{change if change is None else format(change, '.2g')} > contact.kt_tol = {kt_tol:g}); "
        "its curves use the last pass's k_n, k_t", change, kt_tol)]


def unstable_guard(name: str, omega_hz: np.ndarray, stable: np.ndarray) -> list[RunWarning]:
    """A curve with unstable continuation points (Hill's method)."""
    stable = np.asarray(stable, bool)
    n = int(np.sum(~stable))
    if n == 0:
        return []
    f = np.asarray(omega_hz)[~stable]
    return [RunWarning(
        "unstable", name,
        f"{name}: {n} of {len(stable)} continuation points unstable ({f.min():.2f}–{f.max():.2f} Hz): "
        "a stepped sine would jump there", float(n), 0.0)]


#: how the last console line names each kind
KIND_LABELS = {"cutoff": "reduced model misses the band", "gross-slip": "levels beyond gross slip",
               "v3-unconverged": "v3 not converged", "unstable": "unstable parts"}


def done_line(out, warnings: list[RunWarning], report: bool = True) -> str:
    """The run's last console line: ``[fe-joint] done: DIR`` or ``… done with N warnings: …``.

    Args:
        out: the run folder.
        warnings: the run's warnings, in stage order.
        report: whether report.md was written (where the details are), else the manifests.
    """
    if not warnings:
        return f"[fe-joint] done: {out}"
    groups: dict[str, list[str]] = {}
    for w in warnings:
        groups.setdefault(w.kind, []).append(w.subject)
    text = "; ".join(f"{KIND_LABELS.get(k, k)} ({', '.join(v)})" for k, v in groups.items())
    s = "" if len(warnings) == 1 else "s"
    where = f"{out}/report.md" if report else f"{out}/stages/*.json"
    return f"[fe-joint] done with {len(warnings)} warning{s}: {text}; details in {where}"


def backbone_guard(name: str, complete: bool, reached: float, reason: str) -> list[RunWarning]:
    """A backbone whose continuation stopped before its top amplitude (``reached``: its last
    response amplitude, mm); the synthesized peaks beyond it are NaN."""
    if complete:
        return []
    return [RunWarning("backbone-incomplete", name,
                       f"backbone {name} stops at {reached:.4g} mm ({reason})", reached, None)]
