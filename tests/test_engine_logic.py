"""The engine's logic on a scripted rig into an in-memory store (no twin, no HDF5, no processing): re-hits,
operator overrides, load drift, the interlock, pause/abort, stop and resume, missed triggers, progress and status.
Each test runs in milliseconds; the twin-and-file path is covered by tests/test_engine.py."""

from __future__ import annotations

import statistics
import threading

import pytest

from drivers.operators import ScriptedOperator
from labctl import events as ev
from labctl.engine import RunControl
from labctl.physics import load_rig
from labctl.storage.memory import MemoryStore
from tests.engine_util import ScriptedBench, run_scripted, short_protocol

RIG = load_rig()


def _accepted(store: MemoryStore, series: int, run: int, step: int) -> list[bool]:
    return [i.accepted for i in store.impact_infos(series, run, step)]


def test_a_clean_campaign_stores_every_step_and_curve_and_counts_progress():
    proto = short_protocol(reps=2)
    outcome, rec, store = run_scripted(proto, ScriptedBench(RIG))
    assert outcome.status == "complete" and store.attrs["status"] == "complete"
    steps = store.step_results(1, 1)
    assert len(steps) >= 2 and [n for n, *_ in steps] == list(range(1, len(steps) + 1))
    loads = [load for _, load, _, _ in steps]
    assert loads[0] == pytest.approx(RIG.preload_per_roller_n)
    assert all(b > a for a, b in zip(loads, loads[1:], strict=False))
    assert [len(c) for c in outcome.curves] == [len(steps), len(steps)] and outcome.curves == store.curves()
    progress = rec.of(ev.Progress)
    assert [p.impacts_done for p in progress] == list(range(1, 2 * 2 * len(steps) + 1))
    assert progress[-1].impacts_done == store.accepted_count() == progress[-1].impacts_total
    assert len(store.completed_steps()) == 2 * len(steps)


def test_rejected_impacts_are_kept_and_rehit():
    bench = ScriptedBench(RIG, blow_kind=lambda n: "double" if n in (1, 4) else "clean")
    outcome, rec, store = run_scripted(short_protocol(reps=1), bench)
    assert outcome.status == "complete"
    assert _accepted(store, 1, 1, 1) == [False, True, True]
    assert _accepted(store, 1, 1, 2) == [False, True, True]  # blow 4 is the first of step 2
    rejected = rec.of(ev.ImpactRejected)
    assert [(e.position.step, e.attempt) for e in rejected] == [(1, 1), (2, 1)]
    assert all("double_hit" in e.reasons for e in rejected)
    assert store.step_results(1, 1)[0][3].used_attempts == (2, 3)


def test_too_many_rejections_fail_the_step_and_the_loading_goes_on():
    acq = short_protocol(reps=1).acquisition
    bad = 1 + acq.max_rehits  # the blow and its allowed re-hits, all rejected
    bench = ScriptedBench(RIG, blow_kind=lambda n: "double" if n <= bad else "clean")
    outcome, rec, store = run_scripted(short_protocol(reps=1), bench)
    assert outcome.status == "complete"
    assert [e.position.step for e in rec.of(ev.StepFailed)] == [1]
    assert len(store.impacts(1, 1, 1)) == bad and not any(_accepted(store, 1, 1, 1))
    assert any("re-hits" in e.message for e in rec.of(ev.Notice))
    curve = outcome.curves[0]
    assert 1 not in curve.step.tolist() and curve.step.tolist()[0] == 2


def test_operator_override_rejects_an_accepted_impact_and_it_is_hit_again():
    control = RunControl()

    def on_event(event: ev.Event) -> None:
        if isinstance(event, ev.ImpactAcquired) and event.position == ev.Position(1, 1, 1, 1) and event.attempt == 1:
            control.override_last_impact(False)

    outcome, rec, store = _run_with(short_protocol(reps=1), ScriptedBench(RIG), MemoryStore(), control, on_event)
    assert outcome.status == "complete"
    infos = store.impact_infos(1, 1, 1)
    assert [i.accepted for i in infos] == [False, True, True]
    assert infos[0].verdict.source == "operator" and "operator_rejected" in infos[0].reasons
    assert store.step_results(1, 1)[0][3].used_attempts == (2, 3)


