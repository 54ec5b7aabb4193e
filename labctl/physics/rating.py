"""Static load rating C0 of a roller on a flat: the load at which the Hertz line-contact pressure is p₀."""

from __future__ import annotations

import math
from typing import Literal

from labctl.physics.catalogue import Roller
from labctl.physics.materials import Material, effective_modulus

P0_PA = 4000e6
LengthChoice = Literal["total", "contact"]


def static_load_rating_n(roller: Roller, flat: Material, length: LengthChoice = "total", p0_pa: float = P0_PA) -> float:
    """C0 = π·p₀²·L·R/E* (≈ 220·L·D in N, mm for steel on steel at 4000 MPa).

    Which length enters is a protocol choice: the paper's 440 N for type 1 is 30 % of C0 with L_r.
    """
    if length not in ("total", "contact"):
        raise ValueError(f"length for C0 must be 'total' or 'contact', got {length!r}")
    length_m = roller.total_length_m if length == "total" else roller.contact_length_m
    return math.pi * p0_pa**2 * length_m * roller.radius_m / effective_modulus(roller.material, flat)
