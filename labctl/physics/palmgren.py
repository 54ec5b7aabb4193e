"""Palmgren's empirical line contact: δ = 3.84e-5·Q^0.9/L^0.8 (mm, N) per contact, two contacts in series."""

from __future__ import annotations

from dataclasses import dataclass

from numpy.typing import ArrayLike

from labctl.physics.contact import FloatArray, as_load

_COEFF_MM = 3.84e-5
MM = 1e-3


@dataclass(frozen=True)
class PalmgrenContact:
    """A roller of contact length L between two flats (roller-rail contact on each side)."""

    contact_length_m: float
    name: str = "palmgren"

    def _length_mm(self) -> float:
        return self.contact_length_m / MM

    def deflection_m(self, load_n: ArrayLike) -> FloatArray:
        q = as_load(load_n, self.name)
        return 2.0 * _COEFF_MM * q**0.9 / self._length_mm() ** 0.8 * MM

    def stiffness_n_per_m(self, load_n: ArrayLike) -> FloatArray:
        q = as_load(load_n, self.name)
        compliance_mm_per_n = 2.0 * 0.9 * _COEFF_MM * q ** (-0.1) / self._length_mm() ** 0.8
        return 1.0 / (compliance_mm_per_n * MM)
