"""The technician's information folded from engine events: armed/triggered, range use, step and end summaries."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from labctl import events as ev
from labctl.campaign import run_campaign
from labctl.protocol import load_protocol
from labctl.storage import CampaignReader
from labctl.tui.state import CampaignState
from tests.engine_util import Recorder, impact_event, step_event

PROTOCOL = Path(__file__).parent.parent / "protocols" / "quick_check.toml"


def impact(attempt: int, reasons: tuple[str, ...] = (), use: dict[str, float] | None = None) -> ev.ImpactAcquired:
    return impact_event(ev.Position(1, 1, 1, attempt), attempt, reasons, range_use=use)


def step(rejected: dict[int, str], warnings: tuple[str, ...] = ()) -> ev.StepProcessed:
    return step_event(ev.Position(1, 1, 1), 100.0, 400.0, (500.0, 501.0), 5.0e8, np.zeros(3), np.zeros((1, 3)),
                      np.zeros((1, 3)), ("A1Z",), 0.2e8, (2, 3), rejected, warnings, time_s=2.0)


def test_header_goes_armed_then_triggered_then_armed_after_the_verdict():
    s = CampaignState(status="running")
    s.apply(ev.StepStarted(0.0, ev.Position(1, 1, 1), 3, 0.0, 100.0))
    assert "ARMED" in s.header_text()
    s.apply(impact(1))
    assert "TRIGGERED" in s.header_text()
    s.apply(ev.OperatorPrompted(1.5, "…", "review_impact", "accept"))
    assert "ARMED" in s.header_text()
    s.status = "paused"
    assert "ARMED" not in s.header_text()


def test_range_use_names_the_fullest_channels_first_and_marks_the_overload():
    s = CampaignState()
    s.apply(impact(1, ("clipped:A2Z",), {"F": 0.4, "A1Z": 0.25, "A2Z": 1.0}))
    assert s.range_text() == "range use A2Z 100%! F 40% A1Z 25%"


def test_step_and_end_summaries_count_rejections_and_compare_with_the_models():
    s = CampaignState()
    e = step({1: "double_hit, operator_rejected", 4: "clipped:A3Z", 5: "operator_rejected"},
             ("rollers differ: roller 2 is 30 % stiffer", "dead channel(s) left out: A3X"))
    s.apply(e)
    line = s.step_summary(e)
    assert line.startswith("step 1: 2 hits used, rejected impact 1 double hit; impact 4 A3Z clipped; "
                           "impact 5 rejected by the operator")
    assert "k 500.00 ± 20.00 N/µm" in line and "WARNING: rollers differ" in line
    assert "WARNING: dead channel(s) left out: A3X" in line  # every warning, not only the rollers'
    s.apply(ev.RunProcessed(3.0, ev.Position(1, 1), "type 1", (100.0,), (5.0e8,), {"Tripp": (4.0e8,)}))
    end = s.end_summary()
    assert end[0] == "1 steps identified"
    # a flagged blow the operator also rejected is one blow, counted once under the checks' reason
    assert end[1] == "hits not used: 1× double hit, 1× A3Z clipped, 1× rejected by the operator"
    assert end[2].startswith("measured/Tripp: 1.25 on average")


def test_the_engine_reports_each_blows_range_use_and_the_steps_sigma(tmp_path):
    events = Recorder()
    run_campaign(load_protocol(PROTOCOL), out=tmp_path / "r.h5", seed=1, subscribers=(events,))
    first = events.of(ev.ImpactAcquired)[0]
    assert {"A1Z", "A4Z"} <= set(first.range_use) and len(first.range_use) == len(first.channels) + 1
    assert all(0 < u < 1.5 for u in first.range_use.values())
    steps = events.of(ev.StepProcessed)
    with CampaignReader(tmp_path / "r.h5") as reader:
        stored = [s.result for s in reader.runs(1)[0].steps]
    assert [e.used_attempts for e in steps] == [r.used_attempts for r in stored]
    assert all(math.isclose(e.roller_stiffness_std_n_per_m, r.roller_stiffness_std_n_per_m) for e, r in
               zip(steps, stored, strict=True))
