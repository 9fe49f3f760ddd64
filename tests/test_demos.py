"""The teaching demos run and print the number they promise (each under a minute)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _result(script: str, *args: str) -> tuple[float, str]:
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / script), *args], capture_output=True,
                       text=True, timeout=300, env={"OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg",
                                                    "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr[-2000:]
    m = re.search(r"^RESULT \w+ = ([-+0-9.eE]+)", r.stdout, re.M)
    assert m, r.stdout
    return float(m.group(1)), r.stdout


def test_demo_geometry_tributary_areas_tile_the_lap() -> None:
    from geometry.resonator import ResonatorParams, nominal_interface_area
    area, _ = _result("demo_geometry.py", "--lap-size", "4.0")
    assert area == pytest.approx(nominal_interface_area(ResonatorParams()), rel=1e-2)


def test_demo_preload_shank_force_equals_bolt_force() -> None:
    force, out = _result("demo_preload.py")
    assert force == pytest.approx(30000.0, rel=1e-2)
    assert "RESULT" in out


def test_demo_rough_contact_surface_has_requested_rq() -> None:
    rq, out = _result("demo_rough_contact.py", "--rq", "5", "--grid", "64")
    assert rq == pytest.approx(5.0, rel=1e-9)
    frac = float(re.search(r"real contact area ([0-9.]+) %", out).group(1))
    assert 0.0 < frac < 100.0


def test_demo_friction_hbm_matches_describing_function() -> None:
    err, out = _result("demo_friction_hbm.py")
    assert err <= 1e-4
    # the exact integration is matched better with more harmonics
    errs = [float(x) for x in re.findall(r"error vs exact ([0-9.e+-]+)", out)]
    assert len(errs) == 3 and errs[2] < errs[0]


def test_demo_multiscale_coupling_reproduces_fe_pressure() -> None:
    err, out = _result("demo_multiscale.py")
    assert err <= 1e-6
    assert "k_t,eq: Mindlin" in out
