"""The engine on the simulated rig into a campaign file: sequence, storage, events, failing subscribers, failed
steps and the protocol's checks. Re-hits, overrides, drift, the interlock, pause/abort and resume are engine logic,
tested on a scripted rig into memory in tests/test_engine_logic.py."""

from __future__ import annotations

import pytest

from labctl import events as ev
from labctl.campaign import run_campaign
from labctl.physics import load_rig
from labctl.storage import CampaignReader, campaign_stiffness_points
from tests.engine_util import Recorder, run_engine, short_protocol


def test_short_campaign_writes_every_impact_and_curve(tmp_path):
    rec = Recorder()
    out = tmp_path / "c.h5"
    outcome = run_campaign(short_protocol(), out=out, seed=3, subscribers=[rec])
    assert outcome.status == "complete"
    assert len(outcome.curves) == 2
    with CampaignReader(out) as r:
        assert r.attrs["status"] == "complete"
        assert "[specimen]" in r.config_text("protocol.toml") and "upper_disc" in r.config_text("rig.toml")
        runs = r.runs(1)
        assert [run.complete for run in runs] == [True, True]
        loads = [s.load_n for s in runs[0].steps]
        assert loads[0] == pytest.approx(load_rig().preload_per_roller_n, rel=0.03)
        assert all(b > a for a, b in zip(loads, loads[1:], strict=False)) and loads[-1] <= 120 * 1.05
        for run in runs:
            for step in run.steps:
                assert step.accepted_count == 2 and step.result is not None
                data = r.impact_arrays(1, run.run, step.step)
                assert data.force_n.shape == (2, 16384) and data.accel_m_per_s2.shape == (2, 12, 16384)
                assert data.channels[0] == "A1X" and data.sample_rate_hz == pytest.approx(20480)
        assert r.curve(1, 1)["stiffness_n_per_m"].size == len(runs[0].steps)
    points = campaign_stiffness_points(out)
    assert {p.repetition for p in points} == {1, 2} and all(p.roller_type == 1 for p in points)
    kinds = {type(e) for e in rec.events}
    assert {ev.CampaignStarted, ev.RunStarted, ev.StepStarted, ev.LoadMeasured, ev.ImpactAcquired, ev.StepProcessed,
            ev.RunProcessed, ev.Progress, ev.OperatorPrompted, ev.CampaignFinished} <= kinds
    actions = [e.action for e in rec.of(ev.OperatorPrompted)]
    assert actions.count("mount_specimen") == 1 and actions.count("rotate_rollers") == 1
    assert rec.of(ev.RunProcessed)[0].reference_n_per_m.keys() == {"tripp", "fit-ra0.2"}


def test_failing_subscriber_never_stops_the_run(tmp_path):
    def broken(event: ev.Event) -> None:
        raise RuntimeError("display crashed")

    rec = Recorder()
    outcome = run_campaign(short_protocol(reps=1), out=tmp_path / "c.h5", seed=1, subscribers=[broken, rec])
    assert outcome.status == "complete" and rec.of(ev.CampaignFinished)


def test_a_step_that_cannot_be_identified_is_stored_failed_and_the_loading_goes_on(tmp_path):
    from drivers.sim import twin_of
    from labctl.campaign import rig_factory

    base = rig_factory("sim", load_rig(), seed=4)

    def factory(spec, series):
        rig = base(spec, series)
        twin, strike, blows = twin_of(rig), rig.hammer.strike, [0]

        def strike_double_at_first() -> None:  # step 1: the blow, its 5 re-hits and one more are double hits
            blows[0] += 1
            if blows[0] <= 7:
                twin.next_blow_double(delay_s=0.005, ratio=0.3)
            strike()

        rig.hammer.strike = strike_double_at_first
        return rig

    outcome, rec = run_engine(tmp_path / "c.h5", short_protocol(reps=1, max_load=120.0), factory)
    assert outcome.status == "complete"
    assert [e.position.step for e in rec.of(ev.StepFailed)] == [1]
    with CampaignReader(tmp_path / "c.h5") as r:
        steps = r.runs(1)[0].steps
        assert len(steps) == 2 and steps[1].load_n > steps[0].load_n + 50
        assert "all 6 impacts rejected" in steps[0].result.error and not steps[0].result.identified
        assert steps[1].result is not None
        assert r.curve(1, 1)["load_n"].tolist() == [steps[1].load_n]


def test_the_protocols_checks_reach_the_engine(tmp_path):
    from labctl.protocol import parse_protocol

    proto = short_protocol(reps=1, max_load=60.0)
    # the twin's blows last 0.25-0.45 ms: a 0.2 ms upper limit rejects every one of them
    strict = parse_protocol(proto.source_text + "[checks]\npulse_width_max_ms = 0.2\npulse_width_min_ms = 0.05\n",
                            "strict.toml")
    outcome = run_campaign(strict, out=tmp_path / "c.h5", seed=1)
    assert outcome.status == "complete"
    with CampaignReader(tmp_path / "c.h5") as r:
        step = r.runs(1)[0].steps[0]
        assert step.accepted_count == 0 and all("pulse_width" in i.reasons for i in step.impacts)
        assert "failed" in step.attrs
