"""Each simulated instrument through its interface: DAQ, hammer, load cell, actuator, operator, lifecycle."""

from __future__ import annotations

import io

import numpy as np
import pytest

from drivers import Daq, Hammer, LoadActuator, LoadCell, Operator, TriggerSpec
from drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.operators import ConsoleOperator, ScriptedOperator
from drivers.sim import twin_of
from labctl.physics import load_rig
from tests.test_sim_support import sim_rig, strike_records

RIG = load_rig()
PER_HALF_TURN_N = RIG.loading.rods * RIG.loading.spring_rate_n_per_m * 0.5 * RIG.loading.thread_pitch_m / 3


def settled(load_cell, reads: int = 3):
    """Read until the cell reports stable (at most ``reads`` extra reads)."""
    reading = load_cell.read()
    for _ in range(reads):
        if reading.stable:
            break
        reading = load_cell.read()
    return reading


def test_instruments_satisfy_the_interfaces():
    rig = sim_rig()
    assert isinstance(rig.daq, Daq) and isinstance(rig.hammer, Hammer)
    assert isinstance(rig.load_cell, LoadCell) and isinstance(rig.actuator, LoadActuator)
    assert isinstance(rig.operator, Operator)
    assert rig.backend == "sim" and rig.description["seed"] == "7"
    assert rig.description["world"].endswith("default.toml")


def test_daq_channels_have_hammer_and_accelerometer_sensitivities_and_ranges():
    chans = sim_rig().daq.channels
    assert [c.name for c in chans] == ["F", *RIG.channels]
    assert [c.name for c in chans][1:] == [f"A{i}{ax}" for i in range(1, 5) for ax in "XYZ"]
    force, accel = chans[0], chans[1:]
    assert force.kind == "force" and force.unit == "N"
    assert force.sensitivity_v_per_unit == pytest.approx(0.23e-3)  # PCB 086D05: 0.23 mV/N
    assert force.range_units == pytest.approx(22_240)
    for c in accel:
        assert c.kind == "acceleration"
        assert c.sensitivity_v_per_unit * 9.80665 == pytest.approx(0.100)  # 356A16: 100 mV/g
        assert c.range_units == pytest.approx(50 * 9.80665)


def test_record_layout_and_trigger():
    rig = sim_rig()
    assert rig.daq.configure(20_480, 8192) == 20_480
    rig.daq.arm(TriggerSpec(level_n=20.0, pretrigger_samples=128))
    rig.hammer.strike()
    rec = rig.daq.acquire(timeout_s=2.0)
    assert rec.sample_rate_hz == 20_480 and rec.force_n.shape == (8192,)
    assert rec.accel_m_per_s2.shape == (12, 8192) and rec.channels == RIG.channels
    assert rec.trigger_index == 128 and rec.clipped == ()
    first = int(np.argmax(rec.force_n >= 20.0))
    assert first == 128  # the force crosses the trigger level exactly at the trigger index
    assert np.all(np.abs(rec.force_n[:120]) < 1.0)  # before the blow: noise only
    assert 50 < rec.force_n.max() < 2000


def test_acquire_without_a_blow_times_out_at_once_and_needs_arming():
    rig = sim_rig()
    rig.daq.configure(20_480, 4096)
    with pytest.raises(DeviceError, match="not armed"):
        rig.daq.acquire(1.0)
    rig.daq.arm(TriggerSpec())
    with pytest.raises(DeviceTimeout) as exc:
        rig.daq.acquire(timeout_s=30.0)  # returns immediately: the simulation never sleeps
    assert exc.value.device == "sim-daq" and exc.value.action == "acquire"
    # a blow before arming is not caught by the next record
    rig.hammer.strike()
    rig.daq.arm(TriggerSpec())
    with pytest.raises(DeviceTimeout):
        rig.daq.acquire(1.0)


def test_blow_below_the_trigger_level_is_not_recorded():
    rig = sim_rig()
    rig.daq.configure(20_480, 4096)
    twin_of(rig).next_blow_peak(10.0)
    rig.daq.arm(TriggerSpec(level_n=20.0))
    rig.hammer.strike()
    with pytest.raises(DeviceTimeout, match="20 N"):
        rig.daq.acquire(1.0)


def test_daq_refuses_bad_settings_and_can_coerce_the_rate(tmp_path):
    rig = sim_rig()
    for fs, n in [(0.0, 1024), (1e6, 1024), (20_480, 4), (20_480, 1024.5)]:
        with pytest.raises(DeviceError, match="configure"):
            rig.daq.configure(fs, n)
    rig.daq.configure(20_480, 1024)
    with pytest.raises(DeviceError, match="pretrigger"):
        rig.daq.arm(TriggerSpec(pretrigger_samples=2000))
    coerced = sim_rig(world=_world_file(tmp_path, "base_clock_hz = 51200.0"))
    fs = coerced.daq.configure(20_480, 4096)
    assert fs != 20_480 and 51_200 / fs == pytest.approx(round(51_200 / fs))
    assert strike_records(coerced, 1, fs=20_480, samples=4096)[0].sample_rate_hz == fs


def _world_file(folder, instruments: str) -> str:
    path = folder / "world.toml"
    path.write_text(f'[baseline]\nmodel = "tripp"\ndepth_mm = 1.5\n[instruments]\n{instruments}\n', encoding="utf-8")
    return str(path)


