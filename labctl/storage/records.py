"""The typed records of a campaign file: one impact as the DAQ delivered it, one step's result, one curve.

Every reader and writer of campaign files speaks these types; nothing outside ``labctl.storage`` reads
HDF5 attributes by name. ``StepResult`` is built from the processing's ``Identification`` in one place
(``labctl.recording.result_of``), field by named field: a renamed attribute fails there, never silently.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from labctl.stiffness_table import (
    BUDGET_COLUMNS,
    FLAG_CHANNELS,
    FLAG_LOAD_DRIFT,
    FLAG_OVERRIDE,
    RollerContact,
    StiffnessPoint,
)

if TYPE_CHECKING:
    from labctl.storage.reader import StepInfo

VerdictSource = Literal["checks", "operator"]
CHECKS: VerdictSource = "checks"
OPERATOR: VerdictSource = "operator"
NAN = math.nan


@dataclass(frozen=True)
class Verdict:
    """Whether an impact is used, and who decided: the automatic checks, or the operator (with a reason)."""

    accepted: bool
    source: VerdictSource = CHECKS
    reason: str = ""

    @property
    def forced(self) -> bool | None:
        """The operator's decision for identification (None: the checks decide)."""
        return self.accepted if self.source == OPERATOR else None


@dataclass(frozen=True)
class CheckSummary:
    """The automatic checks of one impact at the blow: verdict, reasons and the force pulse."""

    accepted: bool
    reasons: tuple[str, ...] = ()
    peak_force_n: float = NAN
    pulse_width_s: float = NAN


@dataclass(frozen=True)
class Calibration:
    """The DAQ channels' transducer sensitivities and ranges (physical units) when the backend gave them."""

    force_sensitivity_v_per_n: float | None = None
    force_range_n: float | None = None
    accel_sensitivity_v_per_m_per_s2: tuple[float, ...] | None = None
    accel_range_m_per_s2: tuple[float, ...] | None = None


@dataclass(frozen=True)
class ImpactInfo:
    """One stored blow without its traces: timing, checks and verdict (what lists and reports need)."""

    attempt: int
    sample_rate_hz: float
    trigger_index: int
    timestamp_utc: str
    checks: CheckSummary
    verdict: Verdict
    clipped: tuple[str, ...] = ()

    @property
    def accepted(self) -> bool:
        return self.verdict.accepted

    @property
    def reasons(self) -> tuple[str, ...]:
        """The checks' reasons, then the operator's verdict when they overruled or confirmed them."""
        extra = () if self.verdict.source == CHECKS else (
            "operator_accepted" if self.verdict.accepted else "operator_rejected",)
        return (*self.checks.reasons, *extra)

    @property
    def peak_force_n(self) -> float:
        return self.checks.peak_force_n


@dataclass(frozen=True)
class ImpactRecord:
    """One blow as stored: the traces in physical units (bit-exact when the DAQ delivered ADC steps, else float32
    precision), the channels' calibration, the automatic checks and the verdict with its source."""

    info: ImpactInfo
    channels: tuple[str, ...]
    force_n: np.ndarray = field(repr=False)  # (n_samples,)
    accel_m_per_s2: np.ndarray = field(repr=False)  # (n_channels, n_samples)
    calibration: Calibration = Calibration()

    @property
    def attempt(self) -> int:
        return self.info.attempt

    @property
    def accepted(self) -> bool:
        return self.info.accepted

    @property
    def verdict(self) -> Verdict:
        return self.info.verdict

    @property
    def sample_rate_hz(self) -> float:
        return self.info.sample_rate_hz


@dataclass(frozen=True)
class ModeResult:
    """One identified contact mode of a step."""

    kind: str
    frequency_hz: float
    frequency_std_hz: float
    damping_ratio: float
    damping_ratio_std: float
    coherence: float
    bounce_mac: float = NAN
    tilt_fraction: float = NAN


