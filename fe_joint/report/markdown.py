"""``report.md``: the run's tables and figures as Markdown, one function per section."""
from __future__ import annotations

import numpy as np

from ..model.interface_motion import RIGID_NAMES
from ..study.artifacts import rq_label
from . import backbones, like_for_like, stiffness_definitions
from .findings import findings_markdown
from .paraview import paraview_markdown
from .provenance import parameters_markdown, provenance_markdown
from .table1 import table1_markdown
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


def _warnings(s: dict) -> list[str]:
    """The run's warnings (suspect results), one bullet each; nothing when there are none."""
    w = s.get("warnings") or []
    if not w:
        return []
    return ([f"**{len(w)} warning{'s' if len(w) > 1 else ''}** (results to treat with care):", ""]
            + [f"- {x['message']}" for x in w] + [""])


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
         "| Rq [µm] | real contact / usable overlap [%] | paper (/ whole overlap) [%] | k_n mean [N/mm³] | k_n max | k_n,eq (v3) | k_t,eq (v3) |",
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
    L += ["", "![k_eq](figures/keq_contact_fraction.png)", ""]
    return L


def _state_figures() -> list[str]:
    """The contact status, energy and loop figures at resonance."""
    return ["## Contact state, energy, hysteresis at resonance", "",
            "![status](figures/status_energy.png)", "", "![loops](figures/hysteresis_loops.png)", ""]


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


def _v3_row(name: str, v: dict, seconds: list) -> str:
    """One fixed point's row: passes, peaks (Hz), k_t,eq (N/mm³), searches and their wall times
    (``seconds`` per pass), relaxations, final check."""
    h = v.get("history") or []
    peaks = ", ".join("%.3f" % x["peak_hz"] for x in h)
    kts = ", ".join("%.3g" % x["kt_eq"] for x in h)
    secs = list(seconds) + [None] * (len(h) - len(seconds))
    how = ", ".join(f"{x.get('search', 'sweep')} {x.get('points', '')} pts {sec or 0:.0f} s"
                    for x, sec in zip(h, secs))
    rel = ", ".join("%.2f" % x["relaxation"] for x in h if x.get("relaxation") is not None)
    last = h[-1] if h else {}
    agree = (f"{abs(last['sweep_peak_hz'] - last['peak_hz']) / last['peak_hz']:.1e}"
             if "sweep_peak_hz" in last else "same curve")
    return f"| {name} | {len(h)} | {v.get('converged')} | {peaks} | {kts} | {how} | {rel} | {agree} |"


def _v3(s: dict, t: dict) -> list[str]:
    """The v3 fixed points, one row each (``t``: the timings)."""
    L = ["## v3 fixed point (k_t from the BEM loops at resonance)", "",
         "Pass 0 is v2: a full sweep on the comparison surface (it is also the study's v2 curve), "
         "elsewhere a local search from just above the stuck frequency; later passes search the "
         "peak locally from the previous one "
         "(`local`, a full `sweep` if that fails), with Aitken-relaxed stiffness updates. The last "
         "column compares the converged joint's full FRF peak with the last pass's.", "",
         "| surface | passes | converged | peak per pass [Hz] | k_t,eq per pass [N/mm³] | search: points, s "
         "| relaxation | full FRF vs last pass |",
         "|---|---|---|---|---|---|---|---|"]
    return L + [_v3_row(k, v, t["v3"].get(k, [])) for k, v in s["v3"].items()]


def _cost(s: dict, t: dict) -> list[str]:
    """Wall time per stage and per FRF curve, s (from the timings ``t``), beside the paper's."""
    q = t.get("queues", {})
    L = ["", "## Cost", "", "| stage | wall time [s] | ranks busy in its job queue |", "|---|---|---|"]
    L += [f"| {k} | {v:.1f} | {_busy(q.get(k)) or _alone(t, k)} |" for k, v in t["stages"].items()]
    L += ["", "| FRF curve | points | wall time [s] | sweep's Newton tolerance |",
          "|---|---|---|---|"]
    L += [f"| {k} | {v['n_points']} | {t['curves'][k]:.1f} | {_sweep_tol(v)} |"
          for k, v in s["peaks"].items()]
    L += backbones.cost_rows(s, t)
    L += ["", "The paper's FORSE curves took 13 682 s (smooth, 1000 N) and 6 957 / 6 362 / 6 031 / 5 954 s "
          "(Rq 1 / 5 / 10 / 15 µm) on a 20-core node; its BEM analyses are in its Table 3."]
    return L


