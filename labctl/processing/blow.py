"""Is the blow's effect on the step's stiffness material? The hammer-level warning, only when it is.

The linearity test (``linearity.py``) tells at a stated level whether the bounce moves with the blow; with
hundreds of newtons on a stiff contact it nearly always does, by a few hundredths of a hertz. A technician told
to hit softer on every blow stops reading warnings, so the warning is given only when the blows move the
reported stiffness by more than its stated uncertainty or a practical limit (whichever is smaller), and says by
how much against that σ, and what to do.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from labctl.physics import RigConfig
from labctl.processing.linearity import Linearity, ZeroAmplitude
from labctl.processing.stiffness import stiffness_budget, stiffness_from_bounce

# A blow that moves k by less than this changes no conclusion a campaign draws: a third of the seating scatter the
# paper reports for its verification (stiffness standard deviations below 3 %).
PRACTICAL_LIMIT_REL = 0.01


@dataclass(frozen=True)
class BlowEffect:
    """How far the step's blows moved its stiffness (relative), against what the step states."""

    shift_hz: float  # the bounce at these blows minus its small-blow limit (estimate)
    effect_rel: float  # |Δk|/k that shift means
    stated_rel: float  # the stiffness's stated 1-σ (modal fit and rig file), relative
    limit_rel: float  # min(stated_rel, PRACTICAL_LIMIT_REL)
    significant: bool  # the linearity test's verdict at its level
    material: bool  # significant and effect_rel > limit_rel
    peak_force_n: float  # the mean peak force of the step's blows

    def to_dict(self) -> dict:
        return {"shift_hz": self.shift_hz, "effect_rel": self.effect_rel, "stated_rel": self.stated_rel,
                "limit_rel": self.limit_rel, "significant": self.significant, "material": self.material,
                "peak_force_n": self.peak_force_n}

    def warning(self) -> str | None:
        if not self.material:
            return None
        return (f"the blows move the stiffness by about {100 * self.effect_rel:.2f} % (the bounce "
                f"{self.shift_hz:+.2f} Hz from its small-blow limit at {self.peak_force_n:.0f} N peak), more than "
                f"{100 * self.limit_rel:.2f} % (the stiffness's stated σ {100 * self.stated_rel:.2f} % or the "
                f"practical limit {100 * PRACTICAL_LIMIT_REL:g} %): the contact is not linear at this hammer level — "
                "hit softer, or vary the hammer level over the step's blows; the σ reported covers the shift")


def blow_effect(rig: RigConfig, bounce_hz: float, bounce_std_hz: float, lin: Linearity | None,
                small: ZeroAmplitude | None, peaks_n: Sequence[float]) -> BlowEffect | None:
    """The blows' effect on the step's stiffness (None: no linearity estimate — one blow, or blows of one size)."""
    if lin is None:
        return None
    peak = float(sum(peaks_n) / len(peaks_n)) if peaks_n else 0.0
    shift = small.shift_hz if small is not None else lin.slope_hz_per_n * peak
    significant = lin.nonlinear or (small is not None and small.significant)
    k = stiffness_from_bounce(rig, bounce_hz, bounce_std_hz)
    # the shift (a few Hz at most against ~750 Hz) through the rig model's slope there: its curvature changes the
    # effect by less than shift/f of itself, and one eigen-inversion is saved
    effect = abs(shift / k.df_dk_hz_per_n_per_m) / k.value_n_per_m if k.df_dk_hz_per_n_per_m > 0 else math.inf
    stated = stiffness_budget(rig, k.value_n_per_m, k.std_n_per_m).total_std_n_per_m / k.value_n_per_m
    limit = min(stated, PRACTICAL_LIMIT_REL) if math.isfinite(stated) else PRACTICAL_LIMIT_REL
    return BlowEffect(float(shift), float(effect), float(stated), float(limit), bool(significant),
                      bool(significant and effect > limit), peak)
