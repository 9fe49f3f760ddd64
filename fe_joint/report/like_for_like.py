"""Like-for-like comparisons (issue 13, items 8 and 2): the element set of v1 → v2, and the levels.

* **Element set.** v2 and v3 leave out the elements without contact in their rough BEM cell
  (N0 = 0 there, so the patch gives k_n = 0); v1 keeps them (k_ref, open at rest with the cell's
  smallest separation as gap). Measured on v1's forced peaks: how many of those elements close
  during the cycle at each level, their cycle-mean normal force and the friction energy they
  dissipate, with the stuck-mode estimate (``model.joint.closure_onset``) beside it. The split
  v1 → v1' (v1 on v2's element set: elements) → v2 (stiffness), and v2 → v2-keep (v2 with the
  open elements kept), from the stuck frequencies and the backbones' synthesized peaks (SNMS) at
  the study's levels.
* **Levels.** What the paper's 500 / 1000 / 2000 N mean on this resonator (their ratio to the
  linear macroslip estimate, and the modal damping at which they would drive it as our levels do:
  ``study.configurations.damping_for_level``), and every backbone's peak synthesized at levels in
  the paper's ratios 1 : 2 : 4 anchored at our top level, beside the auto-rule levels.
"""
from __future__ import annotations

import numpy as np

from hbm import synthesize

from ..model.joint import JointModel, closure_onset, stuck_modes
from ..study.artifacts import BackboneKey
from ..study.configurations import (KEEP_KN_SHARE, PAPER_LEVELS, damping_for_level,
                                    like_for_like_joints, paper_ratio_levels)
from ..study.frf import OPEN
from .backbones import zeta_at
from .data import ReportData
from .stiffness import configuration_joints

#: the joints of the split, in order: v1 → v1' (element set) → v2 (stiffness) → v2-keep
SPLIT = ("v1", "v1-v2set", "v2", "v2-keep")


def _joints(data: ReportData) -> dict:
    """v1 as the study runs it (every element, k_ref), v2, and the like-for-like joints."""
    j = configuration_joints(data)
    sv, k_ref = data.surfaces[data.v_rq], data.case.contact.k_ref
    full = np.full(len(data.area), k_ref)
    # the report's v1 counts unloaded elements as 0 for k_eq; the dynamics keeps them at k_ref
    v1 = JointModel("v1", n0=sv.n0, gap=sv.gap_el, kn=full, kt=full.copy(), area=data.area,
                       rq_um=data.v_rq)
    base = {"v1": v1, "v2": j["v2"]}
    return {**base, **like_for_like_joints(base, data.case.material.poisson)}


def _light_loads(v2: JointModel) -> dict:
    """{min, max} N0 (N) of the loaded elements whose k_n v2-keep gives the open ones (the
    lightest ``KEEP_KN_SHARE`` by pressure): to compare with the loads closing elements reach."""
    c = v2.closed & (v2.kn > 0)
    p = v2.n0[c] / v2.area[c]
    n = v2.n0[c][p <= np.quantile(p, KEEP_KN_SHARE)]
    return {"min": float(n.min()), "max": float(n.max())}


