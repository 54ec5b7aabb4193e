"""One engine, two paths: quick_check on real drivers (MT-SICS load cell on a pty, MCC DAQ behind a pyusb
backend, serial hammer on a pty) fed by the simulated rig, against the same protocol run all-sim."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.hw import mcc_protocol as mcc
from drivers.interfaces import Rig, TriggerSpec
from drivers.sim import SimSettings
from labctl import campaign
from labctl.backends import make_rig as make_sim_or_hw_rig
from labctl.hardware import make_hw_rig
from labctl.protocol import load_protocol
from tests.emulators.fake_usb import FakeMcc1608, FakeUsbBackend, PlaybackSource
from tests.emulators.instruments import HammerDevice
from tests.emulators.pty_serial import PtySerialEmulator

PROTOCOL = Path(__file__).resolve().parents[1] / "protocols" / "quick_check.toml"
SEED = 11
G = 9.80665
INPUTS = {"F": 0, "A1Z": 1, "A2Z": 2, "A3Z": 3, "A4Z": 4, "A1X": 5, "A2X": 6, "A3X": 7}  # 8 inputs per unit


def devices_toml(load_port: str, hammer_port: str) -> str:
    """A devices file wiring the twin's transducers (same sensitivities) to one USB-1608FS-Plus."""
    s = SimSettings()
    rows = [f'[[daq.channels]]\nname = "F"\nkind = "force"\ninput = 0\n'
            f"sensitivity_mv_per_n = {s.force_sensitivity_v_per_n * 1e3!r}\nrange_n = 2000.0\n"]
    for name, number in INPUTS.items():
        if name != "F":
            rows.append(f'[[daq.channels]]\nname = "{name}"\nkind = "acceleration"\ninput = {number}\n'
                        f"sensitivity_mv_per_g = {s.accel_sensitivity_v_per_m_per_s2 * 1e3 * G!r}\n"
                        f"range_g = {s.accel_range_m_per_s2 / G!r}\n")
    return (f'[load_cell]\ntype = "mtsics"\nport = "{load_port}"\n\n[daq]\ntype = "mcc_usb"\n\n' + "\n".join(rows)
            + f'\n[hammer]\ntype = "serial"\nport = "{hammer_port}"\nlevel = 100\nboot_delay_s = 0\n\n'
            + '[actuator]\ntype = "manual"\nknobs = 4\n')


class TwinBench:
    """Real drivers whose instruments are emulators driven by a simulated rig: the load cell shows the twin's
    load over MT-SICS, the hammer's ``FIRE`` strikes the twin and the USB DAQ streams the twin's response."""

    def __init__(self, tmp_path: Path) -> None:
        acq = load_protocol(PROTOCOL).acquisition
        self.trigger = TriggerSpec(acq.trigger_level_n, acq.pretrigger_samples)
        self.rate_hz = mcc.actual_rate_hz(mcc.pacer_period(acq.sample_rate_hz))
        self.samples = acq.samples
        self.sim: Rig | None = None
        self.source = PlaybackSource(noise_v=0.0)
        self.usb_device = FakeMcc1608(self.source)
        self.cell = PtySerialEmulator(self._sics).__enter__()
        self.hammer_device = HammerDevice(on_fire=self._blow)
        self.hammer = PtySerialEmulator(self.hammer_device).__enter__()
        self.devices = tmp_path / "devices.toml"
        self.devices.write_text(devices_toml(self.cell.port, self.hammer.port), encoding="utf-8")

    def make_rig(self, backend: str, **kw: Any) -> Rig:
        """Stands in for the backend factory: the hardware rig of the devices file, the twin behind it."""
        assert backend == "hw" and kw["devices"] == self.devices
        self.sim = make_sim_or_hw_rig("sim", **{**kw, "devices": None})
        self.sim.daq.configure(self.rate_hz, self.samples)  # the twin sampled at the rate the MCC pacer runs
        rig = make_hw_rig(self.devices, operator=self.sim.operator, usb_backend=FakeUsbBackend(self.usb_device))
        return replace(rig, actuator=self.sim.actuator)  # the knobs are the twin's

    def _sics(self, command: str) -> str:
        assert self.sim is not None
        if command == "SI":
            reading = self.sim.load_cell.read()
            return f"S {'S' if reading.stable else 'D'} {reading.force_n:>10.2f} N"
        if command == "T":
            self.sim.load_cell.tare()
            return "T S       0.00 N"
        return 'I4 A "B947123456"' if command in ("I4", "@") else "ES"

    def _blow(self, level: int) -> None:
        assert self.sim is not None
        self.sim.daq.arm(self.trigger)
        self.sim.hammer.strike()
        record = self.sim.daq.acquire(1.0)
        sensitivity = {c.name: c.sensitivity_v_per_unit for c in self.sim.daq.channels}
        volts = np.zeros((8, record.force_n.size))
        volts[INPUTS["F"]] = record.force_n * sensitivity["F"]
        for name, number in INPUTS.items():
            if name != "F":
                volts[number] = record.accel_m_per_s2[record.channels.index(name)] * sensitivity[name]
        self.source.play(volts, delay_scans=500)

    def stop(self) -> None:
        self.cell.stop()
        self.hammer.stop()


@pytest.fixture
def bench(tmp_path: Path) -> Iterator[TwinBench]:
    b = TwinBench(tmp_path)
    yield b
    b.stop()


def test_quick_check_on_hardware_drivers_matches_the_all_sim_run(tmp_path: Path, bench: TwinBench,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    sim = campaign.run_campaign(PROTOCOL, out=tmp_path / "sim.h5", backend="sim", seed=SEED)
    monkeypatch.setattr(campaign, "make_rig", bench.make_rig)
    hw = campaign.run_campaign(PROTOCOL, out=tmp_path / "hw.h5", backend="hw", seed=SEED, devices=bench.devices)
    assert sim.status == "complete" and hw.status == "complete", (sim.message, hw.message)
    assert len(hw.curves) == len(sim.curves) == 1
    s, h = sim.curves[0], hw.curves[0]
    assert len(h["load_n"]) == len(s["load_n"]) >= 2
    np.testing.assert_allclose(h["load_n"], s["load_n"], atol=0.01)  # the MT-SICS display has 0.01 N
    # 8 of the twin's 13 channels, re-digitised by the 16-bit MCC at its 20 481.3 Hz pacer rate
    np.testing.assert_allclose(h["bounce_hz"], s["bounce_hz"], rtol=2e-4)
    np.testing.assert_allclose(h["stiffness_n_per_m"], s["stiffness_n_per_m"], rtol=2e-4)
    impacts = load_protocol(PROTOCOL).acquisition.impacts_per_step * len(h["load_n"])
    assert bench.usb_device.log.count("START") >= impacts and not bench.usb_device.running
    assert bench.hammer_device.fired == [100] * bench.usb_device.log.count("START")
