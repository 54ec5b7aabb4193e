"""What a campaign report shows, gathered from a campaign file: curves, statistics, one step's FRF, the setup.

Everything comes from the stored step results (``labctl process`` recomputes them from the raw impacts);
model curves come from ``labctl.physics``.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from labctl.errors import InputError
from labctl.physics import ContactCase, RigConfig
from labctl.report.notes import StepEvents, step_events
from labctl.reprocess import rig_of
from labctl.storage import CampaignReader, RunInfo, StepInfo
from labctl.storage.records import curve_from_steps


@dataclass
class RunCurve:
    """One repetition's identified steps, in step order."""

    run: int
    steps: np.ndarray
    load_n: np.ndarray
    stiffness_n_per_m: np.ndarray
    bounce_hz: np.ndarray
    tilt_hz: np.ndarray  # (n, 2)
    load_std_n: np.ndarray | None = None  # 1-σ of each load from the spring curve (None: a load cell read it)


@dataclass
class StepStat:
    """One load step over the repetitions: mean load and stiffness, their extremes and spread."""

    step: int
    load_n: float
    stiffness_n_per_m: float
    k_min: float
    k_max: float
    repetitions: int
    load_std_n: float = math.nan  # one setting's load 1-σ from the spring curve, mean over repetitions

    @property
    def spread(self) -> float:
        return (self.k_max - self.k_min) / self.stiffness_n_per_m


@dataclass
class SeriesData:
    index: int
    label: str
    kind: str
    specimen: dict[str, Any]
    case: ContactCase
    runs: list[RunCurve]
    events: list[StepEvents] = field(default_factory=list)  # what happened at each stored step

    @property
    def name(self) -> str:
        """The series as tables and legends name it: the specimen and its rails (two series of one roller type
        on different rails are told apart)."""
        return f"{self.label} · rails Ra {self.case.rail_ra_m * 1e6:.3g} µm"

    def drifted(self, step: int) -> list[StepEvents]:
        """The repetitions of ``step`` whose load did not hold during the step."""
        return [e for e in self.events if e.step == step and e.drifted()]

    def step_stats(self) -> list[StepStat]:
        """Statistics per step number over the repetitions that identified it."""
        by_step: dict[int, list[tuple[float, float, float]]] = {}
        for r in self.runs:
            stds = r.load_std_n if r.load_std_n is not None else np.full(len(r.steps), np.nan)
            for s, f, k, sf in zip(r.steps, r.load_n, r.stiffness_n_per_m, stds, strict=True):
                by_step.setdefault(int(s), []).append((float(f), float(k), float(sf)))
        out = []
        for s in sorted(by_step):
            f, k, sf = np.array(by_step[s]).T
            load_std = float(np.nanmean(sf)) if np.isfinite(sf).any() else math.nan
            out.append(StepStat(s, float(f.mean()), float(k.mean()), float(k.min()), float(k.max()), len(k),
                                load_std))
        return out

    @property
    def all_loads(self) -> np.ndarray:
        return np.concatenate([r.load_n for r in self.runs]) if self.runs else np.empty(0)


@dataclass
class ImpactRow:
    series: int
    run: int
    step: int
    load_n: float
    accepted: int
    rejected: int
    reasons: list[str]


@dataclass
class ImpactStats:
    """Accepted and rejected impacts, and why: the checks at the blow plus the identification's (coherence)."""

    rows: list[ImpactRow] = field(default_factory=list)

    @property
    def accepted(self) -> int:
        return sum(r.accepted for r in self.rows)

    @property
    def rejected(self) -> int:
        return sum(r.rejected for r in self.rows)

    @property
    def by_reason(self) -> dict[str, int]:
        return dict(Counter(reason for r in self.rows for reason in r.reasons).most_common())


@dataclass
class FrfStep:
    """One step's FRF and coherence with the modes identified in it."""

    series: int
    run: int
    step: int
    load_n: float
    frequencies_hz: np.ndarray
    h1: np.ndarray
    coherence: np.ndarray
    channels: list[str]
    modes: list[tuple[str, float]]  # (kind, frequency)


@dataclass
class ReportData:
    path: Path
    attrs: dict[str, Any]
    series: list[SeriesData]
    impacts: ImpactStats
    frf: FrfStep | None
    config: dict[str, str]
    rig: RigConfig
    failed_steps: list[tuple[int, int, int, str]]
    runs: dict[int, list[RunInfo]] = field(default_factory=dict)  # series → its repetitions, as read


