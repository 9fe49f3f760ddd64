"""The report's section on the contact stiffness definitions (issue 13, items 3–4).

Reads ``contact/stiffness_definitions.json`` (k_n patch vs layer, reversal k_t/k_n per Rq),
``dynamics/stiffness_definitions/kt_definitions.json`` (k_t by stick, secant and energy at the v3
peaks) and the alternative joints' backbones beside it; the parents' backbones come from
``dynamics/backbones/``. Every function returns nothing (or []) when its files are missing.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..study.artifacts import BackboneKey, read_json_artifact, rq_label
from ..study.stiffness_definitions import FOLDER
from .data import PAPER, ReportData

#: the k_t definitions from the loop, in the tables' order
KT_DEFINITIONS = ("stick", "secant", "energy")


def _json(path: Path) -> dict | None:
    return read_json_artifact(path) if path.exists() else None


def _alt_backbones(data: ReportData, names: list[str]) -> dict:
    """name → BackboneResult of the alternative joints present."""
    from ..study.backbone import BackboneResult
    out = {}
    for n in names:
        f = data.out / "dynamics" / FOLDER / f"{n}.npz"
        if f.exists():
            out[n] = BackboneResult.load(f)
    return out


def _parent_key(parent: str, rq_um) -> BackboneKey:
    return BackboneKey(parent, rq_um if parent == "v3" else None)


def _snms(br) -> dict:
    """SNMS peaks [[Hz, mm] or None beyond the backbone, per level], whether the continuation
    reached its end, and the largest response amplitude it reached (mm)."""
    peaks = [[float(f), float(a)] if np.isfinite(f) and np.isfinite(a) else None
             for f, a in zip(br.snms_hz, br.snms_amplitude)]
    return {"peaks": peaks, "complete": bool(br.complete),
            "reached_mm": float(br.displacement_amplitude[-1])}


def section(data: ReportData) -> dict:
    """``summary.json["stiffness_definitions"]``: the contact stage's comparison, the loop
    definitions' statistics per Rq, v3's converged k_t/k_n, and per alternative joint its k_eq,
    stuck frequency and SNMS peaks next to its parent's ([[Hz, mm] per level]). {} when absent."""
    contact = _json(data.out / "contact" / "stiffness_definitions.json")
    loops = _json(data.out / "dynamics" / FOLDER / "kt_definitions.json")
    if contact is None and loops is None:
        return {}
    out: dict = {"contact": contact}
    out["v3_kt_over_kn"] = {}
    for rq, k in data.v3_arrays.items():
        live = k["kn"] > 0
        r = k["kt"][live] / k["kn"][live]
        out["v3_kt_over_kn"][rq_label(rq)] = {"mean": float(r.mean()), "min": float(r.min()),
                                              "max": float(r.max()),
                                              "eq_ratio": float(np.sum(k["kt"] * data.area)
                                                                / np.sum(k["kn"] * data.area))}
    if loops is not None:
        s = loops["summary"]
        out["loops"] = s["surfaces"]
        bbs = _alt_backbones(data, s["backbones"])
        alt = {}
        for name, j in s["joints"].items():
            parent = data.backbones.get(_parent_key(j["parent"], j["rq_um"]))
            alt[name] = {**j, "snms": _snms(bbs[name]) if name in bbs else None,
                         "parent_snms": _snms(parent) if parent is not None else None}
        out["alternatives"] = alt
    return out


def _stat(st: dict, f: str = "{:.3f}") -> str:
    return (f"{f.format(st['mean'])} ± {f.format(st['std'])} ({f.format(st['min'])}–{f.format(st['max'])})")


def _peaks(p) -> str:
    """SNMS peaks of a backbone entry (:func:`_snms`) as text; '–' without a backbone."""
    if not p:
        return "–"
    txt = " · ".join("beyond" if x is None else f"{x[0]:.2f} / {1e3 * x[1]:.4g}" for x in p["peaks"])
    return txt if p["complete"] else f"{txt} (backbone stops at {1e3 * p['reached_mm']:.3g} µm)"


