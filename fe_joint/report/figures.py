"""The report's figures: one function per PNG, each drawn from a :class:`ReportData`.

Every function takes the data and the file to write and returns the path written (None when the
run has nothing to draw in it). Titles and labels are those of the earlier single-function report.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from ..case.schema import CONFIGURATIONS
from ..study.artifacts import rq_label
from ..study.frf import CurveResult
from .data import PAPER, ReportData
from .loops import joint_equivalent_loop, loop_area
from .stiffness import configuration_joints, k_eq_table, rq_joints

STATUS_NAMES = ("stuck", "stick–slip", "gross slip", "partly open", "open")
COLORS = dict(zip(CONFIGURATIONS, ("k", "tab:blue", "tab:orange", "tab:green", "tab:red")))
DPI = 110


def _plt():
    import matplotlib
    matplotlib.use("Agg")   # files only, never a display
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path: Path) -> Path:
    """Lay out, write and close a figure; returns ``path``."""
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    _plt().close(fig)
    return Path(path)


def _map(ax, xy: np.ndarray, values: np.ndarray, title: str, cmap: str = "viridis",
         label: str = "", vmin: float | None = None, vmax: float | None = None,
         hole: float | None = None) -> None:
    """Scatter map of per-element values at their (x, y) in mm, with the bolt hole (diameter, mm)."""
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=values, s=18, cmap=cmap, vmin=vmin, vmax=vmax)
    if hole:
        from matplotlib.patches import Circle
        ax.add_patch(Circle((0, 0), hole / 2, fill=False, lw=0.8, color="k"))
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    cb = ax.figure.colorbar(sc, ax=ax, shrink=0.8)
    cb.set_label(label)


def _grid_image(ax, field: np.ndarray, extent: tuple, title: str, label: str,
                cmap: str = "viridis", log: bool = False) -> None:
    """Image of a BEM grid field over the overlap (extent in mm); ``log``: log scale, ≤ 0 masked."""
    import matplotlib.colors as mc
    data = np.ma.masked_less_equal(field, 0) if log else field
    norm = mc.LogNorm() if log and np.any(field > 0) else None
    im = ax.imshow(data.T, origin="lower", extent=extent, cmap=cmap, norm=norm)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.figure.colorbar(im, ax=ax, shrink=0.8).set_label(label)


def frf_configurations(data: ReportData, path: Path) -> Path:
    """FRFs of every configuration, one panel per level (paper Figs. 11, 16).

    Args:
        data: the run's artifacts.
        path: the PNG to write.
    Returns:
        ``path``. Amplitudes in mm against Hz; unstable points dotted.
    """
    plt = _plt()
    levels = data.levels
    fig, axes = plt.subplots(1, len(levels), figsize=(5 * len(levels), 4), squeeze=False)
    for i, lv in enumerate(levels):
        ax = axes[0, i]
        for cfg in data.configs:
            cr = data.curve(cfg, i)
            if cr is None:
                continue
            ax.plot(cr.omega_hz, np.where(cr.stable, cr.amplitude, np.nan), color=COLORS[cfg], label=cfg)
            ax.plot(cr.omega_hz, np.where(cr.stable, np.nan, cr.amplitude), ":", color=COLORS[cfg])
        ax.set_title(f"excitation {lv:.3g} N ({lv / data.macroslip:.2f} × macroslip est.)", fontsize=9)
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("mass A amplitude, 1st harmonic [mm]")
        ax.legend(fontsize=8)
    return _save(fig, path)


def frf_roughness(data: ReportData, path: Path) -> Path:
    """The baseline FRF and every surface's v3 FRF at the middle level (paper Fig. 21).

    Args:
        data: the run's artifacts.
        path: the PNG to write.
    Returns:
        ``path``. Amplitudes in mm against Hz.
    """
    rq_curves = sorted(((k.rq_um, cr) for k, cr in data.curves.items()
                        if k.config == "v3" and k.level_index == data.mid), key=lambda t: t[0])
    base = data.curve("baseline", data.mid)
    fig, ax = _plt().subplots(figsize=(6, 4))
    if base is not None:
        ax.plot(base.omega_hz, base.amplitude, "k", label="baseline (smooth)")
    for rq, cr in rq_curves:
        ax.plot(cr.omega_hz, cr.amplitude, label=f"v3, Rq = {rq_label(rq)} µm")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("mass A amplitude [mm]")
    ax.set_title(f"roughness sweep at {data.levels[data.mid]:.3g} N", fontsize=9)
    ax.legend(fontsize=8)
    return _save(fig, path)


def _extent(data: ReportData) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) of the overlap, mm: the BEM grid's extent."""
    g = data.case.geometry
    return (-g.overlap / 2, g.overlap / 2, -g.plate_width / 2, g.plate_width / 2)