def test_load_cell_reads_total_force_settles_after_a_turn_and_tares():
    rig = sim_rig()
    first = rig.load_cell.read()
    assert first.stable
    assert first.force_n == pytest.approx(3 * RIG.preload_per_roller_n, abs=2.0)  # three rollers carry the disc
    rig.actuator.turn_knobs(180)
    flags = [rig.load_cell.read() for _ in range(4)]
    assert [r.stable for r in flags] == [False, False, True, True]
    target = 3 * (RIG.preload_per_roller_n + PER_HALF_TURN_N)
    assert flags[0].force_n > target + 1.0  # the first read overshoots while the springs settle
    assert flags[3].force_n == pytest.approx(target, abs=2.0)
    rig.load_cell.tare()
    assert rig.load_cell.read().force_n == pytest.approx(0.0, abs=2.0)
    rig.actuator.turn_knobs(180)
    assert settled(rig.load_cell).force_n == pytest.approx(3 * PER_HALF_TURN_N, abs=2.0)


def test_creep_drifts_the_load_and_keeps_the_cell_unstable():
    rig = sim_rig()
    twin = twin_of(rig)
    twin.set_load_per_roller(200.0)  # (creep never takes the load below the preload)
    twin.set_creep(-2.0)  # N per roller per second of rig time
    readings = [rig.load_cell.read() for _ in range(50)]  # 0.1 s of rig time per read
    assert not any(r.stable for r in readings)
    drift = readings[-1].force_n - readings[0].force_n
    assert drift == pytest.approx(3 * -2.0 * 49 * twin.settings.load_cell_read_s, abs=2.0)


def test_actuator_turns_never_unload_below_the_preload():
    rig = sim_rig()
    twin = twin_of(rig)
    rig.actuator.turn_knobs(360)
    assert rig.actuator.knob_angle_deg == 360
    assert twin.load_per_roller_n() == pytest.approx(RIG.preload_per_roller_n + 2 * PER_HALF_TURN_N)
    rig.actuator.turn_knobs(-720)  # backs the nuts off: the disc still rests on the rollers
    assert rig.actuator.knob_angle_deg == -360
    assert twin.load_per_roller_n() == pytest.approx(RIG.preload_per_roller_n)
    rig.actuator.turn_knobs(360)  # first takes up the slack
    assert twin.load_per_roller_n() == pytest.approx(RIG.preload_per_roller_n)
    with pytest.raises(DeviceError, match="turn_knobs"):
        rig.actuator.turn_knobs(float("nan"))


def test_lifecycle_closed_and_unplugged_instruments_raise_disconnected():
    rig = sim_rig()
    with rig.load_cell as cell:
        assert cell.read().force_n > 0
    with pytest.raises(DeviceDisconnected, match="sim-loadcell: read failed: device is closed"):
        rig.load_cell.read()
    rig.load_cell.open()
    assert rig.load_cell.read().force_n > 0
    twin_of(rig).unplug("sim-hammer")
    with pytest.raises(DeviceDisconnected, match="sim-hammer: strike"):
        rig.hammer.strike()
    with pytest.raises(DeviceDisconnected):
        rig.hammer.open()
    twin_of(rig).replug("sim-hammer")
    rig.hammer.strike()


def test_operator_rotate_prompt_reseats_the_rollers_whoever_answers():
    script = ScriptedOperator(answers={"rotate_rollers": ["done", "abort"]})
    seen: list[str] = []
    script.on("unload", lambda message, choices: seen.append(message) or None)
    rig = sim_rig(operator=script)
    twin = twin_of(rig)
    twin.set_load_per_roller(100.0)
    before = twin.roller_stiffness_n_per_m()
    assert rig.operator.prompt("Lift the disc and rotate the rollers ~5°", ("done", "abort"),
                               "rotate_rollers") == "done"
    after = twin.roller_stiffness_n_per_m()
    assert after != before and twin.rotations == 1
    assert rig.operator.prompt("Rotate again", ("done", "abort"), "rotate_rollers") == "abort"
    assert twin.roller_stiffness_n_per_m() == after  # refused: nothing moved
    rig.operator.prompt("Loosen the knobs", ("ok",), "unload")
    assert seen == ["Loosen the knobs"]
    assert script.actions() == ["rotate_rollers", "rotate_rollers", "unload"]
    assert rig.operator.prompts[0].answer == "done"  # the wrapper exposes the script's log


def test_default_operator_confirms_and_console_operator_reads_stdin():
    rig = sim_rig()
    assert rig.operator.prompt("Mount roller type 1", ("ok", "cancel"), "mount_specimen") == "ok"
    out = io.StringIO()
    console = ConsoleOperator(io.StringIO("\nmaybe\n2\nab\n"), out)
    assert console.prompt("Hit the disc", ("ok", "abort")) == "ok"
    assert console.prompt("Rotate the rollers", ("done", "abort"), "rotate_rollers") == "abort"
    assert "please answer one of: done, abort" in out.getvalue()
    assert console.prompt("Again?", ("done", "abort")) == "abort"  # unique prefix
    with pytest.raises(DeviceDisconnected, match="input closed"):
        console.prompt("Anyone?", ("ok",))


def test_scripted_operator_refuses_answers_not_offered():
    op = ScriptedOperator(answers={"confirm": ["maybe"]})
    with pytest.raises(DeviceError, match="'maybe' is not one of"):
        op.prompt("Proceed?", ("yes", "no"))
