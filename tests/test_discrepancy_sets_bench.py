"""The credible-set bench (bench/discrepancy_sets.py): the fewest candidates reaching the stated mass, probabilities
from a log posterior, and the row's counts."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from discrepancy_sets import credible_set, from_log_posterior, line  # noqa: E402


def test_the_set_is_the_fewest_most_probable_candidates_reaching_the_level() -> None:
    probs = [("a", 0.6), ("b", 0.25), ("c", 0.1), ("d", 0.05)]
    assert credible_set(probs, 0.9) == ["a", "b", "c"]  # 0.85 < 0.9 ≤ 0.95
    assert credible_set(probs, 0.5) == ["a"]
    assert credible_set([("a", 0.5), ("b", 0.3)], 0.9) == ["a", "b"]  # never reached: all of them


def test_probabilities_from_a_log_posterior_sum_to_one_in_order() -> None:
    ranked = from_log_posterior({"x": math.log(2.0) + 700.0, "y": 700.0, "z": -math.inf})
    assert [k for k, _ in ranked] == ["x", "y", "z"]
    assert ranked[0][1] == pytest.approx(2 / 3) and ranked[2][1] == 0.0


def test_a_row_counts_first_top_three_and_the_set() -> None:
    cases = [([("a", 0.95), ("b", 0.05)], "a"),  # first; set {a}
             ([("a", 0.5), ("b", 0.3), ("c", 0.15), ("d", 0.05)], "c"),  # top three; set {a, b, c}
             ([("a", 0.5), ("b", 0.2), ("c", 0.1), ("d", 0.1), ("e", 0.1)], "e")]  # set {a, b, c, d, e}, not top 3
    row = line("x", cases)
    assert "| 3 | 1/3 = 0.33" in row
    assert "| 2/3 = 0.67" in row  # in the top three
    assert "| 3/3 = 1.00" in row  # in the 90 % set
    assert row.endswith("| 3.0 |")  # (1 + 3 + 5) / 3