def _alone(t: dict, stage: str) -> str:
    """"rank 0 alone …" for a stage that ran on one rank of several (``runner.SOLO_STAGES``),
    else ""."""
    stages = t.get("provenance", {}).get("stages", {})
    counts = [v.get("ranks") for v in stages.values() if isinstance(v.get("ranks"), int)]
    if (stages.get(stage) or {}).get("ranks") == 1 and counts and max(counts) > 1:
        return "rank 0 alone (the other ranks built the speed stage's coarser FE models meanwhile)"
    return ""


def _busy(queue: dict | None) -> str:
    """Each rank's busy share of a stage's job queue, and the queue's wall time ("" none)."""
    if not queue:
        return ""
    return (" / ".join(f"{100 * b:.0f} %" for b in queue["busy"])
            + f" of {queue['seconds']:.1f} s")


def _sweep_tol(peak: dict) -> str:
    """The tolerance a curve's sweep ended at, and where it was tightened at a fold ("" unknown)."""
    tol, at = peak.get("sweep_tol"), peak.get("handover_hz")
    if tol is None:
        return ""
    return f"{tol:.0e}" + ("" if at is None else f" from {at:.2f} Hz (thrashed at a fold)")


def _speed(speed: dict | None) -> list[str]:
    """The speed-against-error tables (nothing when the run has none)."""
    if not speed:
        return []
    L = ["", "## Speed against error", ""]
    for title, rows in speed.items():
        if not rows:
            continue
        keys = list(dict.fromkeys(k for r in rows for k in r))    # a row may add a note
        L += [f"### {title}", "", "| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
        for r in rows:
            L.append("| " + " | ".join(_fmt(r[k]) if isinstance(r.get(k), float) else str(r.get(k, ""))
                                       for k in keys) + " |")
        L.append("")
    return L


def report_markdown(data: ReportData, summary: dict, timings: dict) -> str:
    """The text of ``report.md``.

    Args:
        data: the run's artifacts (curves and surfaces for the tables).
        summary: the dict of :func:`~fe_joint.report.summary.build_summary` for the same data.
        timings: the dict of :func:`~fe_joint.report.summary.build_timings` (the cost table).
    Returns:
        Markdown text ending in a newline; figures are linked as ``figures/<name>.png``.
    """
    head = _header(data, summary)
    L = (head[:2] + _warnings(summary) + findings_markdown(summary["findings"] + timings.get("findings", [])) + head[2:]
         + parameters_markdown(data) + table1_markdown(data)
         + _levels(data, summary) + _frf_table(data, summary)
         + _damping(data, summary) + _contact(data, summary) + _contact_area(data, summary)
         + _seeds(data, summary) + _hardness(data, summary)
         + stiffness_definitions.markdown(data, summary) + _state_figures()
         + _paper_figures(data) + paraview_markdown(data)
         + _joint_state(summary) + _interface_motion(summary)
         + _v3(summary, timings) + backbones.markdown(data, summary)
         + like_for_like.markdown(data, summary) + _cost(summary, timings) + _speed(data.speed)
         + [""] + provenance_markdown(data, timings["provenance"]))
    return "\n".join(L) + "\n"


def _trend(a: float, b: float) -> str:
    """'rises' / 'falls' from a to b."""
    return "rises" if b > a else "falls"


def _damping(data: ReportData, s: dict) -> list[str]:
    """Friction damping as ζ per curve (issue 13, item 1): definition, tables, the paper's claim."""
    zs = s["structural_damping_ratio"]
    pk = s["peaks"]
    L = ["## Damping at resonance (like for like: ζ, not energy)", "",
         "A linear viscous damper of modal ratio ζ dissipates 2π ζ ω² a² per cycle on a mode φ "
         "(mass-normalized) moving with modal amplitude a at ω. The friction energy per cycle at a "
         "peak is therefore reported as ζ_fric = E_fric / (2π ω² a²), with ω the peak frequency, φ the "
         "configuration's stuck mode of interest and a = X / |φ_e| its first-harmonic modal amplitude "
         f"(X the response amplitude at the excitation node); ζ_total = ζ_struct + ζ_fric (ζ_struct = {zs:g}) "
         "and the loss factor η = 2 ζ_total. Check: at a peak the force works in quadrature with the "
         "response, so ζ_total must also equal F |φ_e| / (2 ω² a) (last column; the linear check curve "
         "gives back ζ_struct). The raw energy is not comparable between joints at one force: at "
         "resonance E ≈ π F X, so E rises wherever X does.", "",
         "| curve | level [N] | peak [Hz] | X [µm] | E_fric [N·mm] | ζ_fric | ζ_total | η | ζ from F, X (check) |",
         "|---|---|---|---|---|---|---|---|---|"]
    for name in sorted(pk):
        p = pk[name]
        if "zeta_fric" not in p:
            continue
        L.append(f"| {name} | {p['level']:.3g} | {p['peak_hz']:.2f} | {1e3 * p['peak_amplitude']:.4g} | "
                 f"{p['dissipated']:.3g} | {p['zeta_fric']:.3e} | {p['zeta_total']:.3e} | "
                 f"{p['loss_factor']:.3e} | {p['zeta_from_amplitude']:.3e} |")
    on = s["slip_onset_response_mm"]
    L += ["", "Slip onset in the stuck mode (linear estimate): the response amplitude X at which the "
          f"elements holding the first {100 * 0.1:g} % of the clamping load would slip "
          "(μ N0 = k_t A |u_t| in the stuck mode). A joint that starts to slip later dissipates less "
          "at the same amplitude.", "",
          "| joint | slip onset X [µm] |", "|---|---|"]
    L += [f"| {k} | {1e3 * v:.4g} |" for k, v in on["configurations"].items()]
    L += [f"| v3, Rq {k} µm | {1e3 * v:.4g} |" for k, v in on["rq"].items()]
    L += [""] + _damping_findings(data, s) + [""]
    return L


def _damping_findings(data: ReportData, s: dict) -> list[str]:
    """The paper's damping claims against this run's ζ, with the numbers (agree / disagree)."""
    pk, on = s["peaks"], s["slip_onset_response_mm"]
    out = []
    mid = data.mid
    sweep = sorted((c.rq_um, pk[k.name]) for k, c in data.curves.items()
                   if c.config == "v3" and k.level_index == mid and c.rq_um == c.rq_um
                   and "zeta_fric" in pk[k.name])
    if len(sweep) >= 2:
        (r0, a), (r1, b) = sweep[0], sweep[-1]
        agree = b["zeta_fric"] > a["zeta_fric"]
        o0, o1 = on["rq"].get(rq_label(r0)), on["rq"].get(rq_label(r1))
        out.append(
            f"**Rq sweep (v3, L{mid} = {a['level']:.3g} N).** Paper: the higher Rq, the higher the energy "
            f"dissipation and the more damped the FRF. Here from Rq {r0:g} to {r1:g} µm the energy per "
            f"cycle {_trend(a['dissipated'], b['dissipated'])} ({a['dissipated']:.3g} → {b['dissipated']:.3g} N·mm) "
            f"and so does the amplitude ({1e3 * a['peak_amplitude']:.4g} → {1e3 * b['peak_amplitude']:.4g} µm), "
            f"but ζ_fric {_trend(a['zeta_fric'], b['zeta_fric'])} ({a['zeta_fric']:.3e} → {b['zeta_fric']:.3e}; "
            f"ζ_total {a['zeta_total']:.3e} → {b['zeta_total']:.3e}): in damping terms this "
            f"{'agrees' if agree else 'disagrees'} with the paper"
            + ("." if agree else
               f"; the rougher joint is softer (k_t,eq {s['k_eq_vs_rq'][rq_label(r0)]['kt']:.3g} → "
               f"{s['k_eq_vs_rq'][rq_label(r1)]['kt']:.3g} N/mm³), so its elements reach μN0 only at a "
               f"larger amplitude (slip onset {1e3 * o0:.4g} → {1e3 * o1:.4g} µm) and it dissipates less "
               "per unit of modal energy; the energy rises only because the less damped response is "
               "larger (E ≈ π F X at resonance)."))
    rows = []
    for i in range(len(data.levels)):
        b = pk.get(f"baseline@L{i}")
        v = data.curve("v3", i) or data.curve("v2", i)
        if b is None or v is None or "zeta_fric" not in b:
            continue
        vp = pk[v.key.name]
        rows.append((i, b, v.key.name, vp))
    if rows:
        parts = [f"L{i}: baseline {b['zeta_fric']:.3e} vs {n} {vp['zeta_fric']:.3e} "
                 f"(X {1e3 * b['peak_amplitude']:.4g} vs {1e3 * vp['peak_amplitude']:.4g} µm)"
                 for i, b, n, vp in rows]
        top = rows[-1]
        agree = top[3]["zeta_fric"] > top[1]["zeta_fric"]
        ob, ov = on["configurations"].get("baseline"), on["configurations"].get(top[2].split("-")[0].split("@")[0])
        v1 = pk.get(f"v1@L{top[0]}", {})
        v1_text = (f" v1 (rough loads, k_ref) has ζ_fric {v1['zeta_fric']:.3e} there: the rough load map "
                   f"alone {'raises' if v1['zeta_fric'] > top[1]['zeta_fric'] else 'lowers'} the damping, "
                   "the softer BEM stiffness lowers it." if "zeta_fric" in v1 else "")
        out.append(
            "**Multiscale vs baseline.** Paper (Figs. 16–18): the multiscale joints dissipate more and "
            f"respond less. Here ζ_fric at the peaks: {'; '.join(parts)}: this "
            f"{'agrees' if agree else 'disagrees'} with the paper at the top level"
            + ("." if agree or ob is None or ov is None else
               f"; the rough multiscale joint starts to slip later (slip onset {1e3 * ob:.4g} µm baseline, "
               f"{1e3 * ov:.4g} µm multiscale) because its k_t is lower.") + v1_text)
    return out


def _contact_area(data: ReportData, s: dict) -> list[str]:
    """The contact area on three nominal areas beside the paper's values, and the peak pressures."""
    ca = s["contact_area"]
    first = next(iter(ca.values()))
    H = s["material_hardness_MPa"]
    L = ["### Contact area: definition", "",
         f"Real contact area = the cells with p > 0 ({data.case.roughness.grid}² grid over the "
         f"{first['overlap_mm2']:.0f} mm² overlap). Our fraction divides by the usable overlap, the "
         f"overlap without the bolt hole ({first['usable_mm2']:.1f} mm²); the paper's \"total potential "
         "contact area\" is that of its 256² grid over the whole overlap, so the paper's fraction "
         f"divides by {first['overlap_mm2']:.0f} mm² (hole included); the region the smooth FE preload "
         f"closes is {first['fe_loaded_mm2']:.1f} mm². The peak pressure is the largest cell pressure "
         "(grid dependent: it grows as the cells shrink), beside the hardness "
         f"H = {H:g} MPa (stainless steel ≈ 200 HV).", "",
         "| Rq [µm] | real area [mm²] | / usable overlap (ours) [%] | / whole overlap (paper's) [%] | paper [%] "
         "| / FE-loaded [%] | peak pressure [MPa] | peak / H |",
         "|---|---|---|---|---|---|---|---|"]
    for rq in data.rqs:
        c = ca[rq_label(rq)]
        L.append(f"| {rq_label(rq)} | {c['real_mm2']:.2f} | {100 * c['fraction_usable']:.2f} | "
                 f"{100 * c['fraction_overlap']:.2f} | {PAPER['contact_fraction'].get(rq, '–')} | "
                 f"{100 * c['fraction_fe_loaded']:.2f} | {c['peak_pressure_MPa']:.4g} | "
                 + (f"{c['peak_pressure_MPa'] / H:.2f} |" if H > 0 else "– |"))
    return L + [""]


def _pm(st: dict, scale: float = 1.0, f: str = "{:.4g}") -> str:
    """'mean ± std (min–max)' of a statistics dict."""
    return (f"{f.format(scale * st['mean'])} ± {f.format(scale * st['std'])} "
            f"({f.format(scale * st['min'])}–{f.format(scale * st['max'])})")


def _seeds(data: ReportData, s: dict) -> list[str]:
    """Seed statistics per Rq (contact stage, no FRFs)."""
    if "seeds" not in s:
        return []
    L = ["## Surface realizations (seeds)", "",
         f"{data.case.roughness.seeds} realizations per Rq (seeds {data.case.roughness.seed} … "
         f"{data.case.roughness.seed + data.case.roughness.seeds - 1}; the first is the study's surface): mean "
         "± sample standard deviation (min–max). k_n,eq and k_t,eq are v2's (patch k_n at N0, Mindlin k_t; "
         "v3's k_t needs an FRF per seed, which is not run) and f stuck is v2's stuck breathing mode.", "",
         "| Rq [µm] | contact / usable [%] | contact / whole overlap [%] | paper [%] | k_n,eq [N/mm³] "
         "| k_t,eq [N/mm³] | f stuck [Hz] | loaded elements |",
         "|---|---|---|---|---|---|---|---|"]
    for rq in data.rqs:
        st = s["seeds"].get(rq_label(rq))
        if st is None:
            continue
        L.append(f"| {rq_label(rq)} | {_pm(st['contact_fraction'], 100, '{:.2f}')} | "
                 f"{_pm(st['contact_fraction_overlap'], 100, '{:.2f}')} | "
                 f"{PAPER['contact_fraction'].get(rq, '–')} | {_pm(st['kn_eq'], 1, '{:.3g}')} | "
                 f"{_pm(st['kt_eq'], 1, '{:.3g}')} | {_pm(st['stuck_hz'], 1, '{:.2f}')} | "
                 f"{_pm(st['loaded_elements'], 1, '{:.0f}')} |")
    return L + [""]


def _hardness(data: ReportData, s: dict) -> list[str]:
    """The sweep with the pressure capped at the hardness, beside the study's elastic one."""
    hv = s.get("hardness_variant")
    if not hv:
        return []
    H = hv["hardness_MPa"]
    L = ["## Hardness cap (the paper's next step)", "",
         f"The sweep's surfaces solved again with the pressure capped at H = {H:g} MPa (perfectly plastic "
         "asperities, plain clipping; the element patches capped too, k_n their unloading stiffness "
         "after the plastic first loading). Elastic → capped:", "",
         "| Rq [µm] | peak pressure elastic [MPa] | contact area at the cap [%] | contact / whole overlap [%] "
         "| k_n,eq (v2) [N/mm³] | k_t,eq (v2) [N/mm³] | f stuck (v2) [Hz] | loaded elements |",
         "|---|---|---|---|---|---|---|---|"]
    for k, v in hv["surfaces"].items():
        a, b = v["study"], v["capped"]
        L.append(f"| {k} | {a['peak_pressure']:.4g} | {100 * b['capped_share']:.1f} | "
                 f"{100 * a['contact_fraction_overlap']:.2f} → {100 * b['contact_fraction_overlap']:.2f} | "
                 f"{a['kn_eq']:.3g} → {b['kn_eq']:.3g} | {a['kt_eq']:.3g} → {b['kt_eq']:.3g} | "
                 f"{a['stuck_hz']:.2f} → {b['stuck_hz']:.2f} | {a['loaded_elements']} → {b['loaded_elements']} |")
    return L + [""]


#: the counterparts of the paper's figures (paper_figures.py): file stem → caption
PAPER_FIGURE_CAPTIONS = {
    "fig12_smooth_maps": "Paper Fig. 12: baseline (top) and smooth-ms (bottom): FE pressure, k_n, "
                         "status and dissipated energy at resonance (common scales per column).",
    "fig13_heights": "Paper Fig. 13: heights of the comparison surface and its contact morphology "
                     "under the bolt load.",
    "fig17_all_configurations": "Paper Fig. 17: every configuration at the lowest level (common "
                                "energy scale; the top level is in the figure above).",
    "fig21_levels": "Paper Fig. 21 at every level: forced FRFs where swept (solid, unstable dotted), "
                    "elsewhere synthesized from the joint's backbone (dashed).",
    "fig22_loops_rq": "Paper Fig. 22: whole-joint loops at resonance against Rq (area = dissipated "
                      "energy per cycle).",
    "ratio_maps_v3_v2": "v3 / v2 per element (k_n, k_t) and v3's k_t/k_n over Mindlin's ratio "
                        "(paper Fig. 14 b vs c).",
}


def _paper_figures(data: ReportData) -> list[str]:
    """Links to the paper-figure counterparts that were drawn, with their captions."""
    L = ["## Counterparts of the paper's figures", ""]
    for name, cap in PAPER_FIGURE_CAPTIONS.items():
        if (data.out / "figures" / f"{name}.png").exists():
            L += [cap, "", f"![{name}](figures/{name}.png)", ""]
    return L if len(L) > 2 else []
