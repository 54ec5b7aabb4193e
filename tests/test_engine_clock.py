"""The rig's clock: on the simulated rig the engine's settling polls and deadlines run on virtual rig time
(nothing sleeps in real time, the same seed gives the same readings); the hardware path keeps real time."""

from __future__ import annotations

import time
from dataclasses import replace

import pytest

from drivers.interfaces import Clock, SystemClock
from drivers.sim import twin_of
from labctl import events as ev
from labctl.engine.steps import StepRunner
from labctl.physics import load_rig
from tests.engine_util import Recorder, short_protocol
from tests.test_sim_support import sim_rig


class _Services:
    """Just what ``StepRunner.read_load`` uses from the engine."""

    def __init__(self, protocol) -> None:  # noqa: ANN001
        self.protocol, self.rig_config, self.events = protocol, load_rig(), Recorder()

    def call(self, what, fn, *args, **kw):  # noqa: ANN001, ANN002, ANN003, ANN201
        return fn(*args)

    def now(self) -> float:
        return 0.0

    def emit(self, event: ev.Event) -> None:
        self.events(event)


def _settling(timeout_s: float, poll_s: float):  # noqa: ANN202
    proto = short_protocol()
    return replace(proto, loading=replace(proto.loading, settle_timeout_s=timeout_s, settle_poll_s=poll_s))


def _unsettled_runner(seed: int, timeout_s: float = 30.0, poll_s: float = 0.5):  # noqa: ANN202
    rig = sim_rig(seed=seed)
    twin_of(rig).set_creep(5.0)  # a load that keeps creeping never reads stable: the deadline must end the wait
    services = _Services(_settling(timeout_s, poll_s))
    return rig, services, StepRunner(services, rig, 1, 1, cap_n=1e4)


def test_the_simulated_rig_keeps_virtual_time_and_the_deadline_ends_an_unstable_wait(monkeypatch):
    asked: list[float] = []
    monkeypatch.setattr(time, "sleep", lambda s: asked.append(s))
    rig, services, runner = _unsettled_runner(seed=3)
    assert isinstance(rig.clock, Clock) and not isinstance(rig.clock, SystemClock)
    t0 = rig.clock.now()
    load, stable = runner.read_load(ev.Position(1, 1, 1))
    assert not stable and asked == []  # 30 s of settling without a real sleep
    elapsed = rig.clock.now() - t0
    reads = len(services.events.of(ev.LoadMeasured))
    read_s = twin_of(rig).settings.load_cell_read_s
    # each poll is one read plus one pause; the wait ends at the first read at or past the deadline
    assert elapsed >= 30.0 and elapsed - (read_s + 0.5) < 30.0
    assert reads == pytest.approx(elapsed / (read_s + 0.5), abs=1)
    assert load == services.events.of(ev.LoadMeasured)[-1].load_n


def test_same_seed_same_readings_however_long_the_computation_takes():
    runs = []
    for pause_s in (0.0, 0.05):
        rig, services, runner = _unsettled_runner(seed=11, timeout_s=5.0)
        time.sleep(pause_s)  # a loaded machine: real time passes, rig time does not
        runner.read_load(ev.Position(1, 1, 1))
        runs.append([(e.load_n, e.stable) for e in services.events.of(ev.LoadMeasured)])
    assert runs[0] == runs[1] and len(runs[0]) > 1


def test_the_real_clock_sleeps(monkeypatch):
    asked: list[float] = []
    monkeypatch.setattr(time, "sleep", lambda s: asked.append(s))
    clock = SystemClock()
    clock.sleep(0.25)
    clock.sleep(0.0)
    assert asked == [0.25]
    assert clock.now() <= time.monotonic()


def test_a_missed_trigger_spends_its_timeout_on_the_rig_clock():
    from drivers.errors import DeviceTimeout
    from drivers.interfaces import TriggerSpec

    rig = sim_rig(seed=2)
    rig.daq.configure(20_480.0, 2048)
    rig.daq.arm(TriggerSpec())
    t0 = rig.clock.now()
    with pytest.raises(DeviceTimeout):
        rig.daq.acquire(2.5)
    assert rig.clock.now() - t0 == pytest.approx(2.5)