def element_set(data: ReportData) -> dict:
    """Do the elements v2 removes close during the cycle in v1, at each level?

    Returns:
        {removed (count), v1_active, v2_active, gap_um {min, median, max} of the removed,
        kn_open (v2-keep's k_n of the kept open elements, N/mm³), levels: {"L<i>": {level N,
        v1_peak_amplitude mm, closing (removed elements not open all cycle at v1's peak),
        closing_estimate (stuck-mode estimate: closure amplitude below v1's peak amplitude),
        mean_normal_N (their summed cycle-mean normal force), max_mean_normal_N,
        share_of_bolt_force, energy_share (of v1's friction energy per cycle)}}}; {} when v1 or
        v2 is not in the study.
    """
    if not {"v1", "v2"} <= set(data.configs):
        return {}
    js = _joints(data)
    v1, v2 = js["v1"], js["v2"]
    removed = (v1.kn > 0) & ~((v2.kn > 0) & (v2.kt > 0))
    rm = data.rm
    lin = stuck_modes(rm.K, rm.M, rm.pair_dofs, v1)
    x_close = closure_onset(lin, np.asarray(rm.pair_dofs), v1, rm.excitation_dof)
    g = 1e3 * v1.gap[removed]
    out = {"removed": int(removed.sum()), "v1_active": int(np.sum(v1.kn > 0)),
           "v2_active": int(np.sum((v2.kn > 0) & (v2.kt > 0))),
           "gap_um": ({"min": float(g.min()), "median": float(np.median(g)), "max": float(g.max())}
                      if g.size else None),
           "kn_open": float(js["v2-keep"].kn[removed].max()) if removed.any() else None,
           "light_n0_N": _light_loads(v2), "levels": {}}
    bolt = float(np.sum(v1.n0))
    for i in range(len(data.levels)):
        cr = data.curve("v1", i)
        if cr is None:
            continue
        closing = removed & (cr.status != OPEN)
        n = cr.mean_normal[closing]
        out["levels"][f"L{i}"] = {
            "level": cr.level, "v1_peak_amplitude": cr.peak_amplitude,
            "closing": int(closing.sum()),
            "closing_estimate": int(np.sum(removed & (x_close <= cr.peak_amplitude))),
            "mean_normal_N": float(n.sum()), "max_mean_normal_N": float(n.max()) if n.size else 0.0,
            "share_of_bolt_force": float(n.sum() / bolt),
            "energy_share": float(cr.energy[removed].sum() / cr.dissipated) if cr.dissipated > 0 else 0.0}
    return out


def _checked(br, hz: float, x: float) -> dict:
    """A synthesized peak (Hz, mm) and the backbone's ζ there; all NaN when the peak is not on
    the backbone (amplitude outside its range or frequency outside its band ± 1 %: the synthesis
    then returns a spurious maximum, e.g. 17 Hz where ζ(a) falls again at the backbone's end)."""
    a, f = br.displacement_amplitude, br.frequency_hz
    ok = (np.isfinite(hz) and np.isfinite(x) and a[0] <= x <= a[-1]
          and 0.99 * f.min() <= hz <= 1.01 * f.max())
    nan = float("nan")
    return ({"hz": float(hz), "amplitude": float(x), "zeta": zeta_at(br, float(x))} if ok
            else {"hz": nan, "amplitude": nan, "zeta": nan})


def _peak(br, level: float) -> dict:
    """The synthesized peak of a backbone at ``level`` (N): Hz, mm, ζ there (NaN off it)."""
    sr = synthesize(br.backbone(), np.array([level, 0.0]))
    return _checked(br, float(sr.peak_omega / (2 * np.pi)), float(sr.peak_amplitude))


def split(data: ReportData) -> dict:
    """v1 → v1' → v2 → v2-keep: stuck frequencies (Hz) and, per level, the SNMS peak (Hz, mm) and
    the backbone's ζ there, for the backbones present ({} without v1 and v2)."""
    if not {"v1", "v2"} <= set(data.configs):
        return {}
    rm, js = data.rm, _joints(data)
    stuck = {n: stuck_modes(rm.K, rm.M, rm.pair_dofs, js[n]).frequency for n in SPLIT}
    levels = {}
    for i, lv in enumerate(data.levels):
        row = {}
        for n in SPLIT:
            br = data.backbones.get(BackboneKey(n))
            if br is not None:
                row[n] = _checked(br, float(br.snms_hz[i]), float(br.snms_amplitude[i]))
        levels[f"L{i}"] = {"level": float(lv), **row}
    return {"stuck_hz": stuck, "levels": levels}