def test_an_override_for_an_older_impact_is_ignored_with_a_warning():
    control = RunControl()

    def on_event(event: ev.Event) -> None:
        if isinstance(event, ev.ImpactAcquired) and event.position == ev.Position(1, 1, 1, 2):
            control.override_last_impact(False, attempt=1)  # impact 2 was taken since

    outcome, rec, store = _run_with(short_protocol(reps=1), ScriptedBench(RIG), MemoryStore(), control, on_event)
    assert outcome.status == "complete" and _accepted(store, 1, 1, 1) == [True, True]
    assert any("ignored" in e.message for e in rec.of(ev.Notice) if e.kind == "verdict")


def test_load_drift_suspends_the_step_and_asks_the_operator():
    operator = ScriptedOperator()

    def creep(bench: ScriptedBench) -> None:  # the knobs slip during step 1's blows
        if bench.blows == 2:
            bench.offset_n = -0.2 * bench.rig.roller_count * bench.load_per_roller_n()

    bench = ScriptedBench(RIG, after_strike=creep, operator=operator)
    operator.on("confirm", lambda message, choices: setattr(bench, "offset_n", 0.0) or "continue")  # re-tightened
    outcome, rec, store = run_scripted(short_protocol(reps=1), bench)
    assert outcome.status == "complete"
    suspended = rec.of(ev.Suspended)
    assert len(suspended) == 1 and "drifted" in suspended[0].reason and suspended[0].position.step == 1
    assert store.step_attrs(1, 1, 1)["load_drift"] is True and "load_drift" not in store.step_attrs(1, 1, 2)
    assert store.step_attrs(1, 1, 1)["load_after_n"] < 0.9 * store.step_load(1, 1, 1)


def test_the_drift_abort_answer_stops_the_campaign_resumable():
    operator = ScriptedOperator(answers={"confirm": ["abort"]})
    bench = ScriptedBench(RIG, after_strike=lambda b: setattr(b, "offset_n", -50.0), operator=operator)
    outcome, _, store = run_scripted(short_protocol(reps=1), bench)
    assert outcome.status == "aborted" and store.attrs["status"] == "aborted"
    assert store.complete_runs(1) == set()


def test_interlock_unloads_when_the_load_exceeds_the_cap():
    # after step 1's blows the cell reads 300 N per roller more (e.g. a jammed spring): over the cap before step 2
    bench = ScriptedBench(RIG, after_strike=lambda b: setattr(b, "offset_n", b.rig.roller_count * 300.0)
                          if b.blows == 2 else None)
    outcome, rec, store = run_scripted(short_protocol(reps=1, max_load=120.0), bench)
    assert outcome.status == "interlock" and "exceeds the cap" in outcome.message
    assert store.attrs["status"] == "interlock"
    assert [e.action for e in rec.of(ev.OperatorPrompted)][-1] == "unload" and bench.angle_deg == 0.0
    assert store.complete_runs(1) == set()


def test_pause_resume_and_abort_at_safe_points_then_resume_finishes():
    control = RunControl()
    seen = threading.Event()

    def on_event(event: ev.Event) -> None:
        if isinstance(event, ev.ImpactAcquired) and not seen.is_set():
            seen.set()
            control.pause()
            threading.Timer(0.05, control.resume).start()
        if isinstance(event, ev.StepProcessed) and event.position.step == 1:
            control.abort()

    bench = ScriptedBench(RIG)
    outcome, rec, store = _run_with(short_protocol(reps=1), bench, MemoryStore(), control, on_event)
    assert outcome.status == "aborted" and rec.of(ev.Paused) and rec.of(ev.Resumed)
    assert [n for n, *_ in store.step_results(1, 1)] == [1]
    resumed, rec2, _ = run_scripted(short_protocol(reps=1), bench, store)
    assert resumed.status == "complete" and rec2.of(ev.CampaignStarted)[0].resumed
    assert [e.position.step for e in rec2.of(ev.StepProcessed)][0] == 2  # step 1 is not run again


