"""A displacement sensor on a DAQ analog input: a capacitive, eddy-current or LVDT conditioner's voltage output,
read as the DC average of a window of samples and scaled by the conditioner's sensitivity (µm/V at the edge,
m/V inside).

Two window readers: an NI-DAQmx voltage task (a finite acquisition on one ``ai`` terminal) and the
USB-1608FS-Plus (a finite scan of one input over pyusb, with the unit's calibration). A window that touches
the input's range is refused: the probe is out of its stroke and the average would be wrong.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Protocol

import numpy as np
import usb.core
import usb.util

from drivers.errors import DeviceDisconnected, DeviceError
from drivers.hw import mcc_protocol as mcc
from drivers.hw.lifecycle import Lifecycle
from drivers.hw.mcc_usb import usb_error
from drivers.hw.nidaq import import_nidaqmx, ni_error

_CONTROL_TIMEOUT_MS = 1000


@dataclass(frozen=True)
class Window:
    """One window of samples in volts and the input range they were taken on (± volts)."""

    volts: np.ndarray
    range_v: float


class WindowReader(Protocol):
    """Reads ``n`` samples of one analog input at ``rate_hz`` (opened and closed with the sensor)."""

    name: str

    def open(self) -> None: ...
    def close(self) -> None: ...
    def window(self, n: int, rate_hz: float) -> Window: ...


class DaqDisplacementSensor(Lifecycle):
    """``read`` → the DC average of one window × the sensitivity, in metres (``drivers.interfaces``)."""

    def __init__(self, reader: WindowReader, *, sensitivity_um_per_v: float, window_s: float = 0.1,
                 sample_rate_hz: float = 1000.0, name: str | None = None) -> None:
        if not (sensitivity_um_per_v > 0 and window_s > 0 and sample_rate_hz > 0):
            raise ValueError(f"displacement sensor: sensitivity_um_per_v {sensitivity_um_per_v!r}, window_s "
                             f"{window_s!r} and sample_rate_hz {sample_rate_hz!r} must be positive")
        self.reader, self.name = reader, name or f"displacement@{reader.name}"
        self.sensitivity_m_per_v = sensitivity_um_per_v * 1e-6
        self.samples = max(2, round(window_s * sample_rate_hz))
        self.sample_rate_hz = float(sample_rate_hz)

    def open(self) -> None:
        self.reader.open()

    def close(self) -> None:
        self.reader.close()

    def probe(self) -> str:
        """One reading, said plainly (``labctl devices check``)."""
        return f"{self.reader.name}: reads {self.read() * 1e6:.3f} µm ({self.samples} samples per window)"

    def read(self) -> float:
        w = self.reader.window(self.samples, self.sample_rate_hz)
        if w.volts.size == 0:
            raise DeviceError(self.name, "read", "the window held no samples")
        if float(np.max(np.abs(w.volts))) >= w.range_v * (1 - 1e-4):
            raise DeviceError(self.name, "read", f"the conditioner's output reached the input range ±{w.range_v:g} V: "
                              "the probe is out of its stroke; reset its gap")
        return float(np.mean(w.volts)) * self.sensitivity_m_per_v


class NiVoltageWindow:
    """A finite voltage acquisition on one NI terminal (``cDAQ1Mod2/ai0``); ``nidaqmx`` may be injected."""

    def __init__(self, terminal: str, *, range_v: float = 10.0, nidaqmx_module: ModuleType | Any = None) -> None:
        self.terminal, self.range_v, self._ni = terminal, float(range_v), nidaqmx_module
        self.name = f"nidaqmx:{terminal}"

    def open(self) -> None:
        self._module()

    def close(self) -> None:
        pass

    def window(self, n: int, rate_hz: float) -> Window:
        ni = self._module()
        task = None
        try:
            task = ni.Task()
            task.ai_channels.add_ai_voltage_chan(self.terminal, min_val=-self.range_v, max_val=self.range_v)
            task.timing.cfg_samp_clk_timing(rate_hz, sample_mode=ni.constants.AcquisitionType.FINITE,
                                            samps_per_chan=n)
            task.start()
            task.wait_until_done(timeout=n / rate_hz + 5.0)
            volts = np.asarray(task.read(number_of_samples_per_channel=n, timeout=1.0), dtype=float).ravel()
        except ni.errors.Error as exc:
            raise ni_error(self.name, "read", exc) from exc
        finally:
            if task is not None:
                with contextlib.suppress(Exception):
                    task.close()
        return Window(volts, self.range_v)

    def _module(self) -> Any:
        if self._ni is None:
            self._ni = import_nidaqmx(self.name)
        return self._ni


class MccVoltageWindow:
    """A finite scan of one USB-1608FS-Plus input (``0``…``7``) over pyusb, converted with the unit's calibration."""

    def __init__(self, input_number: int, *, range_v: float = 10.0, serial: str | None = None,
                 backend: Any = None) -> None:
        if not 0 <= input_number < mcc.N_CHANNELS:
            raise ValueError(f"input {input_number!r}: the USB-1608FS-Plus has inputs 0-{mcc.N_CHANNELS - 1}")
        self.input, self.range_code = input_number, mcc.range_code(range_v, range_v)
        self.range_v = mcc.RANGES_V[self.range_code]
        self.serial, self._backend = serial, backend
        self.name = f"usb-1608fs-plus:{serial or 'any'}:ch{input_number}"
        self._dev: Any = None
        self._cal: mcc.Calibration | None = None

    def open(self) -> None:
        if self._dev is not None:
            return
        found = list(usb.core.find(find_all=True, idVendor=mcc.VENDOR_ID, idProduct=mcc.PRODUCT_ID,
                                   backend=self._backend))
        try:
            dev = next(d for d in found if self.serial is None or self._serial(d) == self.serial)
        except StopIteration:
            raise DeviceDisconnected(self.name, "open", "no USB-1608FS-Plus"
                                     + (f" with serial {self.serial}" if self.serial else "") + " on the bus") from None
        try:
            dev.set_configuration()
            usb.util.claim_interface(dev, 0)
            raw = b"".join(bytes(dev.ctrl_transfer(mcc.REQ_IN, mcc.CAL_MEMORY, a, 0, mcc.PACKET_BYTES,
                                                   _CONTROL_TIMEOUT_MS))
                           for a in range(0, mcc.CAL_TABLE_BYTES, mcc.PACKET_BYTES))
        except usb.core.USBError as exc:
            raise usb_error(self.name, "open", exc) from exc
        try:
            self._cal = mcc.Calibration.from_memory(raw)
        except ValueError as exc:
            usb.util.dispose_resources(dev)
            raise DeviceError(self.name, "open", str(exc)) from None
        self._dev = dev

    def close(self) -> None:
        if self._dev is not None:
            with contextlib.suppress(DeviceError):
                self._halt()
            usb.util.dispose_resources(self._dev)
        self._dev = None

    def window(self, n: int, rate_hz: float) -> Window:
        self.open()
        ranges = bytearray(mcc.N_CHANNELS)
        ranges[self.input] = self.range_code
        try:
            self._halt()
            self._out(mcc.AIN_CONFIG, bytes(ranges))
            self._out(mcc.AIN_SCAN_START, mcc.scan_start_packet(1 << self.input, mcc.pacer_period(rate_hz), n))
            data = bytearray()
            while len(data) < 2 * n:
                data += bytes(self._dev.read(mcc.BULK_IN, mcc.PACKET_BYTES * 16, int(4000 + 2000 * n / rate_hz)))
            self._halt()
        except usb.core.USBError as exc:
            raise usb_error(self.name, "read", exc) from exc
        codes = np.frombuffer(bytes(data[: 2 * n]), dtype="<u2").reshape(1, n)
        assert self._cal is not None
        volts = self._cal.volts(codes, (self.input,), (self.range_code,))[0]
        volts[mcc.saturated_samples(codes)[0]] = self.range_v  # a code at the rail reads as the range
        return Window(volts, self.range_v)

    def _serial(self, dev: Any) -> str:
        raw = dev.ctrl_transfer(mcc.REQ_IN, mcc.SERIAL, 0, 0, 8, _CONTROL_TIMEOUT_MS)
        return bytes(raw).decode("ascii", errors="replace").strip("\x00 ")

    def _out(self, request: int, payload: bytes) -> None:
        self._dev.ctrl_transfer(mcc.REQ_OUT, request, 0, 0, payload, _CONTROL_TIMEOUT_MS)

    def _halt(self) -> None:
        self._out(mcc.AIN_SCAN_STOP, b"")
        self._out(mcc.AIN_CLR_FIFO, b"")
        with contextlib.suppress(usb.core.USBError):
            self._dev.read(mcc.BULK_IN, mcc.PACKET_BYTES * 16, 20)