def _kn_table(s: dict) -> list[str]:
    """k_n patch vs layer: the contact stage's joints, with SNMS peaks where a backbone ran."""
    c = s["contact"]
    alt = s.get("alternatives") or {}
    J = c["joints"]
    L = ["| joint | k_n | k_n mean / max over loaded [N/mm³] | k_n,eq [N/mm³] | k_t,eq [N/mm³] "
         "| f stuck [Hz] | SNMS peaks L0 · L1 · L2 [Hz / µm] |", "|---|---|---|---|---|---|---|"]
    for name, v in J.items():
        layer = name.endswith("-layer")
        base = name.removesuffix("-layer")
        # the SNMS peaks: smooth-ms and the comparison surface's v2 have backbones
        key = "smooth-ms" if base == "smooth-ms" else ("v2" if base == f"v2-rq{s['v_rq']}" else None)
        peaks = None
        if key is not None:
            a = alt.get(f"{key}-layer")
            peaks = (a or {}).get("snms") if layer else (a or {}).get("parent_snms")
        L.append(f"| {base} | {'layer' if layer else 'patch (paper)'} | {v['kn_mean']:.4g} / "
                 f"{v['kn_max']:.4g} | {v['kn_eq']:.4g} | {v['kt_eq']:.4g} | {v['stuck_hz']:.2f} | "
                 f"{_peaks(peaks)} |")
    return L


def _kn_finding(s: dict) -> str:
    c = s["contact"]
    J, b = c["joints"], c["bulk"]
    sm, sl = J["smooth-ms"], J["smooth-ms-layer"]
    v = f"v2-rq{s['v_rq']}"
    txt = (f"**Finding (k_n).** The paper-literal patch k_n of smooth-ms is the bulk itself on "
           f"{100 * c['smooth_complete_share']:.0f} % of its loaded elements (k_n max = k_bulk = "
           f"{b['kn']:.4g} N/mm³: the flat punch of the {b['patch_side_mm']:.3g} mm patch, "
           f"{b['cells']}² cells; paper max {PAPER['kn_smooth_max']:.3g}), so its k_n measures the "
           f"patch size, not the interface. Without the bulk the smooth interface is tied "
           f"(layer capped at {c['cap']:g} k_bulk; stuck f {sm['stuck_hz']:.2f} → {sl['stuck_hz']:.2f} Hz; "
           f"caps " + " / ".join(c["cap_sensitivity_hz"]) + " k_bulk give "
           + " / ".join(f"{x:.2f}" for x in c["cap_sensitivity_hz"].values())
           + f" Hz: the cap used is {100 * abs(sl['stuck_hz'] / max(c['cap_sensitivity_hz'].values()) - 1):.2f} % "
           "from the stiffest, the tied limit).")
    if v in J and f"{v}-layer" in J:
        a, la = J[v], J[f"{v}-layer"]
        txt += (f" On the rough comparison surface the bulk is a smaller share: v2's k_n,eq "
                f"{a['kn_eq']:.3g} → {la['kn_eq']:.3g} N/mm³ ({100 * (la['kn_eq'] / a['kn_eq'] - 1):+.0f} %), "
                f"stuck f {a['stuck_hz']:.2f} → {la['stuck_hz']:.2f} Hz.")
    txt += _frf_sentence(s, ("smooth-ms-layer", "v2-layer"))
    return txt


def _frf_sentence(s: dict, names: tuple) -> str:
    """' In the FRFs (SNMS at L<mid>): <alt> f / amp vs its parent's ...' for the alternatives
    whose backbone and parent's reach the middle level ('' when none does)."""
    alt = s.get("alternatives") or {}
    parts = []
    for n in names:
        a = alt.get(n) or {}
        mine, par = a.get("snms"), a.get("parent_snms")
        if not mine or not par:
            continue
        m = len(mine["peaks"]) // 2
        x, y = mine["peaks"][m], par["peaks"][m]
        if x is None or y is None:
            parts.append(f"{n}: no SNMS peak at L{m} (backbone stops at {1e3 * mine['reached_mm']:.3g} µm)")
            continue
        parts.append(f"{n} {x[0]:.2f} Hz / {1e3 * x[1]:.4g} µm against {a['parent']}'s {y[0]:.2f} Hz / "
                     f"{1e3 * y[1]:.4g} µm ({100 * (x[1] / y[1] - 1):+.0f} % in amplitude)")
    return (" In the FRFs (SNMS peak at the middle level): " + "; ".join(parts) + ".") if parts else ""


