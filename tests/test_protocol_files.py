"""Protocol files: the shipped ones validate; malformed ones give exit 2 and one line naming the field."""

from __future__ import annotations

import pytest

from labctl.errors import InputError
from labctl.protocol import load_protocol, parse_protocol, shipped_protocols
from tests.cli_util import assert_one_line_error, labctl

GOOD = """
[protocol]
name = "t"
[specimen]
roller_type = 1
[acquisition]
impacts_per_step = 3
"""


def test_shipped_protocols_validate_and_follow_the_paper():
    assert {"roller_stiffness", "ball_verification", "quick_check"} <= set(shipped_protocols())
    p = load_protocol("protocols/roller_stiffness.toml")
    assert p.acquisition.sample_rate_hz == 20480 and p.acquisition.samples == 65536
    assert p.acquisition.impacts_per_step == 3 and p.repetitions.count == 3
    assert p.loading.knob_step_deg == 180 and p.repetitions.rotate_rollers_deg == 5
    assert p.specimens[0].max_load_n == pytest.approx(440, rel=0.02)  # 30 % of C0 with L_r
    balls = load_protocol("ball_verification")
    assert [s.ball_diameter_m for s in balls.specimens] == pytest.approx([3e-3, 6e-3, 9e-3])


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        (GOOD.replace("impacts_per_step = 3", "impacts_per_step = 0"),
         ["acquisition.impacts_per_step = 0", "an integer 1-100"]),
        (GOOD.replace("impacts_per_step = 3", "impacts_per_step = \"three\""), ["impacts_per_step", "integer"]),
        (GOOD + "[loading]\nmax_load_kn = 1.0\n", ["loading: unknown key(s) max_load_kn (did you mean"]),
        (GOOD.replace("roller_type = 1", "roller_type = 1\nmax_load_n = 2000.0"), ["max_load_n = 2000.0", "C0 cap"]),
        (GOOD.replace("roller_type = 1", "roller_type = 42"), ["roller_type = 42"]),
        (GOOD.replace("roller_type = 1", "roller_type = 1\nrail_material = \"cheese\""), ["rail_material"]),
        (GOOD + "[acquisition2]\n", ["unknown key(s) acquisition2 (did you mean 'acquisition'?)"]),
        (GOOD.replace("[acquisition]", "[acquisition]\nsample_rate_hz = -5"), ["sample_rate_hz = -5"]),
        (GOOD.replace("[acquisition]", "[acquisition]\nduration_ms = 3200"), ["duration_ms"]),
        ("[protocol]\nname = 'x'\n", ["missing [specimen]"]),
        (GOOD.replace("[specimen]\nroller_type = 1", "[specimen]\nkind = 'ball'\nball_diameter_mm = 6"),
         ["max_load_n"]),
        ("[protocol\nname=", ["not valid TOML"]),
    ],
)
def test_malformed_protocols_exit_2_naming_the_field(tmp_path, text, fragments):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError):
        parse_protocol(text, str(path))
    line = assert_one_line_error(labctl("run", str(path), "--out", str(tmp_path / "c.h5")), *fragments)
    assert str(path) in line or "bad.toml" in line
    assert not (tmp_path / "c.h5").exists()


def test_missing_protocol_file_names_shipped_ones(tmp_path):
    assert_one_line_error(labctl("run", str(tmp_path / "nope.toml")), "not found", "quick_check")


def test_checks_table_overrides_the_impact_checks_in_si():
    p = parse_protocol(GOOD + "[checks]\npulse_width_max_ms = 0.8\nmin_peak_force_n = 25\n", "c.toml")
    assert p.checks.pulse_width_max_s == pytest.approx(0.8e-3) and p.checks.min_peak_force_n == 25
    assert parse_protocol(GOOD, "c.toml").checks.pulse_width_max_s == pytest.approx(1e-3)  # the default


