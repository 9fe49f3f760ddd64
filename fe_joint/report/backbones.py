"""The nonlinear modes in the report: summary entries, the SNMS-vs-forced table, two figures.

Each backbone (``dynamics/backbones/<name>.npz``, a :class:`~fe_joint.study.backbone.BackboneResult`)
gives the joint's frequency and damping ratio against the response amplitude; the study's forced
peaks at its levels are marked on it, and the peaks synthesized from it (SNMS with the
off-resonant background) stand next to the forced ones.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..study.artifacts import BackboneKey, rq_label
from .data import ReportData


def label(key: BackboneKey) -> str:
    """Legend text of a backbone: the configuration, and the Rq of a v3 surface."""
    return key.config if key.rq_um is None else f"{key.config}, Rq = {rq_label(key.rq_um)} µm"


def zeta_at(br, amplitude: float) -> float:
    """ζ on the backbone at a response amplitude (mm), log-linear between its points (NaN outside)."""
    a = br.displacement_amplitude
    if not (a[0] <= amplitude <= a[-1]) or np.any(np.diff(a) <= 0):
        return float("nan")
    return float(np.interp(np.log(amplitude), np.log(a), br.zeta))


def snms_rows(data: ReportData, key: BackboneKey, br) -> dict:
    """Per level (``L<i>``): the synthesized and, where the study swept it, the forced peak.

    Returns:
        {"L<i>": {level N, snms_hz, snms_amplitude mm, forced_hz, forced_amplitude mm (None when
        not swept), rel_error_hz, rel_error_amplitude (SNMS / forced − 1)}}.
    """
    curves = data.backbone_curves(key)
    out = {}
    for i, lv in enumerate(br.levels):
        cr = curves.get(i)
        row = {"level": float(lv), "snms_hz": float(br.snms_hz[i]),
               "snms_amplitude": float(br.snms_amplitude[i]),
               "forced_hz": None if cr is None else cr.peak_hz,
               "forced_amplitude": None if cr is None else cr.peak_amplitude}
        row["rel_error_hz"] = None if cr is None else float(br.snms_hz[i] / cr.peak_hz - 1)
        row["rel_error_amplitude"] = (None if cr is None
                                      else float(br.snms_amplitude[i] / cr.peak_amplitude - 1))
        out[f"L{i}"] = row
    return out


def backbones_section(data: ReportData) -> dict:
    """``summary.json["backbones"]``: per backbone, its arrays and the peaks it predicts.

    Returns:
        {name: {amplitude_mm (response DOF), modal_amplitude (‖η₁‖, mm·t^0.5), frequency_hz,
        zeta, linear_hz, linear_zeta, zeta_doubled_amplitude_mm, zeta_doubled_modal_amplitude
        (None when ζ never doubles), snms_vs_forced (:func:`snms_rows`), points, seconds,
        complete (False: the continuation stopped early, see the run's warnings)}}.
    """
    def num(x):
        return None if not np.isfinite(x) else float(x)
    out = {}
    for key, br in sorted(data.backbones.items(), key=lambda kv: kv[0].name):
        out[key.name] = {
            "amplitude_mm": br.displacement_amplitude.tolist(),
            "modal_amplitude": br.mass_amplitude.tolist(),
            "frequency_hz": br.frequency_hz.tolist(), "zeta": br.zeta.tolist(),
            "linear_hz": br.linear_hz, "linear_zeta": br.linear_zeta,
            "zeta_doubled_amplitude_mm": num(br.zeta_doubled_amplitude),
            "zeta_doubled_modal_amplitude": num(br.zeta_doubled_modal),
            "snms_vs_forced": snms_rows(data, key, br),
            "points": int(br.omega.size), "complete": bool(br.complete)}
    return out


def markdown(data: ReportData, s: dict) -> list[str]:
    """The "Nonlinear modes" section: figures, the SNMS-vs-forced table, the doubled-ζ amplitudes."""
    bbs = s.get("backbones") or {}
    if not bbs:
        return []
    L = ["", "## Nonlinear modes (backbones)", "",
         "Each joint's mode of interest by EPMC (`hbm.nonlinear_mode`): frequency and damping ratio "
         "against the first-harmonic amplitude at the response DOF. The markers are the study's "
         "forced peaks (filled) and the peaks synthesized from the backbone (open; single-mode "
         "synthesis plus the off-resonant response of the other modes).", "",
         "![backbone frequency](figures/backbone_frequency.png)", "",
         "![backbone damping](figures/backbone_damping.png)", "",
         "| backbone | level | SNMS peak [Hz] / [µm] | forced peak [Hz] / [µm] | error f / amp |",
         "|---|---|---|---|---|"]
    for name, v in bbs.items():
        for lvl, r in v["snms_vs_forced"].items():
            forced = ("not swept" if r["forced_hz"] is None else
                      f"{r['forced_hz']:.3f} / {1e3 * r['forced_amplitude']:.4g}")
            err = ("–" if r["rel_error_hz"] is None else
                   f"{r['rel_error_hz']:.1e} / {r['rel_error_amplitude']:.1e}")
            L.append(f"| {name} | {lvl} ({r['level']:.3g} N) | {r['snms_hz']:.3f} / "
                     f"{1e3 * r['snms_amplitude']:.4g} | {forced} | {err} |")
    L += ["", "| backbone | stuck f [Hz] | stuck ζ | ζ doubled at [µm] | f there [Hz] | "
          "largest ζ | f at the last point [Hz] |", "|---|---|---|---|---|---|---|"]
    for name, v in bbs.items():
        zd = v["zeta_doubled_amplitude_mm"]
        f_zd = ("–" if zd is None else
                f"{np.interp(np.log(zd), np.log(v['amplitude_mm']), v['frequency_hz']):.3f}")
        L.append(f"| {name} | {v['linear_hz']:.3f} | {v['linear_zeta']:.2g} | "
                 f"{'never' if zd is None else f'{1e3 * zd:.4g}'} | {f_zd} | {max(v['zeta']):.3g} | "
                 f"{v['frequency_hz'][-1]:.3f} |")
    return L + [""]


def cost_rows(s: dict, t: dict) -> list[str]:
    """Backbone wall times beside the forced FRFs of the same joint (cost table).

    Args:
        s: the summary (points per backbone); t: the timings (``summary.build_timings``)."""
    bbs = s.get("backbones") or {}
    if not bbs:
        return []
    L = ["", "| backbone | points | wall time [s] | its joint's forced FRFs [s] (count) |",
         "|---|---|---|---|"]
    for name, v in bbs.items():
        head = name + "@"
        frf = [sec for k, sec in t["curves"].items() if k.startswith(head)]
        L.append(f"| {name} | {v['points']} | {t['backbones'][name]:.1f} | {sum(frf):.1f} ({len(frf)}) |")
    return L


def _panels(data: ReportData):
    """(fixed configurations + v3 on the comparison surface, v3 per Rq + baseline) backbones."""
    left, right = [], []
    for key, br in sorted(data.backbones.items(), key=lambda kv: (kv[0].config, kv[0].rq_um or 0)):
        if key.config != "v3" or key.rq_um == data.v_rq:
            left.append((key, br))
        if key.config == "v3" or key.config == "baseline":
            right.append((key, br))
    return left, right


def _draw(data: ReportData, path: Path, quantity: str) -> Path | None:
    """One backbone figure: ``quantity`` "frequency" (Hz) or "zeta" against the amplitude."""
    from ..study.configurations import LIKE_FOR_LIKE
    from .figures import COLORS, _plt, _save
    if not data.backbones:
        return None
    plt = _plt()
    left, right = _panels(data)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    cmap = plt.get_cmap("viridis")
    rqs = sorted({k.rq_um for k, _ in right if k.rq_um is not None})
    markers = "osD^v<>"
    for ax, items, title in ((axes[0], left, "configurations"), (axes[1], right, "v3 per Rq")):
        for key, br in items:
            if key.config == "v3" and ax is axes[1]:
                color = cmap(0.85 * rqs.index(key.rq_um) / max(len(rqs) - 1, 1))
            else:
                # a like-for-like variant (v1-v2set, v2-keep) dashed in its parent's colour: all
                # three were black before, one legend colour for baseline and both variants
                color = COLORS.get(LIKE_FOR_LIKE.get(key.config, key.config), "k")
            y = br.frequency_hz if quantity == "frequency" else br.zeta
            ax.semilogx(1e3 * br.displacement_amplitude, y,
                        "--" if key.config in LIKE_FOR_LIKE else "-", color=color, label=label(key))
            for i, cr in sorted(data.backbone_curves(key).items()):
                m = markers[i % len(markers)]
                yf = cr.peak_hz if quantity == "frequency" else zeta_at(br, cr.peak_amplitude)
                ax.plot(1e3 * cr.peak_amplitude, yf, m, color=color, ms=6)
                ys = br.snms_hz[i] if quantity == "frequency" else zeta_at(br, br.snms_amplitude[i])
                ax.plot(1e3 * br.snms_amplitude[i], ys, m, mfc="none", color=color, ms=10)
        ax.set_xlabel("response amplitude, 1st harmonic [µm]")
        ax.set_ylabel("frequency [Hz]" if quantity == "frequency" else "damping ratio ζ")
        ax.set_title(f"{title}; markers: forced peaks L0, L1, … (filled), SNMS (open)", fontsize=8)
        ax.legend(fontsize=7)
    return _save(fig, path)


def backbone_frequency(data: ReportData, path: Path) -> Path | None:
    """Backbone frequency against the response amplitude, forced and synthesized peaks marked."""
    return _draw(data, path, "frequency")


def backbone_damping(data: ReportData, path: Path) -> Path | None:
    """Backbone damping ratio against the response amplitude, the levels' peaks marked."""
    return _draw(data, path, "zeta")
