"""Where the elastic contact models apply: up to the load at which the peak Hertz pressure reaches p₀.

Tripp, Palmgren, the empirical fits and Hertz describe an elastic contact. At p₀ = 4000 MPa (the pressure
that defines the static load rating C0, labctl.physics.rating) the raceway starts to deform permanently, and
far beyond it the formulas stop meaning anything (Tripp's stiffness turns negative near 10⁵ N for roller
type 1). A load outside (0, limit] is refused with one line naming the model, the load and the limit.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from labctl.errors import InputError
from labctl.physics.catalogue import Roller
from labctl.physics.materials import Material, effective_modulus
from labctl.physics.rating import P0_PA


def roller_load_limit_n(roller: Roller, rail: Material, p0_pa: float = P0_PA) -> float:
    """Load per roller at which the line contact's peak pressure is ``p0_pa``: π·p₀²·L_we·R/E*."""
    return math.pi * p0_pa**2 * roller.contact_length_m * roller.radius_m / effective_modulus(roller.material, rail)


def ball_load_limit_n(diameter_m: float, ball: Material, flat: Material, p0_pa: float = P0_PA) -> float:
    """Load at which a ball on a flat reaches peak pressure ``p0_pa``: π³·p₀³·R²/(6·E*²)."""
    e_star = effective_modulus(ball, flat)
    return math.pi**3 * p0_pa**3 * (0.5 * diameter_m) ** 2 / (6.0 * e_star**2)


def check_loads(model: str, loads_n: Iterable[float], limit_n: float) -> None:
    """InputError unless every load is a finite number in (0, ``limit_n``]."""
    for f in loads_n:
        if not (math.isfinite(f) and 0 < f <= limit_n):
            raise InputError(f"{model}: load {f:g} N is outside the model's validity (0, {limit_n:.5g}] N: above "
                             f"it the peak contact pressure passes {P0_PA / 1e6:g} MPa and the contact is no "
                             "longer elastic")


def check_roller_loads(where: str, cases_and_loads: Iterable[tuple[str, Roller, Material, float]]) -> None:
    """For inputs whose loads a line-contact model (Tripp, Palmgren, the fits) will be evaluated at: each
    ``(label, roller, rail, load)`` must lie in (0, the roller's p₀ limit], else one line naming ``where``,
    the label (e.g. the CSV row) and the load."""
    for label, roller, rail, load_n in cases_and_loads:
        limit_n = roller_load_limit_n(roller, rail)
        if not (math.isfinite(load_n) and 0 < load_n <= limit_n):
            raise InputError(f"{where}: {label}: load_n = {load_n:g} N is outside where the contact models apply "
                             f"to this roller, (0, {limit_n:.5g}] N (peak contact pressure up to "
                             f"{P0_PA / 1e6:g} MPa, elastic); give the load per roller in N")
