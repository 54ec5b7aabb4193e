"""Nut turns matched by rank across seatings, and ln k brought to each turn's load: what the outlier screen compares
a point with across its repetitions."""

from __future__ import annotations

import numpy as np

from labctl.discrepancy.data import CaseData
from labctl.discrepancy.synthetic import case_for
from labctl.discrepancy.turns import level_to_turns, turns_by_rank


def _case(loads: list[list[float]]) -> CaseData:
    """One roller case whose seating r (from 1) reached the loads ``loads[r - 1]``; ln k = 0."""
    load = np.concatenate([np.asarray(s, dtype=float) for s in loads])
    rep = np.concatenate([np.full(len(s), r + 1) for r, s in enumerate(loads)])
    return CaseData(case_for(1), load, np.zeros(load.size), rep)


def test_turns_reached_several_per_cent_apart_are_matched_by_rank_and_a_missing_blow_leaves_a_gap():
    c = _case([[30.0, 220.0, 400.0, 580.0], [32.0, 208.0, 585.0], [28.5, 231.0, 392.0, 570.0]])
    turns = turns_by_rank(c)
    assert [sorted(c.load_n[g].tolist()) for g in turns] == [[28.5, 30.0, 32.0], [208.0, 220.0, 231.0],
                                                            [392.0, 400.0], [570.0, 580.0, 585.0]]


def test_seatings_that_took_other_loads_are_not_taken_for_the_same_turns():
    assert turns_by_rank(_case([[30.0, 220.0, 400.0], [40.0, 290.0, 530.0]])) is None  # a third apart
    assert turns_by_rank(_case([[30.0, 220.0, 400.0]])) is None  # one seating: nothing to match


def test_each_ln_k_is_brought_to_its_turns_mean_load_along_the_curve_of_turn_means():
    x = np.log(np.array([30.0, 33.0, 200.0, 230.0, 400.0, 430.0]))
    y = 0.2 * x - 0.01 * x**2  # a smooth curve, no noise
    turns = [np.array([0, 1]), np.array([2, 3]), np.array([4, 5])]
    level = level_to_turns(x, y, turns)
    for g in turns:  # both repetitions of a turn now agree (to the curve's third-order term)
        assert abs(level[g[0]] - level[g[1]]) < 0.02 * abs(y[g[0]] - y[g[1]])
