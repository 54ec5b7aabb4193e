"""Hertz point contact for a ball between two flats (the rig's verification, paper §2.6)."""

from __future__ import annotations

from dataclasses import dataclass

from numpy.typing import ArrayLike

from labctl.physics.contact import FloatArray, as_load
from labctl.physics.materials import Material, effective_modulus


@dataclass(frozen=True)
class HertzBallContact:
    """δ_total = 2·(9F²/(16E*²R))^(1/3) for the two ball-flat contacts; k = dF/dδ = 1.5·F/δ."""

    diameter_m: float
    ball: Material
    flat: Material
    name: str = "hertz"

    def deflection_m(self, load_n: ArrayLike) -> FloatArray:
        f = as_load(load_n, self.name)
        e_star = effective_modulus(self.ball, self.flat)
        return 2.0 * (9.0 * f**2 / (16.0 * e_star**2 * 0.5 * self.diameter_m)) ** (1.0 / 3.0)

    def stiffness_n_per_m(self, load_n: ArrayLike) -> FloatArray:
        f = as_load(load_n, self.name)
        return 1.5 * f / self.deflection_m(f)
