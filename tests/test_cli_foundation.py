"""The acceptance commands of the foundation, run through the installed console script."""

from __future__ import annotations

import pytest

from tests.cli_util import assert_one_line_error, labctl, labctl_json


def test_model_tripp_default_and_fitted_depth():
    out = labctl_json("model", "tripp", "--roller-type", "1", "--load-n", "440")
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
    proc = labctl("model", "fit-ra0.2", "--roller-type", "4", "--load-n", "10")
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