def paper_levels(data: ReportData) -> dict:
    """The paper's levels on this resonator and every backbone's peak at levels in its ratios.

    Returns:
        {zeta (the model's modal damping), macroslip_N, paper_N, paper_over_macroslip, ours_N,
        ours_over_macroslip, zeta_equivalent (per level: the ζ at which the paper's level i
        drives the resonator as our level i does), zeta_for_top (the ζ at which 2000 N sits at
        our top level's ratio, and then all three paper levels at the ratio levels'),
        ratio_levels_N (1 : 2 : 4 anchored at our top level), v_rq_um, peaks: {backbone: {"auto": [...],
        "ratios": [...]}} with {hz, amplitude mm, zeta} per level}.
    """
    z, ms, ours = data.rm.damping_ratio, data.macroslip, list(data.levels)
    ratio = paper_ratio_levels(ours[-1])
    peaks = {}
    for key, br in sorted(data.backbones.items(), key=lambda kv: kv[0].name):
        auto = [_checked(br, float(br.snms_hz[i]), float(br.snms_amplitude[i]))
                for i in range(len(ours))]
        peaks[key.name] = {"auto": auto, "ratios": [_peak(br, lv) for lv in ratio]}
    eq = ([damping_for_level(z, lv, p) for lv, p in zip(ours, PAPER_LEVELS)]
          if len(ours) == len(PAPER_LEVELS) else [])
    return {"zeta": z, "macroslip_N": ms, "paper_N": list(PAPER_LEVELS),
            "paper_over_macroslip": [p / ms for p in PAPER_LEVELS], "ours_N": ours,
            "ours_over_macroslip": [lv / ms for lv in ours], "zeta_equivalent": eq,
            "zeta_for_top": damping_for_level(z, ours[-1], PAPER_LEVELS[-1]),
            "ratio_levels_N": ratio, "v_rq_um": data.v_rq, "peaks": peaks}


