"""A campaign store in memory: the same groups, records and completeness rules as the HDF5 writer, in dicts.

For engine-logic tests (scripted records, no HDF5, no compression) and for dry runs whose records need not
outlive the process. A write is atomic here, so there is never a partial group to drop on resume.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from labctl.stiffness_table import StiffnessPoint
from labctl.storage.records import (
    ImpactInfo,
    ImpactRecord,
    RepetitionCurve,
    StepResult,
    Verdict,
    curve_from_steps,
)
from labctl.storage.runlog import LogEntry
from labctl.storage.specimen import SpecimenRecord
from labctl.storage.store import StepRow, StepStamp, first_impact_s


@dataclass
class _Step:
    attrs: dict[str, Any]
    impacts: dict[int, ImpactRecord] = field(default_factory=dict)
    result: StepResult | None = None

    static_only: bool = False  # completed without a hammer result (the static method alone)

    @property
    def complete(self) -> bool:
        return self.result is not None or self.static_only


@dataclass
class _Run:
    attrs: dict[str, Any] = field(default_factory=dict)
    steps: dict[int, _Step] = field(default_factory=dict)
    curve: RepetitionCurve | None = None


@dataclass
class _Series:
    specimen: SpecimenRecord
    mounted: bool = False
    runs: dict[int, _Run] = field(default_factory=dict)


class MemoryStore:
    """A ``CampaignStore`` held in memory; ``path`` names it in events and messages."""

    def __init__(self, path: str = "memory", attrs: Mapping[str, Any] | None = None) -> None:
        self.path = path
        self._attrs: dict[str, Any] = {"backend": "sim", "status": "running", **(attrs or {})}
        self._series: dict[int, _Series] = {}
        self.log_entries: list[LogEntry] = []

    # --- groups -------------------------------------------------------------------------------------------
    @property
    def attrs(self) -> dict[str, Any]:
        return dict(self._attrs)

    def has_series(self) -> bool:
        return bool(self._series)

    def series(self, series: int, specimen: Mapping[str, Any]) -> None:
        self._series.setdefault(series, _Series(specimen))

    def is_mounted(self, series: int) -> bool:
        return series in self._series and self._series[series].mounted

    def mark_mounted(self, series: int) -> None:
        self._series[series].mounted = True

    def complete_runs(self, series: int) -> set[int]:
        sg = self._series.get(series)
        return set() if sg is None else {n for n, r in sg.runs.items() if r.curve is not None}

    def run_started(self, series: int, run: int) -> bool:
        return series in self._series and run in self._series[series].runs

    def run(self, series: int, run: int) -> None:
        self._series[series].runs.setdefault(run, _Run({"repetition": run}))

    def run_attrs(self, series: int, run: int) -> dict[str, Any]:
        r = self._series[series].runs.get(run) if series in self._series else None
        return {} if r is None else dict(r.attrs)

    def set_run_attrs(self, series: int, run: int, attrs: Mapping[str, Any]) -> None:
        self._series[series].runs[run].attrs.update({k: v for k, v in attrs.items() if v is not None})

    def _step(self, series: int, run: int, step: int) -> _Step | None:
        r = self._series[series].runs.get(run) if series in self._series else None
        return None if r is None else r.steps.get(step)

    def step(self, series: int, run: int, step: int, attrs: Mapping[str, Any]) -> None:
        self._series[series].runs[run].steps.setdefault(step, _Step({"step": step, **attrs}))

    def step_load(self, series: int, run: int, step: int, *, complete_only: bool = False) -> float | None:
        st = self._step(series, run, step)
        if st is None or "load_n" not in st.attrs or (complete_only and not st.complete):
            return None
        return float(st.attrs["load_n"])

    def update_step(self, series: int, run: int, step: int, attrs: Mapping[str, Any]) -> None:
        st = self._step(series, run, step)
        assert st is not None, f"step {series}/{run}/{step} was never created"
        st.attrs.update({k: v for k, v in attrs.items() if v is not None})

    def step_attrs(self, series: int, run: int, step: int) -> dict[str, Any]:
        """A step's attributes (load, knob angle, drift flags …), for tests and tools."""
        st = self._step(series, run, step)
        return {} if st is None else dict(st.attrs)

    # --- impacts and results ------------------------------------------------------------------------------
    def impact_infos(self, series: int, run: int, step: int) -> list[ImpactInfo]:
        return [r.info for r in self.impacts(series, run, step)]

    def impacts(self, series: int, run: int, step: int) -> list[ImpactRecord]:
        st = self._step(series, run, step)
        return [] if st is None else [st.impacts[k] for k in sorted(st.impacts)]

    def write_impact(self, series: int, run: int, step: int, record: ImpactRecord) -> ImpactRecord:
        st = self._step(series, run, step)
        assert st is not None, f"step {series}/{run}/{step} was never created"
        if record.attempt in st.impacts:
            raise ValueError(f"impact {record.attempt} of step {series}/{run}/{step} is already stored")
        st.impacts[record.attempt] = record
        return record

    def set_verdict(self, series: int, run: int, step: int, attempt: int, verdict: Verdict) -> None:
        st = self._step(series, run, step)
        assert st is not None and attempt in st.impacts, f"no impact {attempt} in step {series}/{run}/{step}"
        r = st.impacts[attempt]
        st.impacts[attempt] = replace(r, info=replace(r.info, verdict=verdict))

    def write_step_result(self, series: int, run: int, step: int, result: StepResult) -> None:
        st = self._step(series, run, step)
        assert st is not None, f"step {series}/{run}/{step} was never created"
        st.result = result
        if result.error:
            st.attrs["failed"] = result.error

    def complete_step(self, series: int, run: int, step: int) -> None:
        st = self._step(series, run, step)
        assert st is not None, f"step {series}/{run}/{step} was never created"
        st.static_only = True

    def step_results(self, series: int, run: int) -> list[StepRow]:
        r = self._series[series].runs[run]
        return [(n, float(st.attrs.get("load_n", math.nan)), float(st.attrs.get("knob_angle_deg", math.nan)),
                 st.result) for n, st in sorted(r.steps.items()) if st.result is not None]

    def stiffness_points(self) -> list[StiffnessPoint]:
        return [sg.specimen.point(run, load, result.roller_stiffness_n_per_m, result,
                                  sg.runs[run].steps[step].attrs.get("load_std_n"))
                for sg_n, sg in sorted(self._series.items()) for run in sorted(sg.runs)
                for step, load, _, result in self.step_results(sg_n, run) if result.identified]

    def store_curve(self, series: int, run: int, steps: list[StepRow] | None = None) -> RepetitionCurve:
        sg = self._series[series]
        curve = curve_from_steps(series, run, sg.specimen.label,
                                 self.step_results(series, run) if steps is None else steps)
        sg.runs[run].curve = curve
        return curve

    def curves(self) -> list[RepetitionCurve]:
        return [r.curve for _, sg in sorted(self._series.items()) for _, r in sorted(sg.runs.items())
                if r.curve is not None]

    # --- progress, log, status ----------------------------------------------------------------------------
    def accepted_count(self) -> int:
        return sum(r.accepted for sg in self._series.values() for run in sg.runs.values()
                   for st in run.steps.values() for r in st.impacts.values())

    def completed_steps(self) -> list[StepStamp]:
        return [StepStamp(sn, rn, n, first_impact_s(r.info for r in st.impacts.values()))
                for sn, sg in sorted(self._series.items()) for rn, run in sorted(sg.runs.items())
                for n, st in sorted(run.steps.items()) if st.complete]

    def append_log(self, entry: LogEntry) -> None:
        self.log_entries.append(entry)

    def set_status(self, status: str, message: str = "") -> None:
        self._attrs.update(status=status, status_message=message)
