"""What happened at one load step, in one record: the load before and after (drift), the channels used and
dropped (and why), every operator decision with its reason, and what identification could not vouch for.

``labctl process --json``, the TUI browser and the report all build their per-step notes here, so a drift
answered "continue", a dead channel or an override reads the same wherever it is shown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from labctl.storage import ImpactInfo, StepInfo, StepResult
from labctl.storage.records import OPERATOR

CHECK_WORDS = {
    "double_hit": "double hit",
    "overload": "overload",
    "pulse_width": "pulse width out of range",
    "low_force": "blow too soft",
    "low_coherence": "low coherence",
}


def check_words(reasons: tuple[str, ...] | list[str]) -> str:
    """The checks' reasons in words (``clipped:A1Z`` → ``A1Z clipped``); ``clean`` when there are none."""
    out = [f"{r.partition(':')[2]} clipped" if r.startswith("clipped:") else CHECK_WORDS.get(r, r.replace("_", " "))
           for r in reasons if r not in ("operator_accepted", "operator_rejected")]
    return ", ".join(out) or "clean"


@dataclass(frozen=True)
class Override:
    """An operator's verdict that differs from the checks' (accepting a flagged blow, rejecting a clean one)."""

    attempt: int
    accepted: bool
    checks: str  # what the checks said, in words
    reason: str

    @property
    def text(self) -> str:
        verb = "accepted" if self.accepted else "rejected"
        said = "flagged " + self.checks if self.checks != "clean" else "clean"
        return f"impact {self.attempt} {verb} by the operator (the checks said {said}): {self.reason or 'no reason'}"

    def to_dict(self) -> dict[str, Any]:
        return {"impact": self.attempt, "accepted": self.accepted, "checks": self.checks, "reason": self.reason}


def overrides_of(impacts: list[ImpactInfo]) -> tuple[Override, ...]:
    """The operator's verdicts that overrule the checks, in impact order."""
    return tuple(Override(i.attempt, i.verdict.accepted, check_words(i.checks.reasons), i.verdict.reason)
                 for i in impacts if i.verdict.source == OPERATOR and i.verdict.accepted != i.checks.accepted)


@dataclass(frozen=True)
class StepEvents:
    """Everything that happened at one step that a reader of its stiffness must know."""

    series: int
    run: int
    step: int
    load_before_n: float
    load_after_n: float
    drift_continued: bool  # the load-drift condition tripped and the operator continued
    channels_used: tuple[str, ...] = ()
    channels_dropped: dict[str, str] = field(default_factory=dict)  # channel → why it was left out
    overrides: tuple[Override, ...] = ()
    warnings: tuple[str, ...] = ()  # identification's warnings not already said above
    error: str = ""
    verdicts: tuple[Override, ...] = ()  # every verdict the operator gave at the step, agreeing or not

    @property
    def drift_fraction(self) -> float:
        """(after − before) / before; NaN when either load is unknown."""
        if not (math.isfinite(self.load_before_n) and math.isfinite(self.load_after_n)) or self.load_before_n == 0:
            return math.nan
        return self.load_after_n / self.load_before_n - 1.0

    def drifted(self, tolerance: float | None = None) -> bool:
        """The load did not hold: the drift condition tripped, or it moved by more than ``tolerance``."""
        moved = tolerance is not None and abs(self.drift_fraction) > tolerance
        return self.drift_continued or moved

    def notes(self, tolerance: float | None = None) -> list[str]:
        """One sentence per event, in the order a reader needs them: load, channels, verdicts, warnings."""
        out = []
        if self.drifted(tolerance):
            out.append(f"load drifted from {self.load_before_n:.1f} N to {self.load_after_n:.1f} N per roller "
                       f"({self.drift_fraction:+.1%}) during the step"
                       + ("; the operator continued" if self.drift_continued else ""))
        out += [f"channel {c} left out: {why}" for c, why in self.channels_dropped.items()]
        out += [o.text for o in self.overrides]
        out += list(self.warnings)
        if self.error:
            out.append(f"not identified: {self.error}")
        return out

    def flags(self, tolerance: float | None = None) -> list[str]:
        """The events in a few words each, for a list line (``LOAD DRIFTED``, ``A3X left out``, ``1 override``)."""
        out = ["LOAD DRIFTED"] if self.drifted(tolerance) else []
        if self.channels_dropped:
            out.append(f"{','.join(self.channels_dropped)} left out")
        if self.overrides:
            out.append(f"{len(self.overrides)} override")
        if self.warnings:
            out.append(f"{len(self.warnings)} warning{'s' if len(self.warnings) > 1 else ''}")
        return out

    def to_dict(self, tolerance: float | None = None) -> dict[str, Any]:
        def num(x: float) -> float | None:
            return x if math.isfinite(x) else None

        return {"load_before_n": num(self.load_before_n), "load_after_n": num(self.load_after_n),
                "load_drift_fraction": num(self.drift_fraction), "load_drifted": self.drifted(tolerance),
                "drift_continued_by_operator": self.drift_continued, "channels_used": list(self.channels_used),
                "channels_dropped": dict(self.channels_dropped),
                "overrides": [o.to_dict() for o in self.overrides],
                "operator_verdicts": [v.to_dict() for v in self.verdicts], "notes": self.notes(tolerance)}


def step_events(info: StepInfo, result: StepResult | None = None) -> StepEvents:
    """The events of a stored step; ``result`` replaces the stored one (a step just reprocessed)."""
    r = result if result is not None else info.result
    dropped: dict[str, str] = {}
    warnings: list[str] = []
    used: tuple[str, ...] = ()
    error = ""
    if r is not None:
        for c in r.dead_channels:
            dropped[c] = "dead (no signal in the step's FRF)"
        for c in r.dropped_channels:
            dropped[c] = "saturated in every impact"
        used = tuple(c for c in r.channels if c not in dropped)
        said = ("dead channel(s) left out", "saturated in every impact")
        warnings = [w for w in r.warnings if not any(s in w for s in said)]
        error = r.error
    verdicts = tuple(Override(i.attempt, i.verdict.accepted, check_words(i.checks.reasons), i.verdict.reason)
                     for i in info.impacts if i.verdict.source == OPERATOR)
    return StepEvents(info.series, info.run, info.step, info.load_n, info.load_after_n, info.load_drift, used,
                      dropped, overrides_of(info.impacts), tuple(warnings), error, verdicts)
