"""Specimen conditions (lubrication, orientation, measured roughness and form): validated in the protocol, stored,
read back, indexed and queried by the archive, shown in the report, and without effect on the twin."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest

from labctl.archive.catalogue import SCHEMA_VERSION, connect, index
from labctl.archive.query import query
from labctl.campaign import run_campaign
from labctl.compare import compare_groups, load_group
from labctl.errors import InputError
from labctl.protocol import parse_protocol
from labctl.storage import CampaignReader

BASE = """
[protocol]
name = "conditions"
[specimen]
roller_type = 1
rail_ra_um = 0.2
max_load_n = 200.0
knob_step_deg = 360.0
{conditions}
[acquisition]
samples = 16384
impacts_per_step = 2
[repetitions]
count = 2
"""
OIL = """[specimen.conditions]
lubrication = "oil"
lubricant = "ISO VG 68"
orientation_deg = 90
roller_ra_um = 0.04
rail_ra_measured_um = 0.21
roundness_um = 0.5
"""


def _protocol(conditions: str) -> str:
    return BASE.format(conditions=conditions)


@pytest.mark.parametrize(("conditions", "message"), [
    ('[specimen.conditions]\nlubrication = "wet"', "specimen.conditions.lubrication = 'wet': expected one of dry"),
    ("[specimen.conditions]\nroundness = 0.5", "unknown key(s) roundness (did you mean 'roundness_um'?)"),
    ('[specimen.conditions]\nlubrication = "dry"\nlubricant = "x"', "a product name only with lubrication"),
    ("[specimen.conditions]\norientation_deg = 120", "specimen.conditions.orientation_deg = 120"),
    ("[specimen.conditions]\nroller_ra_um = -1", "specimen.conditions.roller_ra_um = -1"),
])
def test_bad_conditions_are_one_line_errors(conditions, message):
    with pytest.raises(InputError, match=None) as err:
        parse_protocol(_protocol(conditions), "p.toml")
    assert message in str(err.value) and "\n" not in str(err.value)


def test_conditions_parse_in_si_and_default_to_not_recorded():
    c = parse_protocol(_protocol(OIL), "p.toml").specimens[0].conditions
    assert (c.lubrication, c.lubricant, c.orientation_deg) == ("oil", "ISO VG 68", 90.0)
    assert c.roller_ra_m == pytest.approx(0.04e-6) and c.roundness_m == pytest.approx(0.5e-6)
    none = parse_protocol(_protocol(""), "p.toml").specimens[0].conditions
    assert none.lubrication is None and none.roller_ra_m is None


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory):
    folder = tmp_path_factory.mktemp("conditions")
    out = {}
    for name, conditions in (("dry", '[specimen.conditions]\nlubrication = "dry"'), ("oil", OIL)):
        (folder / f"{name}.toml").write_text(_protocol(conditions), encoding="utf-8")
        out[name] = folder / f"{name}.h5"
        run_campaign(folder / f"{name}.toml", out=out[name], backend="sim", seed=9)
    return folder, out


def test_conditions_are_stored_and_lubrication_has_no_effect_on_the_twin(campaigns):
    _, files = campaigns
    with CampaignReader(files["oil"]) as r:
        spec = r.specimen(1)
        oil = r.curves()
    with CampaignReader(files["dry"]) as r:
        dry = r.curves()
    assert (spec.lubrication, spec.lubricant, spec.orientation_deg) == ("oil", "ISO VG 68", 90.0)
    assert spec.rail_ra_measured_m == pytest.approx(0.21e-6)
    assert "oil (ISO VG 68)" in spec.conditions_text() and "roundness 0.5 µm" in spec.conditions_text()
    for a, b in zip(oil, dry, strict=True):  # same seed, other lubrication: the same stiffness to the last bit
        assert np.array_equal(a.stiffness_n_per_m, b.stiffness_n_per_m)
    assert not compare_groups(load_group(str(files["oil"])), load_group(str(files["dry"]))).significant


def test_the_archive_indexes_and_filters_conditions(campaigns, tmp_path):
    folder, files = campaigns
    db = tmp_path / "lab.db"
    index(db, [folder])
    rows = query(db, "lubrication = 'oil' and roundness_um = 0.5").rows
    assert rows and {r["file_name"] for r in rows} == {"oil.h5"} and rows[0]["orientation_deg"] == 90.0
    assert {r["file_name"] for r in query(db, "lubrication = 'dry'").rows} == {"dry.h5"}
    groups = [load_group(f"lubrication = '{lub}'", db=db) for lub in ("oil", "dry")]
    assert len(groups[0]) == 2 and not compare_groups(*groups).significant


def test_a_version_1_catalogue_is_upgraded_and_reindexed(campaigns, tmp_path):
    folder, _ = campaigns
    db = tmp_path / "old.db"
    index(db, [folder])
    with sqlite3.connect(db) as conn:  # make it look as version 1 left it: no conditions columns
        conn.executescript("DROP VIEW steps; DROP VIEW campaigns; ALTER TABLE specimen_row DROP COLUMN lubrication;"
                           "UPDATE catalogue_info SET value = '1' WHERE key = 'schema_version';")
    conn = connect(db)
    version = conn.execute("SELECT value FROM catalogue_info WHERE key = 'schema_version'").fetchone()[0]
    conn.close()
    assert int(version) == SCHEMA_VERSION
    assert index(db, [folder]).new  # every file read again
    assert query(db, "lubrication = 'oil'").rows


def test_the_report_shows_the_conditions(campaigns, tmp_path):
    from labctl.cli import main

    _, files = campaigns
    assert main(["report", str(files["oil"]), "--out", str(tmp_path / "rep")]) == 0
    html = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    assert "<th>conditions</th>" in html and "oil (ISO VG 68), 90° to the grinding direction" in html
