"""``report.md``: the run's tables and figures as Markdown, one function per section."""
from __future__ import annotations

import numpy as np

from ..model.interface_motion import RIGID_NAMES
from ..study.artifacts import rq_label
from . import backbones
from .data import PAPER, ReportData


def _fmt(x: float | None, f: str = "{:.4g}") -> str:
    """``x`` formatted with ``f``, an en dash for None."""
    return "–" if x is None else f.format(x)


def _header(data: ReportData, s: dict) -> list[str]:
    """Title, mesh size and the three consistency checks."""
    m, order = s["mesh"], data.case.geometry.order
    return [f"# fe-joint report: {data.case.name}", "",
            f"Mesh: {m.get('n_nodes')} nodes, {m.get('n_cells')} P{order} tetrahedra, "
            f"{m.get('n_dofs')} DOFs, {m.get('n_pairs')} friction elements (matched pairs). "
            f"Reduced model vs full FE, first elastic modes: max relative error "
            f"{_fmt(s['reduced_vs_full_max_rel_error'], '{:.1e}')}. Zero-roughness BEM vs FE pressure: "
            f"{_fmt(s['coupling_rel_error'], '{:.1e}')}. Small-excitation FRF peak vs stuck linear mode: "
            f"{_fmt(s['linear_peak_rel_error'], '{:.1e}')}.", ""]


def _levels(data: ReportData, s: dict) -> list[str]:
    """The excitation levels (N) and their ratio to the macroslip estimate."""
    L = ["## Excitation levels", "",
         f"Stuck-joint estimate (baseline, ζ = {data.case.reduction.damping_ratio:g}): macroslip at "
         f"{s['macroslip_estimate_N']:.3g} N. The paper's 500/1000/2000 N would put this resonator in gross "
         "slip, so the levels are where 10 % and 50 % of the loaded area would slip if the joint "
         "stayed linear, and half the linear macroslip estimate (friction damping keeps the real slip "
         "lower; see the slipping elements below).", "",
         "| level | N | level / macroslip |", "|---|---|---|"]
    for i, (lv, r) in enumerate(zip(data.levels, s["levels_over_macroslip"])):
        L.append(f"| L{i} | {lv:.3g} | {r:.3f} |")
    return L


def _frf_table(data: ReportData, s: dict) -> list[str]:
    """Per configuration: stuck frequency (Hz) and, per level, peak Hz / µm / nonlinear elements / N·mm."""
    n = len(data.levels)
    L = ["", "## Frequency responses", "", "![FRFs](figures/frf_configurations.png)", "",
         "| configuration | f stuck [Hz] | " + " | ".join(
             f"L{i}: peak [Hz] / amp [µm] / elements slipping or opening / E [N·mm]" for i in range(n)) + " |",
         "|---|---|" + "---|" * n]
    for cfg in data.configs:
        row = [cfg, _fmt(s["stuck_frequency_hz"].get(cfg), "{:.2f}")]
        for i in range(n):
            cr = data.curve(cfg, i)
            row.append("–" if cr is None else
                       f"{cr.peak_hz:.2f} / {1e3 * cr.peak_amplitude:.3g} / {cr.n_nonlinear} of {cr.n_active} "
                       f"/ {cr.dissipated:.3g}")
        L.append("| " + " | ".join(row) + " |")
    L += ["", "(v3's stuck frequency is that of its converged k_n, k_t.)", "",
          "![FRF vs Rq](figures/frf_roughness.png)", ""]
    return L


def _contact(data: ReportData, s: dict) -> list[str]:
    """Per Rq: contact area (%, and the paper's), k_n mean/max and k_eq (N/mm³); k_eq per configuration."""
    L = ["## Contact", "", "![pressure](figures/pressure_morphology.png)", "",
         "| Rq [µm] | real contact area [%] | paper [%] | k_n mean [N/mm³] | k_n max | k_n,eq (v3) | k_t,eq (v3) |",
         "|---|---|---|---|---|---|---|"]
    for rq in data.rqs:
        sc = data.surfaces[rq]
        kq = s["k_eq_vs_rq"].get(rq_label(rq), {})
        L.append(f"| {rq_label(rq)} | {100 * sc.contact_fraction:.2f} | {PAPER['contact_fraction'].get(rq, '–')} | "
                 f"{np.mean(sc.kn):.3g} | {np.max(sc.kn):.3g} | {_fmt(kq.get('kn'), '{:.3g}')} | "
                 f"{_fmt(kq.get('kt'), '{:.3g}')} |")
    L += ["", f"Smooth multiscale (Rq = {data.case.roughness.smooth_rq_um:g} µm) k_n: mean {s['kn_smooth_mean']:.3g}, "
          f"max {s['kn_smooth_max']:.3g} N/mm³ (paper: 6.6e4 and 1.74e5).", "",
          "![stiffness](figures/stiffness_maps.png)", "",
          "| configuration | k_n,eq [N/mm³] | k_t,eq [N/mm³] |", "|---|---|---|"]
    for k, v in s["k_eq"].items():
        L.append(f"| {k} | {v['kn']:.3g} | {v['kt']:.3g} |")
    L += ["", "![k_eq](figures/keq_contact_fraction.png)", "",
          "## Contact state, energy, hysteresis at resonance", "",
          "![status](figures/status_energy.png)", "", "![loops](figures/hysteresis_loops.png)", ""]
    return L


