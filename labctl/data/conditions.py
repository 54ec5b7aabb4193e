"""The conditions of a test recorded with its specimen: one definition for the protocol and the stored record."""

from __future__ import annotations

from dataclasses import dataclass

LUBRICATIONS = ("dry", "oil", "grease")


@dataclass(frozen=True)
class SpecimenConditions:
    """Conditions of the test recorded with the specimen (paper §3.2–3.3): stored, indexed, reported and
    comparable with ``labctl compare``; no model uses them (the paper found lubrication and orientation
    without significant effect)."""

    lubrication: str | None = None
    """"dry", "oil" or "grease"."""
    lubricant: str | None = None
    """The oil's or grease's product name."""
    orientation_deg: float | None = None
    """Angle between the roller axis and the rails' grinding direction, degrees (0: parallel)."""
    roller_ra_m: float | None = None
    """Measured Ra of the rollers, m."""
    rail_ra_measured_m: float | None = None
    """Measured Ra of the rails, m (the specimen's ``rail_ra_um`` is the nominal grade the models use)."""
    roundness_m: float | None = None
    """Measured roundness deviation of the rollers, m."""
    cylindricity_m: float | None = None
    """Measured cylindricity deviation of the rollers, m."""


__all__ = ["LUBRICATIONS", "SpecimenConditions"]
