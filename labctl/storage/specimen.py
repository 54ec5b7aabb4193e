"""The specimen of a series as stored, typed: one documented field per attribute of ``/series_SS``."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np

from labctl.data.conditions import SpecimenConditions
from labctl.stiffness_table import (
    BUDGET_COLUMNS,
    FLAG_CHANNELS,
    FLAG_LOAD_DRIFT,
    FLAG_OVERRIDE,
    RollerContact,
    StiffnessPoint,
)
from labctl.storage.records import OPERATOR

if TYPE_CHECKING:
    from labctl.storage.reader import StepInfo
    from labctl.storage.records import StepResult

NAN = math.nan


@dataclass(frozen=True)
class SpecimenRecord(RollerContact, SpecimenConditions):
    """The specimen of a series as stored: what was mounted between which rails, and the protocol's limits for it.

    Old files may lack a field: it reads as its default. ``case()`` gives the contact case (``RollerContact``); the
    recorded conditions are the fields of ``SpecimenConditions``."""

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
              load_std_n: float | None = None, step: StepInfo | None = None) -> StiffnessPoint:
        """A stiffness-table row for a measured point of this specimen (with the result's uncertainty budget, and
        with ``step`` the load read after its blows, what happened at it and the spring curve's load 1-σ)."""
        budget = result.roller_stiffness_budget_n_per_m if result is not None else {}
        std = result.roller_stiffness_std_n_per_m if result is not None else None
        after, flags = step_flags(step, result) if step is not None else (None, None)
        if load_std_n is None and step is not None:
            load_std_n = step.attrs.get("load_std_n")
        return StiffnessPoint(
            diameter_m=self.diameter_m, contact_length_m=self.contact_length_m, rail_ra_m=self.rail_ra_m,
            load_n=float(load_n), stiffness_n_per_m=float(stiffness_n_per_m), roller_type=self.roller_type,
            roller_length_m=self.roller_length_m, material=self.material, youngs_modulus_pa=self.youngs_modulus_pa,
            poisson_ratio=self.poisson_ratio, hardness_hrc=self.hardness_hrc, repetition=int(repetition),
            rail_material=self.rail_material or None,
            stiffness_std_n_per_m=std if std is not None and math.isfinite(std) else None,
            load_std_n=float(load_std_n) if load_std_n is not None and math.isfinite(load_std_n) else None,
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
