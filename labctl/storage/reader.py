"""Read campaign files: structure, raw impacts for (re)processing, step results and stiffness curves."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from labctl.errors import InputError
from labctl.storage import schema as s


def _decode(value: Any) -> Any:
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, str) and value[:1] in "[{":
        try:
            return json.loads(value)
        except json.JSONDecodeError:
            return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def attrs_of(obj: h5py.Group | h5py.Dataset) -> dict[str, Any]:
    return {k: _decode(v) for k, v in obj.attrs.items()}


@dataclass
class ImpactInfo:
    attempt: int
    accepted: bool
    reasons: list[str]
    attrs: dict[str, Any]


@dataclass
class StepInfo:
    series: int
    run: int
    step: int
    attrs: dict[str, Any]
    impacts: list[ImpactInfo]
    result: dict[str, Any] | None
    complete: bool

    @property
    def load_n(self) -> float:
        return float(self.attrs.get("load_n", np.nan))

    @property
    def accepted_count(self) -> int:
        return sum(1 for i in self.impacts if i.accepted)


@dataclass
class RunInfo:
    series: int
    run: int
    complete: bool
    steps: list[StepInfo] = field(default_factory=list)


class CampaignReader:
    """Read-only view of a campaign file; errors on corrupt or foreign files name the file."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.path}: campaign file not found")
        try:
            self.h5 = h5py.File(self.path, "r")
        except OSError as exc:
            raise InputError(f"{self.path}: not a readable HDF5 campaign file ({exc})") from None
        if _decode(self.h5.attrs.get("format")) != s.FORMAT:
            self.h5.close()
            raise InputError(f"{self.path}: not a labctl campaign file (no format attribute '{s.FORMAT}')")

    def close(self) -> None:
        if self.h5.id.valid:
            self.h5.close()

    def __enter__(self) -> CampaignReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def attrs(self) -> dict[str, Any]:
        return attrs_of(self.h5)

    def config_text(self, name: str) -> str | None:
        return s.stored_text(self.h5, name)

    def series_indices(self) -> list[int]:
        return sorted(s.index_of(k) for k in self.h5 if k.startswith("series_"))

    def specimen(self, series: int) -> dict[str, Any]:
        return attrs_of(self.h5[s.series_name(series)])

    def runs(self, series: int) -> list[RunInfo]:
        out = []
        for rg in s.children(self.h5[s.series_name(series)], "run_"):
            run = RunInfo(series, s.number(rg), bool(rg.attrs.get(s.COMPLETE, False)))
            run.steps = [self._step_info(series, run.run, g) for g in s.children(rg, "step_")]
            out.append(run)
        return out

    def _step_info(self, series: int, run: int, g: h5py.Group) -> StepInfo:
        impacts = []
        for ig in s.children(g, "impact_"):
            if ig.attrs.get(s.COMPLETE, False):
                a = attrs_of(ig)
                impacts.append(ImpactInfo(s.number(ig), bool(a.get("accepted")), list(a.get("reasons", [])), a))
        result = attrs_of(g[s.RESULT]) if s.RESULT in g and g[s.RESULT].attrs.get(s.COMPLETE, False) else None
        return StepInfo(series, run, s.number(g), attrs_of(g), impacts, result, bool(g.attrs.get(s.COMPLETE, False)))

    def step_group(self, series: int, run: int, step: int) -> h5py.Group:
        return self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)]

    def impact_arrays(self, series: int, run: int, step: int, *, accepted_only: bool = False) -> StepImpacts:
        """A step's stored impacts (all, or only the accepted ones)."""
        return step_impacts(self.step_group(series, run, step), accepted_only=accepted_only)

    def step_frf(self, series: int, run: int, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        g = self.step_group(series, run, step)
        if s.RESULT not in g or "h1" not in g[s.RESULT]:
            return None
        r = g[s.RESULT]
        coh = r["coherence"][()] if "coherence" in r else np.full(r["h1"].shape, np.nan)
        return r["frequencies_hz"][()], r["h1"][()], coh

    def curve(self, series: int, run: int) -> dict[str, np.ndarray] | None:
        rg = self.h5[s.series_name(series)][s.run_name(run)]
        if s.CURVE not in rg:
            return None
        return {k: rg[s.CURVE][k][()] for k in rg[s.CURVE]}


@dataclass
class StepImpacts:
    """A step's impacts as arrays: force (n_imp, n), accel (n_imp, n_ch, n), with calibration attributes."""

    sample_rate_hz: float
    force_n: np.ndarray
    accel_m_per_s2: np.ndarray
    channels: tuple[str, ...]
    attempts: list[int]
    accepted: list[bool]
    force_attrs: dict[str, Any]
    accel_attrs: dict[str, Any]

    @property
    def accel_ranges(self) -> list[float] | None:
        r = self.accel_attrs.get("range_units")
        return None if r is None else list(r)

    @property
    def force_range_n(self) -> float | None:
        r = self.force_attrs.get("range_units")
        return None if r is None else float(r)


def step_impacts(group: h5py.Group, *, accepted_only: bool = False) -> StepImpacts:
    """Read the complete impacts of a step group (used by the engine on its open file and by readers)."""
    forces, accels, attempts, accepted = [], [], [], []
    fs, channels, f_attrs, a_attrs = float("nan"), (), {}, {}
    for name in sorted(k for k in group if k.startswith("impact_")):
        ig = group[name]
        ok = bool(ig.attrs.get("accepted", False))
        if not ig.attrs.get(s.COMPLETE, False) or (accepted_only and not ok):
            continue
        forces.append(ig[s.FORCE][()])
        accels.append(ig[s.ACCEL][()])
        attempts.append(s.index_of(name))
        accepted.append(ok)
        fs = float(ig.attrs["sample_rate_hz"])
        a_attrs, f_attrs = attrs_of(ig[s.ACCEL]), attrs_of(ig[s.FORCE])
        channels = tuple(a_attrs.get("channels", ()))
    if not forces:
        return StepImpacts(fs, np.empty((0, 0)), np.empty((0, 0, 0)), channels, [], [], {}, {})
    return StepImpacts(fs, np.stack(forces).astype(float), np.stack(accels).astype(float), channels, attempts,
                       accepted, f_attrs, a_attrs)
