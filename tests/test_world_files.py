"""World scenario files: the shipped ones parse into the physics they document; bad files name file and key."""

from __future__ import annotations

import json

import numpy as np
import pytest

from labctl.backends import make_rig, sim_settings
from labctl.data.units import to_si
from labctl.errors import InputError
from labctl.physics import (
    EQ5,
    EQ6,
    ContactCase,
    EmpiricalFit,
    EndEffects,
    Misalignment,
    material,
    roller,
    static_load_rating_n,
)
from labctl.physics.rig_config import load_rig
from labctl.physics.world import load_world, shipped_worlds
from labctl.physics.world_laws import ConformingContact, ExpressionLaw, check_expression

STEEL = material("1.3505")
EFFECT_WORLDS = ("surface_roughness", "end_effects", "material_hardness", "misalignment", "setup_compliance")


def test_every_shipped_world_loads_and_builds_a_rig():
    names = shipped_worlds()
    assert {"default", "ideal", "tripp_only", "balls", *EFFECT_WORLDS} <= set(names)
    for name in names:
        world = load_world(name)
        assert world.source.endswith(f"{name}.toml") and world.description
        sim_settings(world)  # instrument overrides are valid simulator settings


def test_default_world_is_the_conforming_contact_without_library_effects():
    world = load_world()
    assert world.law.baseline == "conforming" and world.law.effects == ()
    base = world.law.base
    assert isinstance(base, ConformingContact)
    assert base.depth_m == pytest.approx(4.16e-3) and base.edge_length_m == pytest.approx(5e-5)
    assert base.asperity_spot_rel > 0 and world.scatter.stiffness_rel == 0.0  # scatter from physical sources
    assert world.instruments["knob_slack_deg"] > 0
    assert world.setup_stiffness_factor == 1.0 and world.effect_names == ()


@pytest.mark.parametrize("type_id", range(1, 8))
@pytest.mark.parametrize("rail_ra_m, fit", [(0.2e-6, EQ5), (0.03e-6, EQ6)])
def test_default_world_follows_eq5_and_eq6_for_the_steel_types(type_id, rail_ra_m, fit):
    r = roller(type_id)
    case = ContactCase(r, STEEL, rail_ra_m)
    loads = np.geomspace(38.0, 0.31 * static_load_rating_n(r, STEEL), 8)
    law = load_world().law
    ratio = law.stiffness_n_per_m(case, loads) / EmpiricalFit(fit, r.contact_length_m).stiffness_n_per_m(loads)
    assert np.all(np.abs(ratio - 1) < 0.10), ratio  # the paper's ±10 % of Eqs. 5 and 6


def test_default_world_stainless_conforms_on_rough_rails_and_si3n4_is_stiffer():
    law = load_world().law

    def k(type_id, ra, load):
        return float(law.stiffness_n_per_m(ContactCase(roller(type_id), STEEL, ra), load))

    assert k(9, 0.2e-6, 440.0) > 1.08 * k(1, 0.2e-6, 440.0)  # plastic conformity of the softer roller
    assert k(9, 0.2e-6, 60.0) < 1.01 * k(1, 0.2e-6, 60.0)  # ... only near its hardness
    assert abs(k(9, 0.03e-6, 440.0) / k(1, 0.03e-6, 440.0) - 1) < 0.04  # little of it on mirror rails
    l8, l5 = roller(8).contact_length_m, roller(5).contact_length_m
    for per_length in (15e3, 60e3, 180e3):  # N/m: equal load per contact length
        assert k(8, 0.2e-6, per_length * l8) / l8 > 1.05 * k(5, 0.2e-6, per_length * l5) / l5  # higher E*


TABLE_WORLD = """
description = "measured curves"
[baseline]
model = "table"
[[baseline.tables]]
roller_type = 1
load_n = [40.0, 100.0, 400.0]
stiffness_n_per_m = [2.0e7, 3.0e7, 4.5e7]
[effects.setup_compliance]
stiffness_factor = 1.2
"""


def test_a_world_can_hide_a_tabulated_law(tmp_path):
    path = tmp_path / "table.toml"
    path.write_text(TABLE_WORLD)
    world = load_world(path)
    assert world.law.baseline == "table" and world.effect_names == ("setup_compliance",)
    case = ContactCase(roller(1), STEEL, 0.2e-6)
    k = world.law.stiffness_n_per_m(case, np.array([40.0, 100.0, 200.0, 400.0, 800.0]))
    assert k[:2] == pytest.approx([2.0e7, 3.0e7]) and k[3] == pytest.approx(4.5e7)
    assert k[2] == pytest.approx(3.0e7 * (200 / 100) ** (np.log(1.5) / np.log(4)))  # log-log between points
    assert 4.5e7 < k[4] < 6e7  # extrapolated at the last slope
    with pytest.raises(ValueError, match="no table for roller type 2"):
        world.law.stiffness_n_per_m(ContactCase(roller(2), STEEL, 0.2e-6), 100.0)


