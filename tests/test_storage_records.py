"""Campaign records: lossless compact traces, typed results, the schema-1 fixture, and what the reader refuses."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from labctl.storage import CampaignReader, CampaignWriter, LogEntry, LogSummary, StepResult
from labctl.storage.records import (
    Calibration,
    CheckSummary,
    ImpactInfo,
    ImpactOutcome,
    ImpactRecord,
    ModeResult,
    StepFrf,
    Verdict,
)
from labctl.storage.runlog import summarize
from labctl.storage.specimen import SpecimenRecord
from tests.cli_util import assert_one_line_error, labctl_here, labctl_here_json

V1 = Path(__file__).parent / "fixtures" / "campaign_v1.h5"  # written by labctl's schema-1 writer (see its toml)


def _writer(path: Path) -> CampaignWriter:
    w = CampaignWriter.create(path, protocol_name="t", backend="sim", seed=None,
                              config_files={"rig.toml": "x"}, description={})
    w.series(1, SpecimenRecord(label="roller"))
    w.run(1, 1)
    w.step(1, 1, 1, {"load_n": 50.0, "knob_angle_deg": 0.0})
    return w


def _record(force: np.ndarray, accel: np.ndarray, calib: Calibration, attempt: int = 1) -> ImpactRecord:
    info = ImpactInfo(attempt, 20480.0, 256, "2026-01-01T00:00:00.000+00:00",
                      CheckSummary(False, ("double_hit",), 250.0, 3e-4), Verdict(True, "operator", "looked fine"))
    return ImpactRecord(info, ("A1X", "A1Y"), force, accel, calib)


def test_adc_counts_round_trip_bit_exact_and_small(tmp_path):
    rng = np.random.default_rng(1)
    f_step, a_step = 2 * 22240.0 / 2**24, 2 * 490.3325 / 2**24
    force = np.round(rng.normal(0, 0.05, 8192) / f_step) * f_step
    accel = np.round(rng.normal(0, 0.004, (2, 8192)) / a_step) * a_step
    calib = Calibration(0.23e-3, 22240.0, (0.0102, 0.0102), (490.3325, 490.3325))
    with _writer(tmp_path / "c.h5") as w:
        w.write_impact(1, 1, 1, _record(force, accel, calib))
    with CampaignReader(tmp_path / "c.h5") as r:
        (back,) = r.impacts(1, 1, 1)
    assert np.array_equal(back.force_n, force) and np.array_equal(back.accel_m_per_s2, accel)
    assert back.verdict == Verdict(True, "operator", "looked fine") and back.info.checks.reasons == ("double_hit",)
    assert back.calibration == calib and back.info.reasons == ("double_hit", "operator_accepted")
    with h5py.File(tmp_path / "c.h5") as f:  # what a stranger reads with plain h5py
        ds = f["series_01/run_01/step_001/impact_001/accel_m_per_s2"]
        assert ds.dtype == np.int32
        volts_free = ds[()] * ds.attrs["scale"][:, None] + ds.attrs["offset"][:, None]
        assert np.array_equal(volts_free, accel)
        assert ds.id.get_storage_size() < 0.45 * accel.size * 4  # well under float32


def test_traces_that_are_not_adc_steps_are_kept_as_float32(tmp_path):
    rng = np.random.default_rng(2)
    force, accel = rng.normal(0, 1, 512), rng.normal(0, 1, (2, 512))
    with _writer(tmp_path / "c.h5") as w:
        w.write_impact(1, 1, 1, _record(force, accel, Calibration()))
    with CampaignReader(tmp_path / "c.h5") as r:
        (back,) = r.impacts(1, 1, 1)
    assert np.array_equal(back.accel_m_per_s2, accel.astype(np.float32).astype(float))


def test_step_result_round_trips_through_the_file(tmp_path):
    result = StepResult(bounce_hz=532.1, bounce_hz_std=0.4, bounce_damping_ratio=0.018, bounce_damping_ratio_std=1e-3,
                        tilt_hz=(415.0, 419.0), tilt_hz_std=(0.5, 0.6), roller_stiffness_n_per_m=2.26e7,
                        roller_stiffness_std_n_per_m=1e5, coherence_at_bounce=0.999, channels=("A1X", "A1Y"),
                        fs_hz=20480.0, window_decay_rate_per_s=3.0, fit_band_hz=(300.0, 700.0),
                        modes=(ModeResult("bounce", 532.1, 0.4, 0.018, 0.001, 0.999, 0.98, 0.01),),
                        impacts=(ImpactOutcome(1, True), ImpactOutcome(2, False, ("low_coherence",))),
                        roller_stiffness_budget_n_per_m={"modal_fit": 1e3, "disc_mass": 9e4},
                        roller_stiffnesses_n_per_m=(2.2e7, 2.3e7, 2.28e7), roller_stiffnesses_std_n_per_m=(1e5,) * 3,
                        roller_stiffnesses_resolved=True, roller_stiffness_condition=3.5, rollers_differing=(1,),
                        dropped_channels=("A2Z",), small_blow={"shift_hz": -0.2, "shift_std_hz": 0.01},
                        warnings=("w",), frf=StepFrf(np.linspace(0, 3000, 31), np.ones((2, 31), complex),
                                                     np.ones((2, 31))))
    with _writer(tmp_path / "c.h5") as w:
        w.write_step_result(1, 1, 1, result)
        curve = w.store_curve(1, 1)
    assert curve.step.tolist() == [1] and curve.stiffness_n_per_m.tolist() == [2.26e7]
    with CampaignReader(tmp_path / "c.h5") as r:
        back = r.runs(1)[0].steps[0].result
        assert back == result and back.used_attempts == (1,) and back.rejected_count == 1
        assert back.frf is not None and back.frf.frequencies_hz.max() <= 2000.0
        assert r.curve(1, 1).tilt_b_hz.tolist() == [419.0]


def test_v1_fixture_processes_reports_and_exports(tmp_path, capsys):
    with CampaignReader(V1) as r:
        assert r.format_version == 1
        steps = r.runs(1)[0].steps
        assert [s.result.identified for s in steps] == [True, True]
        assert all(i.verdict.source == "checks" for s in steps for i in s.impacts)
        stored = [s.result.roller_stiffness_n_per_m for s in steps]
        assert r.curve(1, 1).step.tolist() == [1, 2]
    done = labctl_here_json(capsys, "process", str(V1))
    assert done["points"] == 2
    assert [s["roller_stiffness_n_per_m"] for s in done["steps"]] == pytest.approx(stored, rel=1e-3)
    assert labctl_here(capsys, "report", str(V1), "--out", str(tmp_path / "rep")).returncode == 0
    assert (tmp_path / "rep" / "report.html").is_file()
    assert labctl_here(capsys, "export", str(V1), "--uff", str(tmp_path / "x.uff")).returncode == 0
    assert (tmp_path / "x.uff").stat().st_size > 0


def _copy(tmp_path: Path) -> Path:
    out = tmp_path / "c.h5"
    shutil.copy(V1, out)
    return out


def test_reader_refuses_an_unknown_format_version(tmp_path, capsys):
    path = _copy(tmp_path)
    with h5py.File(path, "r+") as f:
        f.attrs["format_version"] = 99
    for cmd in (("process", str(path)), ("report", str(path), "--out", str(tmp_path / "r"))):
        assert_one_line_error(labctl_here(capsys, *cmd), "format_version 99")


def test_reader_refuses_a_complete_impact_without_its_data(tmp_path, capsys):
    path = _copy(tmp_path)
    with h5py.File(path, "r+") as f:
        del f["series_01/run_01/step_002/impact_001/accel_m_per_s2"]
    assert_one_line_error(labctl_here(capsys, "process", str(path)), "impact_001", "accel_m_per_s2", "missing")


def test_reader_refuses_a_campaign_without_its_stored_rig(tmp_path, capsys):
    path = _copy(tmp_path)
    with h5py.File(path, "r+") as f:
        del f["config/rig.toml"]
    assert_one_line_error(labctl_here(capsys, "process", str(path)), "/config/rig.toml")
    assert_one_line_error(labctl_here(capsys, "report", str(path), "--out", str(tmp_path / "r")), "/config/rig.toml")


def test_an_empty_campaign_says_so(tmp_path, capsys):
    path = _copy(tmp_path)
    with h5py.File(path, "r+") as f:
        del f["series_01"]
    assert_one_line_error(labctl_here(capsys, "process", str(path)), "no load step")


def test_process_reproduces_the_stored_results_of_a_new_campaign(tmp_path, capsys):
    from tests.engine_util import short_campaign_file

    path = short_campaign_file(tmp_path / "c.h5", seed=6, reps=1)
    with CampaignReader(path) as r:
        stored = {s.step: s.result for s in r.runs(1)[0].steps}
    done = labctl_here_json(capsys, "process", str(path))
    for s in done["steps"]:
        assert s["roller_stiffness_n_per_m"] == pytest.approx(stored[s["step"]].roller_stiffness_n_per_m, rel=1e-9)
        assert tuple(s["used_impacts"]) == stored[s["step"]].used_attempts


def test_run_log_round_trips_in_order_and_is_readable_with_plain_h5py(tmp_path):
    path = tmp_path / "c.h5"
    entries = [LogEntry("2026-01-01T00:00:00.000+00:00", 1, 1, 2, 0, "warning", "retry",
                        "load cell: no answer within 2 s; retrying (1/2)"),
               LogEntry("2026-01-01T00:00:01.000+00:00", 1, 1, 2, 3, "warning", "suspend", "load drifted — 5 %"),
               LogEntry("2026-01-01T00:00:02.000+00:00", 1, 1, 2, 3, "info", "prompt", "confirm: ... → continue")]
    with _writer(path) as w:
        assert w.log() == []
        for e in entries:
            w.append_log(e)
        assert w.log() == entries
    with CampaignReader(path) as r:
        assert r.log() == entries
    with h5py.File(path) as f:  # no labctl: a compound table with text and integer columns
        table = f["log/entries"]
        assert table.shape == (3,) and table.maxshape == (None,)
        assert table["kind"][1].decode() == "suspend" and int(table["step"][0]) == 2
        assert table["message"][1].decode().endswith("— 5 %")
    with CampaignWriter.open_existing(path) as w:  # a resumed campaign appends to the same log
        w.append_log(entries[0])
    with CampaignReader(path) as r:
        assert r.log() == [*entries, entries[0]]
        assert summarize(r.log()) == LogSummary(4, {"prompt": 1, "retry": 2, "suspend": 1},
                                                {"info": 1, "warning": 3})


def test_run_log_entries_survive_a_process_killed_without_closing_the_file(tmp_path):
    import subprocess
    import sys

    path = tmp_path / "c.h5"
    script = f"""
import os
from labctl.storage import CampaignWriter, LogEntry
w = CampaignWriter.create({str(path)!r}, protocol_name="t", backend="sim", seed=None, config_files={{}},
                          description={{}})
for i in range(3):
    w.append_log(LogEntry("t", 1, 1, i + 1, 0, "warning", "retry", f"entry {{i}}"))
os._exit(0)  # like a kill: nothing closed, nothing flushed beyond what the writer did
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                          cwd=Path(__file__).parent.parent)
    assert done.returncode == 0, done.stderr
    with CampaignReader(path) as r:
        assert [e.message for e in r.log()] == ["entry 0", "entry 1", "entry 2"]


def test_v1_fixture_has_an_empty_run_log(capsys):
    with CampaignReader(V1) as r:
        assert r.log() == []
    done = labctl_here_json(capsys, "process", str(V1))
    assert done["log"] == {"entries": 0, "by_kind": {}, "by_level": {}, "warnings": 0, "errors": 0}
