"""The question "which effect?" resampled over roller cases: a lead must hold across roller types to be stated as
near-certain."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import expit
from scipy.stats import beta

from labctl.discrepancy import build_dataset, run_discrepancy
from labctl.discrepancy.form import BEND_SIGMA, FormPrior, form_basis
from labctl.discrepancy.noise import estimate_noise
from labctl.discrepancy.questions import (
    DRAWS,
    MIN_CASES,
    TEMPERATURE,
    case_weights,
    probabilities,
    resampled,
)
from labctl.discrepancy.synthetic import synthesize
from labctl.physics import ContactLaw, EndEffects
from tests.discrepancy_util import GENERATOR_NOISE

NAMES = ["none", "a", "b"]


def two_candidates(chi2_a: list[float], chi2_b: list[float], t: float = 1.0) -> np.ndarray:
    """p(a), p(b) with equal priors, "none" ruled out, each candidate's log evidence −½·Σχ²/T."""
    chi2 = np.array([[0.0] * len(chi2_a), chi2_a, chi2_b])
    return probabilities(NAMES, np.zeros(3), lambda temp: -0.5 * chi2.sum(axis=1) / temp, t,
                         frozenset({"none"}), case_log_lik=lambda temp: -0.5 * chi2 / temp)[1:]


def test_a_lead_every_roller_case_shares_keeps_its_probability():
    # a beats b by 80 in χ² pooled, the same 80/7 in each of the seven cases: every resample keeps the lead
    p = two_candidates([100.0] * 7, [100.0 + 80.0 / 7] * 7)
    assert p[0] == pytest.approx(expit(80.0 / 2), abs=1e-9)
    assert p[0] > 0.99999


def test_a_lead_that_one_roller_case_overturns_gets_the_share_of_resamples_it_survives():
    # a beats b by 30 in each of six cases; b beats a by 100 in the seventh. Pooled, a leads by 80 (p ≈ 1 - 2e-6);
    # a resample keeps a's lead when the seventh case's weight α₇ < 30/130, Beta(1, 6) for seven cases, and the
    # difference is so large that each resample is all but decided
    p = two_candidates([100.0] * 6 + [130.0], [130.0] * 6 + [30.0])
    share = beta(1, 6).cdf(30.0 / 130.0)
    assert p[0] == pytest.approx(share, abs=4 * np.sqrt(share * (1 - share) / DRAWS))
    assert p[0] < 0.999
    unresampled = probabilities(NAMES, np.zeros(3), lambda t: -0.5 * np.array([0.0, 730.0, 810.0]) / t,
                                1.0, frozenset({"none"}))[1]
    assert unresampled > 0.99999


def test_the_resampled_probabilities_are_a_distribution_and_the_same_every_time():
    rng = np.random.default_rng(3)
    chi2 = rng.uniform(50, 150, size=(6, 7))
    log_post = rng.normal(size=6)
    log_post[2] = -np.inf  # ruled out: no probability
    p = resampled(log_post, -0.5 * chi2)
    assert p.sum() == pytest.approx(1.0) and p[2] == 0.0 and np.all(p >= 0)
    assert np.array_equal(p, resampled(log_post, -0.5 * chi2))
    w = case_weights(7)
    assert w.shape == (DRAWS, 7) and np.allclose(w.sum(axis=1), 0.0)  # weights C·α average 1 in every resample


def test_with_fewer_roller_cases_than_the_minimum_the_pooled_evidence_decides():
    # two cases, one overturning the other: not resampled, the pooled evidence decides
    chi2 = np.array([[0.0, 0.0], [100.0, 130.0], [130.0, 30.0]])
    assert chi2.shape[1] < MIN_CASES
    p = probabilities(NAMES, np.zeros(3), lambda t: -0.5 * chi2.sum(axis=1) / t, TEMPERATURE, frozenset({"none"}),
                      case_log_lik=lambda t: -0.5 * chi2 / t)
    assert p[2] == pytest.approx(expit(70.0 / 2 / TEMPERATURE))


def test_the_case_parts_of_the_form_marginal_sum_to_the_dense_gaussian_integral():
    truth = ContactLaw("tripp", 2e-3, (EndEffects(0.1e-3),)).stiffness_n_per_m
    data = build_dataset(synthesize(truth, range(1, 4), noise=GENERATOR_NOISE, seed=2, seating_rel=0.002))
    noise = estimate_noise(data)
    sigma = noise.sigma_at(data)
    form = FormPrior.of(data, noise, sigma)
    a = noise.whiten(data, form_basis(data), sigma)
    e = np.random.default_rng(1).normal(size=data.n_points) + a @ np.full(a.shape[1], 0.02)
    for t, tau in ((1.0, 3e-3), (2.0, 0.03)):
        cov = t * np.eye(data.n_points) + tau**2 * a @ a.T
        dense = -0.5 * e @ np.linalg.solve(cov, e) - 0.5 * (np.linalg.slogdet(cov)[1] - data.n_points * np.log(t))
        parts = form.case_log_marginals(e, t, tau)
        assert len(parts) == len(data.cases) == 3
        assert sum(parts) == pytest.approx(dense, rel=1e-9)
        # the bend's posterior mean (shared columns, taken off before the parts): the dense Gaussian conditional
        b = np.column_stack([np.linspace(-1, 1, data.n_points), np.linspace(-1, 1, data.n_points) ** 2])
        full = cov + BEND_SIGMA**2 * b @ b.T
        assert form.bend_mean(e, b, t, tau) == pytest.approx(BEND_SIGMA**2 * b @ b.T @ np.linalg.solve(full, e))


@pytest.mark.parametrize(("types", "resampled_"), [(range(1, 8), True), ((3,), False)])
def test_the_json_says_whether_the_question_was_resampled_over_roller_cases(types, resampled_):
    truth = ContactLaw("tripp", 2e-3, (EndEffects(0.1e-3),)).stiffness_n_per_m
    out = run_discrepancy(synthesize(truth, types, noise=GENERATOR_NOISE, seed=5, seating_rel=0.002)).to_dict()
    assert out["decision"]["resampled_over_cases"] is resampled_
    assert out["decision"]["temperature"] == TEMPERATURE
    assert sum(x["probability"] for x in out["explanations"]) == pytest.approx(1.0)


def test_a_wider_resampling_spreads_a_lead_that_rests_on_a_few_cases():
    # candidate 2 wins four cases by a little, candidate 1 three cases by more and the pooled evidence: the lower
    # the Dirichlet concentration, the more often a resample weights a few cases up, and the closer the two come
    chi2 = np.array([[100.0] * 7, [90.0] * 4 + [60.0] * 3, [88.0] * 4 + [64.0] * 3])
    log_post = np.array([-np.inf, *(-0.5 * chi2[1:].sum(axis=1))])
    tops = [resampled(log_post, -0.5 * chi2, concentration=a)[1:] for a in (1.0, 0.25)]
    assert all(p.sum() == pytest.approx(1.0) for p in tops)
    assert abs(tops[1][0] - tops[1][1]) < abs(tops[0][0] - tops[0][1])
    w = case_weights(7, 0.25)
    assert np.allclose(w.sum(axis=1), 0.0) and w.std() > case_weights(7).std()
