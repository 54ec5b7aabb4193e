"""The oracle's posteriors decided again under the workflow's priors (bench/oracle_priors.py): the swap of priors
is exact, the workflow's priors are a distribution over the judge's classes, and the oracle's stated probability
is its normalised posterior."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from oracle_priors import judge_log_prior, with_prior, workflow_log_prior  # noqa: E402
from oracle_report import reliability, stated  # noqa: E402


def test_the_judge_prior_is_its_scenarios_mix_and_the_workflow_prior_sums_to_one() -> None:
    judge = judge_log_prior()
    assert sum(math.exp(v) for v in judge.values()) == pytest.approx(1.0)
    assert math.exp(judge["unlisted"]) == pytest.approx(4 / 16)  # four outside effects of sixteen scenarios
    workflow = workflow_log_prior(list(judge))
    assert sum(math.exp(v) for v in workflow.values()) == pytest.approx(1.0)
    # one physical term against one pair: 0.35/5 against 0.10/10 in the workflow's classes
    assert workflow["end_effects"] - workflow["surface_roughness + end_effects"] == pytest.approx(math.log(7.0))


def test_swapping_the_prior_moves_the_posterior_by_the_prior_ratio_alone() -> None:
    old = {"none": math.log(0.5), "end_effects": math.log(0.25), "unlisted": math.log(0.25)}
    new = {"none": math.log(0.1), "end_effects": math.log(0.1), "unlisted": math.log(0.8)}
    r = {"truth": "unlisted", "post": {"end_effects": -1.0, "unlisted": -1.5, "none": -4.0}, "top": "end_effects"}
    moved = with_prior(r, old, new)
    assert moved["top"] == "unlisted"  # 0.8/0.25 lifts it by ln 3.2 > 0.5
    for k in r["post"]:
        assert moved["post"][k] - r["post"][k] == pytest.approx(new[k] - old[k])
    assert with_prior(r, old, old)["post"] == pytest.approx(r["post"])


def test_the_stated_probability_is_the_normalised_top_and_the_bins_count_right_and_wrong() -> None:
    r = {"truth": "none", "top": "none", "post": {"none": math.log(0.6), "end_effects": math.log(0.3),
                                                 "unlisted": math.log(0.1)}}
    assert stated({**r, "post": {k: v + 7.0 for k, v in r["post"].items()}}) == pytest.approx(0.6)
    wrong = {**r, "truth": "end_effects"}
    line = reliability([r, r, wrong])
    assert "0.5-0.7: stated 0.60, right 0.67" in line and "of 3" in line
    assert not np.isnan(stated(r))
