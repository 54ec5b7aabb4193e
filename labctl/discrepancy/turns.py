"""Which points of a case repeat one nut turn, and each ln k brought to its turn's mean load: what the outlier
screen compares a point with across its seatings.

Every seating of a roller case takes the same nut turns, so its k-th turn is the other seatings' k-th even where
their loads differ by several per cent (the nut's slack, the spring's seat, the load cell's reading) — more than
the few per cent within which the noise floor counts points as one load step. Turns are matched by rank: each
seating aligned, in load order, to the one with most steps, so that a blow not taken leaves a gap, when every point
then sits within ``MAX_SLACK`` of its turn's mean load and nearer it than any other turn's. A turn's stiffnesses
differ with its loads, so before they are compared each ln k is brought to its turn's mean load along the case's
curve of turn means (``level_to_turns``), whose slope comes from the turns' wide spread in load.
"""

from __future__ import annotations

import numpy as np

from labctl.discrepancy.data import CaseData, Dataset

MAX_SLACK = 0.1
"""Farthest (in ln F) a seating's point may sit from its turn's mean load: a nut turn reached ±10 % apart; beyond
it the seatings took other loads, not the same turns."""
CURVE_DEGREE = 2
"""Degree of the polynomial in ln F through a case's turn means whose slope brings a point to its turn's load."""


def seatings_in_load_order(c: CaseData) -> list[np.ndarray] | None:
    """Each seating's points of one case (indices into it), in load order; None with one seating only or a point
    without a repetition number: where steps can be matched by rank at all."""
    reps = np.unique(c.repetition)
    if reps.size < 2 or np.any(reps < 0):
        return None
    return [idx[np.argsort(c.load_n[idx], kind="stable")] for idx in (np.flatnonzero(c.repetition == r) for r in reps)]


def turns_by_rank(c: CaseData) -> list[np.ndarray] | None:
    """One case's nut turns as indices into its points (module doc); None where its seatings' steps do not align
    so (one seating only, a point without a repetition number, a point nearer another turn's load)."""
    seatings = seatings_in_load_order(c)
    if seatings is None:
        return None
    x = np.log(c.load_n)
    reference = max(seatings, key=lambda s: s.size)
    slots: list[list[int]] = [[] for _ in range(reference.size)]
    for s in seatings:
        for point, slot in zip(s, _align(x[s], x[reference]), strict=True):
            slots[slot].append(int(point))
    turns = [np.sort(np.array(g)) for g in slots if g]
    centre = np.array([x[g].mean() for g in turns])
    for j, g in enumerate(turns):
        off = np.abs(x[g][:, None] - centre[None, :])
        if np.any(off[:, j] > MAX_SLACK) or np.any(np.argmin(off, axis=1) != j):
            return None
    return turns


def dataset_turns(data: Dataset, case_groups: list[list[np.ndarray]]
                  ) -> tuple[list[list[np.ndarray]], list[np.ndarray]]:
    """Each case's nut turns (``turns_by_rank``; else its replicate sets, ``case_groups``), and all of them as indices
    into the dataset: the design alone."""
    per_case = [turns_by_rank(c) or cg for c, cg in zip(data.cases, case_groups, strict=True)]
    return per_case, [g + sl.start for tc, sl in zip(per_case, data.case_slices(), strict=True) for g in tc]


def _align(a: np.ndarray, b: np.ndarray) -> list[int]:
    """The order-keeping match of sorted ``a`` into sorted ``b`` (len a ≤ len b, each b used once at most) with
    the least sum of squared distances: positions in ``b``, one per element of ``a`` (dynamic programming)."""
    m, n = a.size, b.size
    if m == n:
        return list(range(n))
    cost = np.full((m + 1, n + 1), np.inf)
    cost[0, :] = 0.0
    for i in range(1, m + 1):
        for j in range(i, n + 1):
            cost[i, j] = min(cost[i, j - 1], cost[i - 1, j - 1] + (a[i - 1] - b[j - 1]) ** 2)
    match, j = [], n
    for i in range(m, 0, -1):
        while cost[i, j] == cost[i, j - 1] and j > i:
            j -= 1
        match.append(j - 1)
        j -= 1
    return match[::-1]


def level_to_turns(x: np.ndarray, y: np.ndarray, turns: list[np.ndarray]) -> np.ndarray:
    """One case's ln k (``y`` at ln F ``x``) brought to its turns' mean loads: less the slope, at each turn, of a
    polynomial (``CURVE_DEGREE``, lower with fewer turns) through the turn means, times the point's distance in ln F
    from its turn's mean (``turns``: the turns' points; the others left as they are)."""
    steps = [g for g in turns if g.size]
    if len(steps) < 2:
        return y.copy()
    centre = np.array([x[g].mean() for g in steps])
    level = np.array([y[g].mean() for g in steps])
    size = np.array([g.size for g in steps], dtype=float)
    scale = max(float(np.ptp(centre)), 1e-12)
    t = (centre - centre.mean()) / scale
    curve = np.polynomial.Polynomial.fit(t, level, min(CURVE_DEGREE, len(steps) - 1), w=np.sqrt(size))
    slope = curve.deriv()(t) / scale
    out = y.copy()
    for g, b, c in zip(steps, slope, centre, strict=True):
        out[g] = y[g] - b * (x[g] - c)
    return out
