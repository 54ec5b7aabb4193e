"""The rig description (discs, roller positions, K_setup, support, sensors, loading) read from a TOML file."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from labctl.data import data_path, positive, read_toml, require
from labctl.errors import InputError

MM = 1e-3
DEFAULT_RIG = "rigs/paper_rig.toml"
AXES = ("X", "Y", "Z")


@dataclass(frozen=True)
class Disc:
    mass_kg: float
    inertia_kg_m2: float
    thickness_m: float


@dataclass(frozen=True)
class Sensor:
    """A tri-axial accelerometer; position relative to its disc's centre of mass, axes X radial, Y tangential."""

    name: str
    disc: str
    x_m: float
    y_m: float
    z_m: float
    angle_rad: float

    @property
    def channels(self) -> tuple[str, str, str]:
        return tuple(f"{self.name}{axis}" for axis in AXES)  # type: ignore[return-value]


@dataclass(frozen=True)
class FlexibleMode:
    """A disc bending mode: frequency, damping, modal mass and relative amplitude per channel and at the hammer."""

    frequency_hz: float
    damping_ratio: float
    modal_mass_kg: float
    hammer: float
    shape: dict[str, float]


@dataclass(frozen=True)
class Loading:
    """How star-knob turns become load: rods with spring pairs compressed by the knob's thread."""

    rods: int
    thread_pitch_m: float
    spring_rate_n_per_m: float
    gravity_m_per_s2: float = 9.81


@dataclass(frozen=True)
class RigUncertainty:
    """1-σ uncertainties of the rig parameters that set every reported stiffness (from the rig file)."""

    mass_std_kg: float = 0.0  # the disc mass (both discs, as in Eq. 4)
    setup_stiffness_std_n_per_m: float = 0.0  # K_setup
    mass_setup_correlation: float = 0.0  # correlation of the two estimates (a calibration fit gives it)
    model_rel: float = 0.0  # relative stiffness error of the rig model's idealisation (rigid discs, point contacts)


@dataclass(frozen=True)
class RigConfig:
    """Everything the rig dynamics and the simulator need to know about the physical setup."""

    name: str
    upper: Disc
    lower: Disc
    contact_radius_m: float
    contact_angles_rad: tuple[float, ...]
    setup_stiffness_n_per_m: float
    support_stiffness_n_per_m: float
    support_radius_m: float
    support_damping_ratio: float
    modal_damping_ratio: float
    loading: Loading
    hammer_xy_m: tuple[float, float]
    sensors: tuple[Sensor, ...]
    flexible_modes: tuple[FlexibleMode, ...] = field(default=())
    source: str = ""
    uncertainty: RigUncertainty = RigUncertainty()
    calibration: dict[str, Any] = field(default_factory=dict)  # provenance of a calibrated rig (empty: nominal)

    @property
    def contact_xy_m(self) -> np.ndarray:
        """(3, 2) positions of the roller contacts in the disc plane."""
        ang = np.asarray(self.contact_angles_rad)
        return self.contact_radius_m * np.column_stack([np.cos(ang), np.sin(ang)])

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(ch for s in self.sensors for ch in s.channels)

    @property
    def roller_count(self) -> int:
        return len(self.contact_angles_rad)

    @property
    def preload_per_roller_n(self) -> float:
        """Initial load on each roller: the upper disc and its rails resting on the rollers."""
        return self.upper.mass_kg * self.loading.gravity_m_per_s2 / self.roller_count

    @property
    def load_per_knob_degree_n(self) -> float:
        """Load per roller added by one degree of star-knob turn: every rod's spring pair, shared by the rollers."""
        lo = self.loading
        return lo.rods * lo.spring_rate_n_per_m * lo.thread_pitch_m / 360.0 / self.roller_count

    def with_setup_stiffness(self, k_setup_n_per_m: float) -> RigConfig:
        """The same rig with another K_setup (e.g. stress stiffening)."""
        from dataclasses import replace

        return replace(self, setup_stiffness_n_per_m=k_setup_n_per_m)


def _disc(doc: dict[str, Any], key: str, where: str) -> Disc:
    t = require(doc, key, dict, where)
    w = f"{where}: {key}"
    return Disc(positive(t, "mass_kg", w), positive(t, "inertia_kg_m2", w), positive(t, "thickness_mm", w) * MM)


def _sensor(entry: dict[str, Any], discs: dict[str, Disc], where: str) -> Sensor:
    name = require(entry, "name", str, where)
    disc = require(entry, "disc", str, where)
    if disc not in discs:
        raise InputError(f"{where}.disc = {disc!r}: expected 'upper' or 'lower'")
    r = require(entry, "radius_mm", float, where) * MM
    ang = math.radians(require(entry, "angle_deg", float, where))
    # upper-disc sensors sit on its top face, lower-disc sensors on its underside
    z = 0.5 * discs[disc].thickness_m * (1.0 if disc == "upper" else -1.0)
    return Sensor(name, disc, r * math.cos(ang), r * math.sin(ang), z, ang)