def _verdicts(step: StepInfo) -> tuple[int, int, list[str]]:
    """(accepted, rejected, rejection reasons) of a step's impacts, the identification's verdict included."""
    late = {i.attempt: i for i in step.result.impacts} if step.result is not None else {}
    accepted, rejected, reasons = 0, 0, []
    for imp in step.impacts:
        why = list(imp.reasons)
        ident = late.get(imp.attempt)
        if ident is not None and not ident.used:
            why += [r for r in ident.reasons if r not in why]
        if imp.accepted and (ident is None or ident.used):
            accepted += 1
        else:
            rejected += 1
            reasons += [r for r in why if r != "operator_accepted"] or ["unspecified"]
    return accepted, rejected, reasons


def _run_curve(run: RunInfo) -> RunCurve | None:
    c = curve_from_steps(run.series, run.run, "",
                         [(s.step, s.load_n, s.knob_angle_deg, s.result) for s in run.steps if s.result is not None])
    if not len(c):
        return None
    by_step = {s.step: float(s.attrs.get("load_std_n", np.nan)) for s in run.steps}
    load_std = np.array([by_step.get(int(n), np.nan) for n in c.step])
    return RunCurve(run.run, c.step, c.load_n, c.stiffness_n_per_m, c.bounce_hz,
                    np.column_stack([c.tilt_a_hz, c.tilt_b_hz]), load_std if np.isfinite(load_std).any() else None)


def _frf(reader: CampaignReader, series: list[SeriesData], runs: dict[int, list[RunInfo]],
         want: tuple[int, int, int] | None) -> FrfStep | None:
    if want is None:
        candidates = [(s.index, r.run, int(r.steps[np.argmax(r.load_n)])) for s in series for r in s.runs]
        if not candidates:
            return None
        want = candidates[0]
    s, r, n = want
    try:
        frf = reader.step_frf(s, r, n)
        info = next(st for run in runs.get(s, ()) if run.run == r for st in run.steps if st.step == n)
    except (KeyError, StopIteration):
        raise InputError(f"{reader.path}: no step series {s} run {r} step {n} (--frf-step)") from None
    if frf is None or info.result is None or not info.result.identified:
        raise InputError(f"{reader.path}: step series {s} run {r} step {n} has no stored FRF (not identified)")
    modes = [(m.kind, m.frequency_hz) for m in info.result.modes] or [("bounce", info.result.bounce_hz)]
    channels = list(info.result.channels or [f"ch{i + 1}" for i in range(frf[1].shape[0])])
    return FrfStep(s, r, n, info.load_n, frf[0], frf[1], frf[2], channels, modes)


def load_report_data(path: str | Path, frf_step: tuple[int, int, int] | None = None) -> ReportData:
    """Read everything the report shows; ``frf_step`` = (series, run, step) for Fig. 7 (default: the first
    repetition's highest load)."""
    with CampaignReader(path) as reader:
        return report_data(reader, frf_step)


def report_data(reader: CampaignReader, frf_step: tuple[int, int, int] | None = None) -> ReportData:
    """``load_report_data`` on an open campaign; the repetitions it read are kept (``ReportData.runs``)."""
    path = Path(reader.path)
    rig = rig_of(reader)
    if reader.step_count() == 0:
        raise InputError(f"{path}: the campaign holds no load step yet (nothing to report)")
    series: list[SeriesData] = []
    stats = ImpactStats()
    failed: list[tuple[int, int, int, str]] = []
    read: dict[int, list[RunInfo]] = {}
    for s in reader.series_indices():
        spec = reader.specimen(s)
        runs = read[s] = reader.runs(s)
        for run in runs:
            for st in run.steps:
                stats.rows.append(ImpactRow(s, run.run, st.step, st.load_n, *_verdicts(st)))
                if st.result is not None and st.result.error:
                    failed.append((s, run.run, st.step, st.result.error))
        curves = [c for c in (_run_curve(r) for r in runs) if c is not None]
        series.append(SeriesData(s, spec.label or f"series {s}", spec.kind, spec, spec.case(), curves,
                                 [step_events(st) for run in runs for st in run.steps]))
    config = {name: text for name in ("protocol.toml", "rig.toml", "world.toml", "devices.toml", "manifest.csv")
              if (text := reader.config_text(name))}
    frf = _frf(reader, series, read, frf_step)
    return ReportData(path, reader.attrs, series, stats, frf, config, rig, failed, read)