@dataclass(frozen=True)
class ImpactOutcome:
    """How identification used one stored impact (numbered by its attempt)."""

    attempt: int
    used: bool
    reasons: tuple[str, ...] = ()


@dataclass(frozen=True)
class StepFrf:
    """The step's averaged FRF as stored (up to the storage band)."""

    frequencies_hz: np.ndarray
    h1: np.ndarray  # (n_channels, n_f) m/s² per N
    coherence: np.ndarray  # (n_channels, n_f)


@dataclass(frozen=True)
class StepResult:
    """One load step's identification (or why it failed); every field has a default so old files read."""

    bounce_hz: float = NAN
    """Bounce (vertical) contact mode frequency, Hz."""
    bounce_hz_std: float = NAN
    """1-σ of the bounce frequency, Hz."""
    bounce_damping_ratio: float = NAN
    """Bounce mode damping ratio (exponential window removed), dimensionless."""
    bounce_damping_ratio_std: float = NAN
    """1-σ of the bounce damping ratio."""
    tilt_hz: tuple[float, ...] = (NAN, NAN)
    """The two tilt (rocking) mode frequencies, Hz."""
    tilt_hz_std: tuple[float, ...] = (NAN, NAN)
    """1-σ of the tilt frequencies, Hz."""
    tilt_pair_resolved: bool = False
    """Whether the data resolve the two tilt modes (else one degenerate frequency is reported twice)."""
    roller_stiffness_n_per_m: float = NAN
    """Contact stiffness per roller from the bounce frequency (rig model), N/m."""
    roller_stiffness_std_n_per_m: float = NAN
    """1-σ of the roller stiffness, N/m."""
    roller_only_stiffness_n_per_m: float | None = None
    """Stiffness with the rig's setup compliance removed when a contact model was given, N/m."""
    roller_only_stiffness_std_n_per_m: float | None = None
    """1-σ of the roller-only stiffness, N/m."""
    roller_stiffness_budget_n_per_m: dict[str, float] = field(default_factory=dict)
    """The roller stiffness's 1-σ by source (modal fit, disc mass, K_setup, rig model), N/m."""
    roller_stiffnesses_n_per_m: tuple[float, ...] = ()
    """Per-roller stiffness in the rig file's roller order (their mean is the roller stiffness), N/m."""
    roller_stiffnesses_std_n_per_m: tuple[float, ...] = ()
    """1-σ of each roller's stiffness (modal fit and rig parameters), N/m."""
    roller_stiffnesses_resolved: bool = False
    """Whether the tilt pair told the rollers apart (else equal rollers were assumed)."""
    roller_stiffness_condition: float | None = None
    """Condition number of the per-roller inverse."""
    rollers_differing: tuple[int, ...] = ()
    """1-based rollers whose stiffness differs from the others' beyond its uncertainty."""
    linearity: dict[str, Any] | None = None
    """Each used impact's bounce frequency against its peak force, the slope and the test's verdict."""
    small_blow: dict[str, Any] | None = None
    """How far the blows' size moved the modes above their small-blow limit (removed from the frequencies)."""
    coherence_at_bounce: float = NAN
    """Coherence at the bounce over the used impacts, 0..1."""
    channels: tuple[str, ...] = ()
    """Response channels of the FRF, in row order."""
    dead_channels: tuple[str, ...] = ()
    """Channels left out because they carried no signal."""
    dropped_channels: tuple[str, ...] = ()
    """Channels saturated in every impact: left out, the step went on with the others."""
    classified_by_shape: bool = True
    """Whether bounce and tilt were told apart by mode shape (else by frequency order)."""
    fs_hz: float = NAN
    """Sample rate of the processed records, Hz."""
    window_decay_rate_per_s: float = NAN
    """Decay rate of the exponential window, 1/s."""
    fit_band_hz: tuple[float, ...] = (NAN, NAN)
    """Frequency band of the modal fit, Hz."""
    modes: tuple[ModeResult, ...] = ()
    """The identified contact modes: bounce first, then tilt."""
    impacts: tuple[ImpactOutcome, ...] = ()
    """Every stored impact of the step and whether identification used it."""
    warnings: tuple[str, ...] = ()
    """What the identification could not vouch for."""
    error: str = ""
    """Why the step could not be identified ("" when it was)."""
    frf: StepFrf | None = field(default=None, compare=False, repr=False)
    """The averaged FRF (not compared; stored as datasets)."""

    @property
    def identified(self) -> bool:
        return not self.error and math.isfinite(self.roller_stiffness_n_per_m)

    @property
    def used_attempts(self) -> tuple[int, ...]:
        """The attempts of the impacts identification averaged."""
        return tuple(i.attempt for i in self.impacts if i.used)

    @property
    def rejected_count(self) -> int:
        return sum(1 for i in self.impacts if not i.used)