def _kt_table(s: dict) -> list[str]:
    c = s["contact"]
    loops = s.get("loops") or {}
    L = ["| Rq [µm] | reversal k_t/k_n at N0 (contact stage) | v3 converged k_t/k_n: mean (min–max); k_t,eq/k_n,eq "
         "| stick / Mindlin at the v3 peak | secant / Mindlin | energy / Mindlin "
         "| k_t,eq stick · secant · energy / Mindlin's |", "|---|---|---|---|---|---|---|"]
    for lab, r in c["reversal_ratio"].items():
        v3 = s["v3_kt_over_kn"].get(lab)
        lp = loops.get(lab)
        v3t = "–" if v3 is None else f"{v3['mean']:.4f} ({v3['min']:.3f}–{v3['max']:.3f}); eq {v3['eq_ratio']:.4f}"
        cells = ["–"] * 4
        if lp is not None:
            cells = [_stat(lp[k]["over_mindlin"]) for k in KT_DEFINITIONS]
            cells.append(" · ".join(f"{lp[k]['kt_eq'] / lp['kt_eq_mindlin']:.3f}" for k in KT_DEFINITIONS))
        L.append(f"| {lab} | {_stat(r['stats'], '{:.4f}')} | {v3t} | " + " | ".join(cells) + " |")
    return L


def _kt_finding(s: dict) -> str:
    c = s["contact"]
    m = c["mindlin_ratio"]
    means = [r["stats"]["mean"] for r in c["reversal_ratio"].values()]
    txt = (f"**Finding (k_t).** The reversal slope is the stuck stiffness of the contact set, and "
           f"for two steel bodies a stuck set obeys Mindlin's ratio: k_t/k_n at reversal averages "
           f"{min(means):.4f}–{max(means):.4f} over the Rq (Mindlin {m:.4f}; a whole stuck patch "
           f"{c['bulk']['kt_over_kn']:.4f}), with a local spread of a few per cent from the contact "
           f"sets' shapes. So v3 with the reversal k_t is v2 with k_n re-evaluated at the cycle-mean "
           f"load, by construction.")
    loops = s.get("loops") or {}
    if loops:
        lab = s["v_rq"] if s["v_rq"] in loops else max(loops, key=lambda k: loops[k]["rq_um"])
        lp = loops[lab]
        st, sec, en = lp["stick"], lp["secant"], lp["energy"]
        eq = {k: lp[k]["kt_eq"] / lp["kt_eq_mindlin"] for k in KT_DEFINITIONS}
        txt += (f" At the v3 peak (Rq = {lab} µm, {lp['clipped']} of {st['over_mindlin']['n']} elements "
                f"at |Q| ≥ 0.99 μN) the stick k_t is {st['over_mindlin']['min']:.2f}–"
                f"{st['over_mindlin']['max']:.2f} × Mindlin's (k_t,eq {eq['stick']:.3f} ×): the paper's "
                f"\"same k_t,eq\" without its local differences. Only an amplitude-dependent reading "
                f"differs locally like Fig. 14: the secant {sec['over_mindlin']['min']:.2f}–"
                f"{sec['over_mindlin']['max']:.2f} × (k_t,eq {eq['secant']:.3f} ×), the energy-equivalent "
                f"{en['over_mindlin']['min']:.2f}–{en['over_mindlin']['max']:.2f} × (k_t,eq "
                f"{eq['energy']:.3f} ×), lowest where the elements slip most; neither keeps k_t,eq at "
                f"Mindlin's, so the paper's two statements (same average, local differences) are not "
                f"both met by one definition here.")
    txt += _frf_sentence(s, tuple(n for n in (s.get("alternatives") or {}) if n.startswith("v3-")))
    return txt


def _alt_rows(s: dict) -> list[str]:
    alt = s.get("alternatives") or {}
    rows = [(n, a) for n, a in alt.items() if n.startswith("v3-")]
    if not rows:
        return []
    L = ["", "The k_t definitions in the dynamics (the comparison surface's converged v3 k_n with "
         "that k_t held fixed; backbone SNMS peaks beside v3's own):", "",
         "| joint | k_n,eq [N/mm³] | k_t,eq [N/mm³] | f stuck [Hz] | SNMS peaks L0 · L1 · L2 [Hz / µm] "
         "| v3's SNMS peaks |", "|---|---|---|---|---|---|"]
    for n, a in rows:
        L.append(f"| {n} | {a['kn_eq']:.4g} | {a['kt_eq']:.4g} | {a['stuck_hz']:.2f} | "
                 f"{_peaks(a['snms'])} | {_peaks(a['parent_snms'])} |")
    return L


