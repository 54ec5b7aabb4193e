"""A USB-1608FS-Plus behind a custom pyusb backend: real ``usb.core`` code (descriptors, configuration,
interface claiming, control and bulk transfers) runs against a device model that streams whatever a signal
source produces, in 64-byte packets of raw codes with the unit's calibration applied in reverse.

Failure injection: permission denied on open, busy interface, a scan left running, FIFO overrun (stall),
unplug (ENODEV) after some scans, zero-length packets.

The device's electrical facts are the maker's, written here independently of ``drivers.hw.mcc_protocol`` (so
a wrong table in the driver is caught, not mirrored): ``MAKER_RANGES_V`` from the USB-1608FS-Plus User's
Guide (Functional Details, "Analog input", p. 11: ±10, ±5, ±2, ±1 V) with the codes of MCC's uldaq
``AiUsb1608fsPlus::mapRangeCode`` (0, 1, 3, 5); any other code in AIN_CONFIG is refused with a stall.
Calibration slots other than 0, 1, 3, 5 are left erased (0xFF), as the maker's driver never reads them.
"""

from __future__ import annotations

import errno
import struct
import threading
import time
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import numpy as np
import usb.backend
import usb.core

from drivers.hw import mcc_protocol as mcc

MAKER_RANGES_V = {0: 10.0, 1: 5.0, 3: 2.0, 5: 1.0}  # AIN_CONFIG code -> ± volts (see the module docstring)
MAKER_MAX_AGGREGATE_HZ = 400e3  # DAQFlex hardware reference, USB-1608FS-Plus: 400 kS/s aggregate streaming
MAKER_PACER_HZ = 40e6  # Linux usb-1608FS-Plus.c, AInScanStart: pacer_period = 40 MHz / rate - 1

SignalSource = Callable[[int], np.ndarray]  # n scans -> volts (8, n), successive calls continue the stream


class PlaybackSource:
    """Quiet noise on all 8 inputs; ``play(volts)`` mixes a waveform in, starting a few scans from now."""

    def __init__(self, noise_v: float = 2e-4, seed: int = 0) -> None:
        self.noise_v = noise_v
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._queued: list[tuple[int, np.ndarray]] = []
        self.produced = 0

    def play(self, volts: np.ndarray, delay_scans: int = 200) -> None:
        with self._lock:
            self._queued.append((self.produced + delay_scans, np.asarray(volts, dtype=float)))

    def __call__(self, n: int) -> np.ndarray:
        with self._lock:
            start, self.produced = self.produced, self.produced + n
            out = self.noise_v * self._rng.standard_normal((mcc.N_CHANNELS, n))
            for begin, wave in self._queued:
                lo, hi = max(begin, start), min(begin + wave.shape[1], start + n)
                if lo < hi:
                    out[: wave.shape[0], lo - start:hi - start] += wave[:, lo - begin:hi - begin]
            self._queued = [(b, w) for b, w in self._queued if b + w.shape[1] > start + n]
        return out


def default_calibration() -> tuple[np.ndarray, np.ndarray]:
    """Slopes and intercepts like a real unit's: close to 1 and 0 in the range slots, erased (NaN) elsewhere."""
    grid = np.arange(8)[:, None] * 8 + np.arange(8)[None, :]
    slope, intercept = 1.0 + 1e-3 * np.sin(grid), 3.0 * np.cos(grid)
    unused = [slot for slot in range(8) if slot not in MAKER_RANGES_V]
    slope[unused] = intercept[unused] = np.nan  # 0xFFFFFFFF as float32
    return slope, intercept