def test_a_world_can_hide_an_expression_read_safely(tmp_path):
    path = tmp_path / "expr.toml"
    path.write_text('[baseline]\nmodel = "expression"\nexpression = "5.151e9 * L * log(F / L / 1.8e3)"\n')
    law = load_world(path).law
    case = ContactCase(roller(3), STEEL, 0.2e-6)
    loads = np.array([50.0, 500.0])
    assert law.stiffness_n_per_m(case, loads) == pytest.approx(
        EmpiricalFit(EQ5, roller(3).contact_length_m).stiffness_n_per_m(loads))
    assert check_expression("E * sqrt(F * R / E) / (1 + Ra / 1e-6) * tanh(H / 1e9) - -2") is not None


@pytest.mark.parametrize("expression, message", [
    ("__import__('os').system('true')", "is not allowed"),
    ("__import__('os')", "'__import__' is not allowed"),
    ("F.real", "'Attribute' is not allowed"),
    ("(lambda: 1)()", "not allowed"),
    ("F if F else L", "'IfExp' is not allowed"),
    ("log(F, base=2)", "not allowed"),
    ("open", "'open' is not allowed"),
    ("F +", "not an expression"),
    ("'1' * 3", "not allowed"),
    ("log * F", "'log' is not allowed"),
    ("log(F, L)", "log() takes 1 argument(s)"),
    ("maximum(F)", "maximum() takes 2 argument(s)"),
])
def test_world_expressions_allow_only_arithmetic_on_known_names(tmp_path, expression, message):
    path = tmp_path / "bad.toml"
    path.write_text(f'[baseline]\nmodel = "expression"\nexpression = {json.dumps(expression)}\n')
    with pytest.raises(InputError) as exc:
        load_world(path)
    assert str(path) in str(exc.value) and "baseline.expression" in str(exc.value) and message in str(exc.value)


def test_an_expression_that_gives_no_stiffness_is_refused_when_evaluated(tmp_path):
    law = ExpressionLaw("F - 100")
    with pytest.raises(ValueError, match="non-positive"):
        law.stiffness_n_per_m(ContactCase(roller(1), STEEL, 0.2e-6), np.array([50.0, 200.0]))


def test_each_effect_world_hides_exactly_its_effect():
    for name in EFFECT_WORLDS:
        assert load_world(name).effect_names == (name,)
    assert load_world("tripp_only").effect_names == () and load_world("ideal").effect_names == ()
    assert load_world("balls").law.baseline == "hertz"
    assert load_world("end_effects").law.effects == (EndEffects(edge_length_m=1e-4),)
    assert load_world("misalignment").law.effects == (Misalignment(tilt_rad=1.5e-3),)
    assert load_world("setup_compliance").setup_stiffness_factor == 1.25


def test_hardness_onset_world_yields_only_in_the_top_quarter_of_type_1s_load_range():
    """Plastic conformity whose onset (p_max = 0.30·H) type 1 on Ra 0.2 µm rails reaches at about 310 N: plain
    Tripp below 300 N (3/4 of a 400 N cap), a rise of a few per cent at the top."""
    world = load_world("hardness_onset")
    assert world.effect_names == ("material_hardness",)
    case = ContactCase(roller(1), STEEL, 0.2e-6)
    tripp = load_world("tripp_only").law
    loads = np.array([38.0, 200.0, 300.0, 320.0, 382.0])
    ratio = world.law.stiffness_n_per_m(case, loads) / tripp.stiffness_n_per_m(case, loads)
    assert np.allclose(ratio[:3], 1.0) and 1.0 < ratio[3] < 1.01 and 1.02 < ratio[4] < 1.05, ratio


def test_units_at_the_edge():
    assert to_si("edge_length_mm", 0.1) == ("edge_length_m", pytest.approx(1e-4))
    assert to_si("tilt_mrad", 2.0) == ("tilt_rad", pytest.approx(2e-3))
    assert to_si("pulse_width_min_ms", 0.3) == ("pulse_width_min_s", pytest.approx(3e-4))
    assert to_si("asperity_scale", 1.5) == ("asperity_scale", 1.5)


