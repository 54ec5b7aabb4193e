"""DAQ backend for the Measurement Computing USB-1608FS-Plus, spoken to directly over pyusb.

The unit has no analog trigger: ``arm`` starts a continuous scan and a reader thread drains the bulk IN
endpoint (so a slow operator prompt never overruns the 32 k-sample FIFO), converts codes to physical units
with the factory calibration and the sensor sensitivities, and catches the force crossing in software,
keeping the pretrigger samples. Up to 8 simultaneously sampled single-ended inputs (referenced to AGND) at
±10/±5/±2/±1 V; IEPE sensors need an external conditioner (the unit supplies no excitation current).
"""

from __future__ import annotations

import contextlib
import errno
import threading
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import usb.core
import usb.util

from drivers.errors import DeviceBusy, DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.hw import mcc_protocol as mcc
from drivers.hw.acquisition import InputWiring, StreamTrigger, check_wiring, make_record, samples_at_rate
from drivers.hw.lifecycle import Lifecycle
from drivers.hw.verify import NOT_VERIFIED, VERIFIED, Finding
from drivers.interfaces import Channel, Record, TriggerSpec

_CONTROL_TIMEOUT_MS = 1000
_BLOCK_S = 0.02  # bulk read size in seconds of data: short enough that a timeout loses little


def usb_error(device: str, action: str, exc: Exception) -> DeviceError:
    """A pyusb failure as the typed error that says what happened to the unit."""
    code = getattr(exc, "errno", None)
    if isinstance(exc, usb.core.USBTimeoutError) or code == errno.ETIMEDOUT:
        return DeviceTimeout(device, action, f"no answer from the unit ({exc})")
    if code == errno.ENODEV:
        return DeviceDisconnected(device, action, "the unit was unplugged (ENODEV)")
    if code == errno.EACCES:
        return DeviceError(device, action, "permission denied on the USB device (install the udev rule in "
                           "docs/hardware.md or run as a member of the 'plugdev' group)")
    if code == errno.EBUSY:
        return DeviceBusy(device, action, "the unit is claimed by another program")
    return DeviceError(device, action, str(exc) or type(exc).__name__)


