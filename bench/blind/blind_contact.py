"""Catalogue and Tripp baseline for the blind worlds, written from the paper's Eqs. (1)-(3) alone.

Only the roller/material catalogue is read from labctl (Table 1 of the paper, as TOML data), so the worlds
stay independent of the library's own contact code; the test checks this baseline against labctl's Tripp.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DATA_DIR = Path(__file__).resolve().parents[2] / "labctl" / "data"
DEPTH_M = 3e-3  # the rail's evaluation depth t
RAIL_MATERIAL = "1.3505"  # steel/steel gives E* = 114.6 GPa
C0_PRESSURE_PA = 4000e6  # static rating: contact pressure 4000 MPa on a flat raceway
PRELOAD_N = 38.0  # weight of the upper disc and rails per roller


@dataclass(frozen=True)
class Mat:
    """Elastic constants and hardness of one catalogue material."""

    name: str
    youngs_pa: float
    poisson: float
    hardness_hrc: float

    @property
    def compliance(self) -> float:
        """Plane-strain compliance (1 - ν²)/E in 1/Pa."""
        return (1.0 - self.poisson**2) / self.youngs_pa


@dataclass(frozen=True)
class RollerSpec:
    """One roller type of Table 1 (SI units)."""

    type: int
    diameter_m: float
    contact_length_m: float
    total_length_m: float
    material: Mat

    @property
    def radius_m(self) -> float:
        return self.diameter_m / 2.0


def load_materials() -> dict[str, Mat]:
    """Materials of the catalogue keyed by name."""
    raw = tomllib.loads((DATA_DIR / "materials.toml").read_text(encoding="utf-8"))["materials"]
    return {
        name: Mat(name, float(m["youngs_modulus_gpa"]) * 1e9, float(m["poisson_ratio"]), float(m["hardness_hrc"]))
        for name, m in raw.items()
    }


def load_rollers() -> dict[int, RollerSpec]:
    """Roller types of the catalogue keyed by type number."""
    mats = load_materials()
    raw = tomllib.loads((DATA_DIR / "rollers.toml").read_text(encoding="utf-8"))["rollers"]
    return {
        int(r["type"]): RollerSpec(
            int(r["type"]), float(r["diameter_mm"]) * 1e-3, float(r["contact_length_mm"]) * 1e-3,
            float(r["total_length_mm"]) * 1e-3, mats[str(r["material"])],
        )
        for r in raw
    }


def effective_modulus_pa(roller: Mat, rail: Mat) -> float:
    """E* with 1/E* = (1-ν₁²)/E₁ + (1-ν₂²)/E₂."""
    return 1.0 / (roller.compliance + rail.compliance)


def half_width_m(p_n_per_m: np.ndarray, radius_m: float, e_star_pa: float) -> np.ndarray:
    """Line-contact half-width a = sqrt(4PR/(πE*))."""
    return np.sqrt(4.0 * p_n_per_m * radius_m / (np.pi * e_star_pa))


def compliance_per_length(
    p_n_per_m: np.ndarray, radius_m: float, roller: Mat, rail: Mat, rail_compliance: np.ndarray | None = None
) -> np.ndarray:
    """Tangent compliance per unit length dδ/dP (m²/N) of roller + two rails (derivative of Eqs. 1-2).

    `rail_compliance` overrides the rail's (1-ν²)/E point by point (a coated rail); E* follows it.
    """
    c_rail_mat = np.full_like(p_n_per_m, rail.compliance) if rail_compliance is None else rail_compliance
    e_star = 1.0 / (roller.compliance + c_rail_mat)
    a = np.sqrt(4.0 * p_n_per_m * radius_m / (np.pi * e_star))
    nu = rail.poisson
    roller_term = 4.0 * roller.compliance / np.pi * (np.log(4.0 * radius_m / a) - 1.0)
    rail_term = 2.0 * c_rail_mat / np.pi * (2.0 * np.log(2.0 * DEPTH_M / a) - nu / (1.0 - nu) - 1.0)
    return roller_term + rail_term


def tripp_stiffness(load_n: np.ndarray, length_m: float | np.ndarray, radius_m: float, roller: Mat,
                    rail: Mat) -> np.ndarray:
    """Tangent stiffness dF/dδ (N/m) of Tripp's line contact over `length_m`."""
    load = np.asarray(load_n, dtype=float)
    return length_m / compliance_per_length(load / length_m, radius_m, roller, rail)


def static_rating_n(spec: RollerSpec, rail: Mat) -> float:
    """C0 of one roller on a flat: the load giving 4000 MPa peak line-contact pressure over the total length.

    p0 = sqrt(P E*/(πR)) so P = p0² πR/E*; the total length reproduces the paper's 440 N (30 %) for type 1.
    """
    e_star = effective_modulus_pa(spec.material, rail)
    return C0_PRESSURE_PA**2 * np.pi * spec.radius_m / e_star * spec.total_length_m


def peak_pressure_pa(p_n_per_m: np.ndarray, radius_m: float, e_star_pa: float) -> np.ndarray:
    """Hertz line-contact peak pressure p0 = sqrt(P E*/(πR))."""
    return np.sqrt(p_n_per_m * e_star_pa / (np.pi * radius_m))


# Vickers hardness of the Rockwell C scale (ASTM E140 table, rounded), to turn HRC into a pressure.
_HRC = np.array([20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 65.0, 68.0])
_HV = np.array([238.0, 302.0, 392.0, 513.0, 595.0, 697.0, 832.0, 940.0])


def hardness_pa(hrc: float) -> float:
    """Indentation hardness (Pa) from HRC via HV (kgf/mm²); beyond the table the end values extrapolate flat."""
    return float(np.interp(hrc, _HRC, _HV)) * 9.80665e6
