"""Linearity across a step's impacts: does the bounce frequency move with the blow's peak force?

The contact is nonlinear (Hertz, Tripp): a blow large against the preload stiffens or softens the
contact during the ring-down, and the bounce frequency then depends on the hammer level. Each impact's own
bounce frequency is estimated to first order from the step's fit (its single-impact FRF mapped through the
fit's linearised variable projection), with its own uncertainty (response noise for its share of the force
energy, its own force noise). A weighted straight line against the peak force gives the slope; the slope's
z value decides at a stated level whether the frequency depends on the hammer level.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

LINEARITY_LEVEL = 0.001  # two-sided level of the "frequency depends on the peak force" test


@dataclass(frozen=True)
class Linearity:
    """Bounce frequency per impact against its peak force, the fitted slope and the test's verdict."""

    peak_force_n: tuple[float, ...]
    bounce_hz: tuple[float, ...]
    bounce_hz_std: tuple[float, ...]
    slope_hz_per_n: float
    slope_std_hz_per_n: float
    z: float
    level: float
    nonlinear: bool

    def to_dict(self) -> dict:
        return {"peak_force_n": list(self.peak_force_n), "bounce_hz": list(self.bounce_hz),
                "bounce_hz_std": list(self.bounce_hz_std), "slope_hz_per_n": self.slope_hz_per_n,
                "slope_std_hz_per_n": self.slope_std_hz_per_n, "z": self.z, "level": self.level,
                "nonlinear": self.nonlinear}

    def warning(self) -> str | None:
        if not self.nonlinear:
            return None
        lo, hi = min(self.peak_force_n), max(self.peak_force_n)
        return (f"the bounce frequency moves with the blow: {100 * self.slope_hz_per_n:+.3f} Hz per 100 N of peak "
                f"force over {lo:.0f}-{hi:.0f} N (z {self.z:+.1f}, test at level {self.level:g}): the contact "
                "is not linear at this hammer level — the hammer level is too high for the preload, hit softer")


def linearity_check(peak_force_n: Sequence[float], bounce_hz: Sequence[float], bounce_hz_std: Sequence[float],
                    level: float = LINEARITY_LEVEL) -> Linearity | None:
    """Weighted straight line of the impacts' bounce frequencies against their peak forces (None: fewer than
    two impacts or all blows of one size)."""
    p, f, s = (np.asarray(v, float) for v in (peak_force_n, bounce_hz, bounce_hz_std))
    if len(p) < 2 or not np.all(np.isfinite(s)) or np.any(s <= 0):
        return None
    w = 1.0 / s**2
    pm = float(np.sum(w * p) / np.sum(w))
    sxx = float(np.sum(w * (p - pm) ** 2))
    if not sxx > 0 or float(np.ptp(p)) < 1e-3 * float(np.max(np.abs(p))):
        return None
    fm = float(np.sum(w * f) / np.sum(w))
    slope = float(np.sum(w * (p - pm) * (f - fm)) / sxx)
    slope_std = 1.0 / math.sqrt(sxx)
    z = slope / slope_std
    return Linearity(tuple(map(float, p)), tuple(map(float, f)), tuple(map(float, s)), slope, slope_std, z, level,
                     bool(abs(z) > norm.isf(level / 2)))
