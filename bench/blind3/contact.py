"""Contact mechanics for the third blind judge: catalogue, Tripp line contact, a roller's per-length law."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "labctl" / "data"
DEPTH_M = 3e-3  # Tripp's evaluation depth t of the rail
P0_RATING_PA = 4.0e9  # ISO 76 reference contact stress for a roller's static load rating
K_SETUP = 1.45e9  # the lab's rig stiffness in series with the three rollers, N/m
# HRC -> HV (ASTM E140 table points); beyond HRC 70 a ceramic is capped at HV 1600
_HRC = np.array([20.0, 30.0, 40.0, 50.0, 54.0, 60.0, 65.0, 70.0, 90.0])
_HV = np.array([238.0, 302.0, 392.0, 513.0, 577.0, 697.0, 832.0, 1076.0, 1600.0])


@dataclass(frozen=True)
class Material:
    """One catalogue material: modulus, Poisson ratio, hardness."""

    name: str
    e_pa: float
    nu: float
    hrc: float

    @property
    def hardness_pa(self) -> float:
        """Vickers hardness in Pa (HRC converted by the ASTM E140 table)."""
        return float(np.interp(self.hrc, _HRC, _HV)) * 9.80665e6

    @property
    def compliance(self) -> float:
        """Plane-strain compliance (1 - nu^2)/E, 1/Pa."""
        return (1.0 - self.nu**2) / self.e_pa


@dataclass(frozen=True)
class Roller:
    """One catalogue roller type."""

    type: int
    d_m: float
    lwe_m: float
    lr_m: float
    material: str
    ra_um: float


def load_catalogue() -> tuple[dict[int, Roller], dict[str, Material]]:
    """Rollers and materials of the paper's Table 1, read from the catalogue files."""
    rol = tomllib.loads((DATA / "rollers.toml").read_text())
    mat = tomllib.loads((DATA / "materials.toml").read_text())
    default_ra = float(rol.get("default_roughness_ra_um", 0.03))
    rollers = {
        int(r["type"]): Roller(int(r["type"]), r["diameter_mm"] * 1e-3, r["contact_length_mm"] * 1e-3,
                               r["total_length_mm"] * 1e-3, r["material"], float(r.get("roughness_ra_um", default_ra)))
        for r in rol["rollers"]
    }
    materials = {k: Material(k, v["youngs_modulus_gpa"] * 1e9, v["poisson_ratio"], v["hardness_hrc"])
                 for k, v in mat["materials"].items()}
    return rollers, materials


def e_star(roller: Material, rail: Material) -> float:
    """Effective modulus E* of the roller-rail pair, Pa."""
    return 1.0 / (roller.compliance + rail.compliance)


def static_rating_n(r: Roller, roller: Material, rail: Material) -> float:
    """C0: the load whose Hertz peak line pressure on a flat rail reaches the ISO 76 4000 MPa."""
    return float(np.pi * (r.d_m / 2) * r.lwe_m * P0_RATING_PA**2 / e_star(roller, rail))


def tripp_per_length(p: np.ndarray, r_m: float, roller: Material, rail: Material,
                     e_scale_roller: float = 1.0, e_scale_rail: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Tripp's approach delta(P) (m) and tangent stiffness dP/ddelta (Pa) per unit length at line loads P (N/m)."""
    c_ro = roller.compliance / e_scale_roller
    c_ra = rail.compliance / e_scale_rail
    es = 1.0 / (c_ro + c_ra)
    p = np.asarray(p, float)
    a = np.sqrt(4.0 * p * r_m / (np.pi * es))
    ln_r = np.log(4.0 * r_m / a)
    ln_t = np.log(2.0 * DEPTH_M / a)
    k1 = 4.0 * c_ro / np.pi
    k2 = c_ra / np.pi
    nn = rail.nu / (1.0 - rail.nu)
    delta = p * (k1 * (ln_r - 0.5) + 2.0 * k2 * (2.0 * ln_t - nn))
    stiff = 1.0 / (k1 * (ln_r - 1.0) + 2.0 * k2 * (2.0 * ln_t - nn - 1.0))
    return delta, stiff


def tripp_k(load_n: np.ndarray, r: Roller, roller: Material, rail: Material) -> np.ndarray:
    """Tripp's roller stiffness dF/ddelta (N/m) at loads F per roller: the lab's baseline."""
    _, s = tripp_per_length(np.asarray(load_n, float) / r.lwe_m, r.d_m / 2, roller, rail)
    return r.lwe_m * s


def half_width(p: np.ndarray, r_m: float, es: float) -> np.ndarray:
    """Hertz half-width a (m) of a line contact at line load P."""
    return np.sqrt(4.0 * np.asarray(p, float) * r_m / (np.pi * es))


class LengthLaw:
    """A roller's per-length law as a table: approach delta(P) and tangent stiffness s(P), with inverse lookup."""

    def __init__(self, p: np.ndarray, stiff: np.ndarray, delta0: float) -> None:
        """Integrate d(delta) = dP/s from the table's first point, whose approach delta0 is given."""
        self.p = p
        self.s = stiff
        inc = 0.5 * (1.0 / stiff[1:] + 1.0 / stiff[:-1]) * np.diff(p)
        self.delta = delta0 + np.concatenate([[0.0], np.cumsum(inc)])
        self._lnp = np.log(p)
        self._lns = np.log(stiff)

    def stiffness(self, p: np.ndarray) -> np.ndarray:
        """Tangent stiffness per length at line load P (log-log interpolation)."""
        return np.exp(np.interp(np.log(np.maximum(p, self.p[0])), self._lnp, self._lns))

    def load_at(self, d: np.ndarray) -> np.ndarray:
        """Line load P at local approach d (0 where the slice is out of contact)."""
        d = np.asarray(d, float)
        out = np.exp(np.interp(d, self.delta, self._lnp))
        out = np.where(d < self.delta[0], self.p[0] * np.clip(d, 0.0, None) / self.delta[0], out)
        return out

    def approach(self, p: np.ndarray) -> np.ndarray:
        """Approach delta at line load P."""
        return np.interp(np.log(np.maximum(p, self.p[0])), self._lnp, self.delta)


P_GRID = np.geomspace(50.0, 3e7, 200)  # N/m: below every preload per length, above every top load per length
