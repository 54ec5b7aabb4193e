"""The rig description (discs, roller positions, K_setup, support, sensors, loading) read from a TOML file."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from labctl.data import data_path, read_toml
from labctl.data.schema import Integer, Number, Numbers, Spec, Table, Tables, Text, Where, build, parse_toml, read
from labctl.physics.springs import SpringCurve

DEFAULT_RIG = "rigs/paper_rig.toml"
AXES = ("X", "Y", "Z")
DEFAULT_INERTIA_ASYMMETRY_REL = 0.02
DEFAULT_TRANSVERSE_SENSITIVITY = 0.05
DEFAULT_MOUNTING_ANGLE_RAD = math.radians(2.0)


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
    transverse_sensitivity: float | None = None  # None: the rig's [uncertainty] value
    mounting_angle_rad: float | None = None

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
    # The discs' inertia about two diameters is taken equal; a real disc with rails, bolts and sensors is not quite.
    # Each component of the discs' combined asymmetry (I1 - I2)/I · (cos 2φ, sin 2φ), principal axes at any angle
    # φ, has this 1-σ: 2 % splits the tilt pair by ~3 Hz at 584 Hz with equal rollers (docs/processing.md §4).
    inertia_asymmetry_rel: float = DEFAULT_INERTIA_ASYMMETRY_REL
    # Accelerometers' cross-axis coupling: the data sheet's maximum transverse sensitivity of the class (PCB 356A
    # tri-axial ICP: ≤ 5 %) and how far a sensor's axes may be turned on its mount (a glued or stud-mounted block
    # on a machined face: ~2°); a sensor's own entry in [[sensors]] overrides both.
    transverse_sensitivity: float = DEFAULT_TRANSVERSE_SENSITIVITY
    mounting_angle_rad: float = DEFAULT_MOUNTING_ANGLE_RAD


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
    springs: SpringCurve | None = None  # the characterised knob-angle → load curve (``[springs]``), if measured

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


_POSITIVE = Number(gt=0)
DISC: dict[str, Spec] = {"mass_kg": _POSITIVE, "inertia_kg_m2": _POSITIVE, "thickness_mm": Number(gt=0, unit="mm")}
CONTACTS: dict[str, Spec] = {"radius_mm": Number(gt=0, unit="mm"), "angles_deg": Numbers(Number(unit="deg"), 3),
                             "setup_stiffness_n_per_m": _POSITIVE}
SUPPORT: dict[str, Spec] = {"stiffness_n_per_m": _POSITIVE, "radius_mm": Number(gt=0, unit="mm"),
                            "damping_ratio": _POSITIVE}
LOADING: dict[str, Spec] = {"rods": Integer(ge=1), "thread_pitch_mm": Number(gt=0, unit="mm"),
                            "spring_rate_n_per_m": _POSITIVE, "gravity_m_per_s2": _POSITIVE}
UNCERTAINTY: dict[str, Spec] = {"mass_std_kg": Number(ge=0), "setup_stiffness_std_n_per_m": Number(ge=0),
                                "mass_setup_correlation": Number(ge=-1, le=1), "model_rel": Number(ge=0),
                                "inertia_asymmetry_rel": Number(ge=0, le=0.5),
                                "transverse_sensitivity": Number(ge=0, le=0.5),
                                "mounting_angle_deg": Number(ge=0, le=30, unit="deg")}
SPRINGS: dict[str, Spec] = {
    "preload_n": Number(ge=0), "rate_n_per_deg": _POSITIVE, "curvature_n_per_deg2": Number(),
    "hysteresis_n": Number(ge=0), "slack_deg": Number(ge=0), "preload_std_n": Number(ge=0),
    "residual_std_n": Number(ge=0), "covariance": Numbers(Number(), 16), "max_angle_deg": _POSITIVE,
    "source": Text(default=""),
}
POINT: dict[str, Spec] = {"radius_mm": Number(ge=0, unit="mm"), "angle_deg": Number(unit="deg")}
SENSOR: dict[str, Spec] = {"name": Text(), "disc": Text(("upper", "lower")), **POINT,
                           "transverse_sensitivity": Number(ge=0, le=0.5, default=None),
                           "mounting_angle_deg": Number(ge=0, le=30, unit="deg", default=None)}
FLEXIBLE_MODE: dict[str, Spec] = {"frequency_hz": _POSITIVE, "damping_ratio": _POSITIVE, "modal_mass_kg": _POSITIVE,
                                  "hammer": Number(default=1.0), "shape": Table(default={})}
TOP: dict[str, Spec] = {
    "name": Text(default=None), "description": Text(default=None), "upper_disc": Table(), "lower_disc": Table(),
    "contacts": Table(), "uncertainty": Table(default={}), "support": Table(), "damping": Table(),
    "loading": Table(), "hammer": Table(), "sensors": Tables(), "flexible_modes": Tables(default=[]),
    "calibration": Table(default={}), "springs": Table(default=None),
}


def _sensor(entry: dict[str, Any], discs: dict[str, Disc], where: Where) -> Sensor:
    t = read(entry, SENSOR, where)
    r, ang = t["radius_m"], t["angle_rad"]
    # upper-disc sensors sit on its top face, lower-disc sensors on its underside
    z = 0.5 * discs[t["disc"]].thickness_m * (1.0 if t["disc"] == "upper" else -1.0)
    return Sensor(t["name"], t["disc"], r * math.cos(ang), r * math.sin(ang), z, ang,
                  t.get("transverse_sensitivity"), t.get("mounting_angle_rad"))


def _flexible_mode(entry: dict[str, Any], channels: tuple[str, ...], where: Where) -> FlexibleMode:
    t = read(entry, FLEXIBLE_MODE, where)
    raw = t.pop("shape")
    shape = read(raw, dict.fromkeys(channels, Number(default=None)), where.at("shape"))
    return FlexibleMode(**t, shape={ch: shape[ch] for ch in raw})  # in the file's order


def load_rig(path: str | Path | None = None) -> RigConfig:
    """Read a rig file (the shipped paper rig by default), converting to SI and naming any bad field."""
    p = str(path or data_path(DEFAULT_RIG))
    return rig_from_doc(read_toml(p), p)


def rig_from_text(text: str, source: str) -> RigConfig:
    """A rig description from TOML text (e.g. the copy stored in a campaign file); ``source`` names it."""
    return rig_from_doc(parse_toml(text, source), source)


def rig_from_doc(doc: dict[str, Any], p: str) -> RigConfig:
    """Validate a parsed rig document; errors name ``p``, the table and the key (``labctl.data.schema``)."""
    top = Where(p)
    t = read(doc, TOP, top)
    discs = {"upper": build(Disc, t["upper_disc"], DISC, top.at("upper_disc")),
             "lower": build(Disc, t["lower_disc"], DISC, top.at("lower_disc"))}
    contacts = read(t["contacts"], CONTACTS, top.at("contacts"))
    support = read(t["support"], SUPPORT, top.at("support"))
    damping = read(t["damping"], {"modal_damping_ratio": _POSITIVE}, top.at("damping"))
    hammer = read(t["hammer"], POINT, top.at("hammer"))
    h_r, h_a = hammer["radius_m"], hammer["angle_rad"]
    sensors = tuple(_sensor(e, discs, top.at("sensors").at(i)) for i, e in enumerate(t["sensors"]))
    channels = tuple(ch for s in sensors for ch in s.channels)
    flex = tuple(_flexible_mode(e, channels, top.at("flexible_modes").at(i))
                 for i, e in enumerate(t["flexible_modes"]))
    return RigConfig(
        name=t.get("name", Path(p).stem),
        upper=discs["upper"],
        lower=discs["lower"],
        contact_radius_m=contacts["radius_m"],
        contact_angles_rad=contacts["angles_rad"],
        setup_stiffness_n_per_m=contacts["setup_stiffness_n_per_m"],
        support_stiffness_n_per_m=support["stiffness_n_per_m"],
        support_radius_m=support["radius_m"],
        support_damping_ratio=support["damping_ratio"],
        modal_damping_ratio=damping["modal_damping_ratio"],
        loading=build(Loading, t["loading"], LOADING, top.at("loading")),
        hammer_xy_m=(h_r * math.cos(h_a), h_r * math.sin(h_a)),
        sensors=sensors,
        flexible_modes=flex,
        source=p,
        uncertainty=build(RigUncertainty, t["uncertainty"], UNCERTAINTY, top.at("uncertainty")),
        calibration=dict(t["calibration"]),
        springs=None if t.get("springs") is None else build(SpringCurve, t["springs"], SPRINGS, top.at("springs")),
    )