class MccUsbDaq(Lifecycle):
    """USB-1608FS-Plus: ``configure`` → actual pacer rate; ``arm`` starts the scan; ``acquire`` the record."""

    def __init__(self, wiring: Sequence[InputWiring], *, serial: str | None = None, backend: Any = None,
                 name: str | None = None, conditioner: str = "") -> None:
        self.name = name or "daq@usb-1608fs-plus" + (f":{serial}" if serial else "")
        self.conditioner = conditioner  # the IEPE conditioner in front of the inputs, as the devices file names it
        self._force_row, _ = check_wiring(self.name, wiring)
        inputs = [self._input_number(w) for w in wiring]
        self._scan = tuple(sorted(inputs))  # the device returns channels in ascending order
        self._to_wiring = [self._scan.index(i) for i in inputs]
        self._ranges = tuple(mcc.range_code(w.adc_range_v, w.full_scale_v) for w in wiring)
        self._scan_ranges = tuple(self._ranges[self._to_wiring.index(row)] for row in range(len(inputs)))
        self._wiring = tuple(wiring)
        self.serial, self._backend = serial, backend
        self._dev: Any = None
        self._cal: mcc.Calibration | None = None
        self._period = mcc.pacer_period(20480.0, len(inputs))
        self._n_samples = 65536
        self.requested_rate_hz = 20480.0
        self._reader: threading.Thread | None = None
        self._stop = threading.Event()
        self._triggered = threading.Event()
        self._finished = threading.Event()
        self._result: Record | DeviceError | None = None
        self._trigger_time = 0.0
        self.stale_scan_stopped = False  # set when open() found a scan left running and stopped it

    # ---- interface -------------------------------------------------------------------------------------
    @property
    def channels(self) -> tuple[Channel, ...]:
        """Channels in wiring order; range = the smaller of the sensor's and the input range's."""
        out = []
        for w, code in zip(self._wiring, self._ranges, strict=True):
            adc_units = mcc.RANGES_V[code] / w.channel.sensitivity_v_per_unit
            out.append(replace(w.channel, range_units=min(w.channel.range_units, adc_units)))
        return tuple(out)

    @property
    def sample_rate_hz(self) -> float:
        return mcc.actual_rate_hz(self._period)

    @property
    def n_samples(self) -> int:
        """Samples per record at the pacer's rate."""
        return self._n_samples

    def configure(self, sample_rate_hz: float, n_samples: int) -> float:
        """Set rate and record length; returns the rate the pacer divisor really gives.

        The record keeps the duration ``n_samples / sample_rate_hz`` at that rate (65 536 samples at 20 480 Hz
        asked = 3.2 s = 65 540 samples at 20 481.3 Hz); the pretrigger likewise at ``arm``.
        """
        if n_samples < 2:
            raise ValueError(f"{self.name}: n_samples = {n_samples!r}: expected at least 2")
        self._period = mcc.pacer_period(sample_rate_hz, len(self._scan))
        self.requested_rate_hz = float(sample_rate_hz)
        self._n_samples = samples_at_rate(n_samples, sample_rate_hz, self.sample_rate_hz)
        return self.sample_rate_hz

    def open(self) -> None:
        """Find and claim the unit, stop a scan a crashed program left running, then load the calibration.

        The scan is stopped first, as the maker's driver does, so the calibration is never read while the unit
        is still streaming.
        """
        if self._dev is not None:
            return
        self._dev = self._find()
        try:
            if self._status("open") & mcc.STATUS_SCAN_RUNNING:
                self._halt_scan("open")
                self.stale_scan_stopped = True
            self._cal = mcc.Calibration.from_memory(self._read_cal(self._dev))
        except (ValueError, DeviceError) as exc:
            usb.util.dispose_resources(self._dev)
            self._dev = None
            if isinstance(exc, DeviceError):
                raise
            raise DeviceError(self.name, "open", str(exc)) from None

    def close(self) -> None:
        self._stop_reader()
        if self._dev is not None:
            with contextlib.suppress(DeviceError):
                self._halt_scan("close")
            usb.util.dispose_resources(self._dev)
        self._dev = None


    def arm(self, trigger: TriggerSpec) -> None:
        """Start a continuous scan and watch it for the force crossing ``trigger.level_n``."""
        self.open()
        self._stop_reader()
        pre = samples_at_rate(trigger.pretrigger_samples, self.requested_rate_hz, self.sample_rate_hz) \
            if trigger.pretrigger_samples else 0
        detector = StreamTrigger(len(self._wiring) * 2, self._n_samples, self._force_row,
                                 replace(trigger, pretrigger_samples=pre))
        ranges = bytearray(mcc.N_CHANNELS)
        for w, code in zip(self._wiring, self._ranges, strict=True):
            ranges[self._input_number(w)] = code
        self._halt_scan("arm")
        self._control_out(mcc.AIN_CONFIG, bytes(ranges), "arm")
        mask = sum(1 << ch for ch in self._scan)
        self._control_out(mcc.AIN_SCAN_START, mcc.scan_start_packet(mask, self._period), "arm")
        self._stop.clear()
        self._triggered.clear()
        self._finished.clear()
        self._result = None
        self._reader = threading.Thread(target=self._stream, args=(detector,), name=f"{self.name} reader", daemon=True)
        self._reader.start()

    def acquire(self, timeout_s: float) -> Record:
        """Wait up to ``timeout_s`` for the trigger, then for the rest of the record."""
        if self._reader is None:
            raise DeviceError(self.name, "acquire", "not armed")
        if not self._triggered.wait(timeout_s) and not self._finished.is_set():
            self._stop_reader()
            raise DeviceTimeout(self.name, "acquire", f"no force above the trigger level within {timeout_s:g} s")
        self._finished.wait(self._n_samples / self.sample_rate_hz + 5.0)
        self._stop_reader()
        result = self._result
        if isinstance(result, DeviceError):
            raise result
        if result is None:
            raise DeviceTimeout(self.name, "acquire", "the record did not complete")
        return result

    def probe(self) -> str:
        self.open()
        serial = self._serial_number(self._dev)
        note = "; stopped a scan left running" if self.stale_scan_stopped else ""
        return (f"USB-1608FS-Plus serial {serial}, {len(self._wiring)} single-ended inputs, "
                f"calibration loaded{note}")

    def read_ranges(self) -> dict[str, float | None]:
        """Each channel's input range (± volts) as the unit reports it (AIN_CONFIG read back); None if unknown."""
        self.open()
        try:
            raw = bytes(self._dev.ctrl_transfer(mcc.REQ_IN, mcc.AIN_CONFIG, 0, 0, mcc.N_CHANNELS, _CONTROL_TIMEOUT_MS))
        except usb.core.USBError as exc:
            raise usb_error(self.name, "check", exc) from exc
        return {w.channel.name: mcc.RANGES_V.get(raw[self._input_number(w)]) for w in self._wiring}

    def settings_report(self) -> list[Finding]:
        """What the unit confirms after a record (ranges read back) and what it cannot (rate, IEPE, coupling)."""
        rows = [Finding("daq", "sample rate", f"{self.sample_rate_hz:.6g} Hz", NOT_VERIFIED,
                        f"40 MHz / ({self._period} + 1) from the pacer divisor; the unit does not report its rate")]
        asked = self.input_ranges_v
        for name, volts in self.read_ranges().items():
            ok = volts == asked[name]
            rows.append(Finding(name, "input range", f"±{volts:g} V" if volts else "unknown code",
                                VERIFIED if ok else "FAILED", "read back from the unit" if ok else
                                f"asked ±{asked[name]:g} V"))
        stage = self.conditioner or "none declared in the devices file"
        rows += [Finding("daq", "coupling", "DC, single-ended to AGND", NOT_VERIFIED,
                         "the unit has no AC coupling; the IEPE conditioner AC couples"),
                 Finding("daq", "IEPE current", f"from the conditioner: {stage}", NOT_VERIFIED,
                         "the unit supplies none; the response rows show which sensors are powered")]
        return rows

    @property
    def input_ranges_v(self) -> dict[str, float]:
        """Each channel's input range (± volts) as sent to the unit."""
        return {w.channel.name: mcc.RANGES_V[code] for w, code in zip(self._wiring, self._ranges, strict=True)}

    # ---- streaming ------------------------------------------------------------------------------------
    def _stream(self, detector: StreamTrigger) -> None:
        """Reader thread: drain the endpoint block by block into the trigger until the record is full."""
        n_ch = len(self._scan)
        scan_bytes = 2 * n_ch
        chunk = max(mcc.PACKET_BYTES, int(self.sample_rate_hz * scan_bytes * _BLOCK_S) // 64 * 64)
        timeout_ms = max(1000, int(4000 * chunk / (self.sample_rate_hz * scan_bytes)))
        sens = np.array([w.channel.sensitivity_v_per_unit for w in self._wiring])[:, None]
        pending = bytearray()
        try:
            while not (self._stop.is_set() or detector.done):
                pending.extend(self._bulk_read(chunk, timeout_ms))  # a zero-length packet adds nothing
                whole = len(pending) // scan_bytes * scan_bytes
                if not whole:
                    continue
                codes = np.frombuffer(bytes(pending[:whole]), dtype="<u2").reshape(-1, n_ch).T
                del pending[:whole]
                assert self._cal is not None
                rows = self._cal.volts(codes, self._scan, self._scan_ranges)[self._to_wiring] / sens
                at_rail = mcc.saturated_samples(codes)[self._to_wiring].astype(float)
                detector.feed(np.vstack([rows, at_rail]))
                if detector.trigger_sample is not None and not self._triggered.is_set():
                    self._trigger_time = time.time()
                    self._triggered.set()
            if detector.done:
                self._result = self._record(detector)
        except DeviceError as exc:
            self._result = exc
        finally:
            try:
                self._halt_scan("acquire")
            except DeviceError as exc:
                if not isinstance(self._result, DeviceError):
                    self._result = exc
            self._triggered.set()
            self._finished.set()

    def _record(self, detector: StreamTrigger) -> Record:
        data = detector.record()
        n = len(self._wiring)
        clipped = [w.channel.name for w, flags in zip(self._wiring, data[n:], strict=True) if flags.any()]
        return make_record(self._wiring_as_set(), data[:n], self.sample_rate_hz, detector.pre, self._trigger_time,
                           clipped)

    def _wiring_as_set(self) -> tuple[InputWiring, ...]:
        return tuple(replace(w, channel=c) for w, c in zip(self._wiring, self.channels, strict=True))

    def _bulk_read(self, size: int, timeout_ms: int) -> bytes:
        try:
            return bytes(self._dev.read(mcc.BULK_IN, size, timeout_ms))
        except usb.core.USBError as exc:
            if getattr(exc, "errno", None) == errno.ENODEV:
                raise usb_error(self.name, "acquire", exc) from exc
            status = self._status("acquire")
            if status & mcc.STATUS_SCAN_OVERRUN or getattr(exc, "errno", None) == errno.EPIPE:
                self._clear_stall()
                raise DeviceError(self.name, "acquire", "FIFO overrun: the host did not read the scan fast "
                                  "enough (fewer channels or a lower rate help)") from exc
            if not status & mcc.STATUS_SCAN_RUNNING:
                raise DeviceError(self.name, "acquire", "the scan stopped unexpectedly") from exc
            raise usb_error(self.name, "acquire", exc) from exc

    # ---- device I/O ------------------------------------------------------------------------------------
    def _find(self) -> Any:
        try:
            found = list(usb.core.find(find_all=True, idVendor=mcc.VENDOR_ID, idProduct=mcc.PRODUCT_ID,
                                       backend=self._backend))
        except usb.core.NoBackendError:
            raise DeviceError(self.name, "open", "libusb is not installed (apt install libusb-1.0-0)") from None
        if not found:
            raise DeviceDisconnected(self.name, "open", "no USB-1608FS-Plus (vendor 0x09db, product 0x00ea) "
                                     "on the USB bus")
        claimed: dict[str, Any] = {}
        refused: list[usb.core.USBError] = []
        for dev in found:
            try:
                if dev.is_kernel_driver_active(0):
                    dev.detach_kernel_driver(0)
            except (NotImplementedError, usb.core.USBError):
                pass
            try:
                dev.set_configuration()
                usb.util.claim_interface(dev, 0)
                claimed[self._serial_number(dev)] = dev
            except usb.core.USBError as exc:
                refused.append(exc)
        if not claimed:
            raise usb_error(self.name, "open", refused[0]) from refused[0]
        chosen = claimed.get(self.serial) if self.serial else next(iter(claimed.values()), None)
        if self.serial is None and len(claimed) > 1:
            chosen = None
        for dev in claimed.values():
            if dev is not chosen:
                usb.util.dispose_resources(dev)
        if chosen is None:
            raise DeviceError(self.name, "open", f"units found: {sorted(claimed)}; set daq.serial to choose one"
                              if not self.serial else f"no unit with serial {self.serial} (found {sorted(claimed)})")
        return chosen

    def _serial_number(self, dev: Any) -> str:
        raw = dev.ctrl_transfer(mcc.REQ_IN, mcc.SERIAL, 0, 0, 8, _CONTROL_TIMEOUT_MS)
        return bytes(raw).decode("ascii", errors="replace").strip("\x00 ")

    def _read_cal(self, dev: Any) -> bytes:
        raw = bytearray()
        for address in range(0, mcc.CAL_TABLE_BYTES, mcc.PACKET_BYTES):
            try:
                raw += bytes(dev.ctrl_transfer(mcc.REQ_IN, mcc.CAL_MEMORY, address, 0, mcc.PACKET_BYTES,
                                               _CONTROL_TIMEOUT_MS))
            except usb.core.USBError as exc:
                raise usb_error(self.name, "open", exc) from exc
        return bytes(raw)

    def _status(self, action: str) -> int:
        try:
            raw = bytes(self._dev.ctrl_transfer(mcc.REQ_IN, mcc.STATUS, 0, 0, 2, _CONTROL_TIMEOUT_MS))
        except usb.core.USBError as exc:
            raise usb_error(self.name, action, exc) from exc
        return int.from_bytes(raw[:2], "little")

    def _control_out(self, request: int, payload: bytes, action: str) -> None:
        try:
            self._dev.ctrl_transfer(mcc.REQ_OUT, request, 0, 0, payload, _CONTROL_TIMEOUT_MS)
        except usb.core.USBError as exc:
            raise usb_error(self.name, action, exc) from exc

    def _halt_scan(self, action: str) -> None:
        """Stop any scan, clear the FIFO and drop what the endpoint still holds."""
        self._control_out(mcc.AIN_SCAN_STOP, b"", action)
        self._control_out(mcc.AIN_CLR_FIFO, b"", action)
        self._clear_stall()
        for _ in range(mcc.FIFO_SAMPLES * 2 // mcc.PACKET_BYTES):
            try:
                if not self._dev.read(mcc.BULK_IN, mcc.PACKET_BYTES * 16, 20):
                    break
            except usb.core.USBError:
                break

    def _clear_stall(self) -> None:
        with contextlib.suppress(usb.core.USBError):
            self._dev.clear_halt(mcc.BULK_IN)

    def _stop_reader(self) -> None:
        if self._reader is not None:
            self._stop.set()
            self._reader.join()
            self._reader = None

    @staticmethod
    def _input_number(w: InputWiring) -> int:
        try:
            number = int(w.terminal)
        except ValueError:
            number = -1
        if not 0 <= number < mcc.N_CHANNELS:
            raise ValueError(f"channel {w.channel.name}: input {w.terminal!r}: the USB-1608FS-Plus has "
                             f"inputs 0-{mcc.N_CHANNELS - 1}")
        return number
