"""Typed events the engine emits at every stage, and the bus that delivers them.

Events carry the records themselves (the stored impact, the step result), not copies of their fields.

Subscribers (TUI, CLI progress, logging) receive each event in the engine's thread; one that raises is logged
and skipped, never stopping the run.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from labctl.storage.records import ImpactRecord, StepFrf, StepResult

log = logging.getLogger("labctl.events")


@dataclass(frozen=True)
class Event:
    """Base of all engine events; ``time_s`` is the engine's monotonic clock since the campaign started."""

    time_s: float


@dataclass(frozen=True)
class Position:
    """Where in the campaign: specimen series, repetition (run), load step and impact, all 1-based."""

    series: int
    run: int
    step: int = 0
    impact: int = 0


@dataclass(frozen=True)
class CampaignStarted(Event):
    protocol: str
    path: str
    backend: str
    series_total: int
    runs_per_series: int
    steps_estimate: tuple[int, ...]  # per series
    impacts_per_step: int
    resumed: bool = False


@dataclass(frozen=True)
class RunStarted(Event):
    position: Position
    specimen: str


@dataclass(frozen=True)
class StepStarted(Event):
    position: Position
    steps_total: int
    knob_angle_deg: float
    expected_load_n: float


@dataclass(frozen=True)
class LoadMeasured(Event):
    position: Position
    load_n: float  # per roller
    stable: bool


@dataclass(frozen=True)
class ImpactAcquired(Event):
    """A blow was stored and passed its checks; ``impact`` is the record as stored (traces in physical units)."""

    position: Position
    impact: ImpactRecord = field(repr=False)
    range_use: dict[str, float] = field(default_factory=dict)  # channel → peak of this blow / channel range

    @property
    def attempt(self) -> int:
        return self.impact.attempt

    @property
    def accepted(self) -> bool:
        return self.impact.accepted

    @property
    def reasons(self) -> tuple[str, ...]:
        return self.impact.info.reasons

    @property
    def peak_force_n(self) -> float:
        return self.impact.info.checks.peak_force_n

    @property
    def pulse_width_s(self) -> float:
        return self.impact.info.checks.pulse_width_s

    @property
    def sample_rate_hz(self) -> float:
        return self.impact.sample_rate_hz

    @property
    def force_n(self) -> np.ndarray:
        return self.impact.force_n

    @property
    def accel_m_per_s2(self) -> np.ndarray:
        return self.impact.accel_m_per_s2

    @property
    def channels(self) -> tuple[str, ...]:
        return self.impact.channels


@dataclass(frozen=True)
class ImpactRejected(ImpactAcquired):
    """An impact failed a check (``reasons``); it is kept in the file and the engine hits again."""


@dataclass(frozen=True)
class StepProcessed(Event):
    """A step was identified; ``result`` is the step result as stored (with its FRF), ``load_n`` per roller."""

    position: Position
    load_n: float
    result: StepResult = field(repr=False)

    @property
    def bounce_hz(self) -> float:
        return self.result.bounce_hz

    @property
    def tilt_hz(self) -> tuple[float, ...]:
        return tuple(self.result.tilt_hz)

    @property
    def roller_stiffness_n_per_m(self) -> float:
        return self.result.roller_stiffness_n_per_m

    @property
    def roller_stiffness_std_n_per_m(self) -> float:
        return self.result.roller_stiffness_std_n_per_m

    @property
    def coherence_at_bounce(self) -> float:
        return self.result.coherence_at_bounce

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.result.channels)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return self._frf.frequencies_hz

    @cached_property
    def h1_magnitude(self) -> np.ndarray:
        """|H1| per channel (n_ch, n_f), computed once per event."""
        return np.abs(self._frf.h1)

    @property
    def coherence(self) -> np.ndarray:
        return self._frf.coherence

    @property
    def used_attempts(self) -> tuple[int, ...]:
        """The blows identification averaged."""
        return self.result.used_attempts

    @property
    def rejected(self) -> dict[int, str]:
        """Attempt → why identification did not use it."""
        return {i.attempt: ", ".join(i.reasons) for i in self.result.impacts if not i.used}

    @property
    def warnings(self) -> tuple[str, ...]:
        """What identification could not vouch for (e.g. rollers differing)."""
        return tuple(self.result.warnings)

    @property
    def _frf(self) -> StepFrf:
        if self.result.frf is None:
            raise ValueError(f"step {self.position.step}: its result carries no FRF")
        return self.result.frf


@dataclass(frozen=True)
class StepFailed(Event):
    position: Position
    reason: str


@dataclass(frozen=True)
class RunProcessed(Event):
    position: Position
    specimen: str
    load_n: tuple[float, ...]
    stiffness_n_per_m: tuple[float, ...]
    reference_n_per_m: dict[str, tuple[float, ...]]  # model name → values at the same loads


@dataclass(frozen=True)
class OperatorPrompted(Event):
    message: str
    action: str
    answer: str
    position: Position | None = None  # None: wherever the engine last reported


@dataclass(frozen=True)
class Paused(Event):
    position: Position


@dataclass(frozen=True)
class Resumed(Event):
    """The run goes on after a pause, or after a suspend the operator chose to continue past (``reason``)."""

    position: Position
    reason: str = ""


@dataclass(frozen=True)
class Suspended(Event):
    """The engine stopped at a safe point because a condition failed (load drift, interlock)."""

    position: Position
    reason: str


@dataclass(frozen=True)
class Progress(Event):
    position: Position
    impacts_done: int
    impacts_total: int
    eta_s: float | None


@dataclass(frozen=True)
class CampaignFinished(Event):
    status: str  # complete | aborted | interrupted | failed
    path: str
    message: str = ""


@dataclass(frozen=True)
class Notice(Event):
    """Something the operator should know; ``kind`` sorts it for the run log (``retry`` when an instrument call
    or a blow is tried again, ``verdict`` when the operator changed a verdict, else ``notice``)."""

    level: str  # info | warning | error
    message: str
    kind: str = "notice"
    position: Position | None = None  # None: wherever the engine last reported


Subscriber = Callable[[Event], Any]


class EventBus:
    """Synchronous publish/subscribe; a failing subscriber is logged and does not stop delivery or the run."""

    def __init__(self) -> None:
        self._subs: list[Subscriber] = []
        self._lock = threading.Lock()

    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        """Add a subscriber; returns a function that removes it."""
        with self._lock:
            self._subs.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._subs:
                    self._subs.remove(callback)

        return unsubscribe

    def publish(self, event: Event) -> None:
        with self._lock:
            subs = list(self._subs)
        for callback in subs:
            try:
                callback(event)
            except Exception:  # a display or logger must never stop acquisition
                log.exception("event subscriber %r failed on %s", callback, type(event).__name__)
