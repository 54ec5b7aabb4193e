"""The Measurement Computing USB-1608FS-Plus at the USB level: requests, status bits, pacer, calibration.

Everything here is pure (no I/O) so the arithmetic the device implies — the pacer divisor behind the actual
sample rate, the per-range calibration slope/offset, codes to volts — is testable on its own.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

VENDOR_ID, PRODUCT_ID = 0x09DB, 0x00EA
BULK_IN = 0x81
PACKET_BYTES = 64  # full-speed bulk wMaxPacketSize
N_CHANNELS = 8  # differential inputs per unit, sampled simultaneously
PACER_CLOCK_HZ = 40e6  # the internal 32-bit pacer counts this clock: rate = 40 MHz / (period + 1)
MAX_RATE_HZ = 100e3  # per channel
FIFO_SAMPLES = 32768

# bmRequestType: vendor request to the device, host-to-device (OUT) or device-to-host (IN)
REQ_OUT, REQ_IN = 0x40, 0xC0
AIN_SCAN_START, AIN_SCAN_STOP, AIN_CONFIG, AIN_CLR_FIFO = 0x11, 0x12, 0x14, 0x15
CAL_MEMORY, STATUS, SERIAL, RESET = 0x30, 0x44, 0x48, 0x42

STATUS_SCAN_RUNNING, STATUS_SCAN_OVERRUN = 0x02, 0x04
OPTION_BLOCK_TRANSFER = 0x00
CAL_TABLE_BYTES = 8 * N_CHANNELS * 8  # per range, per channel: float32 slope, float32 intercept

RANGES_V = {0: 10.0, 1: 5.0, 2: 2.5, 3: 2.0, 4: 1.25, 5: 1.0, 6: 0.625, 7: 0.3125}  # code -> ± volts


def pacer_period(sample_rate_hz: float) -> int:
    """The divisor the device is given for ``sample_rate_hz``: round(40 MHz / rate) - 1."""
    if not (PACER_CLOCK_HZ / 2**32 < sample_rate_hz <= MAX_RATE_HZ):
        raise ValueError(f"sample rate {sample_rate_hz!r} Hz: the USB-1608FS-Plus paces "
                         f"{PACER_CLOCK_HZ / 2**32:.3g} Hz to {MAX_RATE_HZ:g} Hz per channel")
    return max(1, round(PACER_CLOCK_HZ / sample_rate_hz) - 1)


def actual_rate_hz(period: int) -> float:
    """The rate the pacer really runs at for a divisor (20 480 Hz asked → period 1952 → 20 481.3 Hz)."""
    return PACER_CLOCK_HZ / (period + 1)


def scan_start_packet(channel_mask: int, period: int, count: int = 0, options: int = OPTION_BLOCK_TRANSFER) -> bytes:
    """AIN_SCAN_START payload: scan count (0 = continuous), pacer period, channel bit mask, options."""
    return struct.pack("<IIBB", count, period, channel_mask, options)


def range_code(adc_range_v: float | None, full_scale_v: float) -> int:
    """The range code for a requested range, or the smallest range that holds ``full_scale_v``."""
    if adc_range_v is not None:
        for code, volts in RANGES_V.items():
            if math.isclose(volts, adc_range_v, rel_tol=1e-6):
                return code
        raise ValueError(f"adc_range_v = {adc_range_v!r}: the USB-1608FS-Plus ranges are ±"
                         + ", ±".join(f"{v:g}" for v in RANGES_V.values()) + " V")
    fitting = [code for code, volts in RANGES_V.items() if volts >= full_scale_v]
    return min(fitting, key=RANGES_V.__getitem__) if fitting else 0


@dataclass(frozen=True)
class Calibration:
    """Factory calibration from the device's memory: ``slope[range, channel]``, ``intercept[range, channel]``."""

    slope: np.ndarray
    intercept: np.ndarray

    @classmethod
    def from_memory(cls, raw: bytes) -> Calibration:
        """Parse the 512-byte table (range-major, channel-minor, float32 slope then intercept); ValueError if blank."""
        if len(raw) < CAL_TABLE_BYTES:
            raise ValueError(f"calibration table: got {len(raw)} bytes, expected {CAL_TABLE_BYTES}")
        table = np.frombuffer(raw[:CAL_TABLE_BYTES], dtype="<f4").reshape(8, N_CHANNELS, 2).astype(float)
        slope, intercept = table[..., 0], table[..., 1]
        if not (np.all(np.isfinite(table)) and np.all((slope > 0.5) & (slope < 1.5))
                and np.all(np.abs(intercept) < 2000)):
            raise ValueError("calibration table is blank or corrupt (recalibrate the unit with MCC's software)")
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
