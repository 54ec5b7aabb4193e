"""The twin's spring stacks: how a star-knob angle becomes force on the rollers, as real springs do it.

Each rod compresses its spring pair by ``pitch × (angle − slack) / 360`` once its nut has taken up the slack
of the first turn. The pair's force is ``k x (1 + c x / x_ref)`` (a mild progressive nonlinearity, ``c`` at
``x_ref``), and friction in the thread and the spring seats makes a hysteresis band of width ``h``: the force
follows a play operator, so after a reversal it stays put until the knob has crossed the band. Rods differ:
each rod's rate, slack and band are drawn from the nominal rig-file rate with the world's own spring seed (the
rig is built once: every run of a world, whatever its seed, has the same springs; re-seating does not change
them). The load per roller is the sum over rods shared by the
rollers; the twin adds the preload (the upper disc's weight). Loading from zero, each rod sits on the lower
edge of its band (``f0 − h/2``); unloading, on the upper edge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

X_REF_M = 7.5e-3  # ten half turns of an M10 thread: the paper's highest load


@dataclass(frozen=True)
class SpringImperfections:
    """How far the real stacks are from the rig file's linear nominal (scaled by the world's setting)."""

    rate_spread: float = 0.03  # 1-σ of a rod's rate around the nominal
    nonlinearity: float = 0.04  # extra stiffening at X_REF_M
    hysteresis_fraction: float = 0.015  # band width as a fraction of a rod's force at X_REF_M
    slack_min_deg: float = 5.0  # the first turn's slack per rod, uniform in [min, max]
    slack_max_deg: float = 25.0


class SpringStacks:
    """The rods' spring pairs with their state (the play operator's force per rod)."""

    def __init__(self, rods: int, rate_n_per_m: float, pitch_m: float, rollers: int, *, seed: int,
                 scale: float = 1.0, imperfections: SpringImperfections | None = None) -> None:
        imp = imperfections or SpringImperfections()
        rng = np.random.default_rng([seed, 0x5B1])
        self.pitch_m, self.rollers = pitch_m, rollers
        self.rates = rate_n_per_m * (1.0 + scale * imp.rate_spread * rng.standard_normal(rods))
        self.slack_deg = scale * rng.uniform(imp.slack_min_deg, imp.slack_max_deg, rods)
        self.nonlinearity = scale * imp.nonlinearity
        self.band_n = scale * imp.hysteresis_fraction * self.rates * X_REF_M * (1.0 + self.nonlinearity)
        self.angle_deg = 0.0
        self.force_n = np.zeros(rods)  # per rod, on its play operator

    def elastic_n(self, angle_deg: float) -> np.ndarray:
        """Each rod's friction-free force at a knob angle."""
        x = self.pitch_m * np.maximum(0.0, angle_deg - self.slack_deg) / 360.0
        return self.rates * x * (1.0 + self.nonlinearity * x / X_REF_M)

    def move_to(self, angle_deg: float) -> None:
        """Turn the knobs to ``angle_deg``: each rod's force stays inside its friction band around the elastic."""
        steps = max(1, int(np.ceil(abs(angle_deg - self.angle_deg) / 5.0)))
        for a in np.linspace(self.angle_deg, angle_deg, steps + 1)[1:]:  # the path matters only at reversals
            f0 = self.elastic_n(a)
            lower = np.where(f0 > 0, np.maximum(f0 - self.band_n / 2, 0.0), 0.0)
            self.force_n = np.clip(self.force_n, lower, f0 + self.band_n / 2)
            self.force_n = np.where(f0 > 0, self.force_n, 0.0)
        self.angle_deg = float(angle_deg)

    def load_per_roller_n(self) -> float:
        """The springs' force now, shared by the rollers (no preload)."""
        return float(self.force_n.sum() / self.rollers)

    def angle_for_load(self, spring_load_n: float) -> float:
        """The knob angle that reaches ``spring_load_n`` per roller loading from zero (bisection on the branch)."""
        lo, hi = 0.0, 360.0
        while self._loading_branch(hi) < spring_load_n:
            hi *= 2
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self._loading_branch(mid) < spring_load_n else (lo, mid)
        return 0.5 * (lo + hi)

    def _loading_branch(self, angle_deg: float) -> float:
        f0 = self.elastic_n(angle_deg)
        return float(np.maximum(f0 - self.band_n / 2, 0.0).sum() / self.rollers)

    def reset_to(self, angle_deg: float) -> None:
        """Put the stacks at ``angle_deg`` as reached by loading from zero."""
        self.angle_deg, self.force_n = 0.0, np.zeros_like(self.rates)
        self.move_to(angle_deg)
