"""The campaign store the engine writes through: a small Protocol, so the step runner never knows the medium.

``CampaignWriter`` (HDF5, flushed impact by impact) is the store of a real campaign; ``MemoryStore`` keeps the
same records in dicts, so engine logic (re-hits, overrides, drift, resume, progress) is tested in milliseconds.
Both speak the typed records of ``labctl.storage.records``; a write returns the record as it will be read back.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Protocol, runtime_checkable

from labctl.stiffness_table import StiffnessPoint
from labctl.storage.records import ImpactInfo, ImpactRecord, RepetitionCurve, StepResult, Verdict
from labctl.storage.runlog import LogEntry
from labctl.storage.specimen import SpecimenRecord


@dataclass(frozen=True)
class StepStamp:
    """A completed step and when its first stored impact was taken (what the ETA needs from the store)."""

    series: int
    run: int
    step: int
    first_impact_s: float | None  # POSIX seconds of the step's first impact; None without a usable timestamp


def stamp_seconds(stamp: Any) -> float | None:
    """POSIX seconds of a stored ISO timestamp (None when it is missing or unreadable)."""
    try:
        return datetime.fromisoformat(str(stamp)).timestamp()
    except ValueError:
        return None


def first_impact_s(infos: Iterable[ImpactInfo]) -> float | None:
    """The earliest usable timestamp among a step's impacts."""
    times = [t for i in infos if (t := stamp_seconds(i.timestamp_utc)) is not None]
    return min(times) if times else None


StepRow = tuple[int, float, float, StepResult]
"""(step, load per roller N, knob angle deg, result) of a processed step."""


@runtime_checkable
class CampaignStore(Protocol):
    """Where a campaign's records go as they are taken, and what a resumed run reads back from it.

    Groups are series (a mounted specimen) → run (a repetition) → step (a load) → impacts and the step result;
    a step is complete once its result is written, a run once its curve is stored."""

    path: str

    @property
    def attrs(self) -> dict[str, Any]:
        """The campaign's attributes (backend, seed, status …)."""
        ...

    def has_series(self) -> bool: ...
    def series(self, series: int, specimen: SpecimenRecord) -> None: ...
    def is_mounted(self, series: int) -> bool: ...
    def mark_mounted(self, series: int) -> None: ...
    def complete_runs(self, series: int) -> set[int]: ...
    def run_started(self, series: int, run: int) -> bool: ...
    def run(self, series: int, run: int) -> None: ...
    def run_attrs(self, series: int, run: int) -> dict[str, Any]: ...
    def set_run_attrs(self, series: int, run: int, attrs: Mapping[str, Any]) -> None: ...
    def step(self, series: int, run: int, step: int, attrs: Mapping[str, Any]) -> None: ...
    def step_load(self, series: int, run: int, step: int, *, complete_only: bool = False) -> float | None: ...
    def update_step(self, series: int, run: int, step: int, attrs: Mapping[str, Any]) -> None: ...
    def step_attrs(self, series: int, run: int, step: int) -> dict[str, Any]:
        """A stored step's attributes (empty when the step is not stored)."""
        ...

    def impact_infos(self, series: int, run: int, step: int) -> list[ImpactInfo]: ...
    def impacts(self, series: int, run: int, step: int) -> list[ImpactRecord]: ...

    def write_impact(self, series: int, run: int, step: int, record: ImpactRecord) -> ImpactRecord:
        """Store one blow at once; return it exactly as a reader will read it back."""
        ...

    def set_verdict(self, series: int, run: int, step: int, attempt: int, verdict: Verdict) -> None: ...
    def write_step_result(self, series: int, run: int, step: int, result: StepResult) -> None: ...
    def complete_step(self, series: int, run: int, step: int) -> None:
        """Mark a step complete without a hammer result (a static-only step: its reading is in its attributes)."""
        ...

    def step_results(self, series: int, run: int) -> list[StepRow]: ...
    def stiffness_points(self) -> list[StiffnessPoint]: ...

    def store_curve(self, series: int, run: int, steps: list[StepRow] | None = None) -> RepetitionCurve:
        """Store a repetition's curve (from ``steps`` when the caller holds them, else from the stored results)."""
        ...

    def curves(self) -> list[RepetitionCurve]: ...

    def accepted_count(self) -> int:
        """Impacts accepted so far over the whole campaign (what progress counts)."""
        ...

    def completed_steps(self) -> list[StepStamp]:
        """Every completed step with its first impact's time (what the ETA needs)."""
        ...

    def append_log(self, entry: LogEntry) -> None: ...
    def set_status(self, status: str, message: str = "") -> None: ...
