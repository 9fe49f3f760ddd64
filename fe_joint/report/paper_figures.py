"""The counterparts of the paper's figures that the first report lacked (issue 13, "The report").

One function per PNG, as in :mod:`.figures`: Fig. 12 (baseline and smooth-ms maps of pressure,
k_n, status and energy), Fig. 13 (surface heights and contact morphology), Fig. 17 (every
configuration at the lowest slipping level), Fig. 21 at every level (forced curves where swept,
curves synthesized from the backbone elsewhere), Fig. 22 (joint loops against Rq) and the ratio
maps v3 / v2. Panels that are compared share one colour scale.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..study.artifacts import rq_label
from .data import ReportData
from .figures import (CONTACT_TICKS, STATUS_LABEL, STATUS_TICKS, _extent, _grid_image,
                      _legend_styles, _map, _plot_curve, _plt, _save, _zoom, status_energy_panels)
from .findings import _zone_level
from .loops import joint_equivalent_loop
from .stiffness import configuration_joints


def fig12_smooth_maps(data: ReportData, path: Path) -> Path | None:
    """Baseline (top) and smooth-ms (bottom): element pressure, k_n, status and energy per area at
    resonance, at the level the Findings use for Fig. 12 (paper Fig. 12).

    Returns:
        ``path``; None when baseline or smooth-ms has no curve. MPa, N/mm³, N·mm/mm² per cycle.
    """
    import matplotlib.colors as mc
    if "smooth-ms" not in data.configs:
        return None
    i = _zone_level(data, ("baseline", "smooth-ms"))
    if i is None:
        return None
    joints, hole = configuration_joints(data), data.case.geometry.hole_diameter
    rows = [(c, joints[c], data.curve(c, i)) for c in ("baseline", "smooth-ms")]
    p = data.rm.preload_pressure
    kmax = max(float(np.max(j.kn)) for _, j, _ in rows)
    emax = max(float(np.max(cr.energy / data.area)) for _, _, cr in rows) or 1.0
    cmap = mc.ListedColormap(["tab:blue", "tab:green", "tab:red", "tab:orange", "lightgrey"])
    fig, axes = _plt().subplots(2, 4, figsize=(17.5, 7.4))
    for r, (cfg, j, cr) in enumerate(rows):
        _map(axes[r, 0], data.xy, p, f"{cfg}: FE pressure N0/A [MPa]", cmap="jet", label="MPa",
             hole=hole, vmin=0.0, vmax=float(p.max()))
        _map(axes[r, 1], data.xy, j.kn, f"{cfg}: k_n (common scale)", label="N/mm³", hole=hole,
             vmin=0.0, vmax=kmax)
        _map(axes[r, 2], data.xy, cr.status, f"{cfg}: status at resonance, {data.levels[i]:.3g} N",
             cmap=cmap, vmin=-0.5, vmax=4.5, label=STATUS_LABEL, hole=hole, ticks=STATUS_TICKS)
        _map(axes[r, 3], data.xy, cr.energy / data.area, f"{cfg}: energy / area, W = {cr.dissipated:.3g} N·mm",
             cmap="YlOrRd", label="N·mm/mm² per cycle (common scale)", hole=hole, vmin=0.0, vmax=emax)
    return _save(fig, path)


def fig13_heights(data: ReportData, path: Path) -> Path:
    """Heights of the comparison surface and its contact morphology under the bolt load (Fig. 13).

    Returns:
        ``path``. Heights in µm (composite surface), contact as black cells.
    """
    import matplotlib.colors as mc
    sc, extent = data.surfaces[data.v_rq], _extent(data)
    fig, axes = _plt().subplots(1, 2, figsize=(10.5, 4.2))
    _grid_image(axes[0], 1e3 * sc.z, extent, f"heights, Rq = {rq_label(data.v_rq)} µm "
                f"(λ = {data.case.roughness.corr_length:g} mm)", "µm", cmap="terrain")
    _grid_image(axes[1], (sc.pressure > 0).astype(float), extent,
                f"contact morphology at {data.case.preload.bolt_force / 1e3:g} kN: "
                f"{100 * sc.contact_fraction:.2f} % of the usable overlap", "in contact",
                cmap=mc.ListedColormap(["white", "black"]), vmin=0, vmax=1, ticks=CONTACT_TICKS)
    return _save(fig, path)


def fig17_all_configurations(data: ReportData, path: Path) -> Path | None:
    """Every configuration's status and energy at the lowest level (paper Fig. 17 at its lowest,
    500 N; common energy scale). The top level's maps are ``status_energy.png``."""
    return status_energy_panels(data, 0, data.configs, path)


