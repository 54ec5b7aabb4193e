"""Simulated instruments: thin views of one ``RigTwin`` that satisfy the interfaces of ``drivers.interfaces``.

Each is usable as soon as it is made (a simulated device needs no connection); after ``close`` or while the
twin has it unplugged, every operation raises ``DeviceDisconnected`` naming the device and the action.
"""

from __future__ import annotations

import math

from drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.interfaces import Channel, LoadReading, Record, TriggerSpec
from drivers.sim.twin import RigTwin, Strike

DEFAULT_RATE_HZ = 20_480.0
DEFAULT_SAMPLES = 65_536
MAX_SAMPLES = 1 << 24


class SimClock:
    """The twin's virtual clock: ``now`` is rig time, ``sleep`` advances it at once (nothing waits in real time).

    The engine's settling polls and deadlines run on it, so a simulated campaign takes the time of its
    computation and gives the same results for the same seed however loaded the machine is."""

    def __init__(self, twin: RigTwin) -> None:
        self.twin = twin

    def now(self) -> float:
        return self.twin.time_s

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.twin.time_s += seconds


class _SimInstrument:
    """Lifecycle shared by the simulated instruments."""

    def __init__(self, twin: RigTwin, name: str) -> None:
        self.twin, self.name, self._closed = twin, name, False

    def open(self) -> None:
        self._closed = False
        self._check("open")

    def close(self) -> None:
        self._closed = True

    def __enter__(self) -> _SimInstrument:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check(self, action: str) -> None:
        if self.name in self.twin.unplugged:
            raise DeviceDisconnected(self.name, action, "device unplugged")
        if self._closed:
            raise DeviceDisconnected(self.name, action, "device is closed")


class SimDaq(_SimInstrument):
    """Force channel ``F`` plus the rig's accelerometer channels, triggered on the force."""

    def __init__(self, twin: RigTwin, name: str = "sim-daq") -> None:
        super().__init__(twin, name)
        s = twin.settings
        self._channels = (Channel("F", "force", "N", s.force_sensitivity_v_per_n, s.force_range_n),) + tuple(
            Channel(ch, "acceleration", "m/s^2", s.accel_sensitivity_v_per_m_per_s2, s.accel_range_m_per_s2)
            for ch in twin.rig.channels
        )
        self.sample_rate_hz, self.n_samples = DEFAULT_RATE_HZ, DEFAULT_SAMPLES
        self._trigger: TriggerSpec | None = None
        self._armed_after = 0

    @property
    def channels(self) -> tuple[Channel, ...]:
        return self._channels

    def configure(self, sample_rate_hz: float, n_samples: int) -> float:
        self._check("configure")
        s = self.twin.settings
        if not (math.isfinite(sample_rate_hz) and 0 < sample_rate_hz <= s.max_sample_rate_hz):
            raise DeviceError(self.name, "configure",
                              f"sample rate {sample_rate_hz!r} Hz outside 0 < fs <= {s.max_sample_rate_hz:g} Hz")
        if not (isinstance(n_samples, int) and 16 <= n_samples <= MAX_SAMPLES):
            raise DeviceError(self.name, "configure", f"record length {n_samples!r}: expected 16..{MAX_SAMPLES}")
        if s.base_clock_hz > 0:
            sample_rate_hz = s.base_clock_hz / max(1, round(s.base_clock_hz / sample_rate_hz))
        self.sample_rate_hz, self.n_samples = float(sample_rate_hz), n_samples
        return self.sample_rate_hz

    def arm(self, trigger: TriggerSpec) -> None:
        self._check("arm")
        if not 0 <= trigger.pretrigger_samples < self.n_samples:
            raise DeviceError(self.name, "arm",
                              f"pretrigger {trigger.pretrigger_samples} samples: expected 0..{self.n_samples - 1}")
        if not trigger.level_n > 0:
            raise DeviceError(self.name, "arm", f"trigger level {trigger.level_n!r} N: expected > 0")
        self._trigger, self._armed_after = trigger, len(self.twin.strikes)

    def acquire(self, timeout_s: float) -> Record:
        """The record of the first blow since ``arm``; ``DeviceTimeout`` at once if none reached the trigger."""
        self._check("acquire")
        if self._trigger is None:
            raise DeviceError(self.name, "acquire", "not armed: call arm() before acquire()")
        trigger, self._trigger = self._trigger, None
        for strike in self.twin.strikes[self._armed_after:]:
            record = self.twin.record(strike, self.sample_rate_hz, self.n_samples, trigger)
            if record is not None:
                return record
        if timeout_s > 0 and math.isfinite(timeout_s):
            self.twin.time_s += timeout_s  # a real DAQ would have waited that long for the trigger
        raise DeviceTimeout(self.name, "acquire",
                            f"no force above {trigger.level_n:g} N within {timeout_s:g} s (no blow since arm)")


class SimHammer(_SimInstrument):
    """An automatic hammer: each ``strike`` delivers one blow to the twin."""

    def __init__(self, twin: RigTwin, name: str = "sim-hammer") -> None:
        super().__init__(twin, name)

    def strike(self) -> None:
        """One blow at the current rig time (its record's length passes on the rig clock when it is acquired)."""
        self._check("strike")
        self.last: Strike = self.twin.strike()


class SimLoadCell(_SimInstrument):
    """Total force on the three rollers, with noise, settling after a knob turn and optional creep."""

    def __init__(self, twin: RigTwin, name: str = "sim-loadcell") -> None:
        super().__init__(twin, name)

    def read(self) -> LoadReading:
        self._check("read")
        fault = self.twin.load_cell_fault()
        if fault == "timeout":
            raise DeviceTimeout(self.name, "read", f"no answer within {self.twin.settings.load_cell_read_s:g} s")
        if fault == "garbled":
            raise DeviceError(self.name, "read", "unreadable reply 'S D   ?#.2 kg'")
        force, stable = self.twin.read_load_cell()
        return LoadReading(force, stable)

    def tare(self) -> None:
        self._check("tare")
        self.twin.tare()


class SimActuator(_SimInstrument):
    """Turns the star knobs of the twin; ``knob_angle_deg`` is the total turned since the preload."""

    def __init__(self, twin: RigTwin, name: str = "sim-actuator") -> None:
        super().__init__(twin, name)

    @property
    def knob_angle_deg(self) -> float:
        return self.twin.knob_angle_deg

    def turn_knobs(self, angle_deg: float) -> None:
        self._check("turn_knobs")
        try:
            self.twin.turn_knobs(angle_deg)
        except ValueError as exc:
            raise DeviceError(self.name, "turn_knobs", str(exc)) from None
