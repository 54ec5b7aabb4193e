"""Rig files: the shipped default loads; bad files are refused with the file, key and expectation named."""

from __future__ import annotations

import pytest

from labctl.data import data_path
from labctl.errors import InputError
from labctl.physics import load_rig
from labctl.physics.rig_config import DEFAULT_RIG, rig_from_text


def test_default_rig_has_twelve_channels_in_contract_order():
    rig = load_rig()
    assert rig.channels == tuple(f"A{i}{ax}" for i in range(1, 5) for ax in "XYZ")
    assert rig.flexible_modes and min(m.frequency_hz for m in rig.flexible_modes) > 2000


def _write_variant(tmp_path, old, new):
    from labctl.data import data_path

    text = data_path(DEFAULT_RIG).read_text()
    assert old in text
    path = tmp_path / "rig.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_negative_mass_is_named(tmp_path):
    path = _write_variant(tmp_path, "mass_kg = 11.6", "mass_kg = -1")
    with pytest.raises(InputError, match=r"upper_disc.*mass_kg.*positive"):
        load_rig(path)


def test_text_where_number_expected_is_named(tmp_path):
    path = _write_variant(tmp_path, "setup_stiffness_n_per_m = 1.45e9", 'setup_stiffness_n_per_m = "stiff"')
    with pytest.raises(InputError, match=r"setup_stiffness_n_per_m = 'stiff'.*expected float"):
        load_rig(path)


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_rig(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[upper_disc\nmass_kg = 3")
    with pytest.raises(InputError, match="not valid TOML"):
        load_rig(bad)


def test_rig_uncertainty_is_read_and_checked(tmp_path):
    rig = load_rig()
    assert rig.uncertainty.mass_std_kg == pytest.approx(0.12)
    assert rig.uncertainty.setup_stiffness_std_n_per_m == pytest.approx(1.5e8)
    text = (data_path(DEFAULT_RIG)).read_text().replace("mass_setup_correlation = 0.0", "mass_setup_correlation = 2.0")
    bad = tmp_path / "rig.toml"
    bad.write_text(text)
    with pytest.raises(InputError, match=r"uncertainty\.mass_setup_correlation = 2\.0"):
        load_rig(bad)
    bad.write_text(text.replace("mass_setup_correlation = 2.0", "mass_sdt_kg = 1.0"))
    with pytest.raises(InputError, match=r"uncertainty: unknown key\(s\) mass_sdt_kg \(did you mean 'mass_std_kg'\?\)"):
        load_rig(bad)


@pytest.mark.parametrize(("old", "new", "message"), [
    ("thickness_mm = 22.0", "thickness_mm = nan", "upper_disc.thickness_mm = nan: expected a finite positive number"),
    ("setup_stiffness_n_per_m = 1.45e9", "setup_stiffness_n_per_m = inf",
     "contacts.setup_stiffness_n_per_m = inf: expected a finite positive number"),
    ("angles_deg = [0.0, 120.0, 240.0]", "angles_deg = [0.0, nan, 240.0]", "contacts.angles_deg = [0.0, nan, 240.0]"),
    ("gravity_m_per_s2 = 9.81", "gravity_m_per_s2 = nan", "loading.gravity_m_per_s2 = nan: expected a finite"),
    ("angle_deg = 35.0", "angle_deg = nan", "hammer.angle_deg = nan: expected a finite number"),
    ("model_rel = 0.003", "model_rel = nan", "uncertainty.model_rel = nan: expected a finite number ≥ 0"),
    ("hammer = 0.7", "hammer = nan", "flexible_modes[0].hammer = nan: expected a finite number"),
    ("A2Z = -0.5,", "A2Z = nan,", "flexible_modes[0].shape.A2Z = nan: expected a finite number"),
    ("A2Z = -0.5,", "A9Z = -0.5,",
     "flexible_modes[0].shape: unknown key(s) A9Z (did you mean 'A4Z'?); expected one of A1X"),
    ("radius_mm = 77.0", "radius_mmm = 77.0", "contacts: unknown key(s) radius_mmm (did you mean 'radius_mm'?)"),
    ('disc = "upper"', 'disc = "top"', "sensors[0].disc = 'top': expected one of upper, lower"),
    ("[damping]", "[dampings]", "unknown key(s) dampings (did you mean 'damping'?)"),
])
def test_nan_inf_and_typos_are_refused_naming_file_table_key_value(tmp_path, old, new, message):
    path = _write_variant(tmp_path, old, new)
    with pytest.raises(InputError) as err:
        load_rig(path)
    assert str(err.value).startswith(f"{path}: {message}"), str(err.value)


def test_rig_read_from_a_campaign_copy_names_its_source():
    text = data_path(DEFAULT_RIG).read_text().replace("rods = 4", "rods = 4.5")
    with pytest.raises(InputError, match=r"^c\.h5:/config/rig\.toml: loading\.rods = 4\.5: expected int"):
        rig_from_text(text, "c.h5:/config/rig.toml")
