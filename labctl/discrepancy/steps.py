"""Which points repeat one load step (the replicate sets), and how far each sits from its step's load.

Every seating of a roller case takes the same nut turns, so its k-th step is the other seatings' k-th step even
where their loads differ by a few per cent (the nut's slack, the spring's seat, the load cell's own noise). Steps
are matched by rank — each seating aligned, in load order, to the one with most steps, so that a blow not taken
leaves a gap — when every point then sits within ``MAX_SLACK`` of its step's mean load and nearer it than any
other step's; otherwise points
within ``SAME_STEP`` of each other's load, of different seatings, are one step. Where a step's loads differ, its
stiffnesses differ with them (a line contact's k grows slowly with load, about as F^0.1, faster where the surface
is still closing), so the saturated model ("one mean per step") carries, per case, a slope in ln F within the steps
that changes smoothly along the load range (``within_columns``): without it that spread would pass for point noise
(a few per cent of load apart is as much as the point noise of a well-located bounce frequency), and a seating that
reached every turn a little high for a seating offset.
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
SLOPE_TERMS = 2
"""Terms of the within-step slope along a case's load range: a constant and a linear change in ln F (a line
contact's slope falls slowly with load; each term costs the pure error one degree of freedom per case)."""
STEPS_PER_TERM = 3
"""Steps with a load spread each further slope term needs."""
MIN_SPREAD = 0.01
"""Least rms distance (in ln F) of a case's points from their steps' mean loads for the slope within the steps to
enter its saturated model. Below it the spread is as likely the load cell's own reading noise (0.2–1 % of reading),
which the stiffness does not follow, and at a line contact's slope (≲ 0.3) it moves k by less than 0.3 %, while
each slope term costs the pure error a degree of freedom."""
NO_SPREAD = 1e-9
"""A step whose ln F varies less than this has one load."""


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


def block_diagonal(blocks: list[np.ndarray]) -> np.ndarray:
    """Each case's columns (its points × its terms) in one matrix over the dataset, the cases' blocks on the
    diagonal."""
    out = np.zeros((sum(b.shape[0] for b in blocks), sum(b.shape[1] for b in blocks)))
    row = col = 0
    for b in blocks:
        out[row:row + b.shape[0], col:col + b.shape[1]] = b
        row, col = row + b.shape[0], col + b.shape[1]
    return out


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


def within_columns(x: np.ndarray, groups: list[np.ndarray]) -> np.ndarray:
    """A case's within-step slope columns: each point's ln F less its step's mean, times 1 and t (the step's mean
    ln F across the case's range, in [−1, 1]), as many terms as the steps with a load spread allow, none where the
    points sit closer to their steps' loads than ``MIN_SPREAD``; zero at points in no step (``groups``: the steps'
    points kept)."""
    d = np.zeros(x.size)
    centre = np.full(x.size, np.nan)
    spread = 0
    for g in (g for g in groups if g.size):
        centre[g] = x[g].mean()
        d[g] = x[g] - centre[g]
        spread += int(np.ptp(x[g]) > NO_SPREAD)
    terms = min(SLOPE_TERMS, -(-spread // STEPS_PER_TERM))
    shared = np.isfinite(centre) & (d != 0)
    if terms == 0 or float(np.sqrt(np.mean(d[shared] ** 2))) < MIN_SPREAD:
        return np.zeros((x.size, 0))
    lo, hi = float(np.nanmin(centre)), float(np.nanmax(centre))
    t = np.nan_to_num((centre - 0.5 * (hi + lo)) / max(0.5 * (hi - lo), NO_SPREAD))
    columns = np.stack([d, d * t][:terms], axis=1)
    return columns / np.maximum(np.abs(columns).max(axis=0), NO_SPREAD)  # of order one, as the step columns
