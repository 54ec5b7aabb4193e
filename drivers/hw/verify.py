"""The first-day check of a real rig: one triggered record from a light tap and a few load-cell readings, and a
table of what that verified about the instruments and what it could not.

The DAQ reports its own settings (``settings_report``: the rate and ranges it really runs at, coupling, IEPE
current); this module adds what only a record shows (trigger level reached, each channel's response to the tap
and its headroom to clipping) and the load cell's reading and stability. Nothing is marked verified that was
only requested: a value read back from the device or measured in the record is ``verified``; a value labctl set
but cannot read back, or a property no tap can show (sensor sensitivity, load-cell scale), is ``not verified``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from drivers.interfaces import Channel, Daq, Hammer, LoadCell, Record, TriggerSpec

VERIFIED, NOT_VERIFIED, FAILED = "verified", "not verified", "FAILED"
RESPONSE_RATIO = 10.0  # a channel "responds" when its peak after the tap exceeds 10 × its pretrigger RMS
RESPONSE_OF_RANGE = 1e-3  # … and 0.1 % of its range (a quiet 16-bit input's pretrigger RMS can be 0)


@dataclass(frozen=True)
class Finding:
    """One row of the verification table: what was looked at, what was found, and how sure it is."""

    instrument: str
    item: str
    value: str
    status: str  # VERIFIED, NOT_VERIFIED or FAILED
    note: str = ""

    def to_dict(self) -> dict[str, str]:
        return asdict(self)


@runtime_checkable
class SelfReporting(Protocol):
    """A DAQ that can say which of its settings it read back from the device (after a record was taken)."""

    def settings_report(self) -> list[Finding]: ...


@dataclass(frozen=True)
class TapSettings:
    """The test record: rate and length asked for, the trigger, how long to wait for the tap."""

    sample_rate_hz: float = 20480.0
    record_s: float = 3.2
    trigger_level_n: float = 10.0
    pretrigger_s: float = 0.0125
    timeout_s: float = 60.0
    load_readings: int = 5
    reading_interval_s: float = 0.2

    def __post_init__(self) -> None:
        for key in ("sample_rate_hz", "record_s", "trigger_level_n", "timeout_s"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{key} = {value!r}: expected a finite positive number")
        if not 0 <= self.pretrigger_s < self.record_s:
            raise ValueError(f"pretrigger_s = {self.pretrigger_s!r}: expected 0 ≤ pretrigger < record_s")
        if self.load_readings < 2:
            raise ValueError(f"load_readings = {self.load_readings!r}: expected at least 2")


def tap_check(daq: Daq, hammer: Hammer, load_cell: LoadCell, settings: TapSettings = TapSettings(),
              *, unverifiable: Sequence[Finding] = ()) -> list[Finding]:
    """Take one triggered record and read the load cell; the table of findings (never raises a device error for
    a finding: a missing response or a clipped channel is a FAILED row). Instruments must be open."""
    n = max(2, round(settings.record_s * settings.sample_rate_hz))
    rate = daq.configure(settings.sample_rate_hz, n)
    rows = [Finding("daq", "sample rate", f"{rate:.6g} Hz", NOT_VERIFIED,
                    f"asked {settings.sample_rate_hz:g} Hz; as the driver reports it")]
    trigger = TriggerSpec(settings.trigger_level_n, round(settings.pretrigger_s * settings.sample_rate_hz))
    daq.arm(trigger)
    hammer.strike()
    record = daq.acquire(settings.timeout_s)
    if isinstance(daq, SelfReporting):
        rows = daq.settings_report()
    rows.append(Finding("daq", "record length", f"{record.force_n.size} samples = {record.force_n.size / rate:.4g} s",
                        VERIFIED, f"asked {settings.record_s:g} s"))
    rows += _record_findings(record, daq.channels, trigger)
    rows += _load_cell_findings(load_cell, settings)
    rows += list(unverifiable)
    rows += [Finding("sensors", "sensitivities", "from the devices file", NOT_VERIFIED,
                     "a tap cannot calibrate: check against a reference accelerometer or a calibrated exciter"),
             Finding("load_cell", "scale", "from the cell's own calibration", NOT_VERIFIED,
                     "put a known weight on the cell to check it")]
    return rows


def _record_findings(record: Record, channels: Sequence[Channel], trigger: TriggerSpec) -> list[Finding]:
    rows: list[Finding] = []
    force = record.force_n
    peak = float(np.max(force)) if force.size else 0.0
    crossed = record.trigger_index < force.size and force[record.trigger_index] >= trigger.level_n
    rows.append(Finding("daq", "trigger level reached", f"peak {peak:.1f} N, level {trigger.level_n:g} N",
                        VERIFIED if crossed and peak >= trigger.level_n else FAILED,
                        f"trigger at sample {record.trigger_index}"))
    by_name = {c.name: c for c in channels}
    rows_by_name = {next(c.name for c in channels if c.kind == "force"): force}
    rows_by_name.update(zip(record.channels, record.accel_m_per_s2, strict=True))
    for name, data in rows_by_name.items():
        c = by_name[name]
        pre, post = data[: record.trigger_index], data[record.trigger_index:]
        level = float(pre.mean()) if pre.size else 0.0
        noise = float(np.sqrt(np.mean((pre - level) ** 2))) if pre.size > 1 else 0.0
        extreme = float(np.max(np.abs(post - level))) if post.size else 0.0
        responds = extreme > RESPONSE_RATIO * noise and extreme > RESPONSE_OF_RANGE * c.range_units
        rows.append(Finding(name, "response to the tap", f"peak {extreme:.3g} {c.unit}, pretrigger RMS {noise:.2g}",
                            VERIFIED if responds else FAILED,
                            "" if responds else "no signal: check the cable, the IEPE current (coupling, conditioner)"
                            " and that the sensor is mounted"))
        clipped = name in record.clipped
        peak_abs = float(np.max(np.abs(data))) if data.size else 0.0
        headroom_db = 20 * math.log10(c.range_units / peak_abs) if peak_abs > 0 else math.inf
        rows.append(Finding(name, "clipping headroom", f"{headroom_db:.1f} dB below ±{c.range_units:.4g} {c.unit}",
                            FAILED if clipped else VERIFIED,
                            "clipped: a larger input range, or a smaller sensitivity" if clipped else ""))
    return rows


def _load_cell_findings(load_cell: LoadCell, settings: TapSettings) -> list[Finding]:
    readings = []
    for i in range(settings.load_readings):
        if i:
            time.sleep(settings.reading_interval_s)
        readings.append(load_cell.read())
    forces = np.array([r.force_n for r in readings])
    stable = sum(r.stable for r in readings)
    spread = float(forces.max() - forces.min())
    return [Finding("load_cell", "reading", f"{forces.mean():.2f} N", VERIFIED, f"{len(readings)} readings"),
            Finding("load_cell", "stability", f"spread {spread:.2f} N, {stable}/{len(readings)} stable",
                    VERIFIED if stable == len(readings) else FAILED,
                    "" if stable == len(readings) else "the cell reports a moving load: let the rig settle")]


def findings_ok(rows: Sequence[Finding]) -> bool:
    """True when no row FAILED (``not verified`` rows are honest gaps, not failures)."""
    return all(r.status != FAILED for r in rows)


def as_rows(rows: Sequence[Finding]) -> list[dict[str, Any]]:
    return [r.to_dict() for r in rows]
