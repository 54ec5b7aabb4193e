"""The outlier screen on campaigns of coarse load steps whose seatings reach each nut turn at loads several per cent
apart: a point is compared with its nut turn's other repetitions, each brought to the turn's load."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from labctl.discrepancy.set_aside import screened
from labctl.discrepancy.synthetic import NoiseModel, case_for, synthesize
from labctl.discrepancy.workflow import baseline_spec
from tests.discrepancy_util import world

SLACK_REL = 0.04
"""σ of the load a seating reaches at one nut turn about the turn's nominal load (the nut's slack)."""


def _nut_turn_campaign(seed: int) -> list:
    """A null campaign of 7 coarse load steps (preload to 0.3·C0), 0.2 % point noise, where each seating reaches
    each turn at its own load (``SLACK_REL``): the stiffness follows the load reached, so no point is bad, but
    the repetitions of a turn lie further apart than one replicate set holds."""
    law = world()
    rng = np.random.default_rng(100 + seed)
    points = synthesize(law, steps=7, noise=NoiseModel(0.002, 0.002, load_rel=0.0), seating_rel=0.003, seed=seed)
    out = []
    for p in points:
        case, nominal = case_for(p.roller_type), np.array([p.load_n])
        reached = nominal * np.exp(SLACK_REL * rng.standard_normal())
        k = p.stiffness_n_per_m * float(law(case, reached)[0] / law(case, nominal)[0])
        out.append(dataclasses.replace(p, load_n=float(reached[0]), stiffness_n_per_m=k))
    return out


@pytest.mark.parametrize("seed", [7, 9])
def test_a_clean_point_whose_nut_turn_spreads_beyond_a_replicate_set_is_not_set_aside(seed):
    # Between coarse steps ln k bends away from the line through a point's neighbours by several point σ, in every
    # seating alike; with the turn's loads 4 % apart each point was its own replicate set, with no repetition to
    # show the bend, and the screen set a clean point aside in seeds 7 and 9 until it compared each point with its
    # nut turn's other repetitions.
    _, _, screening = screened(_nut_turn_campaign(seed), baseline_spec("tripp"))
    assert screening.outliers == []


@pytest.mark.parametrize("factor", [0.9, 1.1])
def test_a_gross_outlier_among_spread_nut_turns_is_set_aside_and_its_clean_repetitions_kept(factor):
    # 10 % off at the fourth turn of one seating: before, the bend made a clean repetition of that turn the worst
    # point of its neighbourhood, and the step test then set the whole turn aside (three points, two clean).
    points = _nut_turn_campaign(7)
    own = sorted(p.load_n for p in points if p.roller_type == 4 and p.repetition == 2)
    bad = own[3]
    points = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * factor) if p.load_n == bad else p
              for p in points]
    _, _, screening = screened(points, baseline_spec("tripp"))
    assert [o["load_n"] for o in screening.outliers] == [bad]
