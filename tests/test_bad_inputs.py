"""Bad input of every kind is refused the same way (issue 14): exit status 2, one line on stderr
naming the key, file or folder at fault, and nothing written in ``--out``.

Each row runs ``fe-joint run CASE --out DIR`` in-process; validation fails before any stage, so
the whole table takes about a second. The values are absurd on purpose (1e300, 1e-300, a
0.001 mm plate, a mesh that would not finish): none may reach a solver.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from fe_joint.cli import main

# (id, case file text, what the one line must name). Every key family: geometry (ranges,
# relations, the mesh guard), material, preload, reduction, roughness, contact, dynamics,
# the file's structure and the case name.
CASES = [
    ("thin-plate", "[geometry]\nplate_thickness = 0.001\n", "geometry.plate_thickness"),
    ("huge-plate", "[geometry]\nplate_width = 1e300\n", "geometry.plate_width"),
    ("nan-overlap", "[geometry]\noverlap = nan\n", "geometry.overlap"),
    ("mesh-hole", "[geometry]\nhole_mesh_size = 0.01\n", "geometry.hole_mesh_size"),
    ("mesh-lap", "[geometry]\nlap_mesh_size = 0.25\nhole_mesh_size = 0.25\n", "_mesh_size = 0.25"),
    ("mesh-leaf", "[geometry]\nleaf_mesh_size = 0.05\n", "geometry.leaf_mesh_size"),
    ("mesh-body", "[geometry]\nbody_mesh_size = 3.0\nmass_a_size = 1000.0\n", "geometry.body_mesh_size"),
    ("hole-wider-than-head", "[geometry]\nhole_diameter = 14.0\n", "geometry.hole_diameter"),
    ("masses-overlap", "[geometry]\nmass_a_size = 110.0\nleaf_length = 10.0\n", "geometry.leaf_length"),
    ("mesh-order", "[geometry]\nhole_mesh_size = 3.0\n", "geometry.hole_mesh_size"),
    ("order-3", "[geometry]\norder = 3\n", "geometry.order"),
    ("geometry-seed", "[geometry]\nseed = -1\n", "geometry.seed"),
    ("size-string", "[geometry]\nbody_mesh_size = \"coarse\"\n", "geometry.body_mesh_size"),
    ("young-huge", "[material]\nyoung = 1e300\n", "material.young"),
    ("young-tiny", "[material]\nyoung = 1e-300\n", "material.young"),
    ("density-tiny", "[material]\ndensity = 1e-300\n", "material.density"),
    ("density-kg", "[material]\ndensity = 7850.0\n", "material.density"),
    ("poisson-negative", "[material]\npoisson = -0.1\n", "material.poisson"),
    ("poisson-string", "[material]\npoisson = \"0.3\"\n", "material.poisson"),
    ("bolt-huge", "[preload]\nbolt_force = 1e300\n", "preload.bolt_force"),
    ("bolt-tiny", "[preload]\nbolt_force = 1e-300\n", "preload.bolt_force"),
    ("cutoff-tiny", "[reduction]\ncutoff_hz = 1e-6\n", "reduction.cutoff_hz"),
    ("cutoff-inf", "[reduction]\ncutoff_hz = inf\n", "reduction.cutoff_hz"),
    ("check-modes-0", "[reduction]\nn_check_modes = 0\n", "reduction.n_check_modes"),
    ("rq-tiny", "[roughness]\nrq_um = [1e-300]\n", "roughness.rq_um"),
    ("rq-huge", "[roughness]\nrq_um = [1.0, 1e300]\n", "roughness.rq_um"),
    ("rq-empty", "[roughness]\nrq_um = []\n", "roughness.rq_um"),
    ("v-rq-zero", "[roughness]\nv_rq_um = 0.0\n", "roughness.v_rq_um"),
    ("hardness-huge", "[roughness]\nhardness = 1e300\n", "roughness.hardness"),
    ("hardness-negative", "[roughness]\nhardness = -1.0\n", "roughness.hardness"),
    ("corr-length-huge", "[roughness]\ncorr_length = 1e300\n", "roughness.corr_length"),
    ("roughness-seed-float", "[roughness]\nseed = 1.5\n", "roughness.seed"),
    ("grid-huge", "[roughness]\ngrid = 100000\n", "roughness.grid"),
    ("patch-over-grid", "[roughness]\ngrid = 32\npatch = 64\n", "roughness.patch"),
    ("mu-tiny", "[contact]\nmu = 1e-300\n", "contact.mu"),
    ("mu-huge", "[contact]\nmu = 1e300\n", "contact.mu"),
    ("k-ref-huge", "[contact]\nk_ref = 1e300\n", "contact.k_ref"),
    ("kt-tol-zero", "[contact]\nkt_tol = 0.0\n", "contact.kt_tol"),
    ("kt-passes-0", "[contact]\nkt_max_passes = 0\n", "contact.kt_max_passes"),
    ("level-huge", "[dynamics]\nlevels = [1e300]\n", "dynamics.levels"),
    ("level-tiny", "[dynamics]\nlevels = [10.0, 1e-300]\n", "dynamics.levels"),
    ("levels-word", "[dynamics]\nlevels = \"none\"\n", "dynamics.levels"),
    ("levels-bool", "[dynamics]\nlevels = [true]\n", "dynamics.levels"),
    ("harmonics-16", "[dynamics]\nharmonics = 16\n", "dynamics.harmonics"),
    ("samples-aliasing", "[dynamics]\nsamples = 10\n", "dynamics.samples"),
    ("band-one", "[dynamics]\nband = [0.5]\n", "dynamics.band"),
    ("band-tiny", "[dynamics]\nband = [1e-300, 1.0]\n", "dynamics.band"),
    ("configs-twice", "[dynamics]\nconfigurations = [\"v1\", \"v1\"]\n", "dynamics.configurations"),
    ("configs-empty", "[dynamics]\nconfigurations = []\n", "dynamics.configurations"),
    ("max-points-1", "[dynamics]\nmax_points = 1\n", "dynamics.max_points"),
    ("speed-study-yes", "[dynamics]\nspeed_study = \"yes\"\n", "dynamics.speed_study"),
    ("unknown-section", "[solver]\ntol = 1.0\n", "solver"),
    ("unknown-key", "[dynamics]\nharmonic = 3\n", "dynamics.harmonic"),
    ("section-not-table", "geometry = 3\n", "[geometry]"),
    ("toml-syntax", "[material\nyoung = 1\n", "TOML syntax error"),
    ("name-dotdot", "name = \"..\"\n", "name"),
    ("name-dot", "name = \".\"\n", "name"),
    ("name-slash", "name = \"a/b\"\n", "name"),
    ("name-newline", "name = \"a\\nb\"\n", "name"),
    ("name-nul", "name = \"a\\u0000b\"\n", "name"),
    ("name-long", f"name = \"{'x' * 300}\"\n", "name"),
    ("name-empty", "name = \"\"\n", "name"),
    ("name-number", "name = 5\n", "name"),
]


@pytest.fixture(autouse=True)
def _no_stage_runs(monkeypatch) -> None:
    """A case that passed validation by mistake must fail here at once, not run the pipeline."""
    from fe_joint.pipeline import stages

    def refuse(ctx):
        raise AssertionError("a stage ran: the input was accepted")
    for name in stages.REGISTRY:
        monkeypatch.setitem(stages.REGISTRY, name, refuse)


def _main(args: list[str]) -> int:
    try:
        return main(args)
    except SystemExit as e:    # argparse's errors exit from inside the parser
        return int(e.code)


def _refused(capsys, args: list[str], names: str, out: Path) -> None:
    """``args`` exits 2 with one stderr line naming ``names``, nothing on stdout, no ``out``."""
    before = sorted(out.rglob("*")) if out.exists() else None
    code = _main(args)
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert code == 2, cap.err
    assert len(lines) == 1 and lines[0].startswith("fe-joint: error: "), cap.err
    assert names in lines[0], lines[0]
    assert cap.out == ""
    if before is None:
        assert not out.exists()
    else:
        assert sorted(out.rglob("*")) == before


@pytest.mark.parametrize("text,names", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_case_is_refused_naming_the_key(tmp_path: Path, capsys, text: str, names: str) -> None:
    case = tmp_path / "case.toml"
    case.write_text(text)
    _refused(capsys, ["run", str(case), "--out", str(tmp_path / "out")], names, tmp_path / "out")


def test_the_table_covers_every_section() -> None:
    from fe_joint.case import SECTIONS
    named = " ".join(n for _, _, n in CASES)
    assert len(CASES) >= 40
    assert all(f"{s}." in named for s in SECTIONS) and "name" in named


# case files that are not UTF-8 TOML: the line names the file
ENCODED = [
    ("binary", b"\x00\x01\xff\xfe\x80"),
    ("latin-1", "name = \"café\"\n".encode("latin-1")),
    ("utf-16", "name = \"x\"\n".encode("utf-16")),
    ("nul-in-toml", b"name = \"x\"\x00\n"),
]


@pytest.mark.parametrize("raw", [r for _, r in ENCODED], ids=[i for i, _ in ENCODED])
def test_undecodable_case_file_is_named(tmp_path: Path, capsys, raw: bytes) -> None:
    case = tmp_path / "enc.toml"
    case.write_bytes(raw)
    _refused(capsys, ["run", str(case), "--out", str(tmp_path / "out")], str(case), tmp_path / "out")


def test_utf8_with_bom_is_read(tmp_path: Path) -> None:
    case = tmp_path / "bom.toml"
    case.write_bytes("\ufeffname = \"bom\"\n".encode("utf-8"))
    assert main(["check", str(case)]) == 0


def test_missing_and_folder_case_files_are_named(tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    for path in (tmp_path / "missing.toml", tmp_path):
        _refused(capsys, ["run", str(path), "--out", str(out)], str(path), out)


def test_out_that_is_a_file_is_refused(tmp_path: Path, capsys) -> None:
    f = tmp_path / "afile"
    f.write_text("keep")
    _refused(capsys, ["run", "--out", str(f)], "--out", tmp_path / "nothing")
    assert f.read_text() == "keep"
    _refused(capsys, ["run", "--out", str(f / "sub")], "--out", tmp_path / "nothing")


def test_out_that_cannot_be_written_is_refused(tmp_path: Path, capsys) -> None:
    # /proc/self exists and is a folder, but no file can be made in it (root included)
    _refused(capsys, ["run", "--out", "/proc/self", "--stages", "mesh"], "--out '/proc/self'",
             tmp_path / "nothing")


def test_bad_options_are_refused(tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    _refused(capsys, ["run", "--out", str(out), "--stages", "mesh,bogus"], "--stages", out)
    _refused(capsys, ["run", "--out", str(out), "--stages", ","], "--stages", out)
    _refused(capsys, ["run", "--out", str(out), "--preset", "fast"], "--preset", out)


def test_preset_value_in_conflict_names_the_written_key(tmp_path: Path, capsys) -> None:
    """harmonics = 15 under the quick preset (samples = 32 from the preset, < 2(2H+1) = 62): the
    line names the key the file wrote and says where the other value came from."""
    case = tmp_path / "h.toml"
    case.write_text("[dynamics]\nharmonics = 15\n")
    _refused(capsys, ["run", str(case), "--preset", "quick", "--out", str(tmp_path / "o")],
             "dynamics.harmonics = 15", tmp_path / "o")
    assert main(["check", str(case), "--preset", "quick"]) == 2
    assert "[preset quick]" in capsys.readouterr().err
