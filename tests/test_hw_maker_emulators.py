"""The hardware drivers against the blind emulators written from the makers' documents only
(tests/emulators/maker_*.py, facts and sources in tests/emulators/MAKER_FACTS.md): not a line of them was taken
from the drivers, so agreement here is agreement with the makers, not with ourselves."""

from __future__ import annotations

import math
import struct
import types
from collections.abc import Iterator
from enum import Enum
from typing import Any

import numpy as np
import pytest
import serial

from drivers.errors import DeviceError, DeviceTimeout
from drivers.hw.acquisition import InputWiring
from drivers.hw.mcc_usb import MccUsbDaq
from drivers.hw.mtsics import MtSicsLoadCell
from drivers.hw.nidaq import NiDaq
from drivers.interfaces import Channel, TriggerSpec
from tests.emulators import maker_mcc1608fsplus as maker_mcc
from tests.emulators import maker_mtsics
from tests.emulators import maker_ni9234 as maker_ni
from tests.emulators.maker_mcc1608fsplus_backend import Usb1608FsPlusBackend

pytestmark = pytest.mark.waits  # on emulated instruments answering in real time (tests/conftest.py)

G = 9.80665
FORCE_V_PER_N, ACCEL_V_PER_MS2 = 0.23e-3, 0.1 / G
T_BLOW = 0.05  # s after the scan starts


def blow_volts(channel: int, t: float) -> float:
    """The input at the BNC/screw terminal: a 600 N half-sine on input 0 at 50 ms, a 745 Hz ring on input 2."""
    dt = t - T_BLOW
    if channel == 0:
        return 600.0 * FORCE_V_PER_N * math.sin(math.pi * dt / 0.3e-3) if 0 <= dt < 0.3e-3 else 0.0
    if channel == 2 and dt >= 0:
        return 200.0 * ACCEL_V_PER_MS2 * math.exp(-40 * dt) * math.sin(2 * math.pi * 745 * dt)
    return 0.0


def mcc_wiring() -> list[InputWiring]:
    return [InputWiring(Channel("F", "force", "N", FORCE_V_PER_N, 2200.0), "0"),
            InputWiring(Channel("A1Z", "acceleration", "m/s^2", ACCEL_V_PER_MS2, 490.0), "2")]


def mcc_daq(unit: maker_mcc.Usb1608FsPlus) -> MccUsbDaq:
    return MccUsbDaq(mcc_wiring(), backend=Usb1608FsPlusBackend(unit))


def test_mcc_record_in_physical_units_on_the_makers_unit() -> None:
    unit = maker_mcc.Usb1608FsPlus(blow_volts)
    with mcc_daq(unit) as daq:
        fs = daq.configure(20480.0, 2048)
        daq.arm(TriggerSpec(level_n=20.0, pretrigger_samples=128))
        record = daq.acquire(timeout_s=5.0)
    assert unit.ranges[0] == 5 and unit.ranges[2] == 1  # ±1 V for the 0.506 V hammer, ±5 V for 5 V of 50 g
    assert fs == pytest.approx(40e6 / 1953) and record.trigger_index == 128 and record.clipped == ()
    t = (np.arange(record.force_n.size) - 128) / fs
    k0 = round(T_BLOW * fs)  # the scan sample just after the blow starts
    crossing = next(k for k in range(k0, k0 + 10) if blow_volts(0, k / fs) / FORCE_V_PER_N >= 20.0)
    expected_force = np.array([blow_volts(0, crossing / fs + x) for x in t]) / FORCE_V_PER_N
    expected_accel = np.array([blow_volts(2, crossing / fs + x) for x in t]) / ACCEL_V_PER_MS2
    np.testing.assert_allclose(record.force_n, expected_force, atol=0.2)  # 1 LSB on ±1 V = 0.13 N
    np.testing.assert_allclose(record.accel_m_per_s2[0], expected_accel, atol=0.1)  # 1 LSB on ±5 V = 0.015 m/s²


def test_mcc_open_stops_a_leftover_scan_before_reading_the_calibration() -> None:
    unit = maker_mcc.Usb1608FsPlus(blow_volts)
    unit.control_out(maker_mcc.AIN_SCAN_START, 0, 0, struct.pack("<IIBB", 0, 39999, 0xFF, 0))  # a crashed program's
    assert unit.status & maker_mcc.STATUS_SCAN_RUNNING
    with mcc_daq(unit) as daq:
        assert daq.stale_scan_stopped
    order = [request for _type, request, *_ in unit.requests]
    assert order.index(maker_mcc.AIN_SCAN_STOP) < order.index(maker_mcc.CAL_MEMORY)


