"""The rescale bench's recalibration map: fitted on one set of results, it states each block's share right there."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from discrepancy_rescale import isotonic, log_priors, unlisted_at, world_mix  # noqa: E402


def stated(r):
    return [("end_effects", r["p"]), ("unlisted", 0.7 * (1 - r["p"])), ("none", 0.3 * (1 - r["p"]))]


def results(pairs):
    return [{"p": p, "truth_name": "end_effects" if right else "unlisted"} for p, right in pairs]


def test_the_map_fitted_on_overconfident_results_states_their_share_right_and_keeps_the_sum():
    rng = np.random.default_rng(0)
    p = rng.uniform(0.5, 1.0, 400)
    fitted_on = results(zip(p, rng.uniform(size=400) < p - 0.2, strict=True))  # right 0.2 less often than stated
    mapped = isotonic(stated, fitted_on)
    new = np.array([dict(mapped(r))["end_effects"] for r in fitted_on])
    right = np.array([r["truth_name"] == "end_effects" for r in fitted_on])
    assert new.mean() == pytest.approx(right.mean(), abs=1e-9)  # isotonic regression keeps the mean
    assert all(sum(v for _, v in mapped(r)) == pytest.approx(1.0) for r in fitted_on)
    order = np.argsort(p)
    assert np.all(np.diff(new[order]) >= -1e-12)  # monotone in the stated probability
    assert new.mean() < p.mean() - 0.1


def _candidate(name, by_t, cases_by_t):
    return {"explanation": name, "log_prior": -1.0, "log_evidence_by_temperature": by_t,
            "case_log_lik_by_temperature": cases_by_t}


def test_unlisted_gain_is_counted_at_the_higher_inflation_and_nothing_else_moves():
    none = _candidate("none", {"4": -100.0, "8": -60.0}, {"4": [-50.0, -50.0], "8": [-30.0, -30.0]})
    unl = _candidate("unlisted", {"4": -80.0, "8": -52.0}, {"4": [-45.0, -35.0], "8": [-28.0, -24.0]})
    end = _candidate("end_effects", {"4": -90.0, "8": -55.0}, {"4": [-45.0, -45.0], "8": [-27.0, -28.0]})
    r = {"candidates": [none, unl, end]}
    moved = unlisted_at(r, 4.0, 2.0)
    new = moved["candidates"][1]
    assert new["log_evidence_by_temperature"]["4"] == pytest.approx(-100.0 + (-52.0 + 60.0))  # gain 8 at T = 8
    assert new["case_log_lik_by_temperature"]["4"] == pytest.approx([-50.0 + 2.0, -50.0 + 6.0])
    assert new["log_evidence_by_temperature"]["8"] == -52.0
    assert moved["candidates"][0] is none and moved["candidates"][2] is end
    assert r["candidates"][1]["log_evidence_by_temperature"]["4"] == -80.0  # the stored result is not changed


def test_the_judge_mix_prior_is_each_truths_share_with_a_floor_for_no_worlds_truth():
    results = [{"truth_name": t} for t in ("none", "none", "end_effects", "unlisted")]
    mix = world_mix(results)
    r = {"candidates": [{"explanation": n, "log_prior": 0.0} for n in ("none", "end_effects", "misalignment")]}
    assert np.exp(log_priors(r, "judge-mix", mix)) == pytest.approx([0.5, 0.25, 1e-4])
