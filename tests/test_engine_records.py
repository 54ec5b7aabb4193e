"""Data flows forward: a step is identified from the impacts the engine holds since it wrote them, and those
are exactly what a reader of the file returns (bit for bit, verdicts included); the curve is built once."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from labctl.recording import check_record, process_step
from labctl.storage import CampaignReader, CampaignWriter, ImpactRecord
from labctl.storage.records import Calibration, CheckSummary, ImpactInfo, Verdict
from labctl.storage.specimen import SpecimenRecord
from tests.engine_util import run_engine, short_protocol


def _same(a: ImpactRecord, b: ImpactRecord) -> None:
    assert a.info == b.info and a.channels == b.channels and a.calibration == b.calibration
    assert a.force_n.dtype == b.force_n.dtype == np.float64
    np.testing.assert_array_equal(a.force_n, b.force_n)
    np.testing.assert_array_equal(a.accel_m_per_s2, b.accel_m_per_s2)


def test_each_step_is_identified_from_the_held_records_which_equal_the_files(tmp_path, monkeypatch):
    from labctl.backends import make_rig
    from labctl.storage.reader import CampaignReader as Reader

    identified: dict[int, list[ImpactRecord]] = {}

    def spy(records, rig, checks):  # noqa: ANN001, ANN202
        identified[len(identified) + 1] = list(records)
        return process_step(records, rig, checks)

    reads: list[int] = []
    monkeypatch.setattr(CampaignWriter, "impacts", lambda self, *a: reads.append(1) or [])
    proto = short_protocol(reps=1, samples=4096)
    out = tmp_path / "c.h5"
    outcome, _ = run_engine(out, proto, lambda spec, i: make_rig("sim", case=spec.case(), seed=4), identify_step=spy)
    assert outcome.status == "complete" and reads == []  # nothing was read back from the file
    with Reader(out) as r:
        steps = r.runs(1)[0].steps
        assert len(steps) == len(identified) >= 2
        for st in steps:
            stored = r.impacts(1, 1, st.step)
            held = identified[st.step]
            assert len(held) == len(stored) == 2
            for a, b in zip(held, stored, strict=True):
                _same(a, b)
        curve = r.curve(1, 1)
    assert curve is not None and outcome.curves[0].series == 1
    for column, values in curve.columns().items():
        np.testing.assert_array_equal(outcome.curves[0].columns()[column], values, err_msg=column)


def _record(attempt: int, force: np.ndarray, accel: np.ndarray, cal: Calibration) -> ImpactRecord:
    info = ImpactInfo(attempt, 20480.0, 10, "2026-01-01T00:00:00.000+00:00", CheckSummary(True, (), 900.0, 3e-4),
                      Verdict(True), ())
    return ImpactRecord(info, ("A1X", "A1Y"), force, accel, cal)


def _one_step_file(path: Path) -> CampaignWriter:
    """A new campaign file with series 1, repetition 1 and step 1 begun, open for writing impacts."""
    w = CampaignWriter.create(path, protocol_name="t", backend="sim", seed=None, config_files={}, description={})
    w.series(1, SpecimenRecord(label="x"))
    w.run(1, 1)
    w.step(1, 1, 1, {"load_n": 40.0, "knob_angle_deg": 0.0})
    return w


@pytest.mark.parametrize("exact_adc", [True, False])
def test_write_impact_returns_the_record_a_reader_gets_back(tmp_path, exact_adc):
    rng = np.random.default_rng(1)
    cal = Calibration(0.002, 5000.0, (0.01, 0.01), (500.0, 500.0))
    step_f, step_a = 2 * 5000.0 / 2**24, 2 * 500.0 / 2**24
    force = rng.normal(0, 100, 1024)
    accel = rng.normal(0, 10, (2, 1024))
    if exact_adc:  # samples on the ADC grid are stored as counts, bit-exact
        force, accel = np.rint(force / step_f) * step_f, np.rint(accel / step_a) * step_a
    path = tmp_path / "w.h5"
    with _one_step_file(path) as w:
        written = w.write_impact(1, 1, 1, _record(1, force, accel, cal))
    with CampaignReader(path) as r:
        (back,) = r.impacts(1, 1, 1)
    _same(written, back)
    if exact_adc:
        np.testing.assert_array_equal(written.force_n, force)
    else:  # float32 storage: the held record carries the precision the file keeps, not more
        assert not np.array_equal(written.force_n, force)
        np.testing.assert_allclose(written.force_n, force, rtol=1e-7)


def test_check_record_keeps_the_delivered_traces():
    from drivers.interfaces import Record
    from labctl.processing import CheckConfig

    t = np.arange(2048) / 20480.0
    force = 800.0 * np.exp(-(((t - 0.01) / 1.5e-4) ** 2))
    accel = np.vstack([np.sin(2 * np.pi * 700 * t) * np.exp(-30 * t)] * 2)
    rec = Record(20480.0, force, accel, ("A1X", "A1Y"), 200, 0.0)
    impact = check_record(rec, 1, CheckConfig())
    assert impact.force_n is rec.force_n or np.array_equal(impact.force_n, rec.force_n)
    assert impact.info.trigger_index == 200 and impact.channels == ("A1X", "A1Y")


def test_the_writers_kept_impact_infos_are_what_a_reader_gets_back(tmp_path):
    """The engine asks for a step's impact infos before every blow; the writer keeps them from its own writes
    (the checks' verdict, then the operator's) instead of reading the file again: they must be the file's."""
    cal = Calibration(0.002, 5000.0, (0.01, 0.01), (500.0, 500.0))
    force, accel = np.zeros(256), np.zeros((2, 256))
    rejected = ImpactInfo(2, 20480.0, 12, "2026-01-01T00:00:01.000+00:00",
                          CheckSummary(False, ("double_hit", "clipped"), 1200.0, 2e-4), Verdict(False), ("A1Y",))
    path = tmp_path / "w.h5"
    with _one_step_file(path) as w:
        assert w.impact_infos(1, 1, 1) == []
        w.write_impact(1, 1, 1, _record(1, force, accel, cal))
        w.write_impact(1, 1, 1, ImpactRecord(rejected, ("A1X", "A1Y"), force, accel, cal))
        w.set_verdict(1, 1, 1, 2, Verdict(True, "operator", "monitor"))
        w.set_verdict(1, 1, 1, 1, Verdict(False, "operator", "hand slipped"))
        kept = w.impact_infos(1, 1, 1)
    with CampaignReader(path) as r:
        assert kept == r.impact_infos(1, 1, 1)
    assert [(i.attempt, i.accepted) for i in kept] == [(1, False), (2, True)]
    assert kept[1].checks.reasons == ("double_hit", "clipped") and kept[1].verdict.reason == "monitor"
    with CampaignWriter.open_existing(path) as w:  # a resumed writer starts from the file
        assert w.impact_infos(1, 1, 1) == kept
