"""The paper's empirical fits: k = C·ln((F/L_we)/p₀)·L_we, Eq. 5 (Ra 0.2 µm rails) and Eq. 6 (Ra 0.03 µm)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from labctl.errors import ModelDomainError
from labctl.physics.contact import FloatArray, as_load


@dataclass(frozen=True)
class FitCoefficients:
    """C in N/m², p₀ in N/m, and the rail roughness the fit was made for."""

    name: str
    c_n_per_m2: float
    p0_n_per_m: float
    rail_ra_m: float
    equation: str


EQ5 = FitCoefficients("fit-ra0.2", 5.151e9, 1.800e3, 0.2e-6, "Eq. 5")
EQ6 = FitCoefficients("fit-ra0.03", 3.230e9, 1.004e2, 0.03e-6, "Eq. 6")
FITS = {EQ5.name: EQ5, EQ6.name: EQ6}


@dataclass(frozen=True)
class EmpiricalFit:
    """An empirical fit applied to a roller of contact length L_we; no deflection is defined."""

    coefficients: FitCoefficients
    contact_length_m: float

    @property
    def name(self) -> str:
        return self.coefficients.name

    @property
    def minimum_load_n(self) -> float:
        """Below F = p₀·L_we the fit is ≤ 0 and meaningless."""
        return self.coefficients.p0_n_per_m * self.contact_length_m

    def stiffness_n_per_m(self, load_n: ArrayLike) -> FloatArray:
        f = as_load(load_n, self.name)
        low = f <= self.minimum_load_n
        if np.any(low):
            c = self.coefficients
            raise ModelDomainError(
                f"{c.equation} ({c.name}) is valid only for F/L_we > {c.p0_n_per_m / 1e3:.4g} N/mm, i.e. "
                f"F > {np.broadcast_to(self.minimum_load_n, f.shape)[low].flat[0]:.4g} N for L_we = "
                f"{np.broadcast_to(self.contact_length_m, f.shape)[low].flat[0] * 1e3:.4g} mm; "
                f"got {f[low].flat[0]:.4g} N"
            )
        c = self.coefficients
        return c.c_n_per_m2 * np.log(f / self.contact_length_m / c.p0_n_per_m) * self.contact_length_m

    def deflection_m(self, load_n: ArrayLike) -> None:
        return None
