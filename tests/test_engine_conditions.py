"""Safe-point conditions: a lab adds its own (here a door switch and a temperature limit) without touching
the engine; the built-in load interlock and load-drift check are conditions of the same kind."""

from __future__ import annotations

from dataclasses import dataclass

from drivers.operators import ScriptedOperator
from labctl import events as ev
from labctl.campaign import run_campaign
from labctl.engine import LoadDrift, LoadInterlock, SafePoint, Trip
from labctl.storage import CampaignReader
from tests.engine_util import Recorder, short_protocol


@dataclass
class DoorSwitch:
    """Opens before the first blow of step 2: the rig must stop and unload."""

    name: str = "door"

    def check(self, point: SafePoint) -> Trip | None:
        if point.where == "before_impact" and point.position.step == 2:
            return Trip(self.name, "interlock", "enclosure door opened")
        return None


@dataclass
class Thermometer:
    """Reads too warm after step 1's impacts: the operator is asked whether to go on."""

    name: str = "temperature"

    def check(self, point: SafePoint) -> Trip | None:
        if point.where == "after_step" and point.position.step == 1:
            return Trip(self.name, "suspend", "rig at 31 °C, above the 30 °C limit")
        return None


def test_an_added_interlock_condition_stops_and_unloads_at_its_safe_point(tmp_path):
    rec = Recorder()
    out = tmp_path / "c.h5"
    outcome = run_campaign(short_protocol(reps=1, samples=8192), out=out, seed=3, subscribers=[rec],
                           conditions=[DoorSwitch()])
    assert outcome.status == "interlock" and "enclosure door opened" in outcome.message
    assert [e.reason for e in rec.of(ev.Suspended)] == ["enclosure door opened"]
    assert "unload" in [e.action for e in rec.of(ev.OperatorPrompted)]
    with CampaignReader(out) as r:
        assert r.attrs["status"] == "interlock"
        steps = r.runs(1)[0].steps
        assert steps[0].complete and steps[0].result.identified and not steps[1].impacts


def test_an_added_suspend_condition_asks_and_the_answer_is_obeyed(tmp_path):
    operator = ScriptedOperator(answers={"confirm": ["abort"]})
    outcome = run_campaign(short_protocol(reps=1, samples=8192), out=tmp_path / "c.h5", seed=3, operator=operator,
                           conditions=[Thermometer()])
    assert outcome.status == "aborted"
    assert any("31 °C" in p.message for p in operator.prompts if p.action == "confirm")
    going_on = ScriptedOperator(answers={"confirm": ["continue"]})
    outcome = run_campaign(short_protocol(reps=1, samples=8192), out=tmp_path / "d.h5", seed=3, operator=going_on,
                           conditions=[Thermometer()])
    assert outcome.status == "complete"
    with CampaignReader(tmp_path / "d.h5") as r:
        assert r.runs(1)[0].steps[0].attrs["temperature"]  # the step remembers the condition it went past


def test_the_builtin_checks_are_conditions():
    pos = ev.Position(1, 1, 2)
    assert LoadInterlock().check(SafePoint("before_step", pos, 100.0, 0.05, load_n=106.0)).kind == "interlock"
    assert LoadInterlock().check(SafePoint("before_step", pos, 100.0, 0.05, load_n=104.0)) is None
    assert LoadDrift().check(SafePoint("after_step", pos, 100.0, 0.05, load_n=90.0, step_load_n=100.0)).kind == \
        "suspend"
    assert LoadDrift().check(SafePoint("after_step", pos, 100.0, 0.05, load_n=97.0, step_load_n=100.0)) is None