def pressure_morphology(data: ReportData, path: Path) -> Path:
    """Smooth FE pressure and every surface's rough pressure on the BEM grid (Figs. 10, 13, 20).

    Args:
        data: the run's artifacts.
        path: the PNG to write.
    Returns:
        ``path``. Pressures in MPa, the rough ones on a log scale.
    """
    rqs, extent = data.rqs, _extent(data)
    fig, axes = _plt().subplots(1, 1 + len(rqs), figsize=(4.2 * (1 + len(rqs)), 3.6), squeeze=False)
    _grid_image(axes[0, 0], data.extra["p_s"], extent, "smooth FE pressure [MPa]", "MPa", cmap="jet")
    for k, rq in enumerate(rqs):
        sc = data.surfaces[rq]
        _grid_image(axes[0, k + 1], sc.pressure, extent,
                    f"Rq = {rq_label(rq)} µm: contact {100 * sc.contact_fraction:.1f} %", "MPa (log)",
                    cmap="jet", log=True)
    return _save(fig, path)


def stiffness_maps(data: ReportData, path: Path) -> Path:
    """Maps of k_n (smooth-ms, v3) and k_t (Mindlin v2, v3 from the loops) (paper Figs. 8, 14).

    Args:
        data: the run's artifacts.
        path: the PNG to write.
    Returns:
        ``path``. Stiffness per unit area in N/mm³; v3 panels show v2's k_n when v3 is missing.
    """
    rv = data.v_rq
    sv, v3 = data.surfaces[rv], data.v3_arrays.get(rv)
    kn_v3 = v3["kn"] if v3 is not None else sv.kn
    panels = [("k_n smooth-ms [N/mm³]", data.extra["kn_smooth"]),
              (f"k_n Rq={rq_label(rv)} µm (v3) [N/mm³]", kn_v3),
              ("k_t Mindlin (v2) [N/mm³]", sv.kt_mindlin)]
    if v3 is not None:
        panels.append(("k_t from loops (v3) [N/mm³]", v3["kt"]))
    fig, axes = _plt().subplots(1, len(panels), figsize=(4.4 * len(panels), 3.6), squeeze=False)
    for ax, (title, v) in zip(axes[0], panels):
        _map(ax, data.xy, v, title, hole=data.case.geometry.hole_diameter)
    return _save(fig, path)


def status_energy(data: ReportData, path: Path) -> Path | None:
    """Contact status and dissipated energy per area at resonance, top level (Figs. 12, 17).

    Args:
        data: the run's artifacts.
        path: the PNG to write.
    Returns:
        ``path``, or None when none of baseline, v1, v3 has a top-level curve. Energy in
        N·mm/mm² per cycle.
    """
    import matplotlib.colors as mc
    top, hole = data.top, data.case.geometry.hole_diameter
    show = [c for c in ("baseline", "v1", "v3") if data.curve(c, top) is not None]
    if not show:
        return None
    fig, axes = _plt().subplots(2, len(show), figsize=(4.4 * len(show), 7), squeeze=False)
    cmap = mc.ListedColormap(["tab:blue", "tab:green", "tab:red", "tab:orange", "lightgrey"])
    for k, cfg in enumerate(show):
        cr = data.curve(cfg, top)
        _map(axes[0, k], data.xy, cr.status, f"{cfg}: status at resonance, {data.levels[top]:.3g} N",
             cmap=cmap, vmin=-0.5, vmax=4.5, label="0 stuck 1 stick-slip 2 slip 3 part-open 4 open",
             hole=hole)
        _map(axes[1, k], data.xy, cr.energy / data.area, f"{cfg}: dissipated energy / area",
             cmap="magma", label="N·mm/mm² per cycle", hole=hole)
    return _save(fig, path)


