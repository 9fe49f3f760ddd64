"""The report's "Contact stiffness definitions" section on the synthetic run of test_report, with
the two definition files written beside it; expected numbers computed here from what was written."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fe_joint.case import case_from_dict
from fe_joint.study.stiffness_definitions import FOLDER, loop_statistics
from test_report import AREA, CASE, make_run

NE = len(AREA)


def _contact_json() -> dict:
    joint = {"kn_mean": 5.0e4, "kn_max": 9.0e4, "kn_eq": 4.5e4, "kt_eq": 4.5e4, "loaded_elements": 5,
             "stuck_hz": 248.5, "rq_um": None}
    layer = {**joint, "kn_mean": 9e6, "kn_max": 9e6, "kn_eq": 8.1e6, "kt_eq": 8.1e6, "stuck_hz": 250.5}
    v2 = {**joint, "kn_eq": 1.75e4, "kt_eq": 1.44e4, "stuck_hz": 244.5, "rq_um": 5.0}
    v2l = {**v2, "kn_eq": 2.8e4, "kt_eq": 2.3e4, "stuck_hz": 245.7}
    stats = {"mean": 0.8256, "std": 0.018, "min": 0.78, "max": 0.879, "n": 5}
    return {"bulk": {"kn": 9.0e4, "kt": 7.42e4, "kt_over_kn": 0.8246, "patch_side_mm": 1.3, "cells": 4},
            "cap": 100.0, "mindlin_ratio": 0.8235294117647058,
            "joints": {"smooth-ms": joint, "smooth-ms-layer": layer, "v2-rq5": v2, "v2-rq5-layer": v2l},
            "smooth_complete_share": 0.95, "cap_sensitivity_hz": {"10": 250.3, "100": 250.5, "1000": 250.6},
            "reversal_ratio": {"5": {"rq_um": 5.0, "stats": stats}}}


def _loop_arrays() -> dict:
    kn = np.array([3e4, 1e4, 0.0, 2e4, 4e4, 5e3])
    mind = 0.8235294117647058 * kn
    return {"kn": kn, "kt_mindlin": mind, "stick": 1.01 * mind, "secant": mind * np.linspace(0.4, 1.0, NE),
            "energy": mind * np.linspace(0.6, 1.0, NE), "dissipation": np.zeros(NE),
            "q": np.ones(NE), "clipped": np.array([True, False, False, True, False, False])}


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    from fe_joint.report import write_report
    run = tmp_path_factory.mktemp("run")
    written = make_run(run)
    (run / "contact" / "stiffness_definitions.json").write_text(json.dumps(_contact_json()))
    a = _loop_arrays()
    summary = {"surfaces": {"5": {"rq_um": 5.0, **loop_statistics(a, AREA)}}, "backbones": [], "joints": {}}
    (run / "dynamics" / FOLDER).mkdir()
    (run / "dynamics" / FOLDER / "kt_definitions.json").write_text(json.dumps(
        {"summary": summary, "arrays": {"5": {"rq_um": 5.0, **{k: v.tolist() for k, v in a.items()}}}}))
    case = case_from_dict(json.loads(json.dumps(CASE)))
    return run, written, a, write_report(run, case)


def test_section_numbers(report):
    run, written, a, s = report
    sd = s["stiffness_definitions"]
    live = a["kn"] > 0
    # k_t,eq over all elements by hand; the ratio statistics over the loaded ones
    eq = math.fsum(float(k) * float(w) for k, w in zip(a["secant"], AREA)) / math.fsum(AREA)
    assert sd["loops"]["5"]["secant"]["kt_eq"] == pytest.approx(eq, rel=1e-12)
    assert sd["loops"]["5"]["secant"]["over_mindlin"]["min"] == pytest.approx(0.4)
    assert sd["loops"]["5"]["stick"]["over_mindlin"]["n"] == int(live.sum())
    # v3's converged k_t/k_n: the synthetic run writes k_n = 1.1 k_n,v2 and k_t = 0.9 · 0.8 k_n,v2
    assert sd["v3_kt_over_kn"]["5"]["mean"] == pytest.approx(0.72 / 1.1, rel=1e-12)
    assert sd["v3_kt_over_kn"]["5"]["eq_ratio"] == pytest.approx(0.72 / 1.1, rel=1e-12)
    text = (run / "report.md").read_text()
    assert "## Contact stiffness definitions" in text
    assert "| smooth-ms | layer | 9e+06 / 9e+06 | 8.1e+06 | 8.1e+06 | 250.50 |" in text
    assert "248.50 → 250.50 Hz" in text and "250.30 / 250.50 / 250.60 Hz: the cap used is 0.04 %" in text
    assert "0.40–1.00 × Mindlin's" not in text and "secant 0.40–1.00 ×" in text
    assert (run / "figures" / "kt_definitions.png").stat().st_size > 10_000


def test_section_absent_without_files(tmp_path):
    from fe_joint.report import write_report
    make_run(tmp_path)
    s = write_report(tmp_path, case_from_dict(json.loads(json.dumps(CASE))))
    assert s["stiffness_definitions"] == {}
    assert "Contact stiffness definitions" not in (tmp_path / "report.md").read_text()
    assert not (tmp_path / "figures" / "kt_definitions.png").exists()