def test_mcc_settings_read_back_from_the_makers_unit() -> None:
    unit = maker_mcc.Usb1608FsPlus(blow_volts)
    with mcc_daq(unit) as daq:
        daq.configure(20480.0, 1024)
        daq.arm(TriggerSpec(level_n=20.0, pretrigger_samples=64))
        daq.acquire(timeout_s=5.0)
        assert daq.read_ranges() == {"F": 1.0, "A1Z": 5.0}


def test_mcc_a_rate_the_unit_cannot_stream_is_refused_before_it_overruns() -> None:
    eight = [InputWiring(Channel("F", "force", "N", FORCE_V_PER_N, 2200.0), "0"),
             *(InputWiring(Channel(f"A{i // 3 + 1}{'XYZ'[i % 3]}", "acceleration", "m/s^2", ACCEL_V_PER_MS2, 490.0),
                           str(i + 1)) for i in range(7))]
    daq = MccUsbDaq(eight, backend=Usb1608FsPlusBackend(maker_mcc.Usb1608FsPlus(blow_volts)))
    with pytest.raises(ValueError, match="400000 S/s in all"):
        daq.configure(60e3, 4096)


# ---- NI 9234 ---------------------------------------------------------------------------------------------------
class ForceUnits(Enum):  # nidaqmx.constants values (checked against the package in test_hw_nidaq)
    NEWTONS, POUNDS = 15875, 15876


class ForceIEPESensorSensitivityUnits(Enum):
    MILLIVOLTS_PER_NEWTON, MILLIVOLTS_PER_POUND = 15891, 15892


def _add_ai_force_iepe_chan(self: Any, physical_channel: str, name_to_assign_to_channel: str = "",
                            terminal_config: Any = None, min_val: float = -2000.0, max_val: float = 2000.0,
                            units: Any = ForceUnits.NEWTONS, sensitivity: float = 2.25,
                            sensitivity_units: Any = ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON,
                            current_excit_source: Any = None, current_excit_val: float = 0.004,
                            custom_scale_name: str = "") -> Any:
    """The blind emulator models IEPE accelerometer channels only; an IEPE force channel is the same input stage
    (2 mA, AC coupled) scaled in mV/N, so it is added as one with the sensitivity in V per newton."""
    assert sensitivity_units is ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON
    return self._add(physical_channel, name_to_assign_to_channel, "accel", min_val=min_val, max_val=max_val,
                     units=units, sensitivity=sensitivity,
                     sensitivity_units=maker_ni.AccelSensitivityUnits.MILLIVOLTS_PER_G,
                     current_excit_source=current_excit_source, current_excit_val=current_excit_val)


@pytest.fixture
def ni_chassis(monkeypatch: pytest.MonkeyPatch) -> Iterator[types.ModuleType]:
    chassis = maker_ni.Chassis(modules={1: {0: maker_ni.Input(lambda t: blow_volts(0, t)),
                                            1: maker_ni.Input(lambda t: blow_volts(2, t))}})
    monkeypatch.setattr(maker_ni.AIChannelCollection, "add_ai_force_iepe_chan", _add_ai_force_iepe_chan,
                        raising=False)
    with maker_ni.installed(chassis) as nidaqmx:
        monkeypatch.setattr(nidaqmx.constants, "ForceUnits", ForceUnits, raising=False)
        monkeypatch.setattr(nidaqmx.constants, "ForceIEPESensorSensitivityUnits", ForceIEPESensorSensitivityUnits,
                            raising=False)
        yield nidaqmx


def ni_daq(nidaqmx: types.ModuleType, accel_range: float = 480.0) -> NiDaq:
    return NiDaq([InputWiring(Channel("F", "force", "N", FORCE_V_PER_N, 2200.0), "cDAQ1Mod1/ai0"),
                  InputWiring(Channel("A1Z", "acceleration", "m/s^2", ACCEL_V_PER_MS2, accel_range), "cDAQ1Mod1/ai1")],
                 nidaqmx_module=nidaqmx)


