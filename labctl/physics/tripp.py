"""Tripp's line contact for a roller between two flat rails (paper Eqs. 1-3), with closed-form tangent stiffness.

Per unit length P = F/L_we the approach is δ = δ_roller(P) + 2·δ_rail(P) with
δ_roller = 4P(1-ν_r²)/(πE_r)·(ln(4R/a) - 1/2), δ_rail = P(1-ν_s²)/(πE_s)·(2 ln(2t/a) - ν_s/(1-ν_s)),
a = sqrt(4PR/(πE*)). Since d(ln a)/dP = 1/(2P), the compliance per length dδ/dP follows in closed form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from labctl.physics.catalogue import Roller
from labctl.physics.contact import FloatArray, as_load
from labctl.physics.materials import Material, effective_modulus

DEFAULT_DEPTH_M = 3e-3


@dataclass(frozen=True)
class TrippContact:
    """A roller squeezed between two rails of one material, rails evaluated at depth t."""

    roller: Roller
    rail: Material
    depth_m: float = DEFAULT_DEPTH_M
    name: str = "tripp"

    def __post_init__(self) -> None:
        if not self.depth_m > 0:
            raise ValueError(f"tripp: evaluation depth {self.depth_m!r} m must be > 0")

    @property
    def effective_modulus_pa(self) -> float:
        return effective_modulus(self.roller.material, self.rail)

    def half_width_m(self, load_n: ArrayLike) -> FloatArray:
        """Contact half-width a (m) at each load."""
        return self._half_width_m(as_load(load_n, self.name) / self.roller.contact_length_m)

    def _half_width_m(self, p: FloatArray) -> FloatArray:
        return np.sqrt(4.0 * p * self.roller.radius_m / (np.pi * self.effective_modulus_pa))

    def _terms(self, load_n: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray, float, float, float]:
        p = as_load(load_n, self.name) / self.roller.contact_length_m  # checked once, not once per term
        a = self._half_width_m(p)
        c_roller = 4.0 * self.roller.material.plane_strain_compliance / np.pi
        c_rail = self.rail.plane_strain_compliance / np.pi
        nu = self.rail.poisson_ratio
        return p, np.log(4.0 * self.roller.radius_m / a), np.log(2.0 * self.depth_m / a), c_roller, c_rail, nu

    def deflection_m(self, load_n: ArrayLike) -> FloatArray:
        """Total approach of the two rails: roller compression plus two rail indentations."""
        p, ln_r, ln_t, c_roller, c_rail, nu = self._terms(load_n)
        return p * (c_roller * (ln_r - 0.5) + 2.0 * c_rail * (2.0 * ln_t - nu / (1.0 - nu)))

    def rail_compliance_m_per_n(self, load_n: ArrayLike) -> FloatArray:
        """Tangent compliance of the two rail indentations alone (2 × Eq. 2): what separates roller from rails."""
        _, _, ln_t, _, c_rail, nu = self._terms(load_n)
        return 2.0 * c_rail * (2.0 * ln_t - nu / (1.0 - nu) - 1.0) / self.roller.contact_length_m

    def stiffness_n_per_m(self, load_n: ArrayLike) -> FloatArray:
        """Tangent stiffness dF/dδ = L_we / (dδ/dP)."""
        _, ln_r, ln_t, c_roller, c_rail, nu = self._terms(load_n)
        compliance_per_length = c_roller * (ln_r - 1.0) + 2.0 * c_rail * (2.0 * ln_t - nu / (1.0 - nu) - 1.0)
        return self.roller.contact_length_m / compliance_per_length