def _snms_curve(br, level: float, f_peak: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The forced response synthesized from a backbone at ``level`` N: (Hz, mm) along the curve
    (lower branch up to the peak, then the upper branch back) within −5 % … +3 % of its peak
    frequency ``f_peak`` (Hz; far below it the free–free structure's rigid-body background
    dominates), None if the synthesis fails."""
    from hbm import synthesize
    try:
        sr = synthesize(br.backbone(), np.array([level, 0.0]))
    except (ValueError, RuntimeError, FloatingPointError):
        return None
    lo, hi = sr.omega_low / (2 * np.pi), sr.omega_high / (2 * np.pi)
    f = np.concatenate([lo, hi[::-1]])
    a = np.concatenate([sr.amplitude_low, sr.amplitude_high[::-1]])
    ok = np.isfinite(f) & np.isfinite(a) & (f > 0.95 * f_peak) & (f < 1.03 * f_peak)
    return (f[ok], a[ok]) if ok.sum() > 2 else None


def fig21_levels(data: ReportData, path: Path) -> Path:
    """Baseline and v3 per Rq at every level (Fig. 21): forced FRFs where the study swept them
    (solid; unstable dotted), elsewhere the curve synthesized from that joint's backbone (dashed).

    Returns:
        ``path``. Amplitudes in mm against Hz.
    """
    plt = _plt()
    cmap = plt.get_cmap("viridis")
    rqs = data.rqs
    bbs = {k.rq_um: br for k, br in data.backbones.items() if k.config == "v3"}
    fig, axes = plt.subplots(1, len(data.levels), figsize=(5.2 * len(data.levels), 4.3), squeeze=False)
    for i, lv in enumerate(data.levels):
        ax, peaks = axes[0, i], []
        base = data.curve("baseline", i)
        if base is not None:
            _plot_curve(ax, base, "k", "baseline")
            peaks.append(base.peak_hz)
        for j, rq in enumerate(rqs):
            color = cmap(0.85 * j / max(len(rqs) - 1, 1))
            cr = next((c for k, c in data.curves.items()
                       if k.config == "v3" and k.level_index == i and k.rq_um == rq), None)
            if cr is not None:
                _plot_curve(ax, cr, color, f"v3, Rq {rq_label(rq)} µm")
                peaks.append(cr.peak_hz)
            elif (rq in bbs and np.isfinite(bbs[rq].snms_hz[i])
                  and (syn := _snms_curve(bbs[rq], lv, float(bbs[rq].snms_hz[i]))) is not None):
                ax.plot(*syn, "--", color=color, label=f"v3, Rq {rq_label(rq)} µm (SNMS)")
                peaks.append(float(bbs[rq].snms_hz[i]))
        _zoom(ax, peaks)
        ax.set_title(f"L{i}: {lv:.3g} N", fontsize=9)
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("mass A amplitude, 1st harmonic [mm]")
        _legend_styles(ax, [(":", "unstable (Hill)"), ("--", "synthesized from the backbone")], 7)
    return _save(fig, path)


def fig22_loops_rq(data: ReportData, path: Path) -> Path | None:
    """Whole-joint loops at resonance against Rq (v3, the sweep's level) with the baseline's
    (paper Fig. 22): the loop along the joint's slip pattern, area = dissipated energy."""
    sw = sorted(((k.rq_um, cr) for k, cr in data.curves.items()
                 if k.config == "v3" and k.level_index == data.mid and k.rq_um is not None),
                key=lambda t: t[0])
    if not sw:
        return None
    plt = _plt()
    cmap = plt.get_cmap("viridis")
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    base = data.curve("baseline", data.mid)
    items = ([("baseline", base, "k")] if base is not None else []) + [
        (f"v3, Rq {rq_label(q)} µm", cr, cmap(0.85 * j / max(len(sw) - 1, 1))) for j, (q, cr) in enumerate(sw)]
    for name, cr, color in items:
        x, F, X, k = joint_equivalent_loop(cr.elem_u, cr.elem_T, cr.dissipated)
        ax.plot(np.append(x, x[0]) * 1e3, np.append(F, F[0]), color=color,
                label=f"{name}: W = {cr.dissipated:.3g} N·mm, ‖û‖ = {1e3 * X:.3g} µm")
    ax.set_xlabel("joint slip along its pattern, ‖û‖ cos ωt [µm]")
    ax.set_ylabel("joint force (work conjugate) [N]")
    ax.set_title(f"joint loops at resonance, {data.levels[data.mid]:.3g} N", fontsize=9)
    ax.legend(fontsize=7)
    return _save(fig, path)


def ratio_maps(data: ReportData, path: Path) -> Path | None:
    """v3 / v2 per element on the comparison surface: k_n, k_t, and v3's k_t/k_n over Mindlin's
    ratio (1 = Mindlin). One logarithmic colour scale centred on 1 for the three panels, its range
    the 98th percentile of the deviations (the few beyond it saturate). None without v3."""
    import matplotlib.colors as mc
    from matplotlib.patches import Circle
    k3 = data.v3_arrays.get(data.v_rq)
    if k3 is None:
        return None
    sv, nu = data.surfaces[data.v_rq], data.case.material.poisson
    mindlin = 2 * (1 - nu) / (2 - nu)
    on = (sv.kn > 0) & (k3["kn"] > 0) & (sv.kt_mindlin > 0) & (k3["kt"] > 0)
    panels = [("k_n: v3 / v2", k3["kn"][on] / sv.kn[on]),
              ("k_t: v3 (loop) / v2 (Mindlin)", k3["kt"][on] / sv.kt_mindlin[on]),
              ("v3 (k_t / k_n) / Mindlin's ratio", k3["kt"][on] / k3["kn"][on] / mindlin)]
    dev = np.abs(np.log(np.concatenate([v for _, v in panels]))) if on.any() else np.zeros(1)
    r = float(np.exp(max(np.percentile(dev, 98), np.log(1.02))))
    norm = mc.LogNorm(vmin=1 / r, vmax=r)
    fig, axes = _plt().subplots(1, 3, figsize=(15, 4.4))
    for ax, (title, v) in zip(axes, panels):
        ax.scatter(data.xy[~on, 0], data.xy[~on, 1], s=8, marker="x", c="0.6", lw=0.7,
                   label=f"not in contact ({int(np.sum(~on))})")
        sc = ax.scatter(data.xy[on, 0], data.xy[on, 1], c=v, s=26, cmap="RdBu_r", norm=norm,
                        edgecolors="0.3", linewidths=0.4)
        ax.add_patch(Circle((0, 0), data.case.geometry.hole_diameter / 2, fill=False, lw=0.8, color="k"))
        ax.set_aspect("equal")
        ax.set_title(f"{title}, Rq {rq_label(data.v_rq)} µm\nmedian {np.median(v):.3f}, "
                     f"range {v.min():.3f} … {v.max():.3f}", fontsize=8)
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.legend(fontsize=7, loc="upper right")
        cb = ax.figure.colorbar(sc, ax=ax, shrink=0.8, extend="both")
        cb.set_label("ratio (common log scale)")
        ticks = [1 / r, r ** -0.5, 1.0, r ** 0.5, r]
        cb.set_ticks(ticks, labels=[f"{t:.3g}" for t in ticks])
        cb.ax.minorticks_off()
    return _save(fig, path)


#: file stem → figure function (added to :data:`.figures.FIGURES` in this order)
PAPER_FIGURES = {
    "fig12_smooth_maps": fig12_smooth_maps,
    "fig13_heights": fig13_heights,
    "fig17_all_configurations": fig17_all_configurations,
    "fig21_levels": fig21_levels,
    "fig22_loops_rq": fig22_loops_rq,
    "ratio_maps_v3_v2": ratio_maps,
}
