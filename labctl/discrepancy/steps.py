"""Which points repeat one load step (the replicate sets), and how far each sits from its step's load.

Every seating of a roller case takes the same nut turns, so its k-th step is the other seatings' k-th step even
where their loads differ by a few per cent (the nut's slack, the spring's seat, the load cell's own noise). Steps
are matched by rank — each seating aligned, in load order, to the one with most steps, so that a blow not taken
leaves a gap — when every point then sits within ``MAX_SLACK`` of its step's mean load and nearer it than any other
step's; otherwise points within ``SAME_STEP`` of each other's load, of different seatings, are one step. Where a
step's loads differ, its stiffnesses differ with them (a line contact's k grows slowly with load, about as F^0.1,
faster where the surface is still closing). So before the steps are compared each ln k is brought to its step's mean
load along the case's own curve of step means (``level_to_steps``): the curve's slope comes from the steps' spread
in load, which is wide, not from the spread within a step, which holds the load cell's own reading noise as well.
That reading noise (the stiffness follows the load reached, not the load read) then stays in the pure error, as it
stays in every model's residual at the loads read; and a seating that reached every turn a little high is its
load's, not an offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from labctl.discrepancy.data import CaseData, Dataset

SAME_STEP = 0.05
"""Loads of two seatings' points within this relative distance count as one step when steps are not matched by
rank."""
MAX_SLACK = 0.1
"""Farthest (in ln F) a seating's point may sit from its step's mean load when steps are matched by rank: a nut
turn reached ±10 % apart; beyond it the seatings took other loads, not the same turns."""
CURVE_DEGREE = 2
"""Degree of the polynomial in ln F through a case's step means whose slope brings a point to its step's load."""


@dataclass(frozen=True)
class ReplicateSets:
    """The load steps of every case: the design alone."""

    case_groups: list[list[np.ndarray]]
    """Per case, its steps as indices into the case's points."""
    groups: list[np.ndarray]
    """Every step as indices into the dataset's points (singletons included)."""


def replicate_sets(data: Dataset) -> ReplicateSets:
    """The dataset's load steps (``ReplicateSets``)."""
    case_groups = [case_groups_of(c) for c in data.cases]
    groups = [g + sl.start for cg, sl in zip(case_groups, data.case_slices(), strict=True) for g in cg]
    return ReplicateSets(case_groups, groups)


def case_groups_of(c: CaseData) -> list[np.ndarray]:
    """One case's steps: by rank when the seatings' steps align (see the module doc), else by load."""
    reps = np.unique(c.repetition)
    if reps.size > 1 and np.all(reps >= 0):
        ranked = _by_rank(np.log(c.load_n), c.repetition, reps)
        if ranked is not None:
            return ranked
    return _by_load(c)


def _by_rank(x: np.ndarray, repetition: np.ndarray, reps: np.ndarray) -> list[np.ndarray] | None:
    """Steps matched by rank: each seating (points in ln F order) aligned to the seating with most steps; None when
    a point would sit farther than ``MAX_SLACK`` from its step's mean ln F, or nearer another step's."""
    seatings = [idx[np.argsort(x[idx], kind="stable")] for idx in (np.flatnonzero(repetition == r) for r in reps)]
    reference = max(seatings, key=lambda s: s.size)
    slots: list[list[int]] = [[] for _ in range(reference.size)]
    for s in seatings:
        for point, slot in zip(s, _align(x[s], x[reference]), strict=True):
            slots[slot].append(int(point))
    groups = [np.sort(np.array(g)) for g in slots if g]
    centre = np.array([x[g].mean() for g in groups])
    for j, g in enumerate(groups):
        off = np.abs(x[g][:, None] - centre[None, :])
        if np.any(off[:, j] > MAX_SLACK) or np.any(np.argmin(off, axis=1) != j):
            return None
    return groups


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


def _by_load(c: CaseData) -> list[np.ndarray]:
    """Steps by load: points within ``SAME_STEP`` of a step's first load, of a seating not yet in it."""
    groups: list[list[int]] = []
    for i in np.argsort(c.load_n, kind="stable"):
        last = groups[-1] if groups else None
        if (last is not None and c.load_n[i] <= c.load_n[last[0]] * (1 + SAME_STEP)
                and (c.repetition[i] < 0 or c.repetition[i] not in c.repetition[last])):
            last.append(int(i))
        else:
            groups.append([int(i)])
    return [np.array(g) for g in groups]


def level_to_steps(x: np.ndarray, y: np.ndarray, groups: list[np.ndarray]) -> np.ndarray:
    """One case's ln k (``y`` at ln F ``x``) brought to its steps' mean loads: less the slope, at each step, of a
    polynomial (``CURVE_DEGREE``, fewer with fewer steps) through the step means, times the point's distance in
    ln F from its step's mean (``groups``: the steps' points, the others left as they are)."""
    steps = [g for g in groups if g.size]
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
