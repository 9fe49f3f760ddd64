"""The report of a run: ``report.md``, ``figures/*.png`` and ``summary.json``.

Reads the artifacts of the earlier stages (rank 0 only) and draws the figures of the paper for our
resonator: FRFs per configuration and level (paper Figs. 11, 16) and versus Rq (Fig. 21); maps of
pressure, contact morphology, k_n, k_t, contact status and dissipated energy (Figs. 8, 10, 12–14,
17, 20); hysteresis loops of elements and of the whole joint (Figs. 18, 22); the equivalent
stiffness k_eq = Σ k_i A_i / Σ A_i per configuration and versus Rq (Figs. 15, 19); the contact-area
fraction versus Rq; the cost per stage (Tables 2–3) and a speed-against-error section.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..case.schema import CONFIGURATIONS
from ..model.reduced_model import ReducedModel
from ..pipeline.runner import read_manifest
from ..study.artifacts import CurveKey, load_curves, rq_label, v3_job_name
from ..study.contact import load_surfaces
from ..study.frf import CurveResult

STATUS_NAMES = ("stuck", "stick–slip", "gross slip", "partly open", "open")
PAPER = {  # the paper's numbers for the side-by-side table
    "contact_fraction": {1.0: 22.1, 10.0: 2.7, 15.0: 2.0},
    "kn_smooth_mean": 6.6e4, "kn_smooth_max": 1.74e5,
    "hbm_seconds": {"smooth": 13682, "Rq1": 6957, "Rq5": 6362, "Rq10": 6031, "Rq15": 5954},
}


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _map(ax, xy, values, title, cmap="viridis", label="", vmin=None, vmax=None, hole=None):
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


def _grid_image(ax, field, extent, title, label, cmap="viridis", log=False):
    import matplotlib.colors as mc
    data = np.ma.masked_less_equal(field, 0) if log else field
    norm = mc.LogNorm() if log and np.any(field > 0) else None
    im = ax.imshow(data.T, origin="lower", extent=extent, cmap=cmap, norm=norm)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.figure.colorbar(im, ax=ax, shrink=0.8).set_label(label)


def write_report(out: Path, case) -> dict:
    """Draw the figures, write report.md and summary.json from a run's artifacts.

    Args:
        out: the run's folder (stage manifests, fe/, contact/, dynamics/, speed/).
        case: the validated case of the run.
    Returns:
        the summary dict written to summary.json.
    """
    plt = _plt()
    out = Path(out)
    summaries = {s: (read_manifest(out, s) or {}).get("summary", {}) for s in
                 ("mesh", "fe", "contact", "dynamics")}
    sp = out / "speed" / "speed_error.json"
    speed = json.loads(sp.read_text()) if sp.exists() else None
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    rm = ReducedModel.load(str(out / "fe" / "reduced_model.h5"))
    surfaces, extra = load_surfaces(out / "contact" / "surfaces.npz")
    dyn = summaries["dynamics"]
    levels = dyn["levels"]
    xy = np.asarray(rm.pair_xyz)[:, :2]
    area = np.asarray(rm.pair_area)
    g = case.geometry
    hole = g.hole_diameter
    extent = (-g.overlap / 2, g.overlap / 2, -g.plate_width / 2, g.plate_width / 2)
    curves = load_curves(out / "dynamics")
    rv = case.roughness.v_rq_um
    mid = len(levels) // 2

    def curve(cfg: str, i: int) -> CurveResult | None:
        return curves.get(CurveKey("v3", i, rv) if cfg == "v3" else CurveKey(cfg, i))

    configs = list(case.dynamics.configurations)
    colors = dict(zip(CONFIGURATIONS, ("k", "tab:blue", "tab:orange", "tab:green", "tab:red")))

    # --- FRFs per level (Figs. 11, 16) --------------------------------------------------------
    fig, axes = plt.subplots(1, len(levels), figsize=(5 * len(levels), 4), squeeze=False)
    for i, lv in enumerate(levels):
        ax = axes[0, i]
        for cfg in configs:
            cr = curve(cfg, i)
            if cr is None:
                continue
            a = np.where(cr.stable, cr.amplitude, np.nan)
            ax.plot(cr.omega_hz, a, color=colors[cfg], label=cfg)
            ax.plot(cr.omega_hz, np.where(cr.stable, np.nan, cr.amplitude), ":", color=colors[cfg])
        ax.set_title(f"excitation {lv:.3g} N ({lv / dyn['level_info']['macroslip']:.2f} × macroslip est.)",
                     fontsize=9)
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("mass A amplitude, 1st harmonic [mm]")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(figs / "frf_configurations.png", dpi=110)
    plt.close(fig)

    # --- FRFs vs Rq (Fig. 21) -------------------------------------------------------------------
    rq_curves = sorted(((k.rq_um, cr) for k, cr in curves.items()
                        if k.config == "v3" and k.level_index == mid), key=lambda t: t[0])
    base_mid = curve("baseline", mid)
    fig, ax = plt.subplots(figsize=(6, 4))
    if base_mid is not None:
        ax.plot(base_mid.omega_hz, base_mid.amplitude, "k", label="baseline (smooth)")
    for rq, cr in rq_curves:
        ax.plot(cr.omega_hz, cr.amplitude, label=f"v3, Rq = {rq_label(rq)} µm")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("mass A amplitude [mm]")
    ax.set_title(f"roughness sweep at {levels[mid]:.3g} N", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(figs / "frf_roughness.png", dpi=110)
    plt.close(fig)

    # --- pressure and morphology (Figs. 10, 13, 20) ----------------------------------------------
    rqs = sorted(surfaces)
    fig, axes = plt.subplots(1, 1 + len(rqs), figsize=(4.2 * (1 + len(rqs)), 3.6), squeeze=False)
    _grid_image(axes[0, 0], extra["p_s"], extent, "smooth FE pressure [MPa]", "MPa", cmap="jet")
    for k, rq in enumerate(rqs):
        sc = surfaces[rq]
        _grid_image(axes[0, k + 1], sc.pressure, extent,
                    f"Rq = {rq_label(rq)} µm: contact {100 * sc.contact_fraction:.1f} %", "MPa (log)",
                    cmap="jet", log=True)
    fig.tight_layout()
    fig.savefig(figs / "pressure_morphology.png", dpi=110)
    plt.close(fig)

    # --- stiffness maps (Figs. 8, 14) -------------------------------------------------------------
    sv = surfaces[rv]
    v3arr = out / "dynamics" / f"{v3_job_name(rv)}.arrays.npz"
    kt_v3 = np.load(v3arr)["kt"] if v3arr.exists() else None
    kn_v3 = np.load(v3arr)["kn"] if v3arr.exists() else sv.kn
    panels = [("k_n smooth-ms [N/mm³]", extra["kn_smooth"]), (f"k_n Rq={rq_label(rv)} µm (v3) [N/mm³]", kn_v3),
              ("k_t Mindlin (v2) [N/mm³]", sv.kt_mindlin)]
    if kt_v3 is not None:
        panels.append(("k_t from loops (v3) [N/mm³]", kt_v3))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.4 * len(panels), 3.6), squeeze=False)
    for ax, (t, v) in zip(axes[0], panels):
        _map(ax, xy, v, t, hole=hole)
    fig.tight_layout()
    fig.savefig(figs / "stiffness_maps.png", dpi=110)
    plt.close(fig)

    # --- status and energy at resonance (Figs. 12, 17) --------------------------------------------
    top = len(levels) - 1
    show = [c for c in ("baseline", "v1", "v3") if curve(c, top) is not None]
    if show:
        fig, axes = plt.subplots(2, len(show), figsize=(4.4 * len(show), 7), squeeze=False)
        import matplotlib.colors as mc
        cmap = mc.ListedColormap(["tab:blue", "tab:green", "tab:red", "tab:orange", "lightgrey"])
        for k, cfg in enumerate(show):
            cr = curve(cfg, top)
            _map(axes[0, k], xy, cr.status, f"{cfg}: status at resonance, {levels[top]:.3g} N",
                 cmap=cmap, vmin=-0.5, vmax=4.5, label="0 stuck 1 stick-slip 2 slip 3 part-open 4 open",
                 hole=hole)
            _map(axes[1, k], xy, cr.energy / area, f"{cfg}: dissipated energy / area",
                 cmap="magma", label="N·mm/mm² per cycle", hole=hole)
        fig.tight_layout()
        fig.savefig(figs / "status_energy.png", dpi=110)
        plt.close(fig)

    # --- hysteresis loops (Figs. 18, 22) ----------------------------------------------------------
    cr = curve("v3", top) or curve("baseline", top)
    if cr is not None:
        r = np.hypot(xy[:, 0], xy[:, 1])
        act = cr.status < 4
        picks = []
        for target in (hole / 2 + 1.0, (hole / 2 + g.overlap / 2) / 2, g.overlap / 2 * 1.3):
            cand = np.nonzero(act)[0]
            if len(cand):
                picks.append(int(cand[np.argmin(np.abs(r[cand] - target))]))
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        for i in dict.fromkeys(picks):
            axes[0].plot(np.append(cr.elem_u[i], cr.elem_u[i, 0]) * 1e3,
                         np.append(cr.elem_T[i], cr.elem_T[i, 0]),
                         label=f"element {i} (r = {r[i]:.1f} mm, {STATUS_NAMES[cr.status[i]]})")
        axes[0].set_xlabel("relative displacement u_x [µm]")
        axes[0].set_ylabel("tangential force T_x [N]")
        axes[0].set_title(f"{cr.config}: element loops at resonance, {cr.level:.3g} N", fontsize=9)
        axes[0].legend(fontsize=7)
        for cfg in configs:
            c2 = curve(cfg, top)
            if c2 is not None:
                axes[1].plot(np.append(c2.loop_u, c2.loop_u[0]) * 1e3, np.append(c2.loop_T, c2.loop_T[0]),
                             color=colors[cfg], label=cfg)
        axes[1].set_xlabel("mean relative displacement u_x [µm]")
        axes[1].set_ylabel("Σ T_x [N]")
        axes[1].set_title("whole joint", fontsize=9)
        axes[1].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(figs / "hysteresis_loops.png", dpi=110)
        plt.close(fig)

    # --- k_eq and contact fraction vs Rq (Figs. 15, 19) --------------------------------------------
    keq = {}

    def k_eq(k):  # Σ k_i A_i / Σ A_i, as JointModel.k_eq
        return float(np.sum(k * area) / np.sum(area))
    k_ref = case.contact.k_ref
    keq["baseline"] = {"kn": k_ref, "kt": k_ref}
    keq["smooth-ms"] = {"kn": k_eq(extra["kn_smooth"]), "kt": k_eq(extra["kn_smooth"])}
    keq["v1"] = {"kn": k_eq(np.where(sv.n0 > 0, k_ref, 0.0)), "kt": k_eq(np.where(sv.n0 > 0, k_ref, 0.0))}
    keq["v2"] = {"kn": k_eq(sv.kn), "kt": k_eq(sv.kt_mindlin)}
    if kt_v3 is not None:
        keq["v3"] = {"kn": k_eq(kn_v3), "kt": k_eq(kt_v3)}
    keq_rq = {}
    for rq in rqs:
        f = out / "dynamics" / f"{v3_job_name(rq)}.arrays.npz"
        if f.exists():
            a = np.load(f)
            keq_rq[rq] = {"kn": k_eq(a["kn"]), "kt": k_eq(a["kt"])}
        else:
            keq_rq[rq] = {"kn": k_eq(surfaces[rq].kn), "kt": k_eq(surfaces[rq].kt_mindlin)}
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
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
    axes[2].plot(rqs, [100 * surfaces[q].contact_fraction for q in rqs], "o-", label="fe-joint")
    pq = sorted(PAPER["contact_fraction"])
    axes[2].plot(pq, [PAPER["contact_fraction"][q] for q in pq], "kx--", label="paper")
    axes[2].set_xlabel("Rq [µm]")
    axes[2].set_ylabel("real contact area [%]")
    axes[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(figs / "keq_contact_fraction.png", dpi=110)
    plt.close(fig)

    # --- summary.json --------------------------------------------------------------------------------
    fe = summaries.get("fe", {})
    ct = summaries.get("contact", {})
    peaks = {k: {"level": v["level"], "peak_hz": v["peak_hz"], "peak_amplitude": v["peak_amplitude"],
                 "dissipated": v["dissipated"], "n_nonlinear": v["n_nonlinear"], "seconds": v["seconds"],
                 "n_points": v["n_points"], "n_active": v["n_active"]}
             for k, v in dyn["curves"].items()}
    stage_seconds = {}
    for s in ("mesh", "fe", "contact", "dynamics"):
        try:
            stage_seconds[s] = json.loads((out / "stages" / f"{s}.json").read_text())["seconds"]
        except (OSError, ValueError, KeyError):
            pass
    summary = {
        "case": case.name,
        "mesh": {k: summaries.get("mesh", {}).get(k) for k in ("n_nodes", "n_cells", "n_dofs", "n_pairs")},
        "first_elastic_hz_full_free": (fe.get("full_elastic_hz") or [None])[0],
        "reduced_vs_full_max_rel_error": fe.get("max_rel_freq_error"),
        "stuck_frequency_hz": dyn["f_lin"],
        "levels_N": levels, "macroslip_estimate_N": dyn["level_info"]["macroslip"],
        "levels_over_macroslip": [lv / dyn["level_info"]["macroslip"] for lv in levels],
        "contact_fraction": {rq_label(rq): surfaces[rq].contact_fraction for rq in rqs},
        "kn_smooth_mean": float(np.mean(extra["kn_smooth"])), "kn_smooth_max": float(np.max(extra["kn_smooth"])),
        "k_eq": keq, "k_eq_vs_rq": {rq_label(q): v for q, v in keq_rq.items()},
        "peaks": peaks, "v3": {k: {"converged": v.get("converged"), "passes": len(v.get("history", [])),
                                   "history": v.get("history")} for k, v in dyn.get("v3", {}).items()},
        "coupling_rel_error": ct.get("coupling_rel_error"),
        "linear_peak_rel_error": dyn.get("linear_peak_rel_error"),
        "timings_s": {"stages": stage_seconds, "fe": fe.get("timings", {}),
                      "contact": {k: v.get("seconds") for k, v in ct.get("surfaces", {}).items()}},
    }
    if speed:
        summary["speed_vs_error"] = speed
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    (out / "report.md").write_text(_markdown(case, summary, levels, configs, curve, rqs, surfaces, speed))
    return summary


def _fmt(x, f="{:.4g}"):
    return "–" if x is None else f.format(x)


def _markdown(case, s, levels, configs, curve, rqs, surfaces, speed) -> str:
    L = [f"# fe-joint report: {case.name}", ""]
    m = s["mesh"]
    L += [f"Mesh: {m.get('n_nodes')} nodes, {m.get('n_cells')} P{case.geometry.order} tetrahedra, "
          f"{m.get('n_dofs')} DOFs, {m.get('n_pairs')} friction elements (matched pairs). "
          f"Reduced model vs full FE, first elastic modes: max relative error "
          f"{_fmt(s['reduced_vs_full_max_rel_error'], '{:.1e}')}. Zero-roughness BEM vs FE pressure: "
          f"{_fmt(s['coupling_rel_error'], '{:.1e}')}. Small-excitation FRF peak vs stuck linear mode: "
          f"{_fmt(s['linear_peak_rel_error'], '{:.1e}')}.", ""]
    L += ["## Excitation levels", "",
          f"Stuck-joint estimate (baseline, ζ = {case.reduction.damping_ratio:g}): macroslip at "
          f"{s['macroslip_estimate_N']:.3g} N. The paper's 500/1000/2000 N would put this resonator in gross "
          "slip, so the levels are where 10 % and 50 % of the loaded area would slip if the joint "
          "stayed linear, and half the linear macroslip estimate (friction damping keeps the real slip lower; see the slipping elements below).", "",
          "| level | N | level / macroslip |", "|---|---|---|"]
    for i, (lv, r) in enumerate(zip(levels, s["levels_over_macroslip"])):
        L.append(f"| L{i} | {lv:.3g} | {r:.3f} |")
    L += ["", "## Frequency responses", "", "![FRFs](figures/frf_configurations.png)", "",
          "| configuration | f stuck [Hz] | " + " | ".join(
              f"L{i}: peak [Hz] / amp [µm] / elements slipping or opening / E [N·mm]" for i in range(len(levels))) + " |",
          "|---|---|" + "---|" * len(levels)]
    for cfg in configs:
        row = [cfg, _fmt(s["stuck_frequency_hz"].get(cfg if cfg != "v3" else "v2"), "{:.2f}")]
        for i in range(len(levels)):
            cr = curve(cfg, i)
            row.append("–" if cr is None else
                       f"{cr.peak_hz:.2f} / {1e3 * cr.peak_amplitude:.3g} / {cr.n_nonlinear} of {cr.n_active} "
                       f"/ {cr.dissipated:.3g}")
        L.append("| " + " | ".join(row) + " |")
    L += ["", "(v3's stuck frequency column shows v2's, its starting point.)", "",
          "![FRF vs Rq](figures/frf_roughness.png)", "",
          "## Contact", "", "![pressure](figures/pressure_morphology.png)", "",
          "| Rq [µm] | real contact area [%] | paper [%] | k_n mean [N/mm³] | k_n max | k_n,eq (v3) | k_t,eq (v3) |",
          "|---|---|---|---|---|---|---|"]
    for rq in rqs:
        sc = surfaces[rq]
        kq = s["k_eq_vs_rq"].get(rq_label(rq), {})
        L.append(f"| {rq_label(rq)} | {100 * sc.contact_fraction:.2f} | {PAPER['contact_fraction'].get(rq, '–')} | "
                 f"{np.mean(sc.kn):.3g} | {np.max(sc.kn):.3g} | {_fmt(kq.get('kn'), '{:.3g}')} | "
                 f"{_fmt(kq.get('kt'), '{:.3g}')} |")
    L += ["", f"Smooth multiscale (Rq = {case.roughness.smooth_rq_um:g} µm) k_n: mean {s['kn_smooth_mean']:.3g}, "
          f"max {s['kn_smooth_max']:.3g} N/mm³ (paper: 6.6e4 and 1.74e5).", "",
          "![stiffness](figures/stiffness_maps.png)", "",
          "| configuration | k_n,eq [N/mm³] | k_t,eq [N/mm³] |", "|---|---|---|"]
    for k, v in s["k_eq"].items():
        L.append(f"| {k} | {v['kn']:.3g} | {v['kt']:.3g} |")
    L += ["", "![k_eq](figures/keq_contact_fraction.png)", "",
          "## Contact state, energy, hysteresis at resonance", "",
          "![status](figures/status_energy.png)", "", "![loops](figures/hysteresis_loops.png)", "",
          "## v3 fixed point (k_t from the BEM loops at resonance)", "",
          "Pass 0 is v2 (a full sweep); later passes search the peak locally from the previous one "
          "(`local`, a full `sweep` if that fails), with Aitken-relaxed stiffness updates. The last "
          "column compares the converged joint's full FRF peak with the last pass's.", "",
          "| surface | passes | converged | peak per pass [Hz] | k_t,eq per pass [N/mm³] | search: points, s | relaxation | full FRF vs last pass |",
          "|---|---|---|---|---|---|---|---|"]
    for k, v in s["v3"].items():
        h = v.get("history") or []
        peaks_ = ", ".join("%.3f" % x["peak_hz"] for x in h)
        kts_ = ", ".join("%.3g" % x["kt_eq"] for x in h)
        how = ", ".join(f"{x.get('search', 'sweep')} {x.get('points', '')} pts {x.get('seconds', 0):.0f} s"
                        for x in h)
        rel = ", ".join("%.2f" % x["relaxation"] for x in h if x.get("relaxation") is not None)
        last = h[-1] if h else {}
        agree = (f"{abs(last['sweep_peak_hz'] - last['peak_hz']) / last['peak_hz']:.1e}"
                 if "sweep_peak_hz" in last else "same curve")
        L.append(f"| {k} | {len(h)} | {v.get('converged')} | {peaks_} | {kts_} | {how} | {rel} | {agree} |")
    L += ["", "## Cost", "", "| stage | wall time [s] |", "|---|---|"]
    for k, v in s["timings_s"]["stages"].items():
        L.append(f"| {k} | {v:.1f} |")
    L += ["", "| FRF curve | points | wall time [s] |", "|---|---|---|"]
    for k, v in s["peaks"].items():
        L.append(f"| {k} | {v['n_points']} | {v['seconds']:.1f} |")
    L += ["", "The paper's FORSE curves took 13 682 s (smooth, 1000 N) and 6 957 / 6 362 / 6 031 / 5 954 s "
          "(Rq 1 / 5 / 10 / 15 µm) on a 20-core node; its BEM analyses are in its Table 3."]
    if speed:
        L += ["", "## Speed against error", ""]
        for title, rows in speed.items():
            if not rows:
                continue
            keys = list(rows[0])
            L += [f"### {title}", "", "| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
            for r in rows:
                L.append("| " + " | ".join(_fmt(r[k]) if isinstance(r[k], float) else str(r[k]) for k in keys) + " |")
            L.append("")
    return "\n".join(L) + "\n"
