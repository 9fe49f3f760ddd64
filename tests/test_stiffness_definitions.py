"""The study's stiffness definitions (issue 13, items 3–4): layer joints from patch joints, and
the loop definitions' statistics over the elements."""
import numpy as np
import pytest

from contact_bem import LAYER_CAP, BulkStiffness, mindlin_ratio
from fe_joint.model.joint import JointModel
from fe_joint.study.stiffness_definitions import layer_joint, loop_statistics


def test_layer_joint_keeps_loads_and_the_kt_rule():
    kb = 9.0e4
    bulk = BulkStiffness(k_n=kb, k_t=0.82 * kb, area=1.0)
    j = JointModel("v2", n0=np.array([0.0, 50.0, 10.0]), gap=np.zeros(3),
                   kn=np.array([0.0, kb, kb / 10]), kt=np.zeros(3), area=np.array([1.0, 2.0, 1.0]))
    lay = layer_joint(j, bulk, mindlin_ratio(0.3))
    # no contact stays out; complete contact is capped; 1/k_layer = 10/kb − 1/kb = 9/kb
    assert lay.kn == pytest.approx([0.0, LAYER_CAP * kb, kb / 9], rel=1e-12)
    assert lay.kt == pytest.approx(mindlin_ratio(0.3) * lay.kn, rel=1e-12)
    assert lay.name == "v2-layer" and np.array_equal(lay.n0, j.n0)
    assert layer_joint(j, bulk, 1.0, cap=1000.0).kn[1] == pytest.approx(1000 * kb)


def test_loop_statistics_over_loaded_elements():
    d = {"kn": np.array([0.0, 1e4, 2e4]), "kt_mindlin": np.array([0.0, 8e3, 16e3]),
         "stick": np.array([0.0, 8e3, 16e3]), "secant": np.array([0.0, 4e3, 16e3]),
         "energy": np.array([0.0, 6e3, 16e3]), "clipped": np.array([False, True, False])}
    area = np.array([5.0, 1.0, 1.0])
    s = loop_statistics(d, area)
    assert s["secant"]["over_mindlin"]["mean"] == pytest.approx(0.75)
    assert s["secant"]["over_mindlin"]["min"] == pytest.approx(0.5)
    assert s["stick"]["over_kn"]["n"] == 2                       # the unloaded element is left out
    assert s["energy"]["kt_eq"] == pytest.approx(22e3 / 7)       # Σ k A / Σ A over all elements
    assert s["kt_eq_mindlin"] == pytest.approx(24e3 / 7) and s["clipped"] == 1