def test_ni_record_on_the_makers_module_keeps_its_seconds(ni_chassis: types.ModuleType) -> None:
    with ni_daq(ni_chassis) as daq:
        fs = daq.configure(20480.0, 2048)  # 0.1 s asked
        daq.arm(TriggerSpec(level_n=20.0, pretrigger_samples=128))
        record = daq.acquire(timeout_s=1.0)
    assert fs == 25600.0 and record.force_n.size == 2560 and record.trigger_index == 160  # 0.1 s, 6.25 ms
    t = (np.arange(2560) - 160) / fs
    crossing = next(k for k in range(1, 4000) if blow_volts(0, k / fs) / FORCE_V_PER_N >= 20.0)
    expected = np.array([blow_volts(0, crossing / fs + x) for x in t]) / FORCE_V_PER_N
    np.testing.assert_allclose(record.force_n, expected, atol=0.5)  # through the module's 0.5 Hz AC coupling
    ring = np.array([blow_volts(2, crossing / fs + x) for x in t]) / ACCEL_V_PER_MS2
    np.testing.assert_allclose(record.accel_m_per_s2[0], ring, atol=0.5)


def test_ni_the_makers_module_refuses_iepe_without_ac_coupling(ni_chassis: types.ModuleType,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """If the adapter left coupling to a default and the default were DC, DAQmx would refuse at start (−200077)."""
    original = maker_ni.AIChannel.__setattr__
    monkeypatch.setattr(maker_ni.AIChannel, "__setattr__", lambda self, k, v: original(
        self, k, maker_ni.Coupling.DC if k == "ai_coupling" else v))
    with ni_daq(ni_chassis) as daq:
        daq.configure(20480.0, 2048)
        with pytest.raises(DeviceError, match=r"-200077.*AI.Coupling"):
            daq.arm(TriggerSpec(level_n=20.0, pretrigger_samples=128))


def test_ni_a_range_beyond_the_modules_5_v_is_refused(ni_chassis: types.ModuleType) -> None:
    with ni_daq(ni_chassis, accel_range=600.0) as daq:  # 600 m/s² × 10.2 mV/(m/s²) = 6.1 V > ±5 V
        daq.configure(20480.0, 2048)
        with pytest.raises(DeviceError, match=r"-200077.*AI.Max"):
            daq.arm(TriggerSpec(level_n=20.0, pretrigger_samples=128))


# ---- MT-SICS -------------------------------------------------------------------------------------------------
@pytest.fixture
def balance(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[maker_mtsics.MtSicsBalance]:
    fmt, level = request.param
    with maker_mtsics.MtSicsBalance(fmt=fmt, level=level) as b:
        monkeypatch.setattr(serial, "Serial", b.observing_serial())  # the pty cannot carry 7 bits and parity
        b.load_g = 123.45
        yield b


SEVEN_E_ONE = maker_mtsics.SerialFormat(7, "E", 1, True)


@pytest.mark.parametrize("balance", [(SEVEN_E_ONE, 1)], indirect=True)
def test_mtsics_7e1_xonxoff_balance_read_with_its_own_format(balance: maker_mtsics.MtSicsBalance) -> None:
    with MtSicsLoadCell(balance.port, serial_format="7E1", handshake="xonxoff", timeout_s=1.0) as cell:
        reading = cell.read()
        cell.tare()
    assert reading.force_n == pytest.approx(0.12345 * G, abs=1e-6) and reading.stable
    assert balance.declared_host is not None and balance.declared_host.data_bits == 7


@pytest.mark.parametrize("balance", [(SEVEN_E_ONE, 1)], indirect=True)
def test_mtsics_8n1_against_a_7e1_balance_fails_plainly(balance: maker_mtsics.MtSicsBalance) -> None:
    with MtSicsLoadCell(balance.port, timeout_s=0.5, busy_retries=0) as cell, \
            pytest.raises((DeviceError, DeviceTimeout)):
        cell.read()


@pytest.mark.parametrize("balance", [(maker_mtsics.SerialFormat(), 0)], indirect=True)
def test_mtsics_level_0_balance_reads_but_has_no_tare(balance: maker_mtsics.MtSicsBalance) -> None:
    with MtSicsLoadCell(balance.port, timeout_s=1.0) as cell:
        assert cell.read().force_n == pytest.approx(0.12345 * G, abs=1e-6)
        assert "B021002593" in cell.identify()
        with pytest.raises(DeviceError, match="'T' not understood.*level 1"):
            cell.tare()