# Fields written as datasets or as nested JSON, not as plain attributes.
STRUCTURED_FIELDS = frozenset({"modes", "impacts", "frf"})


def failed_step(reason: str, impacts: Sequence[ImpactOutcome] = ()) -> StepResult:
    """The result of a step that could not be identified."""
    return StepResult(error=reason, impacts=tuple(impacts))


def plain(value: Any) -> Any:
    """A numpy scalar or array as the Python value (float, list) it holds; anything else unchanged."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value.item() if isinstance(value, np.generic) else value


def plain_tuple(values: Any) -> tuple:
    """A sequence (list, tuple or array) as a tuple of Python values."""
    return tuple(plain(np.asarray(values)) if isinstance(values, np.ndarray) else values)


def _plain(value: Any, default: Any) -> Any:
    """A result value as a plain Python value of the field's kind (tuples for sequences)."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(default, tuple) or isinstance(value, list | tuple):
        return tuple(value)
    if isinstance(value, np.generic):
        return value.item()
    return value


def result_from_mapping(values: Mapping[str, Any], frf: StepFrf | None = None) -> StepResult:
    """A StepResult from stored attributes (unknown keys ignored, missing ones default): for old files."""
    kwargs: dict[str, Any] = {}
    for f in fields(StepResult):
        if f.name in STRUCTURED_FIELDS or f.name not in values:
            continue
        kwargs[f.name] = _plain(values[f.name], f.default)
    modes = tuple(ModeResult(str(m["kind"]), float(m["frequency_hz"]), float(m.get("frequency_std_hz", NAN)),
                             float(m.get("damping_ratio", NAN)), float(m.get("damping_ratio_std", NAN)),
                             float(m.get("coherence", NAN)), float(m.get("bounce_mac", NAN)),
                             float(m.get("tilt_fraction", NAN)))
                  for m in values.get("modes", []) if isinstance(m, Mapping))
    impacts = tuple(ImpactOutcome(int(i.get("attempt", i.get("index", 0))), bool(i.get("accepted", i.get("used"))),
                                  tuple(i.get("reasons", ())))
                    for i in values.get("impacts", []) if isinstance(i, Mapping))
    return StepResult(**kwargs, modes=modes, impacts=impacts, frf=frf)


CURVE_COLUMNS = ("step", "load_n", "stiffness_n_per_m", "stiffness_std_n_per_m", "bounce_hz", "bounce_damping_ratio",
                 "tilt_a_hz", "tilt_b_hz", "coherence_at_bounce", "knob_angle_deg")


