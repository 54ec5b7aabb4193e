"""The one configuration reader (labctl.data.schema) and edge units (labctl.data.units); the catalogues through it."""

from __future__ import annotations

import math

import pytest

from labctl.data import data_path
from labctl.data.schema import Integer, Number, Numbers, Table, Text, Where, bounded, build, read
from labctl.data.units import from_si, si_name, to_si
from labctl.errors import InputError
from labctl.physics.catalogue import rollers
from labctl.physics.materials import materials
from labctl.physics.rig_config import RigUncertainty

W = Where("f.toml", "t")


def _error(doc, schema, where=W) -> str:
    with pytest.raises(InputError) as err:
        read(doc, schema, where)
    return str(err.value)


def test_one_error_format_names_file_table_key_value_and_expectation():
    assert _error({"x_mm": "3"}, {"x_mm": Number(gt=0, unit="mm")}) == \
        "f.toml: t.x_mm = '3': expected float (a positive number)"
    assert _error({"n": 0}, {"n": Integer(1, 9)}) == "f.toml: t.n = 0: expected an integer 1-9"
    assert _error({}, {"n": Integer(1, 9)}) == "f.toml: t: missing key 'n'; expected an integer 1-9"
    assert _error({"kind": "cube"}, {"kind": Text(("roller", "ball"))}) == \
        "f.toml: t.kind = 'cube': expected one of roller, ball"
    assert _error({"speeed": 1}, {"speed": Number(), "sped_rel": Number()}) == \
        "f.toml: t: unknown key(s) speeed (did you mean 'speed'?); expected one of sped_rel, speed"
    assert _error({"zzz": 1}, {"speed": Number()}) == "f.toml: t: unknown key(s) zzz; expected one of speed"
    nested = Where("f.toml").at("daq").at("channels").at(2)
    assert _error({"r": -1.0}, {"r": Number(ge=0, le=5)}, nested) == \
        "f.toml: daq.channels[2].r = -1.0: expected a number in [0, 5]"
    assert _error(3, {"r": Number()}, Where("f.toml").at("loading")) == "f.toml: loading = 3: expected a table"


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_nan_and_inf_are_refused_by_every_number_spec(bad):
    for spec, expected in [(Number(), "a finite number"), (Number(gt=0), "a finite positive number"),
                           (Number(ge=0, le=1), "a finite number in [0, 1]")]:
        assert _error({"v": bad}, {"v": spec}) == f"f.toml: t.v = {bad!r}: expected {expected}"
    assert "t.v = [1.0, " in _error({"v": [1.0, bad]}, {"v": Numbers(Number(), 2)})


def test_booleans_and_floats_are_not_integers_and_booleans_are_not_numbers():
    assert "expected int" in _error({"n": 3.0}, {"n": Integer()})
    assert "expected int" in _error({"n": True}, {"n": Integer()})
    assert "expected float" in _error({"x": False}, {"x": Number()})


def test_values_come_back_in_si_under_si_names_and_defaults_are_in_file_units():
    out = read({"thickness_mm": 22, "angle_deg": 90.0},
               {"thickness_mm": Number(unit="mm"), "angle_deg": Number(unit="deg"),
                "ra_um": Number(unit="um", default=0.2), "opt": Number(default=None), "t": Table(default={})}, W)
    assert out == {"thickness_m": pytest.approx(0.022), "angle_rad": pytest.approx(math.pi / 2),
                   "ra_m": pytest.approx(0.2e-6), "t": {}}
    assert isinstance(out["thickness_m"], float)


def test_build_fills_a_dataclass_keeping_its_defaults_and_names_its_own_rules():
    u = build(RigUncertainty, {"mass_std_kg": 0.1}, {"mass_std_kg": Number(ge=0), "model_rel": Number(ge=0)}, W)
    assert u == RigUncertainty(mass_std_kg=0.1)

    from labctl.processing import CheckConfig
    from labctl.protocol.parse import CHECKS

    c = build(CheckConfig, {"pulse_width_max_ms": 0.8}, CHECKS, W)
    assert c.pulse_width_max_s == pytest.approx(0.8e-3) and c.min_peak_force_n == CheckConfig().min_peak_force_n
    with pytest.raises(InputError, match=r"^f\.toml: t: pulse width range"):
        build(CheckConfig, {"pulse_width_min_ms": 2.0}, CHECKS, W)