def _joint_state(s: dict) -> list[str]:
    """Per configuration at the top level: the cycle-mean joint shear (N, and as a share of
    μ × bolt force), the mean relative slip (µm), the Σ T_x loop's area and the dissipated energy."""
    L = ["Whole joint at resonance, top level: the cycle-mean shear Σ T_x is a static force the "
         "joint carries under a zero-mean excitation: the elements of the outer ring open and "
         "re-stick displaced every cycle (a ratchet: README, \"Static shear in the joint\"), and "
         "the bolt's shank carries −Σ T_x by equilibrium; it grows with H (H = 1 gives about half "
         "of H = 7). The area of Σ T_x against the mean u_x is not the dissipated energy (elements "
         "move with different phases).", "",
         "| configuration | mean Σ T_x [N] | / μ·F_bolt | mean u_x [µm] | ∮ Σ T_x dū [N·mm] | dissipated W [N·mm] |",
         "|---|---|---|---|---|---|"]
    for cfg, v in s["joint_shear_top_level"].items():
        L.append(f"| {cfg} | {v['mean_shear_N']:.4g} | {v['share_of_mu_bolt_force']:.3f} | "
                 f"{1e3 * v['mean_slip_mm']:.4g} | {v['mean_slip_loop_area']:.4g} | {v['dissipated']:.4g} |")
    return L + [""]


def _interface_motion(s: dict) -> list[str]:
    """How the interface moves in each configuration's stuck mode of interest (shares of Σ A|u|²)."""
    L = ["How the interface moves in the stuck mode of interest (share of the relative motion's "
         "area-weighted mean square; `mean/rms u_x` near 0: the slips cancel over the interface, "
         "the joint does not slide as a whole):", "",
         "| configuration | f [Hz] | " + " | ".join(RIGID_NAMES) + " | deformation x / y / z | mean/rms u_x |",
         "|---|---|" + "---|" * len(RIGID_NAMES) + "---|---|"]
    for name, m in s["interface_motion"].items():
        L.append(f"| {name} | {m['frequency_hz']:.2f} | " + " | ".join(f"{m[n]:.3f}" for n in RIGID_NAMES)
                 + " | " + " / ".join(f"{m[f'deform {c}']:.2f}" for c in "xyz")
                 + f" | {m['mean_over_rms_ux']:.3f} |")
    return L + [""]


def _v3_row(name: str, v: dict) -> str:
    """One fixed point's row: passes, peaks (Hz), k_t,eq (N/mm³), searches, relaxations, final check."""
    h = v.get("history") or []
    peaks = ", ".join("%.3f" % x["peak_hz"] for x in h)
    kts = ", ".join("%.3g" % x["kt_eq"] for x in h)
    how = ", ".join(f"{x.get('search', 'sweep')} {x.get('points', '')} pts {x.get('seconds', 0):.0f} s"
                    for x in h)
    rel = ", ".join("%.2f" % x["relaxation"] for x in h if x.get("relaxation") is not None)
    last = h[-1] if h else {}
    agree = (f"{abs(last['sweep_peak_hz'] - last['peak_hz']) / last['peak_hz']:.1e}"
             if "sweep_peak_hz" in last else "same curve")
    return f"| {name} | {len(h)} | {v.get('converged')} | {peaks} | {kts} | {how} | {rel} | {agree} |"


def _v3(s: dict) -> list[str]:
    """The v3 fixed points, one row each."""
    L = ["## v3 fixed point (k_t from the BEM loops at resonance)", "",
         "Pass 0 is v2 (a full sweep); later passes search the peak locally from the previous one "
         "(`local`, a full `sweep` if that fails), with Aitken-relaxed stiffness updates. The last "
         "column compares the converged joint's full FRF peak with the last pass's.", "",
         "| surface | passes | converged | peak per pass [Hz] | k_t,eq per pass [N/mm³] | search: points, s "
         "| relaxation | full FRF vs last pass |",
         "|---|---|---|---|---|---|---|---|"]
    return L + [_v3_row(k, v) for k, v in s["v3"].items()]


def _cost(s: dict) -> list[str]:
    """Wall time per stage and per FRF curve, s, beside the paper's."""
    L = ["", "## Cost", "", "| stage | wall time [s] |", "|---|---|"]
    L += [f"| {k} | {v:.1f} |" for k, v in s["timings_s"]["stages"].items()]
    L += ["", "| FRF curve | points | wall time [s] |", "|---|---|---|"]
    L += [f"| {k} | {v['n_points']} | {v['seconds']:.1f} |" for k, v in s["peaks"].items()]
    L += backbones.cost_rows(s)
    L += ["", "The paper's FORSE curves took 13 682 s (smooth, 1000 N) and 6 957 / 6 362 / 6 031 / 5 954 s "
          "(Rq 1 / 5 / 10 / 15 µm) on a 20-core node; its BEM analyses are in its Table 3."]
    return L


def _speed(speed: dict | None) -> list[str]:
    """The speed-against-error tables (nothing when the run has none)."""
    if not speed:
        return []
    L = ["", "## Speed against error", ""]
    for title, rows in speed.items():
        if not rows:
            continue
        keys = list(rows[0])
        L += [f"### {title}", "", "| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
        for r in rows:
            L.append("| " + " | ".join(_fmt(r[k]) if isinstance(r[k], float) else str(r[k]) for k in keys) + " |")
        L.append("")
    return L


def report_markdown(data: ReportData, summary: dict) -> str:
    """The text of ``report.md``.

    Args:
        data: the run's artifacts (curves and surfaces for the tables).
        summary: the dict of :func:`~fe_joint.report.summary.build_summary` for the same data.
    Returns:
        Markdown text ending in a newline; figures are linked as ``figures/<name>.png``.
    """
    L = (_header(data, summary) + _levels(data, summary) + _frf_table(data, summary)
         + _contact(data, summary) + _joint_state(summary) + _interface_motion(summary)
         + _v3(summary) + backbones.markdown(data, summary) + _cost(summary)
         + _speed(data.speed))
    return "\n".join(L) + "\n"