def loop_elements(data: ReportData, cr: CurveResult) -> list[int]:
    """Up to three active elements near the hole, mid-overlap and the edge (distinct indices).

    Args:
        data: the run's artifacts (geometry in mm).
        cr: the curve whose active elements (status < 4, not open) are candidates.
    Returns:
        element indices, nearest first to radii hole/2 + 1, halfway to overlap/2, 1.3 · overlap/2 (mm).
    """
    g = data.case.geometry
    r = np.hypot(data.xy[:, 0], data.xy[:, 1])
    cand = np.nonzero(cr.status < 4)[0]
    if not len(cand):
        return []
    targets = (g.hole_diameter / 2 + 1.0, (g.hole_diameter / 2 + g.overlap / 2) / 2, g.overlap / 2 * 1.3)
    picks = [int(cand[np.argmin(np.abs(r[cand] - t))]) for t in targets]
    return list(dict.fromkeys(picks))


def _closed(x: np.ndarray) -> np.ndarray:
    """A periodic sample with its first point repeated at the end (a closed loop)."""
    return np.append(x, x[0])


def _element_loops(ax, data: ReportData, cr: CurveResult) -> None:
    """T_x (N) against u_x (µm) over one cycle for the elements of :func:`loop_elements`; the
    legend gives each x-loop's area against the element's whole dissipated energy (x and y)."""
    r = np.hypot(data.xy[:, 0], data.xy[:, 1])
    for i in loop_elements(data, cr):
        area = loop_area(cr.elem_u[i], cr.elem_T[i])
        ax.plot(_closed(cr.elem_u[i]) * 1e3, _closed(cr.elem_T[i]),
                label=f"element {i} (r = {r[i]:.1f} mm, {STATUS_NAMES[cr.status[i]]}): "
                      f"∮T_x du_x = {area:.3g}, W = {cr.energy[i]:.3g} N·mm")
    ax.set_xlabel("relative displacement u_x [µm]")
    ax.set_ylabel("tangential force T_x [N]")
    ax.set_title(f"{cr.config}: element loops at resonance, {cr.level:.3g} N", fontsize=9)
    ax.legend(fontsize=6)


def _joint_loops(ax, data: ReportData) -> None:
    """Whole joint at the top level, per configuration: the loop along the joint's slip pattern
    (:func:`~.loops.joint_equivalent_loop`: amplitude ‖û‖ of the element slips, in-phase
    stiffness from the energy they store, area = the dissipated energy)."""
    for cfg in data.configs:
        cr = data.curve(cfg, data.top)
        if cr is not None:
            x, F, X, k = joint_equivalent_loop(cr.elem_u, cr.elem_T, cr.dissipated)
            ax.plot(x * 1e3, F, color=COLORS[cfg],
                    label=f"{cfg}: W = {cr.dissipated:.3g} N·mm, k_J = {k:.3g} N/mm")
    ax.set_xlabel("joint slip along its pattern, ‖û‖ cos ωt [µm]")
    ax.set_ylabel("joint force (work conjugate) [N]")
    ax.set_title("whole joint at the top level: area = dissipated energy per cycle", fontsize=9)
    ax.legend(fontsize=7)