@pytest.mark.parametrize(("table", "fragment"), [("overload_fraction = 2.0",
                                                  "checks.overload_fraction = 2.0: expected a number in (0, 1]"),
                                                 ("min_pulse_width_ms = 0.1", "did you mean 'pulse_width_min_ms'"),
                                                 ("pulse_width_min_ms = 2.0", "pulse width range")])
def test_bad_checks_are_named(tmp_path, table, fragment):
    path = tmp_path / "bad.toml"
    path.write_text(GOOD + "[checks]\n" + table + "\n")
    assert_one_line_error(labctl("run", str(path), "--out", str(tmp_path / "c.h5")), fragment)


@pytest.mark.parametrize(("table", "line", "fragment"), [
    ("[loading]", "knob_step_deg = nan", "loading.knob_step_deg = nan: expected a finite number in (0, 3600]"),
    ("[specimen]", "knob_step_deg = nan", "specimen.knob_step_deg = nan: expected a finite number in (0, 3600]"),
    ("[specimen]", "max_load_n = nan", "specimen.max_load_n = nan: expected a finite positive number"),
    ("[specimen]", "max_load_n = -inf", "specimen.max_load_n = -inf: expected a finite positive number"),
    ("[specimen]", "rail_ra_um = nan", "specimen.rail_ra_um = nan: expected a finite number in [0, 50]"),
    ("[acquisition]", "trigger_level_n = nan", "acquisition.trigger_level_n = nan: expected a finite positive number"),
    ("[acquisition]", "timeout_s = inf", "acquisition.timeout_s = inf: expected a finite positive number"),
    ("[repetitions]", "rotate_rollers_deg = nan", "repetitions.rotate_rollers_deg = nan: expected a finite number"),
    ("[checks]", "min_peak_force_n = nan", "checks.min_peak_force_n = nan: expected a finite number ≥ 0"),
])
def test_nan_and_inf_are_refused_naming_file_table_key_value_and_expectation(table, line, fragment):
    text = GOOD if table in GOOD else GOOD + f"{table}\n"
    with pytest.raises(InputError) as err:
        parse_protocol(text.replace(table, f"{table}\n{line}", 1), "p.toml")
    assert str(err.value).startswith(f"p.toml: {fragment}"), str(err.value)


def test_a_nan_protocol_leaves_no_campaign_file(tmp_path):
    path = tmp_path / "nan.toml"
    path.write_text(GOOD.replace("[acquisition]", "[acquisition]\ntrigger_level_n = nan"))
    assert_one_line_error(labctl("run", str(path), "--backend", "sim", "--out", str(tmp_path / "c.h5")),
                          str(path), "acquisition.trigger_level_n = nan")
    assert not (tmp_path / "c.h5").exists()


@pytest.mark.parametrize(("line", "fragment"), [
    ("impacts_per_step = 3.0", "acquisition.impacts_per_step = 3.0: expected int (an integer 1-100)"),
    ("trigger_level_n = true", "acquisition.trigger_level_n = True: expected float (a positive number)"),
    ("trigger_levl_n = 3", "acquisition: unknown key(s) trigger_levl_n (did you mean 'trigger_level_n'?)"),
])
def test_wrong_types_and_typos_name_the_expectation_and_the_closest_key(line, fragment):
    with pytest.raises(InputError, match="^p.toml: " + fragment.replace("(", r"\(").replace(")", r"\)")
                       .replace("?", r"\?").replace(".", r"\.")):
        parse_protocol(GOOD.replace("impacts_per_step = 3", line), "p.toml")


def test_a_bad_world_file_is_refused_before_a_campaign_file_exists(tmp_path):
    world = tmp_path / "w.toml"
    world.write_text('[baseline]\nmodel = "tripp"\n[scatter]\nstiffness_rel = nan\n')
    out = tmp_path / "c.h5"
    proc = labctl("run", "protocols/quick_check.toml", "--backend", "sim", "--world", str(world), "--out", str(out))
    assert_one_line_error(proc, str(world), "scatter.stiffness_rel = nan")
    assert not out.exists()
