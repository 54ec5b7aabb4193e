"""The validated protocol: what the engine runs, in SI units."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from labctl.data.conditions import SpecimenConditions
from labctl.data.units import UM
from labctl.physics import ContactCase, Roller, material, roller, static_load_rating_n
from labctl.processing import CheckConfig
from labctl.protocol.static import StaticSpec

SpecimenKind = Literal["roller", "ball"]


@dataclass(frozen=True)
class SpecimenSpec:
    """What sits between the rails: a catalogue roller type or a ball, on rails of a material and roughness."""

    kind: SpecimenKind
    label: str
    roller_type: int | None
    ball_diameter_m: float | None
    ball_material: str
    rail_material: str
    rail_ra_m: float
    max_load_n: float
    knob_step_deg: float
    conditions: SpecimenConditions = SpecimenConditions()

    def case(self) -> ContactCase:
        """The contact case this specimen makes (for a ball: a 'roller' of the ball's diameter)."""
        rail = material(self.rail_material)
        if self.kind == "roller":
            assert self.roller_type is not None
            return ContactCase(roller(self.roller_type), rail, self.rail_ra_m)
        assert self.ball_diameter_m is not None
        ball = Roller(self.ball_diameter_m, self.ball_diameter_m, self.ball_diameter_m, material(self.ball_material),
                      roughness_ra_m=0.02 * UM)
        return ContactCase(ball, rail, self.rail_ra_m)

    @property
    def reference_model(self) -> str:
        return "hertz" if self.kind == "ball" else "tripp"


@dataclass(frozen=True)
class LoadingSpec:
    knob_step_deg: float = 180.0
    max_load_fraction_c0: float = 0.30
    c0_length: Literal["total", "contact"] = "total"
    max_steps: int = 60
    settle_timeout_s: float = 30.0
    settle_poll_s: float = 0.1
    load_tolerance_fraction: float = 0.05
    load_source: Literal["load_cell", "springs"] = "load_cell"  # springs: the rig file's [springs] curve, no cell


@dataclass(frozen=True)
class AcquisitionSpec:
    sample_rate_hz: float = 20480.0
    samples: int = 65536
    pretrigger_samples: int = 256
    trigger_level_n: float = 20.0
    impacts_per_step: int = 3
    max_rehits: int = 5
    timeout_s: float = 60.0
    retries: int = 2


@dataclass(frozen=True)
class RepetitionSpec:
    count: int = 3
    rotate_rollers_deg: float = 5.0


@dataclass(frozen=True)
class Protocol:
    """A parsed, validated test protocol; ``source_text`` is stored verbatim in every campaign file."""

    name: str
    description: str
    specimens: tuple[SpecimenSpec, ...]
    loading: LoadingSpec
    acquisition: AcquisitionSpec
    repetitions: RepetitionSpec
    checks: CheckConfig = field(default_factory=CheckConfig)
    source_path: str = ""
    source_text: str = ""
    static: StaticSpec | None = None  # the static load–displacement method (§2.5), when the protocol asks for it

    @property
    def duration_s(self) -> float:
        return self.acquisition.samples / self.acquisition.sample_rate_hz


def c0_cap_n(kind: SpecimenKind, roller_type: int | None, rail_material: str, loading: LoadingSpec) -> float | None:
    """The protocol's load cap for a roller: a fraction of its static load rating C0 (None for balls)."""
    if kind != "roller" or roller_type is None:
        return None
    return loading.max_load_fraction_c0 * static_load_rating_n(roller(roller_type), material(rail_material),
                                                              loading.c0_length)
