"""MCC USB-1608FS-Plus as a pyusb backend, written from the maker's protocol facts (tests/emulators/MAKER_FACTS.md).

``usb.core.find(idVendor=0x09DB, idProduct=0x00EA, backend=Usb1608FsPlusBackend(...))`` finds it; it answers the
vendor control requests, streams scans on bulk endpoint 0x81 in 64-byte packets (zero-length packet after a
transfer that is a whole number of packets), decodes range codes to full scales as the unit does, and stalls
what the unit refuses. The physical input is a callable ``volts(channel, t_s) -> V``; time is virtual (scan
sample ``k`` is taken at ``t_trigger + k / rate``) so tests are deterministic.
"""

from __future__ import annotations

import errno
import math
import struct
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import usb.backend
import usb.core

VENDOR_ID = 0x09DB
PRODUCT_ID = 0x00EA
BULK_IN_EP = 0x81
MAX_PACKET = 64
N_CHANNELS = 8
N_GAIN_SLOTS = 8
CLOCK_HZ = 40_000_000
MAX_PACER_HZ = 100_000.0
MAX_STREAM_AGGREGATE_HZ = 400_000.0
FIFO_SAMPLES = 32_768
CAL_MEMORY_BYTES = 0x300
CAL_DATE_ADDR = 0x200
USER_MEMORY_BYTES = 0x100

# range code -> full scale (V); the unit's only ranges (codes 2, 4, 6, 7 are slots of the 8-slot table it never uses)
RANGE_FULL_SCALE_V = {0: 10.0, 1: 5.0, 3: 2.0, 5: 1.0}

# vendor requests
DTRISTATE, DPORT, DLATCH = 0x00, 0x01, 0x02
AIN, AIN_SCAN_START, AIN_SCAN_STOP, AIN_CONFIG, AIN_CLR_FIFO = 0x10, 0x11, 0x12, 0x14, 0x15
COUNTER = 0x20
CAL_MEMORY, USER_MEMORY = 0x30, 0x31
BLINK_LED, RESET, STATUS, SERIAL = 0x41, 0x42, 0x44, 0x48

STATUS_SCAN_RUNNING = 1 << 1
STATUS_SCAN_OVERRUN = 1 << 2

OPT_IMMEDIATE = 1 << 0
OPT_DEBUG = 1 << 5
OPT_INHIBIT_STALL = 1 << 7

Volts = Callable[[int, float], float]


def _pipe_error() -> usb.core.USBError:
    """What libusb reports for a STALL handshake (LIBUSB_ERROR_PIPE)."""
    return usb.core.USBError("Pipe error", -9, errno.EPIPE)


def _timeout_error() -> usb.core.USBTimeoutError:
    return usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)


@dataclass
class Calibration:
    """Per (range code, channel) correction the host applies: corrected = raw * slope + offset (in counts)."""

    slope: dict[tuple[int, int], float] = field(default_factory=dict)
    offset: dict[tuple[int, int], float] = field(default_factory=dict)

    @classmethod
    def typical(cls) -> Calibration:
        """Distinct, plausible coefficients per slot so a driver that reads the wrong slot reads wrong volts."""
        cal = cls()
        for code in RANGE_FULL_SCALE_V:
            for ch in range(N_CHANNELS):
                cal.slope[(code, ch)] = 1.0 + 0.0015 * (code + 1) + 0.0002 * ch
                cal.offset[(code, ch)] = -12.0 * (code + 1) + 3.0 * ch
        return cal

    def memory(self) -> bytearray:
        """Cal memory image: slot i, channel j at 8*(8*i + j): float32 slope then float32 offset (little endian).
        Slots of codes the unit does not use stay erased (0xFF bytes)."""
        mem = bytearray(b"\xff" * CAL_MEMORY_BYTES)
        for code in RANGE_FULL_SCALE_V:
            for ch in range(N_CHANNELS):
                addr = 8 * (N_CHANNELS * code + ch)
                mem[addr : addr + 8] = struct.pack("<ff", self.slope[(code, ch)], self.offset[(code, ch)])
        mem[CAL_DATE_ADDR : CAL_DATE_ADDR + 6] = bytes([24, 3, 14, 10, 30, 0])  # year-2000, month, day, h, m, s
        return mem


@dataclass
class _Scan:
    channels: list[int]
    count: int  # scans; 0 = continuous
    rate_hz: float
    options: int
    t0_s: float
    next_scan: int = 0
    overrun_at: int | None = None  # scan index at which the FIFO overflows


