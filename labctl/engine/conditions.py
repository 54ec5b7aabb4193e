"""Conditions the engine checks at its safe points, in the spirit of bluesky's suspenders.

A condition looks at a ``SafePoint`` (where the engine is, the loads it read) and returns a ``Trip`` when
the run must not go on as it is: an ``interlock`` trip unloads the rig and stops the campaign (resumable);
a ``suspend`` trip asks the operator whether to continue or abort. A lab adds its own (a temperature limit,
a door switch) by passing more conditions to the engine; the engine itself does not change.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

from labctl import events as ev

Where = Literal["before_step", "before_impact", "after_step"]
TripKind = Literal["interlock", "suspend"]


@dataclass(frozen=True)
class SafePoint:
    """Where the engine is and what it last read (loads per roller, N)."""

    where: Where
    position: ev.Position
    cap_n: float
    tolerance_fraction: float
    load_n: float | None = None  # the latest reading
    step_load_n: float | None = None  # the load recorded for the step


@dataclass(frozen=True)
class Trip:
    """A condition that fired: what to tell the operator, and whether to stop or to ask."""

    condition: str
    kind: TripKind
    message: str


class Condition(Protocol):
    """Something the engine checks at every safe point."""

    name: str

    def check(self, point: SafePoint) -> Trip | None: ...


@dataclass(frozen=True)
class LoadInterlock:
    """The load cell reads more than the protocol's cap (plus its tolerance): unload and stop."""

    name: str = "load_interlock"

    def check(self, point: SafePoint) -> Trip | None:
        limit = point.cap_n * (1 + point.tolerance_fraction)
        if point.where != "before_step" or point.load_n is None or point.load_n <= limit:
            return None
        return Trip(self.name, "interlock", f"load {point.load_n:.1f} N per roller exceeds the cap "
                    f"{point.cap_n:.1f} N (+tolerance): unload now")


@dataclass(frozen=True)
class LoadDrift:
    """The load after a step's impacts left the protocol's tolerance around the step's load: ask."""

    name: str = "load_drift"

    def check(self, point: SafePoint) -> Trip | None:
        before, after = point.step_load_n, point.load_n
        if point.where != "after_step" or before is None or after is None:
            return None
        if abs(after - before) <= point.tolerance_fraction * before:
            return None
        return Trip(self.name, "suspend", f"load drifted from {before:.1f} N to {after:.1f} N per roller during "
                    f"the step (tolerance {point.tolerance_fraction:.0%}); check the knobs")


DEFAULT_CONDITIONS: tuple[Condition, ...] = (LoadInterlock(), LoadDrift())
