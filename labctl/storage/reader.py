"""Read campaign files (schema 2: ADC counts with per-channel scale and offset; schema 1: float32 traces) into
typed records; refuses what it does not understand (unknown format version, a complete impact with a missing
dataset, a missing stored configuration) with an InputError naming the file."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from labctl.errors import InputError
from labctl.storage import schema as s
from labctl.storage.inuse import in_use_message, is_lock_error
from labctl.storage.records import (
    CHECKS,
    OPERATOR,
    Calibration,
    CheckSummary,
    ImpactInfo,
    ImpactRecord,
    RepetitionCurve,
    StepFrf,
    StepResult,
    Verdict,
    curve_from_steps,
    failed_step,
    result_from_mapping,
)
from labctl.storage.rollback import recover, wait_for_flush
from labctl.storage.runlog import LogEntry, read_entries
from labctl.storage.safety import check_structure, number_attr
from labctl.storage.specimen import SpecimenRecord

OPERATOR_REASONS = ("operator_accepted", "operator_rejected")


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


def _floats(value: Any) -> tuple[float, ...] | None:
    if value is None:
        return None
    return tuple(float(v) for v in np.atleast_1d(np.asarray(value, dtype=float)))


def _where(group: h5py.Group | h5py.Dataset) -> str:
    return f"{group.file.filename}:{group.name}"


MAX_TRACE_VALUES = 2**28
"""More samples than this in one impact's trace (2 GiB as float64) is not a record a DAQ delivered."""


def trace(ds: h5py.Dataset) -> np.ndarray:
    """A stored trace in physical units: counts × scale + offset (per channel), or the stored floats.

    Refused with one line naming the dataset: not numbers, not 1-D or 2-D, implausibly large, integer counts
    without their ``scale``, a ``scale`` or ``offset`` that is not one finite number per channel."""
    where = _where(ds)
    if ds.dtype.kind not in "iuf" or ds.ndim not in (1, 2):
        raise InputError(f"{where}: expected a 1-D or 2-D array of numbers, found {ds.ndim}-D {ds.dtype}")
    if ds.size > MAX_TRACE_VALUES:
        raise InputError(f"{where}: {ds.size} samples, more than the {MAX_TRACE_VALUES} a record may hold")
    rows = ds.shape[0] if ds.ndim == 2 else 1
    scale = number_attr(ds, "scale")
    if scale is None:
        if ds.dtype.kind in "iu":
            raise InputError(f"{where}: integer ADC counts without their 'scale' attribute (the step per "
                             "count); the samples cannot be read back as physical values")
        return np.asarray(ds[()], dtype=float)
    offset = number_attr(ds, "offset", default=np.zeros(rows))
    for name, values in (("scale", scale), ("offset", offset)):
        if values.size not in (1, rows) or (ds.ndim == 1 and values.size != 1):
            raise InputError(f"{where}: attribute {name!r} has {values.size} values for {rows} channel(s)")
    if not np.all(scale != 0):
        raise InputError(f"{where}: attribute 'scale' is 0; the samples cannot be read back")
    raw = ds[()].astype(float)
    if raw.ndim == 2:
        return raw * np.broadcast_to(scale.reshape(-1), (rows,))[:, None] + np.broadcast_to(
            offset.reshape(-1), (rows,))[:, None]
    return raw * float(scale.reshape(-1)[0]) + float(offset.reshape(-1)[0])


