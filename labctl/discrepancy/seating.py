"""σ_seat, the offset of ln k shared by every point of one seating, by moments (Henderson's method III).

Per roller case, on ln k brought to its steps' mean loads (``labctl.discrepancy.steps``) and whitened by the
point noise: what adding one offset per seating to the saturated model (the step means) takes out of the residual
sum of squares is, with no seating effect, χ² with as many degrees of freedom as the offsets add; each unit of
σ_seat² adds the offsets' squared length beyond what the step means already explain. Steps of unequal size (a blow
not taken, a point set aside) need no special case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

RANK_TOL = 1e-9
"""Singular values below this share of the largest span nothing (a column the others already hold)."""


@dataclass(frozen=True)
class SeatingCase:
    """One roller case's kept points as σ_seat sees them: ln k at its step's load, its point σ, its steps."""

    y: np.ndarray
    sigma: np.ndarray
    repetition: np.ndarray
    """Repetition number per point, -1 where none is given (then the point has no offset of its own here)."""
    steps: list[np.ndarray]


def seating_sigma(cases: list[SeatingCase]) -> tuple[float, int]:
    """σ_seat and its degrees of freedom from the roller cases with two seatings or more (0, 0 without)."""
    gain = df = length = 0.0
    for c in cases:
        seats = np.unique(c.repetition[c.repetition >= 0])
        if seats.size < 2:
            continue
        w = 1.0 / c.sigma
        cells = np.zeros((c.y.size, len(c.steps)))
        for j, g in enumerate(c.steps):
            cells[g, j] = 1.0
        basis = _basis(cells * w[:, None])
        offsets = (c.repetition[:, None] == seats[None, :]).astype(float) * w[:, None]
        y = c.y * w
        r = y - basis @ (basis.T @ y)
        z = offsets - basis @ (basis.T @ offsets)
        extra = _basis(z)
        gain += float(np.sum((extra.T @ r) ** 2))
        df += extra.shape[1]
        length += float(np.sum(z**2))
    if df == 0 or length <= 0:
        return 0.0, 0
    return math.sqrt(max(0.0, (gain - df) / length)), int(df)


def _basis(x: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the columns' span."""
    if x.shape[1] == 0:
        return np.zeros((x.shape[0], 0))
    u, s, _ = np.linalg.svd(x, full_matrices=False)
    return u[:, s > RANK_TOL * s.max()] if s.size and s.max() > 0 else np.zeros((x.shape[0], 0))
