"""Case files, presets and the CLI's handling of bad input (issues 2 and 14; the full table of bad
inputs is tests/test_bad_inputs.py)."""
from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from fe_joint.cli import main
from fe_joint.case import Case, CaseError, case_to_toml, default_case_text, load_case

# (TOML text, the key the one-line message must name)
BAD = [
    ("[foo]\nx = 1\n", "foo"),
    ("[geometry]\nhole_diam = 8.5\n", "geometry.hole_diam"),
    ("[geometry]\nplate_thickness = -1.0\n", "plate_thickness"),
    ("[geometry]\nhole_diameter = 25.0\n", "hole_diameter"),        # hole wider than the overlap
    ("[geometry]\nshank_diameter = 9.0\n", "shank_diameter"),       # bolt wider than the hole
    ("[geometry]\nlap_mesh_size = \"fine\"\n", "geometry.lap_mesh_size"),
    ("[material]\nyoung = 0.0\n", "material.young"),
    ("[material]\npoisson = 0.5\n", "material.poisson"),
    ("[material]\ndensity = \"steel\"\n", "material.density"),
    ("[preload]\nbolt_force = -30000.0\n", "preload.bolt_force"),
    ("[reduction]\ndamping_ratio = 1.0\n", "reduction.damping_ratio"),
    ("[reduction]\ncutoff_hz = -5.0\n", "reduction.cutoff_hz"),
    ("[roughness]\nrq_um = [1.0, -5.0]\n", "roughness.rq_um"),
    ("[roughness]\ncorr_length = 0.0\n", "roughness.corr_length"),
    ("[roughness]\ngrid = 8\n", "roughness.grid"),
    ("[roughness]\npatch = 512\n", "roughness.patch"),
    ("[contact]\nmu = 0.0\n", "contact.mu"),
    ("[contact]\nk_ref = -6e4\n", "contact.k_ref"),
    ("[dynamics]\nharmonics = 0\n", "dynamics.harmonics"),
    ("[dynamics]\nharmonics = 2.5\n", "dynamics.harmonics"),
    ("[dynamics]\nsamples = 4\n", "dynamics.samples"),
    ("[dynamics]\nlevels = [-500.0]\n", "dynamics.levels"),
    ("[dynamics]\nconfigurations = [\"v4\"]\n", "dynamics.configurations"),
    ("[dynamics]\nband = [1.1, 0.9]\n", "dynamics.band"),
    ("name = \"my case\"\n", "name"),
    ("[material\nyoung = 1\n", "TOML syntax error"),
]


@pytest.mark.parametrize("text,key", BAD, ids=[k for _, k in BAD])
def test_bad_case_exit_2_names_key(tmp_path: Path, capsys, text: str, key: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    code = main(["check", str(f)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.count("\n") == 0 and err.startswith("fe-joint: error:")
    assert key in err


def test_bad_values_raise_case_error_before_run(tmp_path: Path) -> None:
    """`run` rejects the case before creating its output folder (nothing half-written)."""
    f = tmp_path / "bad.toml"
    f.write_text("[contact]\nmu = -1.0\n")
    out = tmp_path / "out"
    assert main(["run", str(f), "--out", str(out), "--stages", "mesh"]) == 2
    assert not out.exists()
    with pytest.raises(CaseError, match="contact.mu"):
        load_case(f)


def test_default_case_round_trips(tmp_path: Path) -> None:
    case = load_case()
    assert isinstance(case, Case)
    # the embedded file states every default explicitly: parsed values equal the dataclass defaults
    data = tomllib.loads(default_case_text())
    assert case.contact.mu == data["contact"]["mu"] == 0.6
    assert case.preload.bolt_force == 30000.0
    f = tmp_path / "rt.toml"
    f.write_text(case_to_toml(case))
    again = load_case(f)
    assert again == case
    assert again.section_hash("geometry", "roughness") == case.section_hash("geometry", "roughness")


def test_presets_overlay_and_change_hash() -> None:
    base, quick = load_case(), load_case(preset="quick")
    assert load_case(preset="default") == base
    assert quick.roughness.grid < base.roughness.grid
    assert quick.material == base.material            # untouched sections stay equal
    assert quick.section_hash("roughness") != base.section_hash("roughness")
    assert quick.section_hash("material") == base.section_hash("material")


def test_cli_subprocess_one_line_no_traceback(tmp_path: Path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text("[roughness]\nrq_um = [-1.0]\n")
    exe = Path(sys.executable).parent / "fe-joint"
    r = subprocess.run([str(exe), "check", str(f)], capture_output=True, text=True)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert "roughness.rq_um" in r.stderr
    r = subprocess.run([str(exe), "run", "--stages", "nope"], capture_output=True, text=True)
    assert r.returncode == 2 and "--stages" in r.stderr


# --- precedence: defaults < preset < case file (issue 14) ---

PREC = "[roughness]\ngrid = 128\n[geometry]\nlap_mesh_size = 3.0\n[dynamics]\nharmonics = 3\n"


def test_a_key_written_in_the_file_wins_over_the_preset(tmp_path: Path) -> None:
    f = tmp_path / "prec.toml"
    f.write_text(PREC)
    case = load_case(f, preset="quick")
    # written in the file: kept although quick sets 64, 4.0 and 1
    assert (case.roughness.grid, case.geometry.lap_mesh_size, case.dynamics.harmonics) == (128, 3.0, 3)
    # not written: the preset's
    assert (case.roughness.patch, case.geometry.body_mesh_size, case.dynamics.samples) == (8, 14.0, 32)
    # neither: the default case's
    assert case.material == load_case().material and case.roughness.seed == 0
    # no preset: the file over the defaults
    plain = load_case(f)
    assert (plain.roughness.grid, plain.roughness.patch, plain.geometry.body_mesh_size) == (128, 16, 6.0)


def test_check_prints_every_value_with_its_source(tmp_path: Path, capsys) -> None:
    from fe_joint.case import SECTIONS
    import dataclasses
    f = tmp_path / "prec.toml"
    f.write_text(PREC)
    assert main(["check", str(f), "--preset", "quick"]) == 0
    out = capsys.readouterr().out
    # still TOML, and it reads back as the same case
    again = tmp_path / "again.toml"
    again.write_text(out)
    assert load_case(again) == load_case(f, preset="quick")
    src, section = {}, None
    for line in out.splitlines():
        if line.startswith("["):
            section = line.strip("[]")
        elif "=" in line:
            key = line.split("=")[0].strip()
            src[f"{section}.{key}" if section else key] = line.rsplit("# ", 1)[1]
    assert len(src) == 1 + sum(len(dataclasses.fields(c)) for c in SECTIONS.values())
    assert {k for k, v in src.items() if v == "file"} == {
        "roughness.grid", "geometry.lap_mesh_size", "dynamics.harmonics"}
    assert {k for k, v in src.items() if v == "preset quick"} == {
        "geometry.body_mesh_size", "reduction.n_check_modes", "roughness.patch", "roughness.rq_um", "roughness.seeds",
        "dynamics.samples", "dynamics.max_points", "dynamics.speed_study", "contact.kt_max_passes"}
    assert set(src.values()) == {"file", "preset quick", "default"}
