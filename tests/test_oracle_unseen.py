"""The oracle with the world's own law unseen (bench/oracle_unseen.py): with nothing unseen it is the oracle's
posterior; an unseen law leaves each class its prior mass over the laws left, and a class with none left goes."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from oracle_ceiling import hypotheses, logsumexp  # noqa: E402
from oracle_unseen import posterior  # noqa: E402

SUBS = [("none", [], math.log(0.5), -10.0),
        ("roughness", ["a"], math.log(0.125), -2.0), ("roughness", ["b"], math.log(0.125), -9.0),
        ("roughness + ends", ["a", "c"], math.log(0.125), -1.0),
        ("roughness + ends", ["b", "c"], math.log(0.125), -8.0)]


def test_with_every_law_known_a_class_is_the_sum_of_its_sub_hypotheses() -> None:
    post = posterior(SUBS)
    assert post["roughness"] == pytest.approx(logsumexp([math.log(0.125) - 2.0, math.log(0.125) - 9.0]))
    assert list(post) == ["roughness + ends", "roughness", "none"]


def test_an_unseen_law_leaves_the_class_its_prior_mass_over_the_laws_left() -> None:
    post = posterior(SUBS, frozenset({"a"}))
    # the class keeps its 0.25, now all on law b: ln 0.25 − 9, not ln 0.125 − 9
    assert post["roughness"] == pytest.approx(math.log(0.25) - 9.0)
    assert post["roughness + ends"] == pytest.approx(math.log(0.25) - 8.0)
    assert post["none"] == pytest.approx(math.log(0.5) - 10.0)  # untouched
    assert list(post)[0] == "roughness + ends"


def test_a_class_with_no_law_left_gets_no_probability() -> None:
    assert "roughness + ends" not in posterior(SUBS, frozenset({"c"}))


def test_each_judge_family_is_one_law_and_an_outside_class_keeps_three_when_one_is_unseen() -> None:
    hyps = hypotheses()
    fams = {p.fam.name for h in hyps for p in h.parts if p.fam is not None}
    subs = [(h.label, [p.fam.name for p in h.parts if p.fam is not None], float(h.log_prior), 0.0) for h in hyps]
    flat = posterior(subs)  # equal evidence: the posterior is the prior
    assert sum(math.exp(v) for v in flat.values()) == pytest.approx(1.0)
    for family in fams:
        moved = posterior(subs, frozenset({family}))
        for k, v in moved.items():  # every class keeps its prior mass
            assert v == pytest.approx(flat[k])
    assert sum(h.label == "unlisted" for h in hyps) == 4
