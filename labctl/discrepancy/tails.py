"""How heavy the point noise's tails are, from the repetitions: a Student-t's degrees of freedom by moments.

A rig's point noise need not be Gaussian (a hammer blow that lands off centre, a resonance read between two
lines): heavier tails make the lack-of-fit statistic's null distribution wider than Gaussian draws give it. The
two-way residuals (step means + seating offsets) are each a mix of a case's points, e = (I − H)x, which pulls
their kurtosis toward the Gaussian's: for independent x of excess kurtosis κ, E[z⁴] = 3 + κ·f with z the residual
standardised by its own variance and f = Σ_k M_ik⁴ / M_ii² (M = I − H). So κ = (mean z⁴ − 3) / mean f, and a
Student-t has κ = 6 / (ν − 4). No excess (or too little to tell from the estimate's own scatter, about
sqrt(24/n)/mean f) is Gaussian: ν = ∞.
"""

from __future__ import annotations

import math

import numpy as np

GAUSSIAN = math.inf
LEAST_DOF = 4.5
"""The heaviest tail drawn: below ν = 4 a Student-t has no fourth moment for the estimate to match."""


def tail_dof(z: np.ndarray, fourth_share: np.ndarray) -> float:
    """Student-t degrees of freedom of the point noise from residuals ``z`` standardised to unit variance each
    and their ``fourth_share`` f_i (module doc); ``GAUSSIAN`` when the excess kurtosis is within its standard
    error of none."""
    ok = np.isfinite(z) & (fourth_share > 0)
    z, f = z[ok], fourth_share[ok]
    if z.size < 8:
        return GAUSSIAN
    m2 = float(np.mean(z**2))
    excess = (float(np.mean(z**4)) / m2**2 - 3.0) / float(np.mean(f))
    if excess <= math.sqrt(24.0 / z.size) / float(np.mean(f)):
        return GAUSSIAN
    return max(LEAST_DOF, 4.0 + 6.0 / excess)


def unit_draws(rng: np.random.Generator, dof: float, size: int) -> np.ndarray:
    """Independent draws of unit variance: Gaussian, or Student-t with ``dof`` degrees of freedom scaled."""
    if not math.isfinite(dof):
        return rng.standard_normal(size)
    return rng.standard_t(dof, size) * math.sqrt((dof - 2.0) / dof)
