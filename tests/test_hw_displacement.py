"""The displacement sensor on a DAQ input: a fake NI-DAQmx voltage task and the USB-1608FS-Plus emulator."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.hw.displacement import DaqDisplacementSensor, MccVoltageWindow, NiVoltageWindow
from drivers.interfaces import DisplacementSensor
from tests.emulators.fake_nidaqmx import AcquisitionType, DaqError, Error
from tests.emulators.fake_usb import FakeMcc1608, FakeUsbBackend, PlaybackSource


class FakeVoltageTask:
    """The nidaqmx Task calls a voltage window makes, with the real API's parameter names."""

    def __init__(self, hw: FakeNi) -> None:
        self.hw, self.terminal, self.closed = hw, "", False
        self.ai_channels = SimpleNamespace(add_ai_voltage_chan=self._add)
        self.timing = SimpleNamespace(cfg_samp_clk_timing=self._timing)
        self.n, self.rate = 0, 0.0

    def _add(self, physical_channel: str, name_to_assign_to_channel: str = "", terminal_config: Any = None,
             min_val: float = -5.0, max_val: float = 5.0, units: Any = None, custom_scale_name: str = "") -> None:
        if physical_channel.split("/")[0] not in self.hw.devices:
            raise DaqError(f"Device identifier is invalid: {physical_channel}", -200220)
        self.terminal, self.range = physical_channel, (min_val, max_val)

    def _timing(self, rate: float, source: str = "", active_edge: Any = None,
                sample_mode: Any = AcquisitionType.FINITE, samps_per_chan: int = 1000) -> None:
        assert sample_mode is AcquisitionType.FINITE
        self.rate, self.n = rate, samps_per_chan

    def start(self) -> None:
        if self.hw.timeout:
            raise DaqError("Wait Until Done did not indicate all acquisitions completed", -200560)

    def wait_until_done(self, timeout: float = 10.0) -> None:
        pass

    def read(self, number_of_samples_per_channel: int = 1, timeout: float = 10.0) -> list[float]:
        volts = self.hw.volts + self.hw.rng.normal(0.0, self.hw.noise_v, number_of_samples_per_channel)
        return np.clip(volts, *self.range).tolist()

    def close(self) -> None:
        self.closed = True


class FakeNi:
    def __init__(self, volts: float, noise_v: float = 0.01) -> None:
        self.volts, self.noise_v, self.timeout = volts, noise_v, False
        self.devices = ("cDAQ1Mod2",)
        self.rng = np.random.default_rng(0)
        self.tasks: list[FakeVoltageTask] = []

    def module(self) -> SimpleNamespace:
        def task(new_task_name: str = "") -> FakeVoltageTask:
            self.tasks.append(FakeVoltageTask(self))
            return self.tasks[-1]
        return SimpleNamespace(Task=task, constants=SimpleNamespace(AcquisitionType=AcquisitionType),
                               errors=SimpleNamespace(Error=Error))


def test_ni_window_is_averaged_and_scaled_to_metres() -> None:
    hw = FakeNi(volts=2.5, noise_v=0.01)
    with DaqDisplacementSensor(NiVoltageWindow("cDAQ1Mod2/ai0", nidaqmx_module=hw.module()),
                               sensitivity_um_per_v=100.0, window_s=0.5, sample_rate_hz=2000.0) as sensor:
        assert isinstance(sensor, DisplacementSensor)
        value = sensor.read()
    assert value == pytest.approx(250e-6, abs=3 * 0.01 / np.sqrt(1000) * 100e-6)
    assert hw.tasks[-1].n == 1000 and hw.tasks[-1].rate == 2000.0 and hw.tasks[-1].closed


def test_ni_failures_are_typed() -> None:
    hw = FakeNi(volts=1.0)
    with pytest.raises(DeviceDisconnected, match="not present"):
        DaqDisplacementSensor(NiVoltageWindow("cDAQ9Mod1/ai0", nidaqmx_module=hw.module()),
                              sensitivity_um_per_v=100.0).read()
    hw.timeout = True
    with pytest.raises(DeviceTimeout):
        DaqDisplacementSensor(NiVoltageWindow("cDAQ1Mod2/ai0", nidaqmx_module=hw.module()),
                              sensitivity_um_per_v=100.0).read()
    out_of_stroke = FakeNi(volts=12.0)
    with pytest.raises(DeviceError, match="out of its stroke"):
        DaqDisplacementSensor(NiVoltageWindow("cDAQ1Mod2/ai0", nidaqmx_module=out_of_stroke.module()),
                              sensitivity_um_per_v=100.0).read()
    with pytest.raises(ValueError, match="sensitivity_um_per_v"):
        DaqDisplacementSensor(NiVoltageWindow("cDAQ1Mod2/ai0"), sensitivity_um_per_v=0.0)


def test_mcc_window_reads_one_input_with_the_units_calibration() -> None:
    source = PlaybackSource(noise_v=1e-3)
    device = FakeMcc1608(source)
    level = np.zeros((8, 200_000))
    level[3] = -1.25  # the conditioner's output on input 3
    source.play(level, delay_scans=0)
    reader = MccVoltageWindow(3, range_v=2.0, backend=FakeUsbBackend(device))
    with DaqDisplacementSensor(reader, sensitivity_um_per_v=50.0, window_s=0.2, sample_rate_hz=1000.0) as sensor:
        value = sensor.read()
    assert value == pytest.approx(-62.5e-6, abs=0.05e-6)  # one code at ±2 V is 61 µV = 3.1 nm
    assert "START" in device.log and device.log[-1] == "CLEAR_FIFO" and device.ranges[3] == 3  # ±2 V: code 3


def test_mcc_failures_are_typed() -> None:
    with pytest.raises(DeviceDisconnected, match="no USB-1608FS-Plus"):
        MccVoltageWindow(0, backend=FakeUsbBackend()).open()
    device = FakeMcc1608(PlaybackSource())
    reader = MccVoltageWindow(0, backend=FakeUsbBackend(device))
    reader.open()
    device.unplugged = True
    with pytest.raises(DeviceDisconnected, match="ENODEV"):
        DaqDisplacementSensor(reader, sensitivity_um_per_v=50.0).read()
    with pytest.raises(ValueError, match="inputs 0-7"):
        MccVoltageWindow(8)


def test_devices_file_builds_the_sensor(tmp_path: Any) -> None:
    from labctl.errors import InputError
    from labctl.hardware import example_path, make_hw_rig

    text = example_path().read_text(encoding="utf-8")
    good = tmp_path / "devices.toml"
    good.write_text(text + '\n[displacement]\ntype = "mcc_usb"\ninput = "3"\nsensitivity_um_per_v = 50.0\n'
                    "range_v = 2.0\nwindow_ms = 50\n", encoding="utf-8")
    source = PlaybackSource(noise_v=1e-3)
    level = np.zeros((8, 100_000))
    level[3] = 0.5
    source.play(level, delay_scans=0)
    rig = make_hw_rig(good, usb_backend=FakeUsbBackend(FakeMcc1608(source)))
    assert rig.displacement is not None
    with rig.displacement as sensor:
        assert sensor.read() == pytest.approx(25e-6, abs=0.05e-6)
    bad = tmp_path / "bad.toml"
    bad.write_text(text + '\n[displacement]\ntype = "mcc_usb"\ninput = "cDAQ1Mod2/ai0"\nsensitivity_um_per_v = 50\n',
                   encoding="utf-8")
    with pytest.raises(InputError, match="displacement.*input"):
        make_hw_rig(bad)
