"""Instruments worked by the technician: the hand-held impact hammer and the star knobs.

The manual hammer only asks for a blow: the DAQ, armed beforehand, catches it with its force trigger. The
manual actuator asks for the knob turn and keeps the total turned since the preload.
"""

from __future__ import annotations

from drivers.errors import DeviceError
from drivers.hw.lifecycle import Lifecycle
from drivers.interfaces import Operator

DONE, CANCEL = "done", "cancel"


class ManualHammer(Lifecycle):
    """``strike()`` asks the operator for one blow (``action="strike"``)."""

    def __init__(self, operator: Operator, *, name: str = "hammer (manual)") -> None:
        self.name, self.operator = name, operator

    def strike(self) -> None:
        answer = self.operator.prompt(
            "Strike the upper disc once with the impact hammer at the marked point, then confirm.",
            (DONE, CANCEL), action="strike")
        if answer != DONE:
            raise DeviceError(self.name, "strike", f"the operator answered {answer!r}")

    def probe(self) -> str:
        return "manual: the operator strikes, the DAQ's force trigger catches the blow"


class ManualActuator(Lifecycle):
    """``turn_knobs(angle)`` asks the operator to turn every star knob by ``angle`` degrees together."""

    def __init__(self, operator: Operator, *, knobs: int = 4, name: str = "star knobs (manual)") -> None:
        if knobs < 1:
            raise ValueError(f"knobs = {knobs!r}: expected at least one star knob")
        self.name, self.operator, self.knobs = name, operator, knobs
        self._angle_deg = 0.0

    @property
    def knob_angle_deg(self) -> float:
        return self._angle_deg

    def turn_knobs(self, angle_deg: float) -> None:
        """Positive tightens, negative loosens; loosening stops at the preload (the knobs' start)."""
        delta = max(-self._angle_deg, float(angle_deg))
        if delta == 0.0:
            return
        way = "tighten" if delta > 0 else "loosen"
        answer = self.operator.prompt(
            f"Turn all {self.knobs} star knobs by {delta:+g}° together ({way}), then confirm.",
            (DONE, CANCEL), action="turn_knobs")
        if answer != DONE:
            raise DeviceError(self.name, "turn knobs", f"the operator answered {answer!r}")
        self._angle_deg += delta

    def probe(self) -> str:
        return f"manual: the operator turns {self.knobs} star knobs"
