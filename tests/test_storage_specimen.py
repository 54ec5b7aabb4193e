"""The typed specimen record: what the engine stores for a protocol's specimen is what every reader gets back,
and its contact case is the protocol's (no stand-in stiffness point needed to get it)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from labctl.engine.sequencer import specimen_record
from labctl.protocol import parse_protocol
from labctl.storage import CampaignReader, CampaignWriter
from labctl.storage.memory import MemoryStore
from labctl.storage.specimen import SpecimenRecord

V1 = Path(__file__).parent / "fixtures" / "campaign_v1.h5"  # written by an earlier labctl (schema 1)

PROTO = """
[protocol]
name = "two"
[[specimens]]
roller_type = 3
rail_ra_um = 0.8
rail_material = "1.3505"
max_load_n = 200.0
[[specimens]]
kind = "ball"
ball_diameter_mm = 10.0
rail_ra_um = 0.2
max_load_n = 100.0
"""


@pytest.fixture(scope="module")
def specs():
    return parse_protocol(PROTO, "two.toml").specimens


def test_the_stored_specimen_reads_back_equal_and_gives_the_protocols_contact_case(tmp_path, specs):
    path = tmp_path / "c.h5"
    records = [specimen_record(s) for s in specs]
    with CampaignWriter.create(path, protocol_name="two", backend="sim", seed=1, config_files={},
                               description={}) as w:
        for i, rec in enumerate(records, start=1):
            w.series(i, rec)
            w.mark_mounted(i)  # other attributes of the group are not part of the specimen
    with CampaignReader(path) as r:
        back = [r.specimen(i) for i in r.series_indices()]
    assert back == records
    roller, ball = back
    assert roller.kind == "roller" and roller.roller_type == 3 and roller.ball_diameter_m is None
    assert ball.kind == "ball" and ball.ball_diameter_m == pytest.approx(0.010) and ball.roller_type is None
    case, want = roller.case(), specs[0].case()
    assert case.roller.diameter_m == want.roller.diameter_m and case.rail_ra_m == want.rail_ra_m == 0.8e-6
    assert case.roller.material == want.roller.material and case.rail == want.rail
    point = roller.point(2, 120.0, 4.0e7)
    assert (point.load_n, point.stiffness_n_per_m, point.repetition, point.roller_type) == (120.0, 4.0e7, 2, 3)
    assert point.case() == case


def test_the_memory_store_keeps_the_same_record(specs):
    store = MemoryStore()
    rec = specimen_record(specs[0])
    store.series(1, rec)
    store.run(1, 1)
    assert store.store_curve(1, 1).specimen == rec.label == "roller type 3"


def test_an_old_file_reads_as_a_specimen_with_defaults_for_what_it_lacks():
    with CampaignReader(V1) as r:
        spec = r.specimen(r.series_indices()[0])
    assert isinstance(spec, SpecimenRecord) and spec.label and math.isfinite(spec.diameter_m)
    assert spec.case().roller.diameter_m == spec.diameter_m


def test_from_attrs_types_the_values_and_ignores_other_keys():
    rec = SpecimenRecord.from_attrs({"label": "x", "roller_type": 2.0, "rail_ra_m": "2e-7", "mounted": True,
                                     "created_utc": "2026", "ball_diameter_m": None, "material": ""})
    assert rec == SpecimenRecord(label="x", roller_type=2, rail_ra_m=2e-7)
    assert "ball_diameter_m" not in rec.attrs() and rec.attrs()["roller_type"] == 2
