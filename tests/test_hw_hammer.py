"""Automatic (serial) and manual hammers, the manual knob actuator, and their DAQ force trigger."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.errors import DeviceBusy, DeviceError, DeviceTimeout
from drivers.hw import ManualActuator, ManualHammer, MccUsbDaq, SerialHammer
from drivers.interfaces import Hammer, LoadActuator
from drivers.operators import ScriptedOperator
from tests.emulators.fake_usb import FakeMcc1608, FakeUsbBackend, PlaybackSource
from tests.emulators.impacts import FS, TRIGGER, impact_volts, wiring
from tests.emulators.instruments import HammerDevice
from tests.emulators.pty_serial import ExpectedProtocol, PtySerialEmulator


def test_fire_ok_and_identify_exchange() -> None:
    protocol = ExpectedProtocol([("ID?", "ID AUTOHAMMER 1.2"), ("FIRE 90", "OK"), ("FIRE 90", "OK")])
    with PtySerialEmulator(protocol) as emulator, SerialHammer(emulator.port, level=90) as hammer:
        assert isinstance(hammer, Hammer)
        assert "AUTOHAMMER 1.2" in hammer.probe()
        hammer.strike()
        hammer.strike()
    protocol.assert_consumed()


@pytest.mark.parametrize(("reply", "kind", "fragment"), [
    ("ERR BUSY recharging", DeviceBusy, "ERR BUSY"),
    ("ERR INTERLOCK", DeviceError, "ERR INTERLOCK"),
    (None, DeviceTimeout, "'FIRE 128': no reply within 0.2 s"),
])
def test_fire_failures(reply: str | None, kind: type, fragment: str) -> None:
    protocol = ExpectedProtocol([("FIRE 128", reply)])
    with PtySerialEmulator(protocol) as emulator, SerialHammer(emulator.port, timeout_s=0.2) as hammer, \
            pytest.raises(kind) as err:
        hammer.strike()
    assert fragment in str(err.value) and emulator.port in str(err.value)


def test_level_is_checked() -> None:
    with pytest.raises(ValueError, match="1-255"):
        SerialHammer("/dev/null", level=300)


def test_automatic_hammer_blow_is_caught_by_the_daq_trigger() -> None:
    source = PlaybackSource()
    device = HammerDevice(on_fire=lambda level: source.play(impact_volts(FS, peak_n=2.0 * level), delay_scans=300))
    daq = MccUsbDaq(wiring(), backend=FakeUsbBackend(FakeMcc1608(source)))
    daq.configure(FS, 4096)
    with PtySerialEmulator(device) as emulator, SerialHammer(emulator.port, level=200) as hammer, daq:
        daq.arm(TRIGGER)
        hammer.strike()
        record = daq.acquire(5.0)
    assert device.fired == [200]
    assert record.force_n.max() == pytest.approx(400.0, rel=0.01)


def test_manual_hammer_asks_the_operator_and_the_trigger_catches_the_blow() -> None:
    source = PlaybackSource()
    operator = ScriptedOperator()
    operator.on("strike", lambda message, choices: source.play(impact_volts(FS), delay_scans=500) or None)
    daq = MccUsbDaq(wiring(), backend=FakeUsbBackend(FakeMcc1608(source)))
    daq.configure(FS, 4096)
    hammer = ManualHammer(operator)
    assert isinstance(hammer, Hammer)
    with daq, hammer:
        daq.arm(TRIGGER)
        hammer.strike()
        record = daq.acquire(5.0)
    assert operator.actions() == ["strike"] and "Strike the upper disc" in operator.prompts[0].message
    assert np.max(record.force_n) == pytest.approx(600.0, rel=0.01)


def test_manual_hammer_cancelled_is_an_error() -> None:
    operator = ScriptedOperator(answers={"strike": ["cancel"]})
    with pytest.raises(DeviceError, match="'cancel'"):
        ManualHammer(operator).strike()


def test_manual_actuator_prompts_and_counts_the_knob_angle() -> None:
    operator = ScriptedOperator()
    actuator = ManualActuator(operator, knobs=4)
    assert isinstance(actuator, LoadActuator)
    actuator.turn_knobs(180.0)
    actuator.turn_knobs(180.0)
    assert actuator.knob_angle_deg == 360.0
    actuator.turn_knobs(-720.0)  # loosening stops at the preload
    actuator.turn_knobs(-10.0)  # already there: nothing to ask
    assert actuator.knob_angle_deg == 0.0
    messages = [p.message for p in operator.prompts]
    assert operator.actions() == ["turn_knobs"] * 3
    assert "all 4 star knobs by +180°" in messages[0] and "tighten" in messages[0]
    assert "by -360°" in messages[2] and "loosen" in messages[2]


def test_manual_actuator_declined_keeps_the_angle() -> None:
    actuator = ManualActuator(ScriptedOperator(answers={"turn_knobs": ["cancel"]}))
    with pytest.raises(DeviceError, match="turn knobs"):
        actuator.turn_knobs(180.0)
    assert actuator.knob_angle_deg == 0.0