class Usb1608FsPlus:
    """Device state: registers, memories, the running scan and its pending bulk packets."""

    def __init__(self, volts: Volts, *, serial: str = "01F2A3B4", calibration: Calibration | None = None,
                 trigger_time_s: float | None = 0.0, noise_counts: float = 0.0) -> None:
        self.volts = volts
        self.serial = serial.encode("ascii")[:8].ljust(8, b"0")
        self.calibration = calibration or Calibration.typical()
        self.cal_memory = self.calibration.memory()
        self.user_memory = bytearray(USER_MEMORY_BYTES)
        self.trigger_time_s = trigger_time_s  # external trigger input; None = never arrives
        self.noise_counts = noise_counts
        self.ranges = [0] * N_CHANNELS
        self.tristate, self.latch, self.counter = 0xFF, 0x00, 0
        self.status = 0
        self.scan: _Scan | None = None
        self.packets: deque[bytes] = deque()
        self.halted = False
        self.blinks = 0
        self.requests: list[tuple[int, int, int, int, int]] = []  # (bmRequestType, bRequest, wValue, wIndex, len)

    # -- conversion --------------------------------------------------------------------------------------------
    def raw_code(self, channel: int, code: int, t_s: float) -> int:
        """The unit's 16-bit offset-binary code: ideal = v/FS*32768 + 32768, seen through its calibration error."""
        full_scale = RANGE_FULL_SCALE_V[code]
        ideal = self.volts(channel, t_s) / full_scale * 32768.0 + 32768.0
        if self.noise_counts:
            ideal += self.noise_counts * math.sin(1e4 * t_s + channel)  # deterministic dither
        raw = (ideal - self.calibration.offset[(code, channel)]) / self.calibration.slope[(code, channel)]
        return int(min(65535, max(0, round(raw))))

    # -- control requests ----------------------------------------------------------------------------------------
    def control_in(self, request: int, value: int, index: int, length: int) -> bytes:
        running = self.status & STATUS_SCAN_RUNNING
        if request == AIN:
            if running or value >= N_CHANNELS or index not in RANGE_FULL_SCALE_V:
                raise _pipe_error()
            return struct.pack("<H", self.raw_code(value, index, 0.0))
        if request == AIN_CONFIG:
            if running:  # "reads or writes … will result in a bus stall if an AIn scan is currently running"
                raise _pipe_error()
            return bytes(self.ranges)
        if request == STATUS:
            return struct.pack("<H", self.status)
        if request == CAL_MEMORY:
            if value + length > CAL_MEMORY_BYTES:
                raise _pipe_error()
            return bytes(self.cal_memory[value : value + length])
        if request == USER_MEMORY:
            if value + length > USER_MEMORY_BYTES:
                raise _pipe_error()
            return bytes(self.user_memory[value : value + length])
        if request == SERIAL:
            return self.serial
        if request == COUNTER:
            return struct.pack("<I", self.counter)
        if request == DTRISTATE:
            return bytes([self.tristate])
        if request in (DPORT, DLATCH):
            return bytes([self.latch])
        raise _pipe_error()

    def control_out(self, request: int, value: int, index: int, data: bytes) -> None:
        running = self.status & STATUS_SCAN_RUNNING
        if request == AIN_CONFIG:
            if running or len(data) != N_CHANNELS or any(c not in RANGE_FULL_SCALE_V for c in data):
                raise _pipe_error()
            self.ranges = list(data)
        elif request == AIN_SCAN_START:
            if running or len(data) != 10:
                raise _pipe_error()
            self._start_scan(data)
        elif request == AIN_SCAN_STOP:
            self._stop_scan()
        elif request == AIN_CLR_FIFO:
            self.packets.clear()
        elif request == BLINK_LED:
            self.blinks += data[0] if data else 1
        elif request == RESET:
            self.__init__(self.volts, serial=self.serial.decode(), calibration=self.calibration,
                          trigger_time_s=self.trigger_time_s, noise_counts=self.noise_counts)
        elif request == COUNTER:
            self.counter = 0
        elif request == DTRISTATE:
            self.tristate = value & 0xFF
        elif request == DLATCH:
            self.latch = value & 0xFF
        elif request == USER_MEMORY:
            if value + len(data) > USER_MEMORY_BYTES:
                raise _pipe_error()
            self.user_memory[value : value + len(data)] = data
        else:  # includes CAL_MEMORY writes without the unlock sequence: the memory is write protected
            raise _pipe_error()

    # -- scans -------------------------------------------------------------------------------------------------
    def _start_scan(self, data: bytes) -> None:
        count, pacer_period, mask, options = struct.unpack("<IIBB", data)
        channels = [ch for ch in range(N_CHANNELS) if mask >> ch & 1]
        if not channels or pacer_period == 0:  # external clock (SYNC input) is not emulated
            raise _pipe_error()
        rate_hz = CLOCK_HZ / (pacer_period + 1)
        if rate_hz > MAX_PACER_HZ * (1 + 1e-9):
            raise _pipe_error()
        trig_mode = options >> 2 & 0x7
        if trig_mode > 4:
            raise _pipe_error()
        t0 = 0.0 if trig_mode == 0 else self.trigger_time_s
        scan = _Scan(channels, count, rate_hz, options, t0 if t0 is not None else math.inf)
        aggregate = rate_hz * len(channels)
        total = count * len(channels) if count else math.inf
        if aggregate > MAX_STREAM_AGGREGATE_HZ and total > FIFO_SAMPLES:
            # the FIFO fills at (aggregate - 400 kS/s); it holds 32768 samples
            samples = FIFO_SAMPLES / (1.0 - MAX_STREAM_AGGREGATE_HZ / aggregate)
            scan.overrun_at = int(samples // len(channels))
        self.scan = scan
        self.packets.clear()
        self.halted = False
        self.status = STATUS_SCAN_RUNNING

    def _stop_scan(self) -> None:
        self.scan = None
        self.status &= ~STATUS_SCAN_RUNNING

    def _produce(self, wanted_bytes: int) -> None:
        """Queue packets until ``wanted_bytes`` are pending or the scan ends."""
        while self.scan is not None and sum(map(len, self.packets)) < wanted_bytes:
            scan = self.scan
            if not math.isfinite(scan.t0_s):
                return  # trigger never came: no packets
            if scan.overrun_at is not None and scan.next_scan >= scan.overrun_at:
                self.status = (self.status | STATUS_SCAN_OVERRUN) & ~STATUS_SCAN_RUNNING
                self.scan = None
                if not scan.options & OPT_INHIBIT_STALL:
                    self.halted = True
                return
            per_packet = 1 if scan.options & OPT_IMMEDIATE else MAX_PACKET // (2 * len(scan.channels)) or 1
            buf = bytearray()
            for _ in range(per_packet):
                if scan.count and scan.next_scan >= scan.count:
                    break
                k = scan.next_scan
                t = scan.t0_s + k / scan.rate_hz
                for i, ch in enumerate(scan.channels):
                    if scan.options & OPT_DEBUG:
                        buf += struct.pack("<H", (k * len(scan.channels) + i) & 0xFFFF)
                    else:
                        buf += struct.pack("<H", self.raw_code(ch, self.ranges[ch], t))
                scan.next_scan += 1
            self._queue_bytes(bytes(buf), scan.options & OPT_IMMEDIATE)
            if scan.count and scan.next_scan >= scan.count:
                total = scan.count * len(scan.channels) * 2
                if not scan.options & OPT_IMMEDIATE and total % MAX_PACKET == 0:
                    self.packets.append(b"")  # zero-length packet ends a whole-packet transfer
                self._stop_scan()

    def _queue_bytes(self, data: bytes, immediate: int) -> None:
        if immediate:
            if data:
                self.packets.append(data)
            return
        # block mode: a continuous byte stream cut into 64-byte packets
        tail = self.packets.pop() if self.packets and len(self.packets[-1]) < MAX_PACKET else b""
        stream = tail + data
        for i in range(0, len(stream), MAX_PACKET):
            self.packets.append(stream[i : i + MAX_PACKET])

    def bulk_in(self, length: int) -> bytes:
        """One bulk IN transfer: whole packets until ``length`` is reached or a short packet ends it."""
        if self.halted:
            raise _pipe_error()
        self._produce(length + MAX_PACKET)
        if not self.packets:
            if self.halted:
                raise _pipe_error()
            raise _timeout_error()
        out = bytearray()
        while self.packets and len(out) < length:
            packet = self.packets[0]
            if len(packet) > length - len(out):
                if not out:
                    raise usb.core.USBError("Overflow", -8, errno.EOVERFLOW)
                break
            out += self.packets.popleft()
            if len(packet) < MAX_PACKET:
                break
            if len(out) < length:
                self._produce(length - len(out) + MAX_PACKET)
        return bytes(out)
