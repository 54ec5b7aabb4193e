"""The stiffness-table CSV contract: exact header names, round trip, defaults, clear errors."""

from __future__ import annotations

import csv
import math

import pytest

from labctl.errors import InputError
from labctl.physics import TrippContact, material, roller
from labctl.physics.materials import materials
from labctl.stiffness_table import REQUIRED, StiffnessPoint, read_stiffness_table, write_stiffness_table

FULL = StiffnessPoint(
    diameter_m=3e-3, contact_length_m=1.793e-3, rail_ra_m=0.2e-6, load_n=440.0, stiffness_n_per_m=4.54e7,
    roller_type=1, roller_length_m=2.2e-3, material="1.3505", youngs_modulus_pa=210e9, poisson_ratio=0.29,
    hardness_hrc=60.0, repetition=2,
)
MINIMAL = StiffnessPoint(diameter_m=6e-3, contact_length_m=3.805e-3, rail_ra_m=0.03e-6, load_n=123.4,
                         stiffness_n_per_m=5.1e7)


def _header(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return next(csv.reader(fh))


def test_round_trip_keeps_every_field_and_uses_the_contract_header(tmp_path):
    path = tmp_path / "k.csv"
    write_stiffness_table(path, [FULL, MINIMAL])
    assert _header(path) == ["diameter_mm", "contact_length_mm", "rail_ra_um", "load_n", "stiffness_n_per_m",
                             "roller_type", "roller_length_mm", "material", "youngs_modulus_gpa", "poisson_ratio",
                             "hardness_hrc", "repetition"]
    back = read_stiffness_table(path)
    assert len(back) == 2
    for got, want in zip(back, [FULL, MINIMAL], strict=True):
        for name, value in vars(want).items():
            if isinstance(value, float):
                assert getattr(got, name) == pytest.approx(value, rel=1e-10), name
            else:
                assert getattr(got, name) == value, name
    first_row = path.read_text(encoding="utf-8").splitlines()[1].split(",")
    assert first_row[:5] == ["3", "1.793", "0.2", "440", "45400000"]


def test_only_required_columns_when_no_point_has_optional_values(tmp_path):
    path = tmp_path / "k.csv"
    write_stiffness_table(path, [MINIMAL])
    assert tuple(_header(path)) == REQUIRED
    assert read_stiffness_table(path) == [MINIMAL]


def test_case_defaults_to_bearing_steel_roller_and_rails():
    case = MINIMAL.case()
    assert case.roller.material.youngs_modulus_pa == 210e9
    assert case.roller.material.poisson_ratio == 0.29
    assert case.roller.material.hardness_hrc == 60.0
    assert case.rail.name == "1.3505"
    assert case.rail_ra_m == pytest.approx(0.03e-6)
    assert case.roller.total_length_m == case.roller.contact_length_m


def test_case_of_a_catalogue_row_gives_the_catalogue_physics():
    cat = roller(1)
    k_row = TrippContact(FULL.case().roller, material("1.3505")).stiffness_n_per_m(440.0)
    k_cat = TrippContact(cat, material("1.3505")).stiffness_n_per_m(440.0)
    assert k_row == pytest.approx(k_cat, rel=1e-12)
    assert FULL.case().roller.roughness_ra_m == pytest.approx(cat.roughness_ra_m)
    six = roller(6)
    row6 = StiffnessPoint(six.diameter_m, six.contact_length_m, 0.2e-6, 100.0, 4e7, roller_type=6)
    assert row6.case().roller.roughness_ra_m == pytest.approx(0.08e-6)
    other = StiffnessPoint(5e-3, 4e-3, 0.2e-6, 100.0, 4e7, roller_type=6)  # type number of another geometry
    assert other.case().roller.roughness_ra_m == pytest.approx(0.03e-6)


def test_explicit_material_columns_override_the_catalogue():
    p = StiffnessPoint(3e-3, 1.8e-3, 0.2e-6, 100.0, 4e7, material="1.4034", youngs_modulus_pa=190e9)
    m = p.case().roller.material
    assert (m.name, m.youngs_modulus_pa, m.poisson_ratio, m.hardness_hrc) == ("1.4034", 190e9, 0.28, 54.0)
    custom = StiffnessPoint(3e-3, 1.8e-3, 0.2e-6, 100.0, 4e7, material="brass", youngs_modulus_pa=100e9,
                            poisson_ratio=0.34)
    assert custom.case().roller.material.youngs_modulus_pa == 100e9


def test_spreadsheet_exports_read_cleanly(tmp_path):
    path = tmp_path / "excel.csv"
    path.write_bytes("\ufeffdiameter_mm, contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m,notes\r\n"
                     "3,1.793,0.2,440,4.54e7,first\r\n,,,,,\r\n3,1.793,0.2, 500 ,4.7e7,\r\n".encode())
    points = read_stiffness_table(path)
    assert [p.load_n for p in points] == [440.0, 500.0]
    assert points[0].roller_type is None and points[0].repetition is None


BAD = [
    ("diameter_mm,contact_length_mm,rail_ra_um,stiffness_n_per_m\n3,1.793,0.2,4e7\n", ["missing column", "load_n"]),
    ("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m\n3,1.793,0.2,440,4e7\n"
     "3,1.793,0.2,abc,4e7\n", ["row 3", "column load_n", "'abc'"]),
    ("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m\n3,1.793,0.2,-5,4e7\n",
     ["row 2", "column load_n", "'-5'", "positive"]),
    ("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m\n3,1.793,0.2,440,\n",
     ["row 2", "column stiffness_n_per_m", "empty"]),
    ("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m\n3,1.793,0.2,440,nan\n",
     ["column stiffness_n_per_m", "'nan'"]),
    ("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m,roller_type\n3,1.793,0.2,440,4e7,1.5\n",
     ["column roller_type", "'1.5'", "integer"]),
    ("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m,poisson_ratio\n3,1.793,0.2,440,4e7,0.7\n",
     ["column poisson_ratio", "'0.7'"]),
    ("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m,material\n3,1.793,0.2,440,4e7,brass\n",
     ["row 2", "column material", "brass", "youngs_modulus_gpa"]),
    ("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m\n", ["no data rows"]),
    ("", ["missing column"]),
]


@pytest.mark.parametrize(("text", "fragments"), BAD)
def test_malformed_tables_name_file_row_column_and_value(tmp_path, text, fragments):
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as info:
        read_stiffness_table(path)
    message = str(info.value)
    assert str(path) in message
    for fragment in fragments:
        assert fragment in message, message


def test_missing_file_and_binary_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_stiffness_table(tmp_path / "nope.csv")
    junk = tmp_path / "junk.csv"
    junk.write_bytes(b"\xff\xfe\x00\x81garbage")
    with pytest.raises(InputError, match="junk.csv"):
        read_stiffness_table(junk)


def test_written_numbers_survive_unit_conversion_exactly_enough(tmp_path):
    p = StiffnessPoint(math.pi * 1e-3, 1.0 / 3.0 * 1e-2, 0.123456789e-6, 1234.56789, 9.87654321e7)
    path = tmp_path / "k.csv"
    write_stiffness_table(path, [p])
    (q,) = read_stiffness_table(path)
    for name in ("diameter_m", "contact_length_m", "rail_ra_m", "load_n", "stiffness_n_per_m"):
        assert getattr(q, name) == pytest.approx(getattr(p, name), rel=1e-11)


def test_rail_material_column_is_read_written_and_used_for_the_contact(tmp_path):
    other = "Si3N4"  # a ceramic rail: much stiffer than bearing steel
    point = StiffnessPoint(diameter_m=3e-3, contact_length_m=1.793e-3, rail_ra_m=0.2e-6, load_n=440.0,
                           stiffness_n_per_m=4.5e7, rail_material=other)
    path = tmp_path / "k.csv"
    write_stiffness_table(path, [point, MINIMAL])
    assert _header(path)[-1] == "rail_material"
    back = read_stiffness_table(path)
    assert back == [point, MINIMAL]
    case = back[0].case()
    assert case.rail == materials()[other]
    assert case.effective_modulus_pa > 1.15 * MINIMAL.case().effective_modulus_pa
    bad = tmp_path / "bad.csv"
    bad.write_text("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m,rail_material\n"
                   "3,1.793,0.2,440,4.5e7,unobtainium\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"bad.csv: row 2, column rail_material: unknown rail material 'unobtainium'"):
        read_stiffness_table(bad)


def test_uncertainty_budget_columns_round_trip_and_are_checked(tmp_path):
    point = StiffnessPoint(3e-3, 3.8e-3, 0.2e-6, 100.0, 2.0e7, stiffness_std_n_per_m=1.1e5,
                           stiffness_std_fit_n_per_m=2e3, stiffness_std_mass_n_per_m=1e5,
                           stiffness_std_setup_n_per_m=3e4, stiffness_std_model_n_per_m=6e4)
    path = tmp_path / "t.csv"
    write_stiffness_table(path, [point])
    assert read_stiffness_table(path) == [point]
    path.write_text(path.read_text().replace("110000", "-5"))
    with pytest.raises(InputError, match=r"column stiffness_std_n_per_m: '-5' is not a stiffness uncertainty"):
        read_stiffness_table(path)
