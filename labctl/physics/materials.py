"""Elastic materials and the effective contact modulus (docs/contracts.md, physics conventions)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, cached_property
from pathlib import Path

import numpy as np

from labctl.data import data_path, read_toml
from labctl.data.schema import Number, Spec, Table, Text, Where, read
from labctl.data.units import GPA
from labctl.errors import InputError

__all__ = ["BEARING_STEEL", "GPA", "Material", "effective_modulus", "hardness_pa", "material", "materials"]


@dataclass(frozen=True)
class Material:
    """An isotropic elastic material: E in Pa, Poisson's ratio, hardness in HRC."""

    name: str
    youngs_modulus_pa: float
    poisson_ratio: float
    hardness_hrc: float = 60.0

    def __post_init__(self) -> None:
        e, nu = self.youngs_modulus_pa, self.poisson_ratio
        if type(e) is float and type(nu) is float:  # the common case, built thousands of times in a fit
            e_ok, nu_ok = e > 0, -1.0 < nu < 0.5
        else:  # arrays too: a stack of cases (stack_cases)
            e_ok = bool(np.all(np.asarray(e) > 0))
            nu_ok = bool(np.all((np.asarray(nu) > -1.0) & (np.asarray(nu) < 0.5)))
        if not e_ok:
            raise InputError(f"material {self.name}: Young's modulus {e!r} Pa must be > 0")
        if not nu_ok:
            raise InputError(f"material {self.name}: Poisson ratio {nu!r} must lie in (-1, 0.5)")

    @cached_property
    def plane_strain_compliance(self) -> float:
        """(1 - ν²)/E in 1/Pa: this body's share of 1/E*."""
        return (1.0 - self.poisson_ratio**2) / self.youngs_modulus_pa


def effective_modulus(a: Material, b: Material) -> float:
    """E* in Pa with 1/E* = (1-ν₁²)/E₁ + (1-ν₂²)/E₂ (the seed's Eq. 3 prints the sum itself: a slip)."""
    return 1.0 / (a.plane_strain_compliance + b.plane_strain_compliance)


MATERIAL: dict[str, Spec] = {
    "description": Text(default=""),
    "youngs_modulus_gpa": Number(gt=0, unit="gpa"),
    "poisson_ratio": Number(gt=-1, lt=0.5),
    "hardness_hrc": Number(ge=0, le=100, default=60.0),
}


@cache
def _catalogue(path: str) -> dict[str, Material]:
    top = Where(path)
    table = read(read_toml(path), {"materials": Table()}, top)["materials"]
    out: dict[str, Material] = {}
    for name, entry in table.items():
        t = read(entry, MATERIAL, top.at("materials").at(name))
        out[name] = Material(name=name, youngs_modulus_pa=t["youngs_modulus_pa"], poisson_ratio=t["poisson_ratio"],
                             hardness_hrc=t["hardness_hrc"])
    return out


def materials(path: str | Path | None = None) -> dict[str, Material]:
    """The material catalogue (shipped ``materials.toml`` unless another file is given)."""
    return dict(_catalogue(str(path or data_path("materials.toml"))))


def material(name: str) -> Material:
    """Look a material up by catalogue name, e.g. ``"1.3505"``."""
    cat = materials()
    if name not in cat:
        raise InputError(f"unknown material {name!r}; known: {', '.join(sorted(cat))}")
    return cat[name]


BEARING_STEEL = "1.3505"


# Rockwell C to Vickers (ASTM E140, steels; above HRC 68 extrapolated for hard ceramics).
_HRC = (20.0, 30.0, 40.0, 50.0, 54.0, 60.0, 65.0, 68.0, 90.0)
_HV = (238.0, 302.0, 392.0, 513.0, 577.0, 697.0, 832.0, 940.0, 1600.0)


def hardness_pa(hardness_hrc: float) -> float:
    """Indentation hardness in Pa (Vickers HV·9.807 MPa) from a Rockwell C number (or an array of them)."""
    hv = np.interp(hardness_hrc, _HRC, _HV)
    return (float(hv) if np.ndim(hv) == 0 else hv) * 9.80665e6
