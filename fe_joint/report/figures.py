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
         hole: float | None = None, ticks: dict | None = None) -> None:
    """Scatter map of per-element values at their (x, y) in mm, with the bolt hole (diameter, mm);
    ticks: colour-bar value → label (a categorical field)."""
    # thin grey edges: light colours (a zero on a white-based map) stay visible
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=values, s=20, cmap=cmap, vmin=vmin, vmax=vmax,
                    edgecolors="0.45", linewidths=0.3)
    if hole:
        from matplotlib.patches import Circle
        ax.add_patch(Circle((0, 0), hole / 2, fill=False, lw=0.8, color="k"))
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    cb = ax.figure.colorbar(sc, ax=ax, shrink=0.8)
    cb.set_label(label)
    if ticks:
        cb.set_ticks(list(ticks), labels=list(ticks.values()))


def _grid_image(ax, field: np.ndarray, extent: tuple, title: str, label: str,
                cmap: str = "viridis", log: bool = False, vmin: float | None = None,
                vmax: float | None = None, ticks: dict | None = None) -> None:
    """Image of a BEM grid field over the overlap (extent in mm); ``log``: log scale, ≤ 0 masked;
    vmin, vmax: a colour range shared with other panels (None: this field's); ticks: colour-bar
    value → label (a categorical field)."""
    import matplotlib.colors as mc
    data = np.ma.masked_less_equal(field, 0) if log else field
    norm = mc.LogNorm(vmin=vmin, vmax=vmax) if log and np.any(field > 0) else None
    kw = {} if norm is not None else {"vmin": vmin, "vmax": vmax}
    im = ax.imshow(data.T, origin="lower", extent=extent, cmap=cmap, norm=norm, interpolation="nearest", **kw)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    cb = ax.figure.colorbar(im, ax=ax, shrink=0.8)
    cb.set_label(label)
    if ticks:
        cb.set_ticks(list(ticks), labels=list(ticks.values()))


#: colour-bar labels of a contact map (1 = in contact)
CONTACT_TICKS = {0.0: "no", 1.0: "yes"}


def _legend_styles(ax, extra: list[tuple[str, str]], fontsize: int = 8) -> None:
    """The axes' legend plus one grey proxy entry per (line style, label) in ``extra``."""
    from matplotlib.lines import Line2D
    handles, labels = ax.get_legend_handles_labels()
    for ls, text in extra:
        handles.append(Line2D([], [], color="grey", ls=ls))
        labels.append(text)
    ax.legend(handles, labels, fontsize=fontsize)


def _zoom(ax, peaks_hz: list[float]) -> None:
    """Frequency axis from 2.5 % below the lowest peak to 1.5 % above the highest (the sweeps'
    bands are wider than the resonances they hold)."""
    if peaks_hz:
        ax.set_xlim(0.975 * min(peaks_hz), 1.015 * max(peaks_hz))


def _plot_curve(ax, cr: CurveResult, color, label: str) -> None:
    """A forced FRF, stable part solid, unstable part (Hill) dotted."""
    ax.plot(cr.omega_hz, np.where(cr.stable, cr.amplitude, np.nan), color=color, label=label)
    if not np.all(cr.stable):
        ax.plot(cr.omega_hz, np.where(cr.stable, np.nan, cr.amplitude), ":", color=color, lw=1.6)


