"""The characterised spring curve: knob angle → load per roller, with its 1-σ (the rig file's ``[springs]``).

The curve is what a spring characterisation (``labctl springs fit``) measured with a load cell, so a campaign
can run without one (``load_source = "springs"``). With ``u = max(0, angle − slack)``::

    load = preload + rate·u + curvature·u² ∓ hysteresis/2      (− loading, + unloading)

The parameter covariance (rate, curvature, hysteresis, slack) and the preload's σ give the curve's own σ; the
fit's residual scatter (load-cell noise and setting-to-setting repeatability) is added once, for one setting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

Branch = Literal["loading", "unloading"]
PARAMETERS = ("rate_n_per_deg", "curvature_n_per_deg2", "hysteresis_n", "slack_deg")


@dataclass(frozen=True)
class SpringCurve:
    """Load per roller (N) from the total star-knob angle (degrees, as turned) of all rods together."""

    preload_n: float
    rate_n_per_deg: float
    curvature_n_per_deg2: float
    hysteresis_n: float
    slack_deg: float
    preload_std_n: float
    residual_std_n: float
    covariance: tuple[float, ...]  # 4×4, row-major, over PARAMETERS
    max_angle_deg: float  # the characterised range: the curve is not used beyond it
    source: str = ""

    def _u(self, angle_deg: float, slack_deg: float | None = None) -> float:
        return max(0.0, angle_deg - (self.slack_deg if slack_deg is None else slack_deg))

    def load_n(self, angle_deg: float, branch: Branch = "loading") -> float:
        """The load per roller at ``angle_deg`` reached on ``branch``."""
        u = self._u(angle_deg)
        sign = -0.5 if branch == "loading" else 0.5
        spring = self.rate_n_per_deg * u + self.curvature_n_per_deg2 * u * u + sign * self.hysteresis_n
        return self.preload_n + (max(spring, 0.0) if u > 0 else 0.0)

    def load_std_n(self, angle_deg: float, branch: Branch = "loading") -> float:
        """1-σ of one setting's load: the curve's parameter uncertainty, the preload's, and the residual scatter."""
        u = self._u(angle_deg)
        if u <= 0:
            return math.hypot(self.preload_std_n, self.residual_std_n)
        sign = -0.5 if branch == "loading" else 0.5
        g = np.array([u, u * u, sign, -(self.rate_n_per_deg + 2 * self.curvature_n_per_deg2 * u)])
        cov = np.asarray(self.covariance, dtype=float).reshape(4, 4)
        var = float(g @ cov @ g) + self.preload_std_n**2 + self.residual_std_n**2
        return math.sqrt(max(var, 0.0))

    def check_range(self, angle_deg: float) -> str | None:
        """Why the curve cannot give the load at ``angle_deg`` (None when it can)."""
        if not 0.0 <= angle_deg <= self.max_angle_deg * (1 + 1e-9):
            return (f"knob angle {angle_deg:g}° is outside the characterised range 0..{self.max_angle_deg:g}° "
                    f"of the spring curve{f' ({self.source})' if self.source else ''}")
        return None