TABLE_HEAD = '[baseline]\nmodel = "table"\n[[baseline.tables]]\nroller_type = 1\n'
BAD = [
    ("", "missing key 'baseline'"),
    ('[baseline]\nmodel = "fem"\n', "baseline.model = 'fem': expected one of tripp"),
    ('[baseline]\nmodel = "hertz"\ndepth_mm = 2.0\n', "baseline: unknown key(s) depth_mm"),
    ('[baseline]\nmodel = "tripp"\ndepth_mm = -1.0\n', "baseline.depth_mm = -1.0"),
    ('[baseline]\nmodel = "tripp"\n[effects.lubrication]\nviscosity = 1.0\n',
     "effects: unknown key(s) lubrication; expected one of end_effects, material_hardness"),
    ('[baseline]\nmodel = "tripp"\n[effects.misalignment]\ntilt_deg = 1.0\n',
     "effects.misalignment: unknown key(s) tilt_deg (did you mean 'tilt_rel'?); expected one of tilt_mrad, tilt_rel"),
    ('[baseline]\nmodel = "tripp"\n[effects.misalignment]\ntilt_mrad = 50.0\n',
     "effects.misalignment.tilt_mrad = 50.0: expected a number in [0, 5]"),
    ('[baseline]\nmodel = "tripp"\n[effects.surface_roughness]\nasperity_scale = "big"\n',
     "effects.surface_roughness.asperity_scale = 'big': expected float (a number in [0, 20])"),
    ('[baseline]\nmodel = "tripp"\n[effects.setup_compliance]\nstiffness_factor = 1.2\nstiffness_factor_rel = 0.1\n',
     "effects.setup_compliance: the setup stiffness has no per-seating scatter"),
    ('[baseline]\nmodel = "tripp"\n[scatter]\nstiffness_rel = 2.0\n',
     "scatter.stiffness_rel = 2.0: expected a number in [0, 1]"),
    ('[baseline]\nmodel = "tripp"\n[scatter]\nroughness = 0.1\n',
     "scatter: unknown key(s) roughness; expected one of stiffness_rel"),
    ('[baseline]\nmodel = "tripp"\n[effect.end_effects]\nedge_length_mm = 0.1\n', "unknown key(s) effect"),
    ('[baseline\nmodel = "tripp"\n', "not valid TOML"),
    ('[baseline]\nmodel = "table"\n', "baseline: missing key 'tables'; expected an array of tables"),
    (TABLE_HEAD + "load_n = [1.0, 0.5]\nstiffness_n_per_m = [1.0, 2.0]\n",
     "baseline.tables[0]: load_n must rise strictly"),
    (TABLE_HEAD + "load_n = [1.0, 2.0]\nstiffness_n_per_m = [1.0, -2.0]\n",
     "baseline.tables[0].stiffness_n_per_m = -2.0: expected a positive number"),
    ('[baseline]\nmodel = "conforming"\ndepth_mm = 500.0\n',
     "baseline.depth_mm = 500.0: expected a number in [0.1, 100]"),
    ('[baseline]\nmodel = "conforming"\nroughness = 1.0\n',
     "baseline: unknown key(s) roughness; expected one of asperity_scale"),
    ('[baseline]\nmodel = "tripp"\n[faults]\nunequal_seating_gap_um = 0.5\nunequal_seating_gap_m = 5e-7\n',
     "faults: unequal_seating_gap_um and unequal_seating_gap_m both set unequal_seating_gap_m; give one"),
    ('[baseline]\nmodel = "tripp"\n[faults]\ncreep_n_per_ms = 1.0\n', "faults: unknown key(s) creep_n_per_ms"),
    ('[baseline]\nmodel = "expression"\nexpression = "F"\ntables = []\n',
     "baseline: unknown key(s) tables; expected one of expression, model"),
    ('[baseline]\nmodel = "tripp"\n[faults]\ndouble_hit_rate = "often"\n',
     "faults.double_hit_rate = 'often': expected float (a number)"),
]


@pytest.mark.parametrize("text, message", BAD)
def test_bad_world_files_name_file_key_and_expectation(tmp_path, text, message):
    path = tmp_path / "world.toml"
    path.write_text(text)
    with pytest.raises(InputError) as exc:
        load_world(path)
    assert str(path) in str(exc.value) and message in str(exc.value)


