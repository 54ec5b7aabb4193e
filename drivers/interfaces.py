"""Instrument interfaces: small Protocols the engine uses; simulated and real backends satisfy them by duck typing.

Every instrument is a context manager (``open`` on enter, ``close`` on exit) and raises only the typed errors
of ``drivers.errors``. Values are SI: N, m/s², Hz, s, degrees only for knob angles (as the operator turns them).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal, Protocol, runtime_checkable

import numpy as np

ChannelKind = Literal["force", "acceleration"]


@dataclass(frozen=True)
class Channel:
    """One DAQ input: name (``F``, ``A1X`` … ``A4Z``), physical kind, unit, sensor sensitivity and range.

    ``sensitivity_v_per_unit`` is the transducer's (V per N or V per m/s²); ``range_units`` is the largest
    magnitude the chain can record before clipping, in the physical unit.
    """

    name: str
    kind: ChannelKind
    unit: str
    sensitivity_v_per_unit: float
    range_units: float


@dataclass(frozen=True)
class TriggerSpec:
    """Start a record when the force channel rises through ``level_n``; keep ``pretrigger_samples`` before."""

    level_n: float = 20.0
    pretrigger_samples: int = 256


@dataclass
class Record:
    """One acquired impact: the force and all response channels, in physical units, at the actual rate."""

    sample_rate_hz: float
    force_n: np.ndarray  # (n_samples,)
    accel_m_per_s2: np.ndarray  # (n_channels, n_samples)
    channels: tuple[str, ...]
    trigger_index: int
    timestamp_s: float
    clipped: tuple[str, ...] = field(default=())  # channels that reached their range


@runtime_checkable
class Instrument(Protocol):
    """Lifecycle shared by every instrument."""

    name: str

    def open(self) -> None: ...
    def close(self) -> None: ...
    def __enter__(self) -> Instrument: ...
    def __exit__(self, *exc: object) -> None: ...


@runtime_checkable
class Daq(Instrument, Protocol):
    """Acquisition: a force channel and accelerometer channels, triggered on the force."""

    @property
    def channels(self) -> tuple[Channel, ...]: ...

    def configure(self, sample_rate_hz: float, n_samples: int) -> float:
        """Set the rate and record length; return the rate as actually set (a DAQ may coerce it)."""
        ...

    def arm(self, trigger: TriggerSpec) -> None:
        """Wait for the next force-trigger; the record is fetched with ``acquire``."""
        ...

    def acquire(self, timeout_s: float) -> Record:
        """Block until the armed record is complete; ``DeviceTimeout`` if no trigger within ``timeout_s``."""
        ...


@runtime_checkable
class Hammer(Instrument, Protocol):
    """Deliver one blow (manual hammers ask the operator; the DAQ's trigger catches it)."""

    def strike(self) -> None: ...


@dataclass(frozen=True)
class LoadReading:
    force_n: float
    stable: bool


@runtime_checkable
class LoadCell(Instrument, Protocol):
    def read(self) -> LoadReading: ...
    def tare(self) -> None: ...


@runtime_checkable
class DisplacementSensor(Instrument, Protocol):
    """The upper disc's displacement towards the lower one (m, positive closing), a DC average over the sensor's
    window: what the static load–displacement method reads at each load step."""

    def read(self) -> float: ...


@runtime_checkable
class LoadActuator(Instrument, Protocol):
    """Turns all star knobs together; ``knob_angle_deg`` is the total turned since the preload."""

    @property
    def knob_angle_deg(self) -> float: ...

    def turn_knobs(self, angle_deg: float) -> None: ...


OperatorAction = Literal["mount_specimen", "turn_knobs", "strike", "rotate_rollers", "unload", "confirm",
                         "review_impact"]
REVIEW_CHOICES = ("accept", "reject")


@dataclass(frozen=True)
class ImpactReview:
    """One stored blow put to the operator: where it is, and what the automatic checks said about it."""

    series: int
    run: int
    step: int
    attempt: int
    checks_accepted: bool
    reasons: tuple[str, ...]
    peak_force_n: float
    pulse_width_s: float

    def message(self) -> str:
        said = "passed the checks" if self.checks_accepted else f"flagged: {', '.join(self.reasons)}"
        return (f"series {self.series} run {self.run} step {self.step} impact {self.attempt}: {said} "
                f"(peak {self.peak_force_n:.0f} N, pulse {self.pulse_width_s * 1e3:.2f} ms); accept or reject?")


@runtime_checkable
class Operator(Protocol):
    """A person at the rig or a script: confirms instructions, chooses among options, is told things.

    ``action`` tags what the prompt asks for, so a script (or the simulated rig's operator, which rotates the
    twin's rollers on ``rotate_rollers``) can act on it without parsing the message.
    """

    def prompt(self, message: str, choices: tuple[str, ...] = ("ok",), action: OperatorAction = "confirm") -> str:
        """Show ``message``, return the chosen entry of ``choices``."""
        ...

    def notify(self, message: str) -> None: ...


@runtime_checkable
class ImpactReviewer(Protocol):
    """An operator that gives a verdict on each stored blow (optional; the engine asks only such operators,
    or ones with ``reviews_impacts = True`` through ``prompt(..., REVIEW_CHOICES, "review_impact")``).

    ``review_impact`` returns ("accept" or "reject", reason), or None to leave the checks' verdict.
    """

    def review_impact(self, review: ImpactReview) -> tuple[str, str] | None: ...


@runtime_checkable
class Clock(Protocol):
    """The rig's time: the engine waits and keeps deadlines on it, so a simulated rig runs at the speed of its
    computation (virtual time) while real instruments keep real time."""

    def now(self) -> float:
        """Seconds on a monotonic clock (any origin)."""
        ...

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` pass (a real clock waits; a virtual one advances)."""
        ...


class SystemClock:
    """Real time: ``time.monotonic`` and ``time.sleep`` (the hardware path)."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


@dataclass
class Rig:
    """The instruments of one test stand, as the engine receives them from a backend factory."""

    daq: Daq
    hammer: Hammer
    load_cell: LoadCell
    actuator: LoadActuator
    operator: Operator
    backend: str = "sim"
    description: dict[str, str] = field(default_factory=dict)
    clock: Clock = field(default_factory=SystemClock)  # real time unless the backend keeps its own
    displacement: DisplacementSensor | None = None  # only rigs that run the static method have one
