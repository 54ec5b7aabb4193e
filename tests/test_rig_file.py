"""Rig files: the shipped default loads; bad files are refused with the file, key and expectation named."""

from __future__ import annotations

import pytest

from labctl.data import data_path
from labctl.errors import InputError
from labctl.physics import load_rig
from labctl.physics.rig_config import DEFAULT_RIG


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
    with pytest.raises(InputError, match=r"uncertainty\.mass_sdt_kg: unknown key"):
        load_rig(bad)
