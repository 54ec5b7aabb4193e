"""Roller types of the paper's Table 1, read from the shipped catalogue file."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

from labctl.data import data_path, read_toml
from labctl.data.schema import Integer, Number, Spec, Tables, Text, Where, read
from labctl.data.units import MM, UM
from labctl.errors import InputError
from labctl.physics.materials import Material, material, materials

__all__ = ["MM", "UM", "Roller", "roller", "rollers"]


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


ROLLER: dict[str, Spec] = {
    "type": Integer(ge=1),
    "diameter_mm": Number(gt=0, unit="mm"),
    "contact_length_mm": Number(gt=0, unit="mm"),
    "total_length_mm": Number(gt=0, unit="mm"),
    "material": Text(),
    "roughness_ra_um": Number(ge=0, unit="um", default=None),
}


@cache
def _rollers(path: str) -> dict[int, Roller]:
    top = Where(path)
    doc = read(read_toml(path), {"default_roughness_ra_um": Number(ge=0, unit="um", default=0.03),
                                 "rollers": Tables()}, top)
    known = tuple(materials())
    out: dict[int, Roller] = {}
    for i, entry in enumerate(doc["rollers"]):
        where = top.at("rollers").at(i)
        t = read(entry, {**ROLLER, "material": Text(known)}, where)
        if t["type"] in out:
            raise where.bad("type", t["type"], f"a type number not used before (types so far: {sorted(out)})")
        if t["contact_length_m"] > t["total_length_m"]:
            raise where.bad("contact_length_mm", entry["contact_length_mm"],
                            f"at most total_length_mm = {entry['total_length_mm']!r} (L_we ≤ L_r)")
        out[t["type"]] = Roller(
            diameter_m=t["diameter_m"],
            contact_length_m=t["contact_length_m"],
            total_length_m=t["total_length_m"],
            material=material(t["material"]),
            roughness_ra_m=t.get("roughness_ra_m", doc["default_roughness_ra_m"]),
            type_id=t["type"],
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