def hysteresis_loops(data: ReportData, path: Path) -> Path | None:
    """Element loops (v3, else baseline) and whole-joint loops at resonance (Figs. 18, 22).

    Args:
        data: the run's artifacts.
        path: the PNG to write.
    Returns:
        ``path``, or None when neither v3 nor baseline has a top-level curve.
    """
    cr = data.curve("v3", data.top) or data.curve("baseline", data.top)
    if cr is None:
        return None
    fig, axes = _plt().subplots(1, 2, figsize=(10, 4))
    _element_loops(axes[0], data, cr)
    _joint_loops(axes[1], data)
    return _save(fig, path)


def keq_contact_fraction(data: ReportData, path: Path) -> Path:
    """k_eq per configuration, k_eq against Rq and the real contact area against Rq (Figs. 15, 19).

    Args:
        data: the run's artifacts.
        path: the PNG to write.
    Returns:
        ``path``. Stiffness in N/mm³, contact area in % of the usable nominal area.
    """
    keq = k_eq_table(configuration_joints(data))
    keq_rq, rqs = k_eq_table(rq_joints(data)), data.rqs
    fig, axes = _plt().subplots(1, 3, figsize=(14, 3.8))
    names = list(keq)
    xs = np.arange(len(names))
    axes[0].bar(xs - 0.2, [keq[n]["kn"] for n in names], 0.4, label="k_n,eq")
    axes[0].bar(xs + 0.2, [keq[n]["kt"] for n in names], 0.4, label="k_t,eq")
    axes[0].set_xticks(xs, names)
    axes[0].set_ylabel("N/mm³")
    axes[0].set_title("equivalent stiffness Σ k A / Σ A (unloaded elements count 0 for v1)", fontsize=8)
    axes[0].legend(fontsize=8)
    axes[1].plot(rqs, [keq_rq[q]["kn"] for q in rqs], "o-", label="k_n,eq (v3)")
    axes[1].plot(rqs, [keq_rq[q]["kt"] for q in rqs], "s-", label="k_t,eq (v3)")
    axes[1].set_xlabel("Rq [µm]")
    axes[1].set_ylabel("N/mm³")
    axes[1].legend(fontsize=8)
    axes[2].plot(rqs, [100 * data.surfaces[q].contact_fraction for q in rqs], "o-", label="fe-joint")
    pq = sorted(PAPER["contact_fraction"])
    axes[2].plot(pq, [PAPER["contact_fraction"][q] for q in pq], "kx--", label="paper")
    axes[2].set_xlabel("Rq [µm]")
    axes[2].set_ylabel("real contact area [%]")
    axes[2].legend(fontsize=8)
    return _save(fig, path)


#: file stem → figure function, in drawing order (the stems are the report's figure names)
FIGURES: dict[str, Callable[[ReportData, Path], Path | None]] = {
    "frf_configurations": frf_configurations,
    "frf_roughness": frf_roughness,
    "pressure_morphology": pressure_morphology,
    "stiffness_maps": stiffness_maps,
    "status_energy": status_energy,
    "hysteresis_loops": hysteresis_loops,
    "keq_contact_fraction": keq_contact_fraction,
    "backbone_frequency": lambda data, path: _backbones().backbone_frequency(data, path),
    "backbone_damping": lambda data, path: _backbones().backbone_damping(data, path),
    "kt_definitions": lambda data, path: _stiffness_definitions().figure(data, path),
}


def _backbones():
    # imported when drawn: report.backbones imports this module's helpers
    from . import backbones
    return backbones


def _stiffness_definitions():
    from . import stiffness_definitions
    return stiffness_definitions


def draw_figures(data: ReportData, folder: Path) -> list[Path]:
    """Draw every figure into ``folder`` (created if needed) as ``<name>.png``.

    Args:
        data: the run's artifacts.
        folder: where the PNGs go.
    Returns:
        the files written (figures with nothing to draw are skipped).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = [draw(data, folder / f"{name}.png") for name, draw in FIGURES.items()]
    return [p for p in written if p is not None]
