"""Stage cache, resume after a kill, and the stage log (issue 2/6 'robust runs')."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from fe_joint.case import load_case
from fe_joint.pipeline.runner import STAGES, read_stage_log, run_stages, stage_keys


class Killed(Exception):
    pass


def _registry(calls: list, kill_at: str | None = None) -> dict:
    def make(name):
        def f(ctx):
            if name == kill_at:
                raise Killed(name)
            calls.append(name)
            return {"n": len(calls)}
        return f
    return {s: make(s) for s in STAGES}


def test_rerun_skips_finished_stages(tmp_path: Path) -> None:
    case = load_case(preset="quick")
    calls: list = []
    # a run killed in 'contact': mesh and fe are finished and logged
    with pytest.raises(Killed):
        run_stages(case, tmp_path, ("dynamics",), _registry(calls, kill_at="contact"))
    assert calls == ["mesh", "fe"]
    calls.clear()
    run_stages(case, tmp_path, ("dynamics",), _registry(calls))
    assert calls == ["contact", "dynamics"]          # resumed where it stopped
    log = read_stage_log(tmp_path)
    assert [(e["stage"], e["action"]) for e in log] == [
        ("mesh", "ran"), ("fe", "ran"), ("mesh", "cached"), ("fe", "cached"),
        ("contact", "ran"), ("dynamics", "ran")]


def test_changed_section_reruns_downstream_only(tmp_path: Path) -> None:
    case = load_case(preset="quick")
    calls: list = []
    run_stages(case, tmp_path, STAGES, _registry(calls))
    assert calls == list(STAGES)
    # friction coefficient: the BEM (contact) does not read it; dynamics onwards must rerun
    case2 = dataclasses.replace(case, contact=dataclasses.replace(case.contact, mu=0.3))
    k1, k2 = stage_keys(case), stage_keys(case2)
    assert [s for s in STAGES if k1[s] != k2[s]] == ["dynamics", "speed", "report"]
    calls.clear()
    run_stages(case2, tmp_path, STAGES, _registry(calls))
    assert calls == ["dynamics", "speed", "report"]
    calls.clear()
    run_stages(case2, tmp_path, STAGES, _registry(calls), force=False)
    assert calls == []


def test_speed_study_switch_keeps_the_curves() -> None:
    """dynamics.speed_study is read by the speed stage only: toggling it keeps every dynamics
    curve (the dynamics key) and reruns speed and report."""
    case = load_case(preset="quick")
    case2 = dataclasses.replace(case, dynamics=dataclasses.replace(case.dynamics, speed_study=True))
    k1, k2 = stage_keys(case), stage_keys(case2)
    assert [s for s in STAGES if k1[s] != k2[s]] == ["speed", "report"]


def test_forced_stage_reruns_everything_after_it(tmp_path: Path) -> None:
    case = load_case(preset="quick")
    calls: list = []
    run_stages(case, tmp_path, STAGES, _registry(calls))
    calls.clear()
    run_stages(case, tmp_path, ("contact",), _registry(calls), force=True)
    assert calls == ["contact"]
    calls.clear()
    # dynamics and report read contact's new output: they must not come from the cache
    run_stages(case, tmp_path, STAGES, _registry(calls))
    assert calls == ["dynamics", "speed", "report"]
    calls.clear()
    run_stages(case, tmp_path, STAGES, _registry(calls))
    assert calls == []
    (tmp_path / "stages" / "fe.json").unlink()
    run_stages(case, tmp_path, STAGES, _registry(calls))
    assert calls == ["fe", "contact", "dynamics", "speed", "report"]


def test_changed_artifact_or_unrecorded_manifest_reruns_the_stage(tmp_path: Path, capsys) -> None:
    """A file edited in place (same size, other bytes) reruns the stage that wrote it, with one
    line naming it; a manifest without a file record (an older run) is not trusted either."""
    import json
    case = load_case(preset="quick")
    calls: list = []

    def writer(name):
        def f(ctx):
            calls.append(name)
            ctx.path(name).mkdir(exist_ok=True)
            ctx.path(name, "a.bin").write_bytes(b"x" * 64)
            return {}
        return f
    reg = {s: writer(s) for s in STAGES}
    run_stages(case, tmp_path, ("contact",), reg)
    f = tmp_path / "fe" / "a.bin"
    f.write_bytes(b"y" * 64)
    calls.clear()
    capsys.readouterr()
    run_stages(case, tmp_path, ("contact",), reg)
    assert calls == ["fe", "contact"]
    out = capsys.readouterr().out
    assert [l for l in out.splitlines() if "a.bin" in l] == [
        "[fe-joint] fe: fe/a.bin changed (sha256 differs): rerunning fe"]
    m = tmp_path / "stages" / "contact.json"
    man = json.loads(m.read_text())
    del man["files"]
    m.write_text(json.dumps(man))
    calls.clear()
    run_stages(case, tmp_path, ("contact",), reg)
    assert calls == ["contact"]