def frf_configurations(data: ReportData, path: Path) -> Path:
    """FRFs of every configuration, one panel per level (paper Figs. 11, 16), with each joint's
    stuck (linear) FRF.

    Args:
        data: the run's artifacts.
        path: the PNG to write.
    Returns:
        ``path``. Amplitudes in mm against Hz; unstable points dotted; the stuck FRFs dash-dot,
        clipped at 1.4 × the largest forced peak of the panel.
    """
    from .linear_frf import StuckReceptance
    plt = _plt()
    levels, joints = data.levels, configuration_joints(data)
    stuck = {}        # one eigenproblem per joint, not per panel (a full one: ≈ 3 s at 2198 DOFs)
    fig, axes = plt.subplots(1, len(levels), figsize=(5.2 * len(levels), 4.3), squeeze=False)
    for i, lv in enumerate(levels):
        ax, top = axes[0, i], 0.0
        for cfg in data.configs:
            cr = data.curve(cfg, i)
            if cr is None:
                continue
            _plot_curve(ax, cr, COLORS[cfg], cfg)
            top = max(top, float(np.max(cr.amplitude)))
            if cfg in joints:
                if cfg not in stuck:
                    stuck[cfg] = StuckReceptance(data.rm, joints[cfg])
                ax.plot(cr.omega_hz, lv * np.abs(stuck[cfg](cr.omega_hz)),
                        "-.", color=COLORS[cfg], lw=0.8, alpha=0.7)
        if top > 0:
            ax.set_ylim(0, 1.4 * top)
        _zoom(ax, [c.peak_hz for c in (data.curve(g, i) for g in data.configs) if c is not None])
        ax.set_title(f"excitation {lv:.3g} N ({lv / data.macroslip:.2f} × macroslip est.)", fontsize=9)
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("mass A amplitude, 1st harmonic [mm]")
        _legend_styles(ax, [(":", "unstable (Hill)"), ("-.", "stuck joint, linear (clipped)")])
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
        _plot_curve(ax, base, "k", "baseline (smooth)")
    cmap = _plt().get_cmap("viridis")
    for j, (rq, cr) in enumerate(rq_curves):
        _plot_curve(ax, cr, cmap(0.85 * j / max(len(rq_curves) - 1, 1)), f"v3, Rq = {rq_label(rq)} µm")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("mass A amplitude [mm]")
    ax.set_title(f"roughness sweep at {data.levels[data.mid]:.3g} N", fontsize=9)
    _zoom(ax, [cr.peak_hz for _, cr in rq_curves] + ([base.peak_hz] if base is not None else []))
    _legend_styles(ax, [(":", "unstable (Hill)")])
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
    import matplotlib.colors as mc
    rqs, extent = data.rqs, _extent(data)
    fig, axes = _plt().subplots(2, 1 + len(rqs), figsize=(4.2 * (1 + len(rqs)), 7.4), squeeze=False)
    _grid_image(axes[0, 0], data.extra["p_s"], extent, "smooth FE pressure [MPa]", "MPa", cmap="jet")
    pos = [data.surfaces[q].pressure[data.surfaces[q].pressure > 0] for q in rqs]
    lo = min((float(p.min()) for p in pos if p.size), default=None)
    hi = max((float(p.max()) for p in pos if p.size), default=None)
    mask = data.extra["mask"].astype(bool)
    binary = mc.ListedColormap(["white", "black"])
    _grid_image(axes[1, 0], np.where(mask, 1.0, 0.0), extent, "usable overlap (white: the bolt hole)",
                "usable", cmap=binary, vmin=0, vmax=1, ticks=CONTACT_TICKS)
    for k, rq in enumerate(rqs):
        sc = data.surfaces[rq]
        _grid_image(axes[0, k + 1], sc.pressure, extent,
                    f"Rq = {rq_label(rq)} µm: pressure (common log scale)", "MPa (log)",
                    cmap="jet", log=True, vmin=lo, vmax=hi)
        _grid_image(axes[1, k + 1], (sc.pressure > 0).astype(float), extent,
                    f"Rq = {rq_label(rq)} µm: contact morphology, {100 * sc.contact_fraction:.1f} % "
                    "of the usable overlap", "in contact", cmap=binary, vmin=0, vmax=1,
                    ticks=CONTACT_TICKS)
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
    vmax = max(float(np.max(v)) for _, v in panels)     # one scale: the panels compare
    for ax, (title, v) in zip(axes[0], panels):
        _map(ax, data.xy, v, title + " (common scale)", hole=data.case.geometry.hole_diameter,
             vmin=0.0, vmax=vmax, label="N/mm³")
    return _save(fig, path)


STATUS_LABEL = ""
#: colour-bar labels of a status map
STATUS_TICKS = dict(enumerate(STATUS_NAMES))