def test_edge_units_round_trip_and_keys_without_a_unit_pass():
    assert to_si("edge_length_mm", 0.1) == ("edge_length_m", pytest.approx(1e-4))
    assert to_si("youngs_modulus_gpa", 210.0) == ("youngs_modulus_pa", pytest.approx(2.1e11))
    assert to_si("rail_ra_um", 0.2) == ("rail_ra_m", pytest.approx(2e-7))
    assert to_si("asperity_scale", 1.5) == ("asperity_scale", 1.5)
    for key, v in [("tilt_mrad", 2.0), ("pulse_width_min_ms", 0.3), ("edge_length_mm", 0.1)]:
        si_key, si = to_si(key, v)
        assert from_si(si_key, si, key.rsplit("_", 1)[1]) == (key, pytest.approx(v))
    assert si_name("iepe_current_ma", "ma") == "iepe_current_a" and si_name("knob_step_deg", "deg") == "knob_step_rad"


def _catalogue(tmp_path, name, old, new):
    text = data_path(name).read_text()
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(("name", "old", "new", "message"), [
    ("materials.toml", "hardness_hrc = 60.0", "hardness_hrc = nan",
     'materials.1.3505.hardness_hrc = nan: expected a finite number in [0, 100]'),
    ("materials.toml", "poisson_ratio = 0.29", "poisson_ratio = 0.7",
     "materials.1.3505.poisson_ratio = 0.7: expected a number in (-1, 0.5)"),
    ("materials.toml", "youngs_modulus_gpa = 210.0", "youngs_modulus_gpa = inf",
     "materials.1.3505.youngs_modulus_gpa = inf: expected a finite positive number"),
    ("materials.toml", "poisson_ratio = 0.29", "poisson = 0.29",
     "materials.1.3505: unknown key(s) poisson (did you mean 'poisson_ratio'?)"),
    ("rollers.toml", "roughness_ra_um = 0.028", "roughness_ra_um = nan",
     "rollers[0].roughness_ra_um = nan: expected a finite number ≥ 0"),
    ("rollers.toml", "default_roughness_ra_um = 0.03", "default_roughness_ra_um = inf",
     "default_roughness_ra_um = inf: expected a finite number ≥ 0"),
    ("rollers.toml", "diameter_mm = 3.00", "diameter_mm = -3.0",
     "rollers[0].diameter_mm = -3.0: expected a positive number"),
    ("rollers.toml", 'material = "1.3505"', 'material = "cheese"', "rollers[0].material = 'cheese': expected one of"),
    ("rollers.toml", "total_length_mm = 2.20", "total_length_mm = 1.0",
     "rollers[0].contact_length_mm = 1.793: expected at most total_length_mm = 1.0"),
])
def test_bad_catalogue_entries_are_refused_naming_file_table_key_value(tmp_path, name, old, new, message):
    path = _catalogue(tmp_path, name, old, new)
    with pytest.raises(InputError) as err:
        (materials if name == "materials.toml" else rollers)(path)
    assert str(err.value).startswith(f"{path}: {message}"), str(err.value)


def test_shipped_catalogues_read_in_si():
    assert materials()["1.3505"].youngs_modulus_pa == pytest.approx(210e9)
    assert rollers()[1].diameter_m == pytest.approx(3e-3) and rollers()[1].roughness_ra_m == pytest.approx(0.028e-6)


def test_bounded_schemas_read_world_effect_parameters_in_edge_units():
    from labctl.physics.effects import EFFECTS

    misalignment = bounded(EFFECTS["misalignment"].BOUNDS)
    assert list(misalignment) == ["tilt_mrad"]
    assert read({"tilt_mrad": 1.5}, misalignment, W) == {"tilt_rad": pytest.approx(1.5e-3)}
    assert _error({"tilt_mrad": 50.0}, misalignment, Where("w.toml").at("effects").at("misalignment")) == \
        "w.toml: effects.misalignment.tilt_mrad = 50.0: expected a number in [0, 5]"
    assert read({"edge_length_mm": 0.1}, bounded(EFFECTS["end_effects"].BOUNDS), W) == \
        {"edge_length_m": pytest.approx(1e-4)}
    assert _error({"tilt_deg": 1.0}, misalignment, W).startswith("f.toml: t: unknown key(s) tilt_deg (did you mean")