def impact_info(g: h5py.Group) -> ImpactInfo:
    """The timing, checks and verdict of a stored impact (either schema)."""
    a = attrs_of(g)
    reasons = [str(r) for r in a.get("reasons", [])]
    auto = tuple(r for r in reasons if r not in OPERATOR_REASONS)  # the checks' reasons
    if "verdict_source" in a:  # schema 2
        by_operator = a["verdict_source"] == OPERATOR
        checks = CheckSummary(bool(a.get("check_accepted", not auto)) if by_operator else bool(a["accepted"]), auto,
                              float(a.get("peak_force_n", np.nan)), float(a.get("pulse_width_s", np.nan)))
        verdict = Verdict(bool(a["accepted"]), OPERATOR if by_operator else CHECKS, str(a.get("verdict_reason", "")))
    else:  # schema 1: the operator's verdict was only a reason among the checks'
        by_operator = any(r in OPERATOR_REASONS for r in reasons)
        checks = CheckSummary(not auto if by_operator else bool(a.get("accepted")), auto,
                              float(a.get("peak_force_n", np.nan)), float(a.get("pulse_width_s", np.nan)))
        verdict = Verdict(bool(a.get("accepted")), OPERATOR if by_operator else CHECKS)
    return ImpactInfo(int(a.get("attempt", s.number(g))), float(a.get("sample_rate_hz", np.nan)),
                      int(a.get("trigger_index", 0)), str(a.get("timestamp_utc", "")), checks, verdict,
                      tuple(str(c) for c in a.get("clipped", ())))


def impact_record(g: h5py.Group) -> ImpactRecord:
    """A stored impact with its traces; a complete impact without its datasets is a damaged file."""
    missing = [name for name in (s.FORCE, s.ACCEL) if name not in g]
    if missing:
        raise InputError(f"{_where(g)}: impact is marked complete but dataset {', '.join(missing)} is missing "
                         "(damaged file)")
    f, a = g[s.FORCE], g[s.ACCEL]
    fa, aa = attrs_of(f), attrs_of(a)
    sens = fa.get("sensitivity_v_per_unit")
    calib = Calibration(None if sens is None else float(sens),
                        None if fa.get("range_units") is None else float(fa["range_units"]),
                        _floats(aa.get("sensitivity_v_per_unit")), _floats(aa.get("range_units")))
    return ImpactRecord(impact_info(g), tuple(str(c) for c in aa.get("channels", ())), trace(f), trace(a), calib)


def step_frf(g: h5py.Group) -> StepFrf | None:
    r = g.get(s.RESULT)
    if r is None or "h1" not in r:
        return None
    coh = r["coherence"][()] if "coherence" in r else np.full(r["h1"].shape, np.nan)
    return StepFrf(r["frequencies_hz"][()], r["h1"][()], coh)


def step_result_of(g: h5py.Group) -> StepResult | None:
    """The stored result of a step group (None: not identified yet); a failed step carries its reason."""
    r = g.get(s.RESULT)
    if r is not None and r.attrs.get(s.COMPLETE, False):
        return result_from_mapping(attrs_of(r), step_frf(g))
    if "failed" in g.attrs:  # schema 1 kept the failure on the step
        return failed_step(str(_decode(g.attrs["failed"])))
    return None


def complete_impacts(g: h5py.Group) -> list[h5py.Group]:
    return [ig for ig in s.children(g, "impact_") if ig.attrs.get(s.COMPLETE, False)]


@dataclass(frozen=True)
class StepInfo:
    """A stored load step: its load, its impacts (without traces) and its result."""

    series: int
    run: int
    step: int
    load_n: float
    knob_angle_deg: float
    impacts: list[ImpactInfo]
    result: StepResult | None
    complete: bool
    attrs: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def accepted_count(self) -> int:
        return sum(1 for i in self.impacts if i.accepted)

    @property
    def load_drift(self) -> bool:
        return bool(self.attrs.get("load_drift", False))

    @property
    def load_after_n(self) -> float:
        """The load read after the step's impacts (NaN when the step has none)."""
        return float(self.attrs.get("load_after_n", np.nan))


def processed_steps(run_group: h5py.Group) -> list[tuple[int, float, float, StepResult]]:
    """(step, load, knob angle, result) of a repetition's identified steps, in step order: what its curve is built
    from (the impacts' attributes are not read)."""
    out = []
    for g in s.children(run_group, "step_"):
        result = step_result_of(g)
        if result is not None:
            a = g.attrs
            out.append((s.number(g), float(a.get("load_n", np.nan)), float(a.get("knob_angle_deg", np.nan)), result))
    return out