def status_energy_panels(data: ReportData, level: int, configs: list[str], path: Path) -> Path | None:
    """Contact status (top row) and dissipated energy per area (bottom row, one colour scale for
    all panels) at resonance for ``configs`` at level index ``level``.

    Returns:
        ``path``, or None when none of ``configs`` has a curve at that level. Energy in
        N·mm/mm² per cycle.
    """
    import matplotlib.colors as mc
    hole = data.case.geometry.hole_diameter
    show = [(c, data.curve(c, level)) for c in configs if data.curve(c, level) is not None]
    if not show:
        return None
    fig, axes = _plt().subplots(2, len(show), figsize=(4.4 * len(show), 7), squeeze=False)
    cmap = mc.ListedColormap(["tab:blue", "tab:green", "tab:red", "tab:orange", "lightgrey"])
    emax = max(float(np.max(cr.energy / data.area)) for _, cr in show) or 1.0
    for k, (cfg, cr) in enumerate(show):
        n = np.bincount(np.asarray(cr.status, int), minlength=5)
        _map(axes[0, k], data.xy, cr.status, f"{cfg}: status at resonance, {data.levels[level]:.3g} N\n"
             f"stuck {n[0]}, stick–slip {n[1]}, slip {n[2]}, part-open {n[3]}, open {n[4]}",
             cmap=cmap, vmin=-0.5, vmax=4.5, label=STATUS_LABEL, hole=hole, ticks=STATUS_TICKS)
        _map(axes[1, k], data.xy, cr.energy / data.area,
             f"{cfg}: dissipated energy / area, W = {cr.dissipated:.3g} N·mm", cmap="YlOrRd",
             label="N·mm/mm² per cycle (common scale)", hole=hole, vmin=0.0, vmax=emax)
    return _save(fig, path)


def status_energy(data: ReportData, path: Path) -> Path | None:
    """Contact status and dissipated energy per area at resonance, top level, baseline, v1, v3
    (Figs. 12, 17 at the top level; common energy scale).

    Returns:
        ``path``, or None when none of baseline, v1, v3 has a top-level curve.
    """
    return status_energy_panels(data, data.top, ["baseline", "v1", "v3"], path)


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
    usable = float(np.mean(data.extra["mask"]))      # usable share of the whole overlap
    axes[2].plot(rqs, [100 * data.surfaces[q].contact_fraction for q in rqs], "o-",
                 label="fe-joint / usable overlap")
    axes[2].plot(rqs, [100 * usable * data.surfaces[q].contact_fraction for q in rqs], "s--",
                 label="fe-joint / whole overlap (paper's)")
    pq = sorted(PAPER["contact_fraction"])
    # markers only: the paper gives no Rq 5 value, so no line may suggest one
    axes[2].plot(pq, [PAPER["contact_fraction"][q] for q in pq], "kx", ms=8, mew=2,
                 label="paper (/ whole overlap)")
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


#: on 2 ranks rank 0 draws one figure in RANK0_CYCLE, rank 1 the others: rank 0 also builds
#: the summary afterwards (2.5 s on the default run against the figures' 7.6 s, serially)
RANK0_CYCLE = 4


def figure_ranks(n: int, size: int) -> list[int]:
    """The rank that draws each of ``n`` figures on ``size`` ranks, in cycles of
    1 + (RANK0_CYCLE − 1)(size − 1) figures: the first of each cycle is rank 0's, the others go
    round-robin to ranks 1 … size − 1 (each of them draws RANK0_CYCLE − 1 times as many as rank
    0)."""
    if size <= 1:
        return [0] * n
    cycle = 1 + (RANK0_CYCLE - 1) * (size - 1)
    return [0 if i % cycle == 0 else 1 + (i % cycle - 1) % (size - 1) for i in range(n)]


def draw_figures(data: ReportData, folder: Path, rank: int = 0, size: int = 1) -> list[Path]:
    """Draw every figure (or rank ``rank``'s share of ``size``) into ``folder`` (created if
    needed) as ``<name>.png``.

    On several ranks rank 0 draws fewer than the others, as it builds the summary afterwards
    (:func:`figure_ranks`).

    Args:
        data: the run's artifacts.
        folder: where the PNGs go.
        rank, size: this rank and the number of ranks sharing the figures.
    Returns:
        the files this rank wrote (figures with nothing to draw are skipped).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    from .paper_figures import PAPER_FIGURES      # it imports this module's helpers
    every = list({**FIGURES, **PAPER_FIGURES}.items())
    owner = figure_ranks(len(every), size)
    mine = [(name, draw) for (name, draw), r in zip(every, owner) if r == rank]
    written = [draw(data, folder / f"{name}.png") for name, draw in mine]
    return [p for p in written if p is not None]
