"""The Measurement Computing USB-1608FS-Plus at the USB level: requests, status bits, pacer, calibration.

Everything here is pure (no I/O) so the arithmetic the device implies — the pacer divisor behind the actual
sample rate, the per-range calibration slope/offset, codes to volts — is testable on its own. Every number is
the maker's (docs/hardware.md, "USB-1608FS-Plus facts", cites the User's Guide, MCC's DAQFlex hardware
reference and MCC's uldaq driver for each); none is inferred from this driver's own behaviour.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

VENDOR_ID, PRODUCT_ID = 0x09DB, 0x00EA
BULK_IN = 0x81
PACKET_BYTES = 64  # full-speed bulk wMaxPacketSize
N_CHANNELS = 8  # single-ended inputs per unit (referenced to AGND), sampled simultaneously
PACER_CLOCK_HZ = 40e6  # the internal 32-bit pacer counts this clock: rate = 40 MHz / (period + 1)
MAX_RATE_HZ = 100e3  # per channel
MAX_AGGREGATE_HZ = 400e3  # all scanned channels together, streaming (the USB transfer limit)
FIFO_SAMPLES = 32768

# bmRequestType: vendor request to the device, host-to-device (OUT) or device-to-host (IN)
REQ_OUT, REQ_IN = 0x40, 0xC0
AIN_SCAN_START, AIN_SCAN_STOP, AIN_CONFIG, AIN_CLR_FIFO = 0x11, 0x12, 0x14, 0x15
CAL_MEMORY, STATUS, SERIAL, RESET = 0x30, 0x44, 0x48, 0x42

STATUS_SCAN_RUNNING, STATUS_SCAN_OVERRUN = 0x02, 0x04
OPTION_BLOCK_TRANSFER = 0x00
CAL_SLOTS = 8  # the calibration memory holds 8 gain slots × 8 channels of (float32 slope, float32 intercept)
CAL_TABLE_BYTES = CAL_SLOTS * N_CHANNELS * 8

# The unit's input ranges: AIN_CONFIG code -> ± volts. The codes are not contiguous (2, 4, 6, 7 are the older
# USB-1608FS's ±2.5/±1.25/±0.625/±0.3125 V, which this unit does not have); a range's code is also its slot in
# the calibration memory, so only slots 0, 1, 3, 5 hold coefficients the maker's driver uses.
RANGES_V = {0: 10.0, 1: 5.0, 3: 2.0, 5: 1.0}


def pacer_period(sample_rate_hz: float, n_channels: int = 1) -> int:
    """The divisor the device is given for ``sample_rate_hz``: round(40 MHz / rate) - 1.

    ValueError if the rate is outside the pacer's span or ``n_channels`` at that rate exceed the aggregate limit.
    """
    if not (PACER_CLOCK_HZ / 2**32 < sample_rate_hz <= MAX_RATE_HZ):
        raise ValueError(f"sample rate {sample_rate_hz!r} Hz: the USB-1608FS-Plus paces "
                         f"{PACER_CLOCK_HZ / 2**32:.3g} Hz to {MAX_RATE_HZ:g} Hz per channel")
    period = max(1, round(PACER_CLOCK_HZ / sample_rate_hz) - 1)
    if actual_rate_hz(period) * n_channels > MAX_AGGREGATE_HZ:
        raise ValueError(f"sample rate {sample_rate_hz:g} Hz × {n_channels} channels = "
                         f"{sample_rate_hz * n_channels:g} S/s: the USB-1608FS-Plus streams at most "
                         f"{MAX_AGGREGATE_HZ:g} S/s in all (at most {MAX_AGGREGATE_HZ / n_channels:g} Hz "
                         f"for {n_channels} channels)")
    return period


def actual_rate_hz(period: int) -> float:
    """The rate the pacer really runs at for a divisor (20 480 Hz asked → period 1952 → 20 481.3 Hz)."""
    return PACER_CLOCK_HZ / (period + 1)


def scan_start_packet(channel_mask: int, period: int, count: int = 0, options: int = OPTION_BLOCK_TRANSFER) -> bytes:
    """AIN_SCAN_START payload: scan count (0 = continuous), pacer period, channel bit mask, options."""
    return struct.pack("<IIBB", count, period, channel_mask, options)


def range_code(adc_range_v: float | None, full_scale_v: float) -> int:
    """The range code for a requested range, or the smallest range that holds ``full_scale_v`` (±10 V if none)."""
    if adc_range_v is not None:
        for code, volts in RANGES_V.items():
            if math.isclose(volts, adc_range_v, rel_tol=1e-6):
                return code
        raise ValueError(f"adc_range_v = {adc_range_v!r}: the USB-1608FS-Plus ranges are ±"
                         + ", ±".join(f"{v:g}" for v in RANGES_V.values()) + " V")
    fitting = [code for code, volts in RANGES_V.items() if volts >= full_scale_v * (1 - 1e-9)]  # 5 V fits ±5 V
    return min(fitting, key=RANGES_V.__getitem__) if fitting else 0


@dataclass(frozen=True)
class Calibration:
    """Factory calibration from the device's memory: ``slope[range, channel]``, ``intercept[range, channel]``."""

    slope: np.ndarray
    intercept: np.ndarray

    @classmethod
    def from_memory(cls, raw: bytes) -> Calibration:
        """Parse the 512-byte table (slot-major, channel-minor, float32 slope then intercept).

        Only the slots of the unit's ranges (0, 1, 3, 5) are checked: the others are unused and may be blank on a
        healthy unit. ValueError naming the slot if a used one is blank or corrupt.
        """
        if len(raw) < CAL_TABLE_BYTES:
            raise ValueError(f"calibration table: got {len(raw)} bytes, expected {CAL_TABLE_BYTES}")
        table = np.frombuffer(raw[:CAL_TABLE_BYTES], dtype="<f4").reshape(CAL_SLOTS, N_CHANNELS, 2).astype(float)
        slope, intercept = table[..., 0], table[..., 1]
        for code, volts in RANGES_V.items():
            s, i = slope[code], intercept[code]
            if not (np.all(np.isfinite(table[code])) and np.all((s > 0.5) & (s < 1.5)) and np.all(np.abs(i) < 2000)):
                raise ValueError(f"calibration of the ±{volts:g} V range (slot {code}) is blank or corrupt "
                                 "(recalibrate the unit with MCC's software)")
        return cls(slope, intercept)

    def volts(self, codes: np.ndarray, channels: tuple[int, ...], ranges: tuple[int, ...]) -> np.ndarray:
        """Raw codes (n_ch, n) of the scanned ``channels`` at ``ranges`` → calibrated volts."""
        out = np.empty(codes.shape, dtype=float)
        for row, (ch, code) in enumerate(zip(channels, ranges, strict=True)):
            corrected = np.clip(codes[row] * self.slope[code, ch] + self.intercept[code, ch], 0.0, 65535.0)
            out[row] = (corrected - 32768.0) * RANGES_V[code] / 32768.0
        return out


def saturated_samples(codes: np.ndarray) -> np.ndarray:
    """True where a raw code sits at either end of the converter (the input itself clipped)."""
    return (codes == 0) | (codes == 65535)
