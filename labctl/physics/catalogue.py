"""Roller types of the paper's Table 1, read from the shipped catalogue file."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

from labctl.data import data_path, positive, read_toml, require
from labctl.errors import InputError
from labctl.physics.materials import Material, material

MM = 1e-3
UM = 1e-6


@dataclass(frozen=True)
class Roller:
    """A cylindrical roller: diameter, effective contact length L_we, total length L_r (all m)."""

    diameter_m: float
    contact_length_m: float
    total_length_m: float
    material: Material
    roughness_ra_m: float = 0.03 * UM
    type_id: int | None = None

    @property
    def radius_m(self) -> float:
        return 0.5 * self.diameter_m


@cache
def _rollers(path: str) -> dict[int, Roller]:
    doc = read_toml(path)
    default_ra = float(doc.get("default_roughness_ra_um", 0.03))
    out: dict[int, Roller] = {}
    for i, entry in enumerate(require(doc, "rollers", list, path)):
        where = f"{path}: rollers[{i}]"
        type_id = require(entry, "type", int, where)
        out[type_id] = Roller(
            diameter_m=positive(entry, "diameter_mm", where) * MM,
            contact_length_m=positive(entry, "contact_length_mm", where) * MM,
            total_length_m=positive(entry, "total_length_mm", where) * MM,
            material=material(require(entry, "material", str, where)),
            roughness_ra_m=float(entry.get("roughness_ra_um", default_ra)) * UM,
            type_id=type_id,
        )
    return out


def rollers(path: str | Path | None = None) -> dict[int, Roller]:
    """All catalogue roller types keyed by type number."""
    return dict(_rollers(str(path or data_path("rollers.toml"))))


def roller(type_id: int) -> Roller:
    """One roller type from Table 1; an unknown number names the valid ones."""
    cat = rollers()
    if type_id not in cat:
        raise InputError(f"unknown roller type {type_id}; valid types: {', '.join(map(str, sorted(cat)))}")
    return cat[type_id]
