"""Units at the edge: files and operators speak mm, µm, GPa, mrad, ms; everything inside labctl is SI.

A quantity's unit is the suffix of its name (``thickness_mm``, ``rail_ra_um``, ``youngs_modulus_gpa``); converting
a value converts its name too (``thickness_mm`` → ``thickness_m``), so a key read from a file always says which
unit its number is in. This is the one table of edge units: file readers, the world's effect parameters and the
protocol's check thresholds all convert through it.
"""

from __future__ import annotations

import math

MM = 1e-3
UM = 1e-6
GPA = 1e9
MRAD = 1e-3
MS = 1e-3
DEG = math.pi / 180.0
MV = 1e-3  # sensitivities in mV per unit
STANDARD_GRAVITY_M_PER_S2 = 9.80665  # accelerations and ranges in g

# edge unit -> (SI unit, factor to SI); the name suffix is ``_<unit>``
EDGE_UNITS: dict[str, tuple[str, float]] = {
    "mm": ("m", MM), "um": ("m", UM), "gpa": ("pa", GPA), "mrad": ("rad", MRAD), "ms": ("s", MS), "ma": ("a", 1e-3),
}
# the edge units a name suffix converts by itself (``to_si``); others (mA, deg) are converted where read
AUTO_UNITS = ("mm", "um", "mrad", "ms", "gpa")


def factor(unit: str) -> float:
    """The factor from an edge unit to SI (``factor("mm") == 1e-3``); an SI or empty unit gives 1."""
    unit = unit.lower()
    if unit in ("", "m", "s", "pa", "rad", "a", "n", "kg", "hz"):
        return 1.0
    if unit == "deg":
        return DEG
    if unit not in EDGE_UNITS:
        raise KeyError(f"unknown edge unit {unit!r}; known: {', '.join(EDGE_UNITS)}, deg")
    return EDGE_UNITS[unit][1]


def si_name(key: str, unit: str) -> str:
    """The SI name of an edge key in ``unit``: ``si_name("thickness_mm", "mm") == "thickness_m"``.

    A key that does not end in ``_<unit>`` (or a unit without an SI rename, like ``deg``) keeps its name.
    """
    unit = unit.lower()
    if unit in EDGE_UNITS and key.endswith(f"_{unit}"):
        return f"{key[: -len(unit)]}{EDGE_UNITS[unit][0]}"
    if unit == "deg" and key.endswith("_deg"):
        return f"{key[:-3]}rad"
    return key


def edge_name(si_key: str, unit: str) -> str:
    """The name of an SI quantity at the edge in ``unit``: ``edge_name("pulse_width_min_s", "ms")`` → ``..._ms``."""
    unit = unit.lower()
    si = EDGE_UNITS[unit][0] if unit in EDGE_UNITS else "rad" if unit == "deg" else ""
    if si and si_key.endswith(f"_{si}"):
        return f"{si_key[: -len(si)]}{unit}"
    return si_key


def unit_of(key: str) -> str:
    """The edge unit a key's suffix names among the automatically converted ones (``""`` if none)."""
    return next((u for u in AUTO_UNITS if key.endswith(f"_{u}")), "")


def to_si(key: str, value: float) -> tuple[str, float]:
    """``("edge_length_mm", 0.1)`` → ``("edge_length_m", 1e-4)``; keys without an edge unit pass unchanged."""
    unit = unit_of(key)
    if not unit:
        return key, value
    return si_name(key, unit), value * factor(unit)


def from_si(si_key: str, value: float, unit: str) -> tuple[str, float]:
    """The inverse of ``to_si`` for a chosen edge unit: ``("tilt_rad", 2e-3), "mrad"`` → ``("tilt_mrad", 2.0)``."""
    return edge_name(si_key, unit), value / factor(unit)
