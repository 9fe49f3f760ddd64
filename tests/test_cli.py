"""Exit statuses and messages of the command line, and its logging."""
from __future__ import annotations

import logging

import pytest

import contact_bem
import hbm
from fe_joint.cli import main
from fe_joint.errors import CaseError, ConvergenceError, JobFailed, classify


@pytest.mark.parametrize("error, code", [
    (CaseError("roughness.grid = 3: allowed range [16, 4096]"), 2),
    (ConvergenceError("active set cycled"), 3),
    (hbm.ConvergenceError("Newton did not converge", 1e-3), 3),
    (contact_bem.ConvergenceError("normal solve", 1e-4), 3),
    (JobFailed("baseline@L1", 3, "did not converge: x"), 3),
    (KeyError("1.23457"), 1),
    (ValueError("an internal inconsistency"), 1),
    (TypeError("unsupported operand"), 1),
])
def test_exit_status_by_error_class(error: BaseException, code: int) -> None:
    got, msg = classify(error)
    assert got == code
    assert "\n" not in msg
    if code == 1:   # a bug: says so, and how to see the traceback
        assert msg.startswith("internal error:") and "--debug" in msg


def _bad_case(tmp_path) -> str:
    p = tmp_path / "bad.toml"
    p.write_text("[roughness]\ngrid = 3\n")
    return str(p)


def test_bad_case_exits_2_with_one_line(tmp_path, capsys) -> None:
    assert main(["check", _bad_case(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["fe-joint: error: roughness.grid = 3: allowed range [16, 4096]"]


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_is_honoured_before_and_after_the_subcommand(tmp_path, where: str) -> None:
    args = ["check", _bad_case(tmp_path)]
    args = ["--debug"] + args if where == "before" else args + ["--debug"]
    with pytest.raises(CaseError):      # the traceback, not the one-line message
        main(args)


def test_report_of_a_folder_that_is_not_a_run_is_bad_input(tmp_path, capsys) -> None:
    assert main(["report", str(tmp_path)]) == 2
    assert "not a finished run's folder" in capsys.readouterr().err


def test_library_info_logs_are_silenced_unless_debug(capsys) -> None:
    from fe_joint.logs import configure_logging
    root = logging.getLogger()
    saved = root.level, list(root.handlers)
    try:
        configure_logging(debug=False)
        root.setLevel(logging.INFO)            # as distutils' set_verbosity does while compiling
        logging.getLogger().info("x86_64-linux-gnu-gcc -c form.c")
        logging.getLogger("fe_joint.study").info("own progress")
        logging.getLogger("ffcx").warning("a real warning")
        err = capsys.readouterr().err
        assert "gcc" not in err and "own progress" in err and "a real warning" in err
        configure_logging(debug=True)
        logging.getLogger().info("x86_64-linux-gnu-gcc -c form.c")
        assert "gcc" in capsys.readouterr().err
    finally:
        for h in list(root.handlers):
            if h not in saved[1]:
                root.removeHandler(h)
        root.setLevel(saved[0])