@dataclass(frozen=True)
class RepetitionCurve:
    """One repetition's stiffness-vs-load table: one entry per identified step, in step order."""

    series: int
    run: int
    specimen: str
    step: np.ndarray
    load_n: np.ndarray
    stiffness_n_per_m: np.ndarray
    stiffness_std_n_per_m: np.ndarray
    bounce_hz: np.ndarray
    bounce_damping_ratio: np.ndarray
    tilt_a_hz: np.ndarray
    tilt_b_hz: np.ndarray
    coherence_at_bounce: np.ndarray
    knob_angle_deg: np.ndarray

    def columns(self) -> dict[str, np.ndarray]:
        return {c: getattr(self, c) for c in CURVE_COLUMNS}

    def __getitem__(self, column: str) -> np.ndarray:
        """Column access kept for scripts written against the earlier dict curves (``curve["load_n"]``)."""
        if column not in CURVE_COLUMNS:
            raise KeyError(column)
        return getattr(self, column)

    def __len__(self) -> int:
        return int(self.load_n.size)


def curve_from_steps(series: int, run: int, specimen: str, steps: Sequence[tuple[int, float, float, StepResult]]
                     ) -> RepetitionCurve:
    """The curve of a repetition from its (step, load, knob angle, result) of identified steps."""
    rows = [(n, load, r.roller_stiffness_n_per_m, r.roller_stiffness_std_n_per_m, r.bounce_hz, r.bounce_damping_ratio,
             *(tuple(r.tilt_hz) + (NAN, NAN))[:2], r.coherence_at_bounce, angle)
            for n, load, angle, r in steps if r.identified]
    cols = [np.array([row[i] for row in rows], dtype=float) for i in range(len(CURVE_COLUMNS))]
    cols[0] = cols[0].astype(int)
    return RepetitionCurve(series, run, specimen, *cols)


def jsonable(value: Any) -> Any:
    """Plain JSON values: dataclasses as objects, numpy scalars and arrays as Python ones, non-finite floats as null."""
    if is_dataclass(value) and not isinstance(value, type):
        return jsonable(asdict(value))
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def result_summary(result: StepResult) -> dict[str, Any]:
    """A StepResult as plain JSON values (no spectra; NaN as null): for catalogues, sidecars and ``--json``."""
    return {f.name: jsonable(getattr(result, f.name)) for f in fields(StepResult) if f.name != "frf"}


