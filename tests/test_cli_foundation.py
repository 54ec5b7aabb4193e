"""The acceptance commands of the foundation, run through the installed console script."""

from __future__ import annotations

import pytest

from tests.cli_util import assert_one_line_error, labctl, labctl_json, labctl_process, one_json_object

pytestmark = pytest.mark.waits  # on labctl subprocesses (tests/conftest.py)


def test_model_tripp_default_and_fitted_depth():
    out = one_json_object(labctl_process("model", "tripp", "--roller-type", "1", "--load-n", "440", "--json"))
    assert out["model"] == "tripp" and out["load_n"] == [440.0]
    assert out["stiffness_n_per_m"][0] == pytest.approx(4.376e7, rel=5e-3)
    assert out["deflection_m"][0] > 0
    out = labctl_json("model", "tripp", "--roller-type", "1", "--load-n", "440", "--depth-mm", "1.94")
    assert out["stiffness_n_per_m"][0] == pytest.approx(4.65e7, rel=1e-2)


def test_model_fits_and_hertz():
    assert labctl_json("model", "fit-ra0.2", "--roller-type", "1", "--load-n", "440")["stiffness_n_per_m"][0] == \
        pytest.approx(4.540e7, rel=1e-3)
    assert labctl_json("model", "fit-ra0.03", "--roller-type", "1", "--load-n", "440")["stiffness_n_per_m"][0] == \
        pytest.approx(4.518e7, rel=1e-3)
    out = labctl_json("model", "hertz", "--ball-diameter-mm", "6", "--load-n", "100", "200")
    assert out["stiffness_n_per_m"][0] == pytest.approx(1.44e7, rel=1e-2) and len(out["deflection_m"]) == 2


def test_rig_modes_and_inverse():
    out = labctl_json("rig", "modes", "--stiffness-n-per-m", "4.65e7")
    assert out["bounce_hz"] == pytest.approx(745, abs=4)
    assert len(out["tilt_hz"]) == 2 and all(abs(f - 581) <= 6 for f in out["tilt_hz"])
    out = labctl_json("rig", "stiffness", "--bounce-hz", "745")
    assert out["roller_stiffness_n_per_m"] == pytest.approx(4.65e7, rel=1e-2)


def test_fit_below_validity_is_one_line_exit_2():
    proc = labctl_process("model", "fit-ra0.2", "--roller-type", "4", "--load-n", "10")  # the console script
    assert_one_line_error(proc, "1.8 N/mm")


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["model", "tripp", "--roller-type", "12", "--load-n", "100"], "roller type 12"),
        (["model", "tripp", "--roller-type", "1", "--load-n", "-5"], "-5"),
        (["model", "hertz", "--load-n", "100"], "--ball-diameter-mm"),
        (["model", "tripp", "--roller-type", "1", "--load-n", "100", "--depth-mm", "0"], "--depth-mm"),
        (["rig", "stiffness", "--bounce-hz", "9000"], "9000"),
        (["rig", "modes", "--stiffness-n-per-m", "1e7", "--rig", "/nonexistent/rig.toml"], "not found"),
        (["model", "tripp", "--roller-type", "1", "--load-n", "abc"], "abc"),
    ],
)
def test_bad_values_exit_2_with_one_line(args, fragment):
    assert_one_line_error(labctl(*args), fragment)


HEAVY = ("numpy", "scipy", "h5py", "textual", "matplotlib")


def loaded_in_a_fresh_interpreter(statements: str, modules: tuple[str, ...]) -> list[str]:
    """Which of ``modules`` a new Python process has loaded after running ``statements``."""
    import subprocess
    import sys

    code = f"import sys; {statements}; print(','.join(m for m in {modules!r} if m in sys.modules))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return [m for m in proc.stdout.strip().split(",") if m]


def test_registering_every_command_imports_no_heavy_library():
    """The rule for command modules (labctl/cli/__init__.py): heavy imports happen when a command runs."""
    loaded = loaded_in_a_fresh_interpreter("from labctl.cli import build_parser; build_parser()", HEAVY)
    assert loaded == [], f"imported at registration: {loaded}"


def test_the_statistics_commands_start_without_scipy_stats():
    """``labctl discrepancy``, ``compare`` and ``calibrate`` take their F and Student-t functions from scipy.special:
    scipy.stats costs about 0.3 s of start-up per process (it builds every distribution's docstring)."""
    loaded = loaded_in_a_fresh_interpreter(
        "import labctl.discrepancy.workflow, labctl.compare.test, labctl.calibration.fit", ("scipy.stats",))
    assert loaded == []


def test_main_imports_only_the_named_commands_module():
    from labctl.cli import _modules_for, command_modules

    assert _modules_for(["--version"]) == []
    assert _modules_for(["import", "x.uff", "--json"]) == ["importer"]
    assert _modules_for(["report", "--help"]) == ["report"]
    assert _modules_for(["--help"]) is None and _modules_for(["nosuch"]) is None
    assert {"importer", "report", "devices", "tui"} <= set(command_modules())


def _leaf_parsers(parser, path=()):
    import argparse

    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield path, parser
        return
    for sub in subs:
        for name, child in sub.choices.items():
            yield from _leaf_parsers(child, (*path, name))


def test_every_command_takes_json():
    from labctl.cli import build_parser

    leaves = list(_leaf_parsers(build_parser()))
    assert len(leaves) > 10
    missing = [" ".join(path) for path, p in leaves if "--json" not in p._option_string_actions]
    assert missing == []


def test_devices_example_json_and_no_source_tree_path(capsys, tmp_path, monkeypatch):
    from tests.cli_util import labctl_here, labctl_here_json

    out = labctl_here_json(capsys, "devices", "example")
    assert "[load_cell]" in out["example"]
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("LABCTL_DEVICES", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    proc = labctl_here(capsys, "devices", "check")
    line = assert_one_line_error(proc, "labctl devices example")
    assert "labctl/data" not in line


def test_tui_json_is_accepted_and_fails_cleanly_without_a_terminal(capsys):
    from tests.cli_util import labctl_here

    assert_one_line_error(labctl_here(capsys, "tui", "--json"), "interactive terminal")
