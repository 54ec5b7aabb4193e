"""The judge's own line-contact physics: catalogue rows, Tripp's approach and tangent stiffness, C0, loads.

Written from the formulas of the brief (Tripp's roller + two rails at depth t), not from labctl's code, so that
the judge shares no implementation with the method it scores; tests cross-check it against labctl's baseline.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "labctl" / "data"
DEPTH_M = 3e-3
P0_RATING_PA = 4.0e9  # Hertz line-contact pressure that defines the static rating C0
RAIL = "1.3505"  # the rails are bearing steel (paper Table 2)
# Vickers hardness from Rockwell C (standard conversion table points); Si3N4 given directly in HV.
_HRC = np.array([20.0, 30.0, 40.0, 50.0, 54.0, 58.0, 60.0, 62.0, 65.0, 68.0])
_HV = np.array([238.0, 302.0, 392.0, 513.0, 577.0, 653.0, 697.0, 746.0, 832.0, 940.0])
HV_CERAMIC = 1550.0
G = 9.80665


@dataclass(frozen=True)
class Mat:
    """Elastic constants and hardness of one catalogue material."""

    name: str
    e_pa: float
    nu: float
    hrc: float

    @property
    def plane_strain(self) -> float:
        return (1.0 - self.nu**2) / self.e_pa

    @property
    def hardness_pa(self) -> float:
        """Vickers hardness in Pa (HRC converted; ceramics above the HRC table use a typical HV)."""
        hv = HV_CERAMIC if self.hrc > 70 else float(np.interp(self.hrc, _HRC, _HV))
        return hv * G * 1e6


@dataclass(frozen=True)
class Roller:
    """One catalogue roller type (SI units)."""

    type: int
    diameter_m: float
    contact_length_m: float
    total_length_m: float
    material: Mat

    @property
    def radius_m(self) -> float:
        return self.diameter_m / 2.0


def load_catalogue() -> tuple[dict[int, Roller], dict[str, Mat]]:
    """Roller types and materials from the shipped Table 1 files."""
    mats_raw = tomllib.loads((DATA / "materials.toml").read_text())["materials"]
    mats = {k: Mat(k, v["youngs_modulus_gpa"] * 1e9, v["poisson_ratio"], v["hardness_hrc"])
            for k, v in mats_raw.items()}
    rows = tomllib.loads((DATA / "rollers.toml").read_text())["rollers"]
    rollers = {
        r["type"]: Roller(r["type"], r["diameter_mm"] * 1e-3, r["contact_length_mm"] * 1e-3,
                          r["total_length_mm"] * 1e-3, mats[r["material"]])
        for r in rows
    }
    return rollers, mats


def e_star(m1: Mat, m2: Mat) -> float:
    """Effective modulus 1/E* = (1-ν1²)/E1 + (1-ν2²)/E2."""
    return 1.0 / (m1.plane_strain + m2.plane_strain)


@dataclass(frozen=True)
class Line:
    """Tripp's plane-strain line contact of a roller between two rails, with an optional modulus scale."""

    radius_m: float
    roller: Mat
    rail: Mat
    modulus_scale: float = 1.0
    depth_m: float = DEPTH_M

    @property
    def estar(self) -> float:
        return self.modulus_scale * e_star(self.roller, self.rail)

    def half_width(self, p: np.ndarray) -> np.ndarray:
        return np.sqrt(4.0 * p * self.radius_m / (np.pi * self.estar))

    def _c(self) -> tuple[float, float, float]:
        s = self.modulus_scale
        return 4.0 * self.roller.plane_strain / (np.pi * s), self.rail.plane_strain / (np.pi * s), self.rail.nu

    def approach(self, p: np.ndarray) -> np.ndarray:
        """Total approach δ(P) (m) for load per unit length P (N/m)."""
        p = np.asarray(p, dtype=float)
        a = self.half_width(np.maximum(p, 1e-30))
        cr, cs, nu = self._c()
        rail = 2.0 * cs * (2.0 * np.log(2.0 * self.depth_m / a) - nu / (1.0 - nu))
        d = p * (cr * (np.log(4.0 * self.radius_m / a) - 0.5) + rail)
        return np.where(p > 0, d, 0.0)

    def compliance_per_length(self, p: np.ndarray) -> np.ndarray:
        """dδ/dP (m²/N); the tangent stiffness of a length L is L / this."""
        a = self.half_width(np.asarray(p, dtype=float))
        cr, cs, nu = self._c()
        rail = 2.0 * cs * (2.0 * np.log(2.0 * self.depth_m / a) - nu / (1.0 - nu) - 1.0)
        return cr * (np.log(4.0 * self.radius_m / a) - 1.0) + rail

    def stiffness(self, load_n: np.ndarray, length_m: float) -> np.ndarray:
        """Tangent stiffness dF/dδ (N/m) of a uniformly loaded length."""
        return length_m / self.compliance_per_length(np.asarray(load_n, dtype=float) / length_m)

    def p_max(self, p: np.ndarray) -> np.ndarray:
        """Peak Hertz pressure p0 = sqrt(P E*/(π R))."""
        return np.sqrt(np.asarray(p, dtype=float) * self.estar / (np.pi * self.radius_m))

    def load_per_length(self, delta: np.ndarray) -> np.ndarray:
        """Inverse of approach(): P for a local approach δ (log-log table, 0 where δ ≤ 0)."""
        lp, ld = _inverse_table(self)
        delta = np.asarray(delta, dtype=float)
        out = np.exp(np.interp(np.log(np.maximum(delta, 1e-30)), ld, lp))
        return np.where(delta > 0, out, 0.0)


@lru_cache(maxsize=64)
def _inverse_table(line: Line) -> tuple[np.ndarray, np.ndarray]:
    p = np.geomspace(1e-2, 1e8, 4000)
    return np.log(p), np.log(line.approach(p))


def rating_c0_n(roller: Roller, rail: Mat) -> float:
    """Static rating C0 = π p0² L_r R / E*(rail, rail) (ISO 14728-2 style, p0 = 4000 MPa, total length)."""
    return float(np.pi * P0_RATING_PA**2 * roller.total_length_m * roller.radius_m / e_star(rail, rail))


def load_steps(c0_n: float, preload_n: float, rng: np.random.Generator, n: int = 11) -> np.ndarray:
    """11 roughly evenly spaced loads from the preload to 0.31·C0 (the middle steps jittered by ≤ 3 % of a step)."""
    f = np.linspace(preload_n, 0.31 * c0_n, n)
    step = f[1] - f[0]
    f[1:-1] += rng.uniform(-0.03, 0.03, n - 2) * step
    return f