def _json(x):
    """``x`` with every NaN float replaced by None (summary.json stays strict JSON)."""
    if isinstance(x, dict):
        return {k: _json(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_json(v) for v in x]
    return None if isinstance(x, float) and not np.isfinite(x) else x


def section(data: ReportData) -> dict:
    """``summary.json["like_for_like"]``: element_set, split, paper_levels (None where a peak is
    not on its backbone)."""
    return _json({"element_set": element_set(data), "split": split(data),
                  "paper_levels": paper_levels(data)})


def warnings(s: dict) -> list[dict]:
    """The element-set check: one warning (``RunWarning`` fields) when elements v2/v3 leave out
    close during the cycle in v1 at some level (v1 → v2 then changes which elements exist, not
    only their stiffness), with what keeping them changes (v2-keep against v2) where known."""
    lf = s.get("like_for_like") or {}
    es = lf.get("element_set") or {}
    closing = {k: v for k, v in es.get("levels", {}).items() if v["closing"] > 0}
    if not closing:
        return []
    top = list(closing)[-1]
    row = (lf.get("split") or {}).get("levels", {}).get(top, {})
    a, b = row.get("v2"), row.get("v2-keep")
    known = a and b and all(a[k] is not None and b[k] is not None for k in ("hz", "amplitude", "zeta"))
    effect = ("no v2-keep backbone quantifies what that changes" if not known else
              f"keeping them (v2-keep) moves v2's {top} peak by {100 * (b['hz'] / a['hz'] - 1):+.2f} % "
              f"in f, {100 * (b['amplitude'] / a['amplitude'] - 1):+.1f} % in amplitude and "
              f"{100 * (b['zeta'] / a['zeta'] - 1):+.1f} % in ζ")
    counts = ", ".join(f"{v['closing']} at {k}" for k, v in closing.items())
    return [{"kind": "element-set", "subject": "v1 → v2", "value": closing[top]["closing"],
             "limit": 0, "message": (
                 f"Of the {es['removed']} elements v2/v3 leave out (no contact in their rough BEM "
                 f"cell), {counts} close during the cycle in v1 (cycle-mean N up to "
                 f"{closing[top]['max_mean_normal_N']:.3g} N, {100 * closing[top]['energy_share']:.1f} % "
                 f"of v1's friction energy at {top}): v1 → v2 is not like for like; {effect} "
                 "(report: \"Like for like\")")}]


def _f(x, f: str = "{:.4g}") -> str:
    """``x`` formatted, an en dash for None or NaN."""
    return "–" if x is None or not np.isfinite(x) else f.format(x)  # None: NaN in summary.json


def _um(x):
    """mm → µm; None stays None (a peak not on its backbone)."""
    return None if x is None else 1e3 * x


def _element_set_md(es: dict, sp: dict) -> list[str]:
    """The element-set evidence and the split v1 → v1' → v2 → v2-keep."""
    if not es:
        return []
    g = es["gap_um"] or {}
    L = ["### Element set of v1 → v2", "",
         f"v2 and v3 leave out the {es['removed']} elements without contact in their rough BEM cell "
         f"(N0 = 0, so k_n = 0; gaps {_f(g.get('min'), '{:.3g}')}–{_f(g.get('max'), '{:.3g}')} µm, "
         f"median {_f(g.get('median'), '{:.3g}')} µm); v1 keeps them at k_ref ({es['v1_active']} "
         f"elements against v2's {es['v2_active']}). Do they close during the cycle in v1? Measured "
         "at v1's forced peaks (status not open all cycle), with the stuck-mode estimate (closure "
         "once the normal relative amplitude reaches the gap) beside it:", "",
         "| level | v1 peak [µm] | removed elements closing (estimate) | Σ cycle-mean N [N] | "
         "largest [N] | / bolt force | share of v1's friction energy |", "|---|---|---|---|---|---|---|"]
    for lvl, v in es["levels"].items():
        L.append(f"| {lvl} ({v['level']:.3g} N) | {1e3 * v['v1_peak_amplitude']:.4g} | {v['closing']} "
                 f"({v['closing_estimate']}) | {v['mean_normal_N']:.3g} | {v['max_mean_normal_N']:.3g} | "
                 f"{v['share_of_bolt_force']:.2e} | {100 * v['energy_share']:.2f} % |")
    if not sp:
        return L + [""]
    st = sp["stuck_hz"]
    L += ["", "Split of v1 → v2 into the element set and the stiffness: v1' = v1 on v2's element set "
          "(v1's loads, gaps and k_ref without the removed elements), v2-keep = v2 with the removed "
          f"elements kept open at rest as in v1, at the k_n of a lightly loaded contact of this surface "
          f"(the area-weighted mean k_n of the lightest-loaded {100 * KEEP_KN_SHARE:g} % of v2's elements, "
          f"N0 {es['light_n0_N']['min']:.3g}–{es['light_n0_N']['max']:.3g} N, the range of the cycle-mean "
          f"loads closing elements reach above: {_f(es['kn_open'], '{:.3g}')} N/mm³; Mindlin k_t). "
          "The stuck modes model only the loaded "
          "elements, so v1 and v1' share theirs exactly: the element set acts only through elements "
          "that close during the cycle. Peaks synthesized from each joint's backbone (SNMS), ζ the "
          "backbone's there (– : the peak is not on the backbone):", "",
          "| level | " + " | ".join(f"{n}: f [Hz] / X [µm] / ζ" for n in SPLIT) + " |",
          "|---|" + "---|" * len(SPLIT),
          "| stuck | " + " | ".join(f"{st[n]:.3f} / – / –" for n in SPLIT) + " |"]
    for lvl, row in sp["levels"].items():
        cells = [("–" if n not in row else f"{_f(row[n]['hz'], '{:.3f}')} / {_f(_um(row[n]['amplitude']))} / "
                  f"{_f(row[n]['zeta'], '{:.3e}')}") for n in SPLIT]
        L.append(f"| {lvl} ({row['level']:.3g} N) | " + " | ".join(cells) + " |")
    return L + [""]


def _levels_md(pl: dict) -> list[str]:
    """What the paper's levels mean here, and the peaks at levels in the paper's ratios."""
    ms, z = pl["macroslip_N"], pl["zeta"]
    L = ["### The paper's levels on this resonator", "",
         f"The linear macroslip estimate (the stuck resonant response's net interface shear reaches "
         f"μΣN0) is {ms:.3g} N at ζ = {z:g}; it is proportional to ζ (docs/design.md, \"Excitation "
         "levels\"). The paper's 500 / 1000 / 2000 N are "
         + " / ".join(f"{r:.3g}" for r in pl["paper_over_macroslip"])
         + " × that estimate (gross slip), ours " + " / ".join(f"{r:.3g}" for r in pl["ours_over_macroslip"])
         + ". " + (("The paper's level i would drive this resonator as our level i does at ζ = "
                    + " / ".join(f"{100 * x:.3g} %" for x in pl["zeta_equivalent"]) + "; its")
                   if pl["zeta_equivalent"] else "The paper's")
         + f" 2000 N sits at our top level's ratio at ζ = {100 * pl['zeta_for_top']:.3g} %, and at that "
         "damping its three levels are our top level × 1/4, 1/2, 1 (the paper's ratios): "
         + " / ".join(f"{x:.3g}" for x in pl["ratio_levels_N"])
         + " N. Every backbone's peak at those levels (SNMS, no forced FRF) beside the auto-rule levels "
         "(– : the synthesized peak is not on the backbone):", "",
         "| backbone | auto: f [Hz] / X [µm] / ζ per level | paper ratios 1:2:4: f [Hz] / X [µm] / ζ per level |",
         "|---|---|---|"]
    for name, v in pl["peaks"].items():
        cell = [", ".join(f"{_f(p['hz'], '{:.2f}')} / {_f(_um(p['amplitude']))} / {_f(p['zeta'], '{:.2e}')}"
                          for p in v[k]) for k in ("auto", "ratios")]
        L.append(f"| {name} | {cell[0]} | {cell[1]} |")
    return L + [""] + _trends(pl) + [""]


def _trends(pl: dict) -> list[str]:
    """ζ of v3 against the baseline, and ζ against Rq, at each level of both level sets."""
    pk = pl["peaks"]
    v3 = sorted((float(k.split("rq")[1]), k) for k in pk if k.startswith("v3-rq"))
    out = []
    for which, title in (("auto", "auto-rule levels"), ("ratios", "paper-ratio levels")):
        parts = []
        if "baseline" in pk and v3:
            mid = [k for r, k in v3 if r == pl["v_rq_um"]] or [v3[-1][1]]
            zb = [p["zeta"] for p in pk["baseline"][which]]
            zv = [p["zeta"] for p in pk[mid[0]][which]]
            parts.append(f"{mid[0]} vs baseline ζ: " + ", ".join(
                f"{_f(a, '{:.2e}')} vs {_f(b, '{:.2e}')}" for b, a in zip(zb, zv)))
        if len(v3) >= 2:
            lo, hi = pk[v3[0][1]][which], pk[v3[-1][1]][which]
            parts.append(f"ζ from Rq {v3[0][0]:g} to {v3[-1][0]:g} µm: " + ", ".join(
                f"{_f(a['zeta'], '{:.2e}')} → {_f(b['zeta'], '{:.2e}')}" for a, b in zip(lo, hi)))
        if parts:
            out.append(f"- {title} (lowest to highest level): " + "; ".join(parts) + ".")
    return out


def markdown(data: ReportData, s: dict) -> list[str]:
    """The "Like for like" section of report.md (element set, the paper's levels)."""
    lf = s.get("like_for_like") or {}
    if not lf:
        return []
    return (["## Like for like: element set and levels", ""]
            + _element_set_md(lf.get("element_set") or {}, lf.get("split") or {})
            + _levels_md(lf["paper_levels"]))
