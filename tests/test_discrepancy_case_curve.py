"""Each case's own bend of ln k, fitted robustly for the outlier screen: the bend is found, a gross point does not
pull it, and offsets and slopes (which lines through two neighbours ignore) are not part of it."""

from __future__ import annotations

import numpy as np
import pytest

from labctl.discrepancy.case_curve import case_bend
from labctl.discrepancy.data import Dataset, build_dataset
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from tests.discrepancy_util import world

SIGMA = 0.004


def _campaign(seed: int = 1) -> Dataset:
    """Seven types, three seatings, eleven steps of Tripp's law with 0.4 % point noise and seating offsets."""
    return build_dataset(synthesize(world(), steps=11, noise=NoiseModel(SIGMA, SIGMA, load_rel=0.0), seed=seed,
                                    seating_rel=0.01))


def _bend_only(data: Dataset, values: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
    """``values`` less, per seating, their least-squares line in ln F (over the points ``at``, a mask): what the
    screen's lines see of them."""
    at = np.ones(data.n_points, dtype=bool) if at is None else at
    out, runs, x = values.copy(), data.run_ids(), np.log(data.load_n)
    for r in np.unique(runs):
        m = (runs == r) & at
        out[m] -= np.polyval(np.polyfit(x[m], values[m], 1), x[m])
    return np.where(at, out, 0.0)


def test_the_bend_of_a_smooth_curve_is_found_and_offsets_and_slopes_are_not_part_of_it():
    data = _campaign()
    x, runs = np.log(data.load_n), data.run_ids()
    curve = 0.3 * (x - x.mean()) ** 2 - 0.05 * (x - x.mean()) ** 3
    ln_k = curve + 0.02 * runs + 0.7 * x  # a seating offset and a slope on top
    bend = case_bend(data.with_ln_stiffness(ln_k), np.ones(data.n_points, dtype=bool))
    assert np.max(np.abs(_bend_only(data, bend) - _bend_only(data, curve))) < 1e-8


@pytest.mark.parametrize("factor", [0.85, 1.2])
def test_a_gross_point_does_not_pull_the_curve_it_is_judged_against(factor):
    data = _campaign(seed=4)
    bad = int(np.argmax(data.load_n > np.median(data.load_n)))
    ln_k = data.ln_stiffness.copy()
    ln_k[bad] += np.log(factor)  # 40–45 point σ off
    others = np.arange(data.n_points) != bad
    judged = case_bend(data.with_ln_stiffness(ln_k), np.ones(data.n_points, dtype=bool))
    without = case_bend(data, others)  # the curve as if the point had not been measured
    shift = _bend_only(data, judged - without, others)
    # Least squares bends the case's curve towards the bad point by 3–4 point σ; the bisquare by < 0.1 σ.
    assert np.max(np.abs(shift)) < 0.1 * SIGMA
    pulled = _bend_only(data, _least_squares_bend(data, ln_k) - _least_squares_bend(data, data.ln_stiffness), others)
    assert np.max(np.abs(pulled)) > 1.0 * SIGMA  # the bad point is large enough for the test to mean something


def _least_squares_bend(data: Dataset, ln_k: np.ndarray) -> np.ndarray:
    """Each case's cubic in ln F beside a seating offset, fitted by plain least squares."""
    out, runs, x = np.zeros(data.n_points), data.run_ids(), np.log(data.load_n)
    for sl in data.case_slices():
        seat = (runs[sl, None] == np.unique(runs[sl])[None, :]).astype(float)
        a = np.hstack([seat, np.stack([x[sl] ** d for d in (1, 2, 3)], axis=1)])
        coef = np.linalg.lstsq(a, ln_k[sl], rcond=None)[0]
        out[sl] = a[:, -3:] @ coef[-3:]
    return out