def markdown(data: ReportData, summary: dict) -> list[str]:
    """The section "Contact stiffness definitions" of report.md ([] without its files)."""
    s = summary.get("stiffness_definitions") or {}
    if not s.get("contact"):
        return []
    s = {**s, "v_rq": rq_label(data.v_rq)}
    b = s["contact"]["bulk"]
    L = ["## Contact stiffness definitions (patch vs layer k_n; k_t from the loop)", "",
         "k_n is the paper's (dN/dδ)/A of the element's patch: the flat-punch stiffness of its "
         "contact set, which includes the half-space bulk below the patch. The *layer* k_n removes "
         f"it in series, 1/k_layer = 1/k_n − 1/k_bulk, with k_bulk = {b['kn']:.4g} N/mm³ the flat punch "
         "of the whole patch (complete contact: k_layer → ∞, capped at "
         f"{s['contact']['cap']:g} k_bulk; sparse contact: k_layer → k_n). The layer joints keep their "
         "k_t rule (smooth-ms: k_t = k_n; v2: Mindlin). The study's curves use the patch k_n (the "
         "paper's); the layer joints are reported here, with their backbones' SNMS peaks as the FRF "
         "comparison.", ""]
    L += _kn_table(s) + ["", _kn_finding(s), "",
                         "k_t from the element loops (±Q at the cycle-mean N, paper Fig. 4): *stick* = "
                         "slope at load reversal (v3's k_t); *secant* = 2Q/Δδ; *energy* = the Jenkins "
                         "element through the loop's tips with the loop's area, k = Q²/(2∫₀^Q δ dq) "
                         "(Masing). Ratios over Mindlin's k_t = 2(1−ν)/(2−ν)·k_n at the same k_n, loaded "
                         "elements: mean ± std (min–max).", ""]
    L += _kt_table(s) + _alt_rows(s) + ["", _kt_finding(s), ""]
    if s.get("loops"):
        L += ["![k_t definitions](figures/kt_definitions.png)", ""]
    return L


def figure(data: ReportData, path: Path) -> Path | None:
    """Paper Fig. 14 for every k_t definition on the comparison surface: k_n, Mindlin k_t, and k_t
    by stick, secant and energy (one colour scale), and their ratios to Mindlin (one scale)."""
    from .figures import _map, _plt, _save
    loops = _json(data.out / "dynamics" / FOLDER / "kt_definitions.json")
    if loops is None or rq_label(data.v_rq) not in loops["arrays"]:
        return None
    a = {k: np.asarray(v) for k, v in loops["arrays"][rq_label(data.v_rq)].items() if k != "rq_um"}
    live = a["kn"] > 0
    hole = data.case.geometry.hole_diameter
    xy = data.xy[live]
    top = [("k_n at the cycle-mean N", a["kn"]), ("Mindlin k_t", a["kt_mindlin"])]
    top += [(f"k_t {k}", a[k]) for k in KT_DEFINITIONS]
    vmax = max(float(v[live].max()) for _, v in top)
    ratios = [a[k][live] / a["kt_mindlin"][live] for k in KT_DEFINITIONS]
    lo, hi = min(float(r.min()) for r in ratios), max(float(r.max()) for r in ratios)
    span = max(1 - lo, hi - 1, 1e-3)
    fig, axes = _plt().subplots(2, 5, figsize=(22, 8))
    for ax, (title, v) in zip(axes[0], top):
        _map(ax, xy, v[live], f"{title} [N/mm³]", vmin=0, vmax=vmax, hole=hole)
    for ax, k, r in zip(axes[1][2:], KT_DEFINITIONS, ratios):
        _map(ax, xy, r, f"k_t {k} / Mindlin", cmap="coolwarm_r", vmin=1 - span, vmax=1 + span, hole=hole)
    for ax in axes[1][:2]:
        ax.axis("off")
    axes[1][0].text(0, 0.5, f"Rq = {rq_label(data.v_rq)} µm, v3 peak at L{data.mid}\n"
                    "(elements in contact)", fontsize=10, transform=axes[1][0].transAxes)
    return _save(fig, path)