CONFORMING = '[baseline]\nmodel = "conforming"\n'
TRIPP = '[baseline]\nmodel = "tripp"\n'
# (a table with {} for a number, "TABLE.KEY = nan: expected ...", "TABLE: unknown key(s) K (did you mean ...")
ONE_FORMAT = [
    (CONFORMING + "conformity = {}\n", "baseline.conformity = nan: expected a finite number in [0.01, 10]",
     "baseline: unknown key(s) conformty (did you mean 'conformity'?); expected one of asperity_scale"),
    (TRIPP + "depth_mm = {}\n",
     "baseline.depth_mm = nan: expected a finite number in [0.001, 1000]",
     "baseline: unknown key(s) depth (did you mean 'depth_mm'?); expected one of depth_mm, model"),
    (TRIPP + "[faults]\ndouble_hit_rate = {}\n", "faults.double_hit_rate = nan: expected a finite number",
     "faults: unknown key(s) double_hit_rat (did you mean 'double_hit_rate'?); expected one of creep_n_per_s"),
    (TRIPP + "[rig.support]\nstiffness_n_per_m = {}\n",
     "rig.support.stiffness_n_per_m = nan: expected a finite positive number",
     "rig.support: unknown key(s) stiffnes_n_per_m (did you mean 'stiffness_n_per_m'?); expected one of damping_ratio"),
    (TRIPP + "[rig.upper_disc]\nthickness_mm = {}\n", "rig.upper_disc.thickness_mm = nan: expected a finite positive",
     "rig.upper_disc: unknown key(s) thicknes_mm (did you mean 'thickness_mm'?); expected one of inertia_kg_m2"),
    (TRIPP + "[instruments]\npulse_width_min_ms = {}\n", "instruments.pulse_width_min_ms = nan: expected a finite",
     "instruments: unknown key(s) pulse_width_min_mms (did you mean 'pulse_width_min_ms'?); expected one of"),
    (TRIPP + "[effects.end_effects]\nedge_length_mm = {}\n",
     "effects.end_effects.edge_length_mm = nan: expected a finite number in [0, 2]",
     "effects.end_effects: unknown key(s) edge_lenght_mm (did you mean 'edge_length_mm'?); expected one of"),
]


@pytest.mark.parametrize("text, nan_message, typo_message", ONE_FORMAT)
def test_nan_and_misspelt_keys_are_reported_in_the_one_format(tmp_path, text, nan_message, typo_message):
    path = tmp_path / "world.toml"
    key = typo_message.split("unknown key(s) ")[1].split(" ")[0]
    right = typo_message.split("did you mean '")[1].split("'")[0]
    for body, message in [(text.format("nan"), nan_message), (text.format("-inf"), nan_message.replace("nan", "-inf")),
                          (text.format("1.0").replace(f"{right} =", f"{key} ="), typo_message)]:
        path.write_text(body)
        with pytest.raises(InputError) as exc:
            load_world(path)
        assert str(exc.value).startswith(f"{path}: {message}"), str(exc.value)


def test_world_rig_overrides_and_fault_sizes_convert_through_the_one_unit_table(tmp_path):
    path = tmp_path / "world.toml"
    path.write_text(TRIPP + "[rig.upper_disc]\nthickness_mm = 25.0\n[faults]\nunequal_seating_gap_mm = 0.002\n"
                    "[instruments]\nload_cell_read_ms = 50.0\n")
    world = load_world(path)
    assert world.rig_overrides == (("upper_disc", "thickness_mm", 25.0),)  # kept in the rig file's units
    assert world.faults == {"unequal_seating_gap_m": pytest.approx(2e-6)}
    assert world.instruments == {"load_cell_read_s": pytest.approx(0.05)}
    assert world.true_rig(load_rig(None)).upper.thickness_m == pytest.approx(0.025)


def test_bad_instrument_settings_are_refused_with_the_world(tmp_path):
    case = ContactCase(roller(1), STEEL, 0.2e-6)
    for text, message in [("accel_noise_g = 0.1", "instruments: unknown key(s) accel_noise_g"),
                          ("force_noise_n = -1.0",
                           "instruments: simulator setting force_noise_n = -1.0: expected a finite number >= 0")]:
        path = tmp_path / "w.toml"
        path.write_text(f'[baseline]\nmodel = "tripp"\n[instruments]\n{text}\n')
        with pytest.raises(InputError) as exc:
            make_rig("sim", case=case, world=path)
        assert str(path) in str(exc.value) and message in str(exc.value)


def test_unknown_backend_is_refused_and_hw_is_handed_to_the_hardware_factory(tmp_path):
    case = ContactCase(roller(1), STEEL, 0.2e-6)
    with pytest.raises(InputError, match="unknown backend 'lab'; valid backends: sim, hw"):
        make_rig("lab", case=case)
    missing = tmp_path / "devices.toml"
    try:
        import labctl.hardware  # noqa: F401
    except ImportError:
        with pytest.raises(InputError, match="hardware backend not available"):
            make_rig("hw", case=case, devices=missing)
    else:
        with pytest.raises(InputError, match=str(missing)):
            make_rig("hw", case=case, devices=missing)
