"""``labctl devices check --acquire`` on an emulated rig: one triggered record of a light tap through the real
drivers (MCC behind a pyusb backend, NI-DAQmx fake task, MT-SICS load cell on a pty), and the verification table."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.hw.verify import FAILED, NOT_VERIFIED, VERIFIED, TapSettings
from drivers.operators import ScriptedOperator
from labctl.cli import devices as devices_cli
from labctl.hardware import tap_check_devices
from tests.cli_util import assert_one_line_error, labctl_here, labctl_here_json
from tests.emulators.fake_nidaqmx import FakeNiHardware
from tests.emulators.fake_usb import FakeMcc1608, FakeUsbBackend, PlaybackSource
from tests.emulators.instruments import MtSicsDevice
from tests.emulators.pty_serial import PtySerialEmulator
from tests.test_hw_devices import PAPER_CHANNELS, daq_section, devices_file

pytestmark = pytest.mark.waits  # on other processes or real time (tests/conftest.py)

G = 9.80665
FS = 40e6 / 1953  # the MCC pacer's rate for 20 480 Hz
TAP = TapSettings(sample_rate_hz=20480.0, record_s=0.4, trigger_level_n=10.0, timeout_s=5.0, reading_interval_s=0.01)
EXAMPLE_INPUTS = ["F", "A1Z", "A2Z", "A3Z", "A4Z", "A1X", "A2X", "A3X"]  # the shipped example, inputs 0-7


def tap_waves(fs: float, n: int, names: list[str], peak_n: float = 150.0) -> dict[str, np.ndarray]:
    """A light tap: a 0.3 ms half-sine force and every accelerometer ringing at its own frequency (m/s²)."""
    t = np.arange(n) / fs
    waves = {"F": np.where(t < 0.3e-3, peak_n * np.sin(np.pi * t / 0.3e-3), 0.0)}
    for k, name in enumerate(names):
        if name != "F":
            waves[name] = (20.0 + k) * np.exp(-30 * t) * np.sin(2 * np.pi * (500 + 37 * k) * t)
    return waves


def mcc_rig(tmp_path: Path, cell_port: str, silent: tuple[str, ...] = ()) -> tuple[Path, dict[str, Any]]:
    source = PlaybackSource(noise_v=2e-5)
    waves = tap_waves(FS, 4096, EXAMPLE_INPUTS)
    volts = np.zeros((8, 4096))
    for i, name in enumerate(EXAMPLE_INPUTS):
        if name not in silent:
            volts[i] = waves[name] * (0.23e-3 if name == "F" else 0.1 / G)
    operator = ScriptedOperator()
    operator.on("strike", lambda message, choices: source.play(volts, delay_scans=800))
    path = devices_file(tmp_path, load_port=cell_port)
    return path, {"usb_backend": FakeUsbBackend(FakeMcc1608(source)), "operator": operator}


def by_item(rows: list[dict[str, str]]) -> dict[tuple[str, str], dict[str, str]]:
    return {(r["instrument"], r["item"]): r for r in rows}


def test_acquire_on_the_emulated_mcc_rig_prints_the_verification_table(tmp_path: Path, capsys: Any,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    with PtySerialEmulator(MtSicsDevice(lambda: 114.2)) as cell:
        path, over = mcc_rig(tmp_path, cell.port)
        monkeypatch.setattr(devices_cli, "instrument_overrides", lambda: over)
        out = labctl_here_json(capsys, "devices", "check", "--devices", str(path), "--acquire", "--seconds", "0.4",
                               "--timeout", "5")
        path, over = mcc_rig(tmp_path, cell.port)
        text = labctl_here(capsys, "devices", "check", "--devices", str(path), "--acquire", "--seconds", "0.4",
                           "--timeout", "5")
    assert out["ok"] is True and text.returncode == 0, text.stdout
    rows = by_item(out["verification"])
    assert rows[("daq", "sample rate")]["value"] == "20481.3 Hz"
    assert rows[("daq", "sample rate")]["status"] == NOT_VERIFIED  # the unit cannot report it
    assert rows[("daq", "record length")]["value"] == "8193 samples = 0.4 s"  # 0.4 s at 20 481.3 Hz
    assert rows[("F", "input range")] == {"instrument": "F", "item": "input range", "value": "±1 V",
                                          "status": VERIFIED, "note": "read back from the unit"}
    assert rows[("A1Z", "input range")]["value"] == "±5 V"
    assert rows[("daq", "trigger level reached")]["status"] == VERIFIED
    assert rows[("daq", "trigger level reached")]["value"].startswith("peak 15")  # the 150 N tap
    for name in EXAMPLE_INPUTS:
        assert rows[(name, "response to the tap")]["status"] == VERIFIED
        assert rows[(name, "clipping headroom")]["status"] == VERIFIED
    assert rows[("F", "clipping headroom")]["value"].startswith("23.")  # 20 log10(2200 / 150) = 23.3 dB
    assert rows[("load_cell", "reading")]["value"] == "114.20 N"
    assert rows[("load_cell", "stability")]["status"] == VERIFIED
    assert rows[("daq", "IEPE current")]["status"] == NOT_VERIFIED and rows[("daq", "coupling")]["value"].startswith(
        "DC, single-ended")
    assert rows[("sensors", "sensitivities")]["status"] == NOT_VERIFIED
    assert "test record of one tap:" in text.stdout and "all checks passed" in text.stdout
    assert any(line.split()[:5] == ["F", "input", "range", "±1", "V"] and "verified" in line
               for line in text.stdout.splitlines())


def test_a_silent_channel_fails_the_check(tmp_path: Path, capsys: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    with PtySerialEmulator(MtSicsDevice(lambda: 50.0, stable=False)) as cell:
        path, over = mcc_rig(tmp_path, cell.port, silent=("A3X",))
        monkeypatch.setattr(devices_cli, "instrument_overrides", lambda: over)
        proc = labctl_here(capsys, "devices", "check", "--devices", str(path), "--acquire", "--seconds", "0.4",
                           "--timeout", "5", "--json")
    assert proc.returncode == 1
    rows = by_item(json.loads(proc.stdout)["verification"])
    assert rows[("A3X", "response to the tap")]["status"] == FAILED
    assert "IEPE current" in rows[("A3X", "response to the tap")]["note"]
    assert rows[("A2X", "response to the tap")]["status"] == VERIFIED
    assert rows[("load_cell", "stability")]["status"] == FAILED  # the cell reports a moving load


@pytest.mark.parametrize(("rule", "rate"), [("up", 25600.0), ("nearest", 51200.0 / 3)])
def test_tap_check_on_four_ni_9234_modules(tmp_path: Path, rule: str, rate: float) -> None:
    hardware = FakeNiHardware(rate_rule=rule)
    operator = ScriptedOperator()
    operator.on("strike", lambda message, choices: hardware.blow(tap_waves(rate, 20000, PAPER_CHANNELS)))
    with PtySerialEmulator(MtSicsDevice(lambda: 80.0)) as cell:
        path = devices_file(tmp_path, load_port=cell.port, daq=daq_section("nidaqmx", PAPER_CHANNELS))
        rows = by_item([r.to_dict() for r in tap_check_devices(path, operator, TAP,
                                                               nidaqmx_module=hardware.module())])
    assert rows[("daq", "sample rate")]["value"] == f"{rate:.6g} Hz" and rows[("daq", "sample rate")]["status"] == \
        VERIFIED
    assert rows[("daq", "record length")]["value"] == f"{round(0.4 * rate)} samples = 0.4 s"
    for name in PAPER_CHANNELS:
        assert rows[(name, "coupling")]["value"] == "AC" and rows[(name, "coupling")]["status"] == VERIFIED
        assert rows[(name, "IEPE current")]["value"] == "2 mA (internal)"
        assert rows[(name, "response to the tap")]["status"] == VERIFIED
    assert all(r["status"] != FAILED for r in rows.values()), [r for r in rows.values() if r["status"] == FAILED]


def test_no_tap_is_a_failed_row_not_a_traceback(tmp_path: Path) -> None:
    with PtySerialEmulator(MtSicsDevice(lambda: 80.0)) as cell:
        path = devices_file(tmp_path, load_port=cell.port)
        rows = tap_check_devices(path, ScriptedOperator(), TapSettings(record_s=0.2, timeout_s=0.2),
                                 usb_backend=FakeUsbBackend(FakeMcc1608()))
    assert len(rows) == 1 and rows[0].status == FAILED and "no force above the trigger level" in rows[0].note


def test_acquire_on_the_makers_emulated_units(tmp_path: Path, capsys: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same check on the blind emulators written from the makers' documents: MCC unit and MT-SICS balance."""
    import math

    from tests.emulators import maker_mcc1608fsplus as maker_mcc
    from tests.emulators import maker_mtsics
    from tests.emulators.maker_mcc1608fsplus_backend import Usb1608FsPlusBackend

    def volts(channel: int, t: float) -> float:  # a 150 N tap at 50 ms; input k rings at its own frequency
        dt = t - 0.05
        if dt < 0:
            return 0.0
        if channel == 0:
            return 150.0 * 0.23e-3 * math.sin(math.pi * dt / 0.3e-3) if dt < 0.3e-3 else 0.0
        return 2.0 * math.exp(-30 * dt) * math.sin(2 * math.pi * (500 + 37 * channel) * dt) * 0.1

    unit = maker_mcc.Usb1608FsPlus(volts)
    with maker_mtsics.MtSicsBalance(capacity_g=20000.0) as cell:
        cell.load_g = 11645.0
        path = devices_file(tmp_path, load_port=cell.port)
        over = {"usb_backend": Usb1608FsPlusBackend(unit), "operator": ScriptedOperator()}
        monkeypatch.setattr(devices_cli, "instrument_overrides", lambda: over)
        out = labctl_here_json(capsys, "devices", "check", "--devices", str(path), "--acquire", "--seconds", "0.2",
                               "--timeout", "5")
    rows = by_item(out["verification"])
    assert out["ok"] is True, [r for r in out["verification"] if r["status"] == FAILED]
    assert rows[("F", "input range")]["value"] == "±1 V" and rows[("F", "input range")]["status"] == VERIFIED
    peak = float(rows[("daq", "trigger level reached")]["value"].split()[1])
    assert 140.0 < peak <= 150.1  # the 150 N half-sine as 20.5 kS/s samples it
    assert all(rows[(name, "response to the tap")]["status"] == VERIFIED for name in EXAMPLE_INPUTS)
    assert rows[("load_cell", "reading")]["value"] == f"{11.645 * G:.2f} N"


@pytest.mark.parametrize(("option", "value"), [("--rate", "0"), ("--seconds", "nan"), ("--trigger-n", "-5"),
                                               ("--timeout", "inf")])
def test_bad_acquire_options_are_one_line_errors(capsys: Any, option: str, value: str) -> None:
    proc = labctl_here(capsys, "devices", "check", "--devices", "labctl/data/devices.example.toml", "--acquire",
                       option, value)
    assert_one_line_error(proc, f"{option} {float(value):g}: expected a finite positive number")


if __name__ == "__main__":  # print the table of docs/hardware.md: PYTHONPATH=. python -m tests.test_hw_tap_check
    import sys
    import tempfile

    from labctl.cli import main

    with tempfile.TemporaryDirectory() as folder, PtySerialEmulator(MtSicsDevice(lambda: 114.2)) as cell:
        file, overrides = mcc_rig(Path(folder), cell.port)
        devices_cli.instrument_overrides = lambda: overrides  # type: ignore[assignment]
        code = main(["devices", "check", "--devices", str(file), "--acquire",
                     "--seconds", "0.4", "--timeout", "5"])
    sys.exit(code)