def _uncertainty(doc: dict[str, Any], where: str) -> RigUncertainty:
    table = doc.get("uncertainty", {})
    if not isinstance(table, dict):
        raise InputError(f"{where}: uncertainty = {table!r}: expected a table")
    known = {"mass_std_kg", "setup_stiffness_std_n_per_m", "mass_setup_correlation", "model_rel"}
    for key in table:
        if key not in known:
            raise InputError(f"{where}: uncertainty.{key}: unknown key; expected one of {', '.join(sorted(known))}")
    values = {}
    for key in known:
        if key in table:
            v = require(table, key, float, f"{where}: uncertainty")
            lo = -1.0 if key == "mass_setup_correlation" else 0.0
            hi = 1.0 if key == "mass_setup_correlation" else math.inf
            if not (math.isfinite(v) and lo <= v <= hi):
                raise InputError(f"{where}: uncertainty.{key} = {v!r}: expected a finite number in [{lo:g}, {hi:g}]")
            values[key] = v
    return RigUncertainty(**values)


def load_rig(path: str | Path | None = None) -> RigConfig:
    """Read a rig file (the shipped paper rig by default), converting to SI and naming any bad field."""
    p = str(path or data_path(DEFAULT_RIG))
    return rig_from_doc(read_toml(p), p)


def rig_from_text(text: str, source: str) -> RigConfig:
    """A rig description from TOML text (e.g. the copy stored in a campaign file); ``source`` names it."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{source}: not valid TOML ({exc})") from None
    return rig_from_doc(doc, source)


def rig_from_doc(doc: dict[str, Any], p: str) -> RigConfig:
    """Validate a parsed rig document; errors name ``p`` and the key."""
    discs = {"upper": _disc(doc, "upper_disc", p), "lower": _disc(doc, "lower_disc", p)}
    contacts = require(doc, "contacts", dict, p)
    angles = require(contacts, "angles_deg", list, f"{p}: contacts")
    if len(angles) != 3:
        raise InputError(f"{p}: contacts.angles_deg = {angles!r}: expected three roller positions")
    support = require(doc, "support", dict, p)
    loading = require(doc, "loading", dict, p)
    hammer = require(doc, "hammer", dict, p)
    h_r = require(hammer, "radius_mm", float, f"{p}: hammer") * MM
    h_a = math.radians(require(hammer, "angle_deg", float, f"{p}: hammer"))
    sensors = tuple(
        _sensor(e, discs, f"{p}: sensors[{i}]") for i, e in enumerate(require(doc, "sensors", list, p))
    )
    flex = tuple(
        FlexibleMode(
            frequency_hz=positive(e, "frequency_hz", f"{p}: flexible_modes[{i}]"),
            damping_ratio=positive(e, "damping_ratio", f"{p}: flexible_modes[{i}]"),
            modal_mass_kg=positive(e, "modal_mass_kg", f"{p}: flexible_modes[{i}]"),
            hammer=float(e.get("hammer", 1.0)),
            shape={str(k): float(v) for k, v in e.get("shape", {}).items()},
        )
        for i, e in enumerate(doc.get("flexible_modes", []))
    )
    return RigConfig(
        name=str(doc.get("name", Path(p).stem)),
        upper=discs["upper"],
        lower=discs["lower"],
        contact_radius_m=positive(contacts, "radius_mm", f"{p}: contacts") * MM,
        contact_angles_rad=tuple(math.radians(float(a)) for a in angles),
        setup_stiffness_n_per_m=positive(contacts, "setup_stiffness_n_per_m", f"{p}: contacts"),
        support_stiffness_n_per_m=positive(support, "stiffness_n_per_m", f"{p}: support"),
        support_radius_m=positive(support, "radius_mm", f"{p}: support") * MM,
        support_damping_ratio=positive(support, "damping_ratio", f"{p}: support"),
        modal_damping_ratio=positive(require(doc, "damping", dict, p), "modal_damping_ratio", f"{p}: damping"),
        loading=Loading(
            rods=require(loading, "rods", int, f"{p}: loading"),
            thread_pitch_m=positive(loading, "thread_pitch_mm", f"{p}: loading") * MM,
            spring_rate_n_per_m=positive(loading, "spring_rate_n_per_m", f"{p}: loading"),
            gravity_m_per_s2=float(loading.get("gravity_m_per_s2", 9.81)),
        ),
        hammer_xy_m=(h_r * math.cos(h_a), h_r * math.sin(h_a)),
        sensors=sensors,
        flexible_modes=flex,
        source=p,
        uncertainty=_uncertainty(doc, p),
        calibration=dict(require(doc, "calibration", dict, p)) if "calibration" in doc else {},
    )
