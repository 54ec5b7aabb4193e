"""An instrument error is one value for every roller: the consistency test of a measurement-side term.

A load cell offset or gain, or a wrong modulus, is a property of the instrument or the catalogue, so every roller
type measured with it shows the same value. A term that only mends the form of a physical law (a load offset
that shifts a tilt law's closing, say) wants a different value for each roller type, because the form error
differs with the roller's length and diameter. Each measurement-side parameter of a fitted explanation is refitted
on each roller geometry alone (every other parameter held at the joint fit) and the values are compared: Cochran's
Q = Σ w_g·(θ_g − θ̄)², w_g = 1/σ_g², against χ² with G − 1 degrees of freedom at level ``CONSISTENCY_LEVEL``. A term
whose joint fit sits at an end of its range is no instrument error either: it is being stretched to another shape.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import chdtrc

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import Fit, residuals_at
from labctl.discrepancy.noise import NoiseFloor

CONSISTENCY_LEVEL = 0.01
"""A measurement-side term whose per-roller-type values differ at this level is not an instrument error."""
MIN_GEOMETRIES = 3
"""Roller geometries needed to compare (with fewer, the test is not made and nothing is ruled out)."""
BOUND_TOLERANCE = 1e-6
"""How near an end of its range (in the [0, 1] scale) a joint-fit value counts as pinned there."""
_STEP = 1e-6
"""Forward-difference step (in the parameter's [0, 1] scale) for the Gauss–Newton steps and each value's standard
error."""
NEWTON_STEPS = 8
NEWTON_TOLERANCE = 1e-7


@dataclass(frozen=True)
class InstrumentCheck:
    """One measurement-side parameter refitted per roller geometry, and whether the values agree."""

    term: str
    parameter: str
    values: tuple[float, ...]
    """Per roller geometry, in the parameter's SI unit."""
    sigmas: tuple[float, ...]
    q: float
    df: int
    p: float
    at_bound: bool
    """The joint fit's value sits at an end of the term's range: the data want more than an instrument error of
    this kind plausibly is (the range is the term's prior support), so the term is bending to fit another shape."""

    @property
    def passed(self) -> bool:
        """The term can be an instrument error: one value for every roller, inside its range."""
        return self.p >= CONSISTENCY_LEVEL and not self.at_bound

    def describe(self) -> str:
        """Why the term can or cannot be an instrument error, in words."""
        if self.at_bound:
            return (f"{self.term} pinned at the end of its range: an error larger than the range allows, or the term "
                    "stretched to another shape")
        p = "p < 1e-10" if self.p < 1e-10 else f"p {self.p:.2g}"
        verb = "agrees across" if self.p >= CONSISTENCY_LEVEL else "differs by"
        return (f"{self.term} {verb} roller type (Cochran's Q {self.q:.1f}, {self.df} df, {p} at level "
                f"{CONSISTENCY_LEVEL:g})")

    def to_dict(self) -> dict[str, Any]:
        return {"term": self.term, "parameter": self.parameter, "values": list(self.values),
                "sigmas": list(self.sigmas), "q": self.q, "df": self.df, "p": self.p, "at_bound": self.at_bound,
                "level": CONSISTENCY_LEVEL, "passed": self.passed, "description": self.describe()}


def _refit(sub: Dataset, fit: Fit, j: int, noise: NoiseFloor) -> tuple[float, float]:
    """Parameter ``j`` of ``fit`` (in its [0, 1] scale) refitted on ``sub`` alone (Gauss–Newton from the joint
    fit's value, held in [0, 1]), and its Fisher information there."""
    spec, sigma = fit.spec, noise.sigma_at(sub)

    def white(u: float) -> np.ndarray:
        x = fit.x.copy()
        x[j] = u
        return noise.whiten(sub, residuals_at(sub, spec, x, sub.ln_stiffness), sigma)

    u = float(fit.x[j])
    for _ in range(NEWTON_STEPS):
        h = _STEP if u + _STEP <= 1.0 else -_STEP
        r = white(u)
        jac = (white(u + h) - r) / h
        info = float(jac @ jac)
        if info <= 0:
            return u, 0.0
        step = -float(jac @ r) / info
        u_next = min(1.0, max(0.0, u + step))
        done = abs(u_next - u) < NEWTON_TOLERANCE
        u = u_next
        if done:
            break
    h = _STEP if u + _STEP <= 1.0 else -_STEP
    jac = (white(u + h) - white(u)) / h
    return u, float(jac @ jac)


def check_instrument(data: Dataset, fit: Fit, noise: NoiseFloor) -> list[InstrumentCheck]:
    """Every measurement-side parameter of ``fit`` refitted per roller geometry; empty with fewer than
    ``MIN_GEOMETRIES`` geometries or no measurement-side term."""
    spec = fit.spec
    groups = [data.subset(idx) for idx in data.roller_groups()]
    if len(groups) < MIN_GEOMETRIES or not spec.measurement:
        return []
    out = []
    for slot, (term, parameter, lo, hi) in enumerate(spec.slots()):
        if term not in MEASUREMENT:
            continue
        j = int(spec.fits_depth) + slot
        at_bound = bool(min(fit.x[j], 1.0 - fit.x[j]) < BOUND_TOLERANCE)
        refits = [_refit(sub, fit, j, noise) for sub in groups]
        v = np.array([lo + u * (hi - lo) for u, _ in refits])
        w = np.array([info / (hi - lo) ** 2 for _, info in refits])
        informative = int(np.count_nonzero(w))
        mean = float(np.sum(w * v) / np.sum(w)) if informative else 0.0
        q = float(np.sum(w * (v - mean) ** 2))
        p = float(chdtrc(informative - 1, q)) if informative >= 2 else 1.0
        sigmas = tuple(float(1.0 / np.sqrt(x)) if x > 0 else float("inf") for x in w)
        out.append(InstrumentCheck(term, parameter, tuple(float(x) for x in v), sigmas, q, max(0, informative - 1), p,
                                   at_bound))
    return out
