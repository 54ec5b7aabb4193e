"""Static load rating C0 of a roller on a flat: the load at which the Hertz line-contact pressure is p₀.

Convention (how the paper loaded, ISO 14728-2 style): C0 = π·p₀²·L·R/E* with p₀ = 4000 MPa, L the roller's
total length L_r (the protocol may choose L_we) and E* of the *raceway's material against itself*: C0 rates the
raceway, so a Si3N4 or stainless roller of a given geometry has the C0 of a bearing-steel roller of that
geometry on the same rail (type 8: 1841 N, type 9: 1447 N, like type 1's 1447 N). The paper's top load for type 1,
440 N, is 30.4 % of this C0 (its "30 %" is rounded), so the shipped protocol caps at 0.31·C0.
"""

from __future__ import annotations

import math
from typing import Literal

from labctl.physics.catalogue import Roller
from labctl.physics.materials import Material, effective_modulus

P0_PA = 4000e6
LengthChoice = Literal["total", "contact"]


def static_load_rating_n(roller: Roller, flat: Material, length: LengthChoice = "total", p0_pa: float = P0_PA) -> float:
    """C0 = π·p₀²·L·R/E*(flat, flat) (≈ 220·L·D in N, mm on bearing steel), whatever the roller's material.

    Which length enters is a protocol choice: the paper's 440 N for type 1 is 30.4 % of C0 with L_r.
    """
    if length not in ("total", "contact"):
        raise ValueError(f"length for C0 must be 'total' or 'contact', got {length!r}")
    length_m = roller.total_length_m if length == "total" else roller.contact_length_m
    return math.pi * p0_pa**2 * length_m * roller.radius_m / effective_modulus(flat, flat)