def step_info(series: int, run: int, g: h5py.Group) -> StepInfo:
    a = attrs_of(g)
    return StepInfo(series, run, s.number(g), float(a.get("load_n", np.nan)), float(a.get("knob_angle_deg", np.nan)),
                    [impact_info(ig) for ig in complete_impacts(g)], step_result_of(g),
                    bool(a.get(s.COMPLETE, False)), a)


@dataclass
class RunInfo:
    series: int
    run: int
    complete: bool
    steps: list[StepInfo] = field(default_factory=list)


def curve_of(run_group: h5py.Group, series: int, specimen: str) -> RepetitionCurve | None:
    """The stored curve of a repetition (None before the repetition finished)."""
    c = run_group.get(s.CURVE)
    if c is None:
        return None
    run = s.number(run_group)
    built = curve_from_steps(series, run, specimen, processed_steps(run_group))
    stored = {k: np.asarray(c[k][()]) for k in c}
    if "step" not in stored:  # schema 1 stored no step numbers: the identified steps in order
        stored["step"] = built.step if built.step.size == stored["load_n"].size else np.arange(
            1, stored["load_n"].size + 1)
    cols = {k: np.asarray(stored.get(k, np.full(stored["load_n"].size, np.nan))) for k in built.columns()}
    cols["step"] = cols["step"].astype(int)
    return RepetitionCurve(series, run, specimen, **cols)


def curves_of(h5: h5py.File) -> list[RepetitionCurve]:
    """The stored curve of every finished repetition of a campaign, in series and run order."""
    out = []
    for sg in s.children(h5, "series_"):
        label = SpecimenRecord.from_attrs(attrs_of(sg)).label
        for rg in s.children(sg, "run_"):
            curve = curve_of(rg, s.number(sg), label)
            if curve is not None:
                out.append(curve)
    return out