class FakeMcc1608:
    """Device model: vendor requests, status, calibration memory, the scan and the bulk IN stream."""

    def __init__(self, source: SignalSource | None = None, *, serial: str = "01D2B3A4", address: int = 5) -> None:
        self.source = source or PlaybackSource()
        self.serial, self.address = serial, address
        self.slope, self.intercept = default_calibration()
        self.ranges = [0] * 8
        self.running = False
        self.overrun = False
        self.stalled = False
        self.mask, self.period, self.count = 0, 0, 0
        self.log: list[str] = []
        self.scans_sent = 0
        self._out = bytearray()
        self._reads = 0
        # failure injection
        self.open_errno: int | None = None
        self.claim_errno: int | None = None
        self.overrun_after_scans: int | None = None
        self.unplug_after_scans: int | None = None
        self.zlp_every: int | None = None
        self.unplugged = False
        self.pace_s = 0.0002  # per bulk read: lets other threads run while the stream idles

    def leave_scan_running(self) -> None:
        """As after a crashed program: a scan running, its data waiting."""
        self.running, self.mask, self.period = True, 0xFF, round(MAKER_PACER_HZ / 1000.0) - 1
        self._out.extend(b"\x00\x80" * 512)

    # ---- USB requests ------------------------------------------------------------------------------------
    def control(self, request_type: int, request: int, value: int, index: int, data: Any) -> bytes | int:
        self._check_plugged()
        if request_type & 0x80:
            reply = self._control_in(request, value, len(data))
            data[: len(reply)] = type(data)(data.typecode, reply)
            return len(reply)
        payload = bytes(data)
        self._control_out(request, payload)
        return len(payload)

    def _control_in(self, request: int, value: int, length: int) -> bytes:
        if request == mcc.STATUS:
            bits = (mcc.STATUS_SCAN_RUNNING if self.running else 0) | (mcc.STATUS_SCAN_OVERRUN if self.overrun else 0)
            return struct.pack("<H", bits)
        if request == mcc.SERIAL:
            return self.serial.encode("ascii")[:8].ljust(8, b"\x00")
        if request == mcc.CAL_MEMORY:
            self.log.append("CAL" + (" (scan running)" if self.running else ""))
            table = np.stack([self.slope, self.intercept], axis=-1).astype("<f4").tobytes()
            return (table + b"\xff" * 768)[value:value + length]
        if request == mcc.AIN_CONFIG:
            return bytes(self.ranges)
        raise usb.core.USBError("Pipe error", -9, errno.EPIPE)

    def _control_out(self, request: int, payload: bytes) -> None:
        names = {mcc.AIN_SCAN_START: "START", mcc.AIN_SCAN_STOP: "STOP", mcc.AIN_CONFIG: "CONFIG",
                 mcc.AIN_CLR_FIFO: "CLEAR_FIFO"}
        self.log.append(names.get(request, hex(request)))
        if request == mcc.AIN_SCAN_START:
            if self.running:
                raise usb.core.USBError("Pipe error", -9, errno.EPIPE)  # the unit stalls: scan already running
            self.count, self.period, self.mask, _ = struct.unpack("<IIBB", payload)
            self.running, self.overrun, self.stalled = True, False, False
        elif request == mcc.AIN_SCAN_STOP:
            self.running = False
        elif request == mcc.AIN_CLR_FIFO:
            self._out.clear()
        elif request == mcc.AIN_CONFIG:
            if self.running or any(code not in MAKER_RANGES_V for code in payload[:8]):
                raise usb.core.USBError("Pipe error", -9, errno.EPIPE)  # a code the unit does not have: stall
            self.ranges = list(payload[:8])

    def bulk_in(self, size: int) -> bytes:
        self._check_plugged()
        self._reads += 1
        time.sleep(self.pace_s)
        if self.stalled:
            raise usb.core.USBError("Pipe error", -9, errno.EPIPE)
        if self.zlp_every and self._reads % self.zlp_every == 0:
            return b""
        if self.running:
            self._stream(size)
        if not self._out:
            raise usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)
        take = min(len(self._out), size // mcc.PACKET_BYTES * mcc.PACKET_BYTES or len(self._out))
        chunk, self._out[:take] = bytes(self._out[:take]), b""
        return chunk

    def _stream(self, size: int) -> None:
        channels = [ch for ch in range(8) if self.mask >> ch & 1]
        scans = max(1, (size - len(self._out)) // (2 * len(channels)) + 1)
        if self.unplug_after_scans is not None and self.scans_sent + scans > self.unplug_after_scans:
            self.unplugged = True
            self._check_plugged()
        if self.overrun_after_scans is not None and self.scans_sent + scans > self.overrun_after_scans:
            self.running, self.overrun, self.stalled = False, True, True
            raise usb.core.USBError("Pipe error", -9, errno.EPIPE)
        rate = MAKER_PACER_HZ / (self.period + 1)
        if rate * len(channels) > MAKER_MAX_AGGREGATE_HZ:  # the host cannot drain it: the FIFO overruns
            self.overrun_after_scans = self.scans_sent if self.overrun_after_scans is None else \
                self.overrun_after_scans
        volts = self.source(scans)[channels]
        ranges = np.array([MAKER_RANGES_V[self.ranges[ch]] for ch in channels])[:, None]
        ideal = volts / ranges * 32768.0 + 32768.0
        slope = np.array([self.slope[self.ranges[ch], ch] for ch in channels])[:, None]
        intercept = np.array([self.intercept[self.ranges[ch], ch] for ch in channels])[:, None]
        raw = np.clip(np.rint((ideal - intercept) / slope), 0, 65535).astype("<u2")
        self._out.extend(raw.T.tobytes())
        self.scans_sent += scans

    def _check_plugged(self) -> None:
        if self.unplugged:
            raise usb.core.USBError("No such device (it may have been disconnected)", -4, errno.ENODEV)


def _descriptor(**fields: Any) -> SimpleNamespace:
    return SimpleNamespace(extra_descriptors=[], **fields)


class FakeUsbBackend(usb.backend.IBackend):
    """The pyusb backend interface over a list of fake devices (pass to ``usb.core.find(backend=...)``)."""

    def __init__(self, *devices: FakeMcc1608) -> None:
        super().__init__()
        self.devices = list(devices)
        self.claimed: set[int] = set()

    def enumerate_devices(self) -> list[FakeMcc1608]:
        return [d for d in self.devices if not d.unplugged]

    def get_device_descriptor(self, dev: FakeMcc1608) -> SimpleNamespace:
        return _descriptor(bLength=18, bDescriptorType=1, bcdUSB=0x0200, bDeviceClass=0, bDeviceSubClass=0,
                           bDeviceProtocol=0, bMaxPacketSize0=64, idVendor=mcc.VENDOR_ID, idProduct=mcc.PRODUCT_ID,
                           bcdDevice=0x0100, iManufacturer=0, iProduct=0, iSerialNumber=0, bNumConfigurations=1,
                           address=dev.address, bus=1, port_number=dev.address, port_numbers=(dev.address,),
                           speed=2)

    def get_configuration_descriptor(self, dev: FakeMcc1608, config: int) -> SimpleNamespace:
        if config != 0:
            raise IndexError(config)
        return _descriptor(bLength=9, bDescriptorType=2, wTotalLength=25, bNumInterfaces=1, bConfigurationValue=1,
                           iConfiguration=0, bmAttributes=0x80, bMaxPower=50)

    def get_interface_descriptor(self, dev: FakeMcc1608, intf: int, alt: int, config: int) -> SimpleNamespace:
        if intf != 0 or alt != 0:
            raise IndexError((intf, alt))
        return _descriptor(bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0, bNumEndpoints=1,
                           bInterfaceClass=0xFF, bInterfaceSubClass=0, bInterfaceProtocol=0, iInterface=0)

    def get_endpoint_descriptor(self, dev: FakeMcc1608, ep: int, intf: int, alt: int, config: int) -> SimpleNamespace:
        if ep != 0:
            raise IndexError(ep)
        return _descriptor(bLength=7, bDescriptorType=5, bEndpointAddress=mcc.BULK_IN, bmAttributes=0x02,
                           wMaxPacketSize=mcc.PACKET_BYTES, bInterval=0, bRefresh=0, bSynchAddress=0)

    def open_device(self, dev: FakeMcc1608) -> FakeMcc1608:
        dev._check_plugged()
        if dev.open_errno is not None:
            raise usb.core.USBError("Access denied (insufficient permissions)", -3, dev.open_errno)
        return dev

    def close_device(self, handle: FakeMcc1608) -> None:
        self.claimed.discard(id(handle))

    def set_configuration(self, handle: FakeMcc1608, config_value: int) -> None:
        handle._check_plugged()

    def get_configuration(self, handle: FakeMcc1608) -> int:
        return 1

    def claim_interface(self, handle: FakeMcc1608, intf: int) -> None:
        handle._check_plugged()
        if handle.claim_errno is not None:
            raise usb.core.USBError("Resource busy", -6, handle.claim_errno)
        self.claimed.add(id(handle))

    def release_interface(self, handle: FakeMcc1608, intf: int) -> None:
        self.claimed.discard(id(handle))

    def is_kernel_driver_active(self, handle: FakeMcc1608, intf: int) -> bool:
        return False

    def ctrl_transfer(self, handle: FakeMcc1608, bmRequestType: int, bRequest: int, wValue: int, wIndex: int,
                      data: Any, timeout: int) -> int:
        return handle.control(bmRequestType, bRequest, wValue, wIndex, data)

    def bulk_read(self, handle: FakeMcc1608, ep: int, intf: int, buff: Any, timeout: int) -> int:
        if ep != mcc.BULK_IN:
            raise usb.core.USBError("Invalid parameter", -2, errno.EINVAL)
        chunk = handle.bulk_in(len(buff) * buff.itemsize)
        buff[: len(chunk)] = type(buff)(buff.typecode, chunk)
        return len(chunk)

    def clear_halt(self, handle: FakeMcc1608, ep: int) -> None:
        handle._check_plugged()
        handle.stalled = False