@dataclass(frozen=True)
class SpecimenRecord(RollerContact):
    """The specimen of a series as stored: what was mounted between which rails, and the protocol's limits for it.

    Old files may lack a field: it reads as its default. ``case()`` gives the contact case (``RollerContact``)."""

    kind: str = "roller"
    """What was mounted: "roller" (three rollers of one type) or "ball" (calibration balls)."""
    label: str = ""
    """The protocol's name for the specimen (e.g. "roller type 1")."""
    roller_type: int | None = None
    """Catalogue roller type (paper Table 1), None for a roller given by its dimensions or a ball."""
    ball_diameter_m: float | None = None
    """Diameter of a calibration ball, m (None for rollers)."""
    diameter_m: float = NAN
    """Roller diameter, m."""
    contact_length_m: float = NAN
    """Roller contact length L_we, m."""
    roller_length_m: float | None = None
    """Roller overall length, m (None: the contact length)."""
    material: str | None = None
    """Catalogue name of the roller material (None: 1.3505 bearing steel)."""
    youngs_modulus_pa: float | None = None
    """Roller Young's modulus, Pa."""
    poisson_ratio: float | None = None
    """Roller Poisson's ratio."""
    hardness_hrc: float | None = None
    """Roller hardness, HRC."""
    rail_material: str | None = None
    """Catalogue name of the rails' material (None: 1.3505 bearing steel)."""
    rail_ra_m: float = NAN
    """Arithmetic mean roughness Ra of the rails, m."""
    max_load_n: float = NAN
    """The protocol's largest load per roller for this specimen, N."""
    knob_step_deg: float = NAN
    """Knob turn between load steps, degrees."""
    lubrication: str | None = None
    """"dry", "oil" or "grease" (None: not recorded)."""
    lubricant: str | None = None
    """The oil's or grease's product name."""
    orientation_deg: float | None = None
    """Angle between the roller axis and the rails' grinding direction, degrees."""
    roller_ra_m: float | None = None
    """Measured Ra of the rollers, m."""
    rail_ra_measured_m: float | None = None
    """Measured Ra of the rails, m (``rail_ra_m`` is the nominal grade the models use)."""
    roundness_m: float | None = None
    """Measured roundness deviation of the rollers, m."""
    cylindricity_m: float | None = None
    """Measured cylindricity deviation of the rollers, m."""

    @classmethod
    def from_attrs(cls, attrs: Mapping[str, Any]) -> SpecimenRecord:
        """The specimen of stored attributes (other keys, e.g. ``mounted``, ignored; a blank value is None)."""
        kinds = {f.name: f for f in fields(cls)}
        values: dict[str, Any] = {}
        for name, value in attrs.items():
            if name not in kinds or value is None or (isinstance(value, str) and value == "" and name != "label"):
                continue
            value = value.item() if isinstance(value, np.generic) else value
            if name == "roller_type":
                value = int(value)
            elif name in ("kind", "label", "material", "rail_material", "lubrication", "lubricant"):
                value = str(value)
            else:
                value = float(value)
            values[name] = value
        return cls(**values)

    def conditions_text(self) -> str:
        """The recorded conditions in words ("not recorded" when none were given)."""
        parts = []
        if self.lubrication:
            parts.append(self.lubrication + (f" ({self.lubricant})" if self.lubricant else ""))
        if self.orientation_deg is not None:
            parts.append(f"{self.orientation_deg:g}° to the grinding direction")
        for label, value in (("roller Ra", self.roller_ra_m), ("rail Ra measured", self.rail_ra_measured_m),
                             ("roundness", self.roundness_m), ("cylindricity", self.cylindricity_m)):
            if value is not None:
                parts.append(f"{label} {value * 1e6:.3g} µm")
        return ", ".join(parts) or "not recorded"

    def attrs(self) -> dict[str, Any]:
        """The stored attributes (None values are not stored)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    def point(self, repetition: int, load_n: float, stiffness_n_per_m: float, result: StepResult | None = None,
              step: StepInfo | None = None) -> StiffnessPoint:
        """A stiffness-table row for a measured point of this specimen (with the result's uncertainty budget, and
        with ``step`` the load read after its blows and what happened at it)."""
        budget = result.roller_stiffness_budget_n_per_m if result is not None else {}
        std = result.roller_stiffness_std_n_per_m if result is not None else None
        after, flags = step_flags(step, result) if step is not None else (None, None)
        return StiffnessPoint(
            diameter_m=self.diameter_m, contact_length_m=self.contact_length_m, rail_ra_m=self.rail_ra_m,
            load_n=float(load_n), stiffness_n_per_m=float(stiffness_n_per_m), roller_type=self.roller_type,
            roller_length_m=self.roller_length_m, material=self.material, youngs_modulus_pa=self.youngs_modulus_pa,
            poisson_ratio=self.poisson_ratio, hardness_hrc=self.hardness_hrc, repetition=int(repetition),
            rail_material=self.rail_material or None,
            stiffness_std_n_per_m=std if std is not None and math.isfinite(std) else None,
            load_after_n=after, flags=flags,
            **{column: float(budget[key]) for key, column in BUDGET_COLUMNS.items() if key in budget})


def step_flags(step: StepInfo, result: StepResult | None = None) -> tuple[float | None, str | None]:
    """The load read after a step's blows and what happened at it, as the stiffness table's optional columns."""
    r = result if result is not None else step.result
    flags = [FLAG_LOAD_DRIFT] if step.load_drift else []
    if r is not None and (r.dead_channels or r.dropped_channels):
        flags.append(FLAG_CHANNELS)
    if any(i.verdict.source == OPERATOR and i.verdict.accepted != i.checks.accepted for i in step.impacts):
        flags.append(FLAG_OVERRIDE)
    after = step.load_after_n
    return (after if math.isfinite(after) else None), (";".join(flags) or None)