class CampaignReader:
    """Read-only view of a campaign file; errors on corrupt or foreign files name the file."""

    def __init__(self, path: str | Path, *, live: bool = False, attrs_only: bool = False,
                 locking: bool | None = None) -> None:
        """``live`` (or ``locking=False``): open a file a running campaign writes without HDF5's lock (a read may
        meet a half-flushed impact and must be retried: ``read_live``). ``attrs_only``: only the root attributes
        are read, so the walk over every link that guards data reads is skipped."""
        live = live or locking is False
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.path}: campaign file not found")
        # not live: a writer killed inside a flush is rolled back; live: the writer's flush in progress ends
        wait_for_flush(self.path) if live else recover(self.path)
        try:
            self.h5 = h5py.File(self.path, "r", locking=False) if live else h5py.File(self.path, "r")
        except OSError as exc:
            if is_lock_error(exc):
                raise InputError(in_use_message(self.path)) from None
            raise InputError(f"{self.path}: not a readable HDF5 campaign file ({exc})") from None
        if _decode(self.h5.attrs.get("format")) != s.FORMAT:
            self.h5.close()
            raise InputError(f"{self.path}: not a labctl campaign file (no format attribute '{s.FORMAT}')")
        version = _decode(self.h5.attrs.get("format_version"))
        if version not in s.READABLE_VERSIONS:
            self.h5.close()
            raise InputError(f"{self.path}: format_version {version!r} is not one this labctl reads "
                             f"({', '.join(map(str, s.READABLE_VERSIONS))}); update labctl")
        self.format_version = int(version)
        if attrs_only:
            return
        try:
            check_structure(self.h5, self.path)
        except BaseException:
            self.h5.close()
            raise

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

    def required_config(self, name: str) -> str:
        """A stored configuration file the caller cannot do without (InputError when absent)."""
        text = self.config_text(name)
        if not text:
            raise InputError(f"{self.path}: has no stored /config/{name}; the campaign cannot be reprocessed "
                             "without the configuration it ran with")
        return text

    def log(self) -> list[LogEntry]:
        """The run log in the order written: retries, suspends, resumes, prompts, warnings (empty for a file
        written without one, e.g. schema 1)."""
        return read_entries(self.h5)

    def series_indices(self) -> list[int]:
        return sorted(s.index_of(k) for k in self.h5 if k.startswith("series_"))

    def specimen(self, series: int) -> SpecimenRecord:
        return SpecimenRecord.from_attrs(attrs_of(self.h5[s.series_name(series)]))

    def runs(self, series: int) -> list[RunInfo]:
        out = []
        for rg in s.children(self.h5[s.series_name(series)], "run_"):
            run = RunInfo(series, s.number(rg), bool(rg.attrs.get(s.COMPLETE, False)))
            run.steps = [step_info(series, run.run, g) for g in s.children(rg, "step_")]
            out.append(run)
        return out

    def run_attrs(self, series: int, run: int) -> dict[str, Any]:
        """A repetition's attributes (e.g. its stored static stiffness curve)."""
        return attrs_of(self.h5[s.series_name(series)][s.run_name(run)])

    def step_count(self) -> int:
        return sum(1 for _ in s.all_steps(self.h5))

    def step_group(self, series: int, run: int, step: int) -> h5py.Group:
        return self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)]

    def impacts(self, series: int, run: int, step: int) -> list[ImpactRecord]:
        """Every complete impact of a step, with traces, calibration and verdict."""
        return [impact_record(ig) for ig in complete_impacts(self.step_group(series, run, step))]

    def impact_infos(self, series: int, run: int, step: int) -> list[ImpactInfo]:
        """Timing, checks and verdict of every complete impact of a step (no traces read)."""
        return [impact_info(ig) for ig in complete_impacts(self.step_group(series, run, step))]

    def impact_arrays(self, series: int, run: int, step: int, *, accepted_only: bool = False) -> StepImpacts:
        """A step's stored impacts stacked as arrays (all, or only those whose verdict is accepted)."""
        return stack_impacts([r for r in self.impacts(series, run, step) if r.accepted or not accepted_only])

    def step_frf(self, series: int, run: int, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        frf = step_frf(self.step_group(series, run, step))
        return None if frf is None else (frf.frequencies_hz, frf.h1, frf.coherence)

    def curve(self, series: int, run: int) -> RepetitionCurve | None:
        rg = self.h5[s.series_name(series)][s.run_name(run)]
        return curve_of(rg, series, self.specimen(series).label)

    def curves(self) -> list[RepetitionCurve]:
        """The stored curve of every finished repetition, in series and run order."""
        return curves_of(self.h5)


@dataclass
class StepImpacts:
    """A step's impacts as arrays: force (n_imp, n), accel (n_imp, n_ch, n), with calibration and verdicts."""

    sample_rate_hz: float
    force_n: np.ndarray
    accel_m_per_s2: np.ndarray
    channels: tuple[str, ...]
    attempts: list[int]
    accepted: list[bool]
    calibration: Calibration = Calibration()

    @property
    def accel_ranges(self) -> list[float] | None:
        r = self.calibration.accel_range_m_per_s2
        return None if r is None else list(r)

    @property
    def force_range_n(self) -> float | None:
        return self.calibration.force_range_n


def stack_impacts(records: list[ImpactRecord]) -> StepImpacts:
    if not records:
        return StepImpacts(float("nan"), np.empty((0, 0)), np.empty((0, 0, 0)), (), [], [])
    return StepImpacts(records[-1].sample_rate_hz, np.stack([r.force_n for r in records]),
                       np.stack([r.accel_m_per_s2 for r in records]), records[-1].channels,
                       [r.attempt for r in records], [r.accepted for r in records], records[-1].calibration)