def test_a_stop_mid_step_resumes_with_the_impacts_taken_and_runs_every_step_once():
    control = RunControl()

    def on_event(event: ev.Event) -> None:
        if isinstance(event, ev.ImpactAcquired) and event.position == ev.Position(1, 2, 2, 1):
            control.stop()

    proto = short_protocol(reps=2)
    bench = ScriptedBench(RIG)
    outcome, _, store = _run_with(proto, bench, MemoryStore(), control, on_event)
    assert outcome.status == "interrupted" and store.complete_runs(1) == {1}
    held = store.impacts(1, 2, 2)
    assert len(held) == 1
    resumed, rec, _ = run_scripted(proto, bench, store)
    assert resumed.status == "complete" and store.complete_runs(1) == {1, 2}
    assert store.impacts(1, 2, 2)[0] is held[0]  # the impact taken before the stop is kept and used
    assert [i.attempt for i in store.impact_infos(1, 2, 2)] == [1, 2]
    assert [e.position.step for e in rec.of(ev.StepStarted)][0] == 2
    assert [len(c) for c in resumed.curves] == [len(store.step_results(1, 1))] * 2
    assert rec.of(ev.CampaignStarted)[0].resumed
    assert "mount_specimen" not in [e.action for e in rec.of(ev.OperatorPrompted)]


def test_a_complete_store_has_nothing_left_to_do():
    proto = short_protocol(reps=1)
    bench = ScriptedBench(RIG)
    _, _, store = run_scripted(proto, bench)
    blows = bench.blows
    again, rec, _ = run_scripted(proto, bench, store)
    assert again.status == "complete" and "nothing left" in again.message and bench.blows == blows
    assert not rec.of(ev.StepStarted)


def test_a_missed_trigger_is_struck_again_and_a_dead_hammer_fails_the_campaign():
    bench = ScriptedBench(RIG, blow_kind=lambda n: "miss" if n == 1 else "clean")
    outcome, rec, store = run_scripted(short_protocol(reps=1), bench)
    assert outcome.status == "complete" and _accepted(store, 1, 1, 1) == [True, True]
    assert any(e.kind == "retry" for e in rec.of(ev.Notice))
    dead = ScriptedBench(RIG, blow_kind=lambda n: "miss")
    outcome, _, store = run_scripted(short_protocol(reps=1), dead)
    assert outcome.status == "failed" and "no record after" in outcome.message
    assert store.attrs["status"] == "failed" and store.accepted_count() == 0


def test_the_eta_is_measured_from_the_steps_and_counts_the_stored_ones_as_done():
    from labctl.engine.eta import campaign_estimator

    proto = short_protocol(reps=1, max_load=300.0, step=180.0)
    _, _, store = run_scripted(proto, ScriptedBench(RIG))
    stamps = store.completed_steps()
    assert len(stamps) >= 4 and all(s.first_impact_s is not None for s in stamps)
    gaps = [b.first_impact_s - a.first_impact_s for a, b in zip(stamps, stamps[1:], strict=False)]
    est = campaign_estimator(stamps, len(stamps) + 3, 2, 0.8)
    assert est.steps_done == len(stamps) and est.step_s == pytest.approx(statistics.median(gaps))
    assert est.eta_s(0.0) == pytest.approx(3 * statistics.median(gaps))
    assert campaign_estimator([], 5, 2, 0.8).eta_s(0.0) is None


def _run_with(proto, bench, store, control, on_event):  # noqa: ANN001, ANN202
    """``run_scripted`` with a subscriber that steers the run (``on_event``) before the recorder sees events."""
    from labctl.engine import Engine
    from tests.engine_util import Recorder, scripted_identify

    rec = Recorder()
    bus = ev.EventBus()
    bus.subscribe(on_event)
    bus.subscribe(rec)
    engine = Engine(proto, RIG, bench.rig_factory, store, bus, control, identify_step=scripted_identify)
    return engine.run(), rec, store
