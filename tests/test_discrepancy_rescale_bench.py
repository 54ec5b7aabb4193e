"""The rescale bench's recalibration map: fitted on one set of results, it states each block's share right there."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from discrepancy_rescale import isotonic  # noqa: E402


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
