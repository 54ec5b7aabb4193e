"""The two questions the posterior answers: is there any effect, and which one — the latter resampled over roller
cases (a Bayesian bootstrap of each candidate's fit) when there are enough of them.

A law that differs from the truth can still win on the pooled evidence through one or two roller cases it happens to
fit, where another candidate wins the rest. The evidence alone states such a lead as near-certain; resampled over
the cases it holds only in the resamples that weight those cases up. Each resample weights the cases by
C·α_c, α ~ Dirichlet(1, …, 1) (the Bayesian bootstrap; the weights average 1), and moves every candidate's log
posterior by Σ_c (C·α_c − 1)·ℓ_kc, ℓ_kc case c's part of its log marginal likelihood at the inflation T; the
probabilities are the mean over resamples of the softmax (as pseudo-BMA+ weights are, Yao et al. 2018, with roller
cases in place of points: a name must hold across roller types). With fewer than ``MIN_CASES`` cases there is no
spread between cases to resample, and the pooled evidence decides.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np
from scipy.special import logsumexp

TEMPERATURE = 4.0
"""The inflation of the question "which effect?" (and the one each candidate's discrepancy scale and shape are
chosen at), chosen on the blind worlds' twenty calibration seeds: the largest T whose log loss of the true
explanation is within one standard error of the lowest (docs/discrepancy.md, Evaluation)."""
PRESENCE_TEMPERATURE = 1.0
"""The scale "none" is weighed against every effect at: the noise model's own (no inflation)."""
MIN_CASES = 3
"""Fewest roller cases the question "which effect?" is resampled over."""
DRAWS = 1000
"""Resamples per decision (fixed draws: the same data always give the same probabilities)."""


@lru_cache(maxsize=16)
def case_weights(n_cases: int, concentration: float = 1.0) -> np.ndarray:
    """``DRAWS`` × ``n_cases`` Bayesian-bootstrap weights less one, C·α − 1 with α ~ Dirichlet(a, …, a), a the
    ``concentration`` (1: the Bayesian bootstrap; below 1 a bench's wider resampling, the weights spread further)."""
    draws = np.random.default_rng(0).dirichlet(np.full(n_cases, concentration), size=DRAWS) * n_cases - 1.0
    draws.setflags(write=False)
    return draws


def resampled(log_post: np.ndarray, case_log_lik: np.ndarray, concentration: float = 1.0) -> np.ndarray:
    """Each candidate's probability, the mean over resamples of softmax(log_post + Σ_c w_c·ℓ_kc).

    ``log_post``: each candidate's log prior + log evidence at T (−inf: no probability); ``case_log_lik``:
    candidates × roller cases, each case's part ℓ_kc of the candidate's log likelihood at T."""
    alive = np.isfinite(log_post)
    out = np.zeros(log_post.size)
    if not alive.any():
        return out
    ell = np.asarray(case_log_lik, dtype=float)[alive]
    s = log_post[alive][None, :] + case_weights(ell.shape[1], concentration) @ ell.T
    out[alive] = np.mean(np.exp(s - logsumexp(s, axis=1, keepdims=True)), axis=0)
    return out


def probabilities(names: Sequence[str], log_prior: np.ndarray, log_evidence: Callable[[float], np.ndarray],
                  temperature: float = TEMPERATURE, rejected: frozenset[str] = frozenset(), scale: float = 1.0,
                  case_log_lik: Callable[[float], np.ndarray] | None = None, concentration: float = 1.0
                  ) -> np.ndarray:
    """Every candidate's posterior probability, in two questions. Is there any effect? "none" against all the
    others at the noise model's own scale (``PRESENCE_TEMPERATURE``): the noise comes from the repetitions, and
    a misfit beyond it is evidence of some effect whatever its law. Which one? The others against each other at
    the inflated ``temperature``, where every law is only approximate; resampled over the roller cases
    (``resampled``) when ``case_log_lik(T)`` (candidates × cases: each case's part of each candidate's log
    likelihood at T) is given for at least ``MIN_CASES`` cases. ``log_evidence(T)``: each candidate's
    log p(D | M) at inflation T; the ``rejected`` explanations (``rejected_explanations``) get no probability.
    ``scale`` divides the second question's log posterior (1 in the workflow; a bench's confidence scale, which
    keeps the ranking and spreads the probabilities); ``concentration``: the resampling's (``case_weights``)."""
    names_a = np.array(names)
    none = names_a == "none"
    ruled_out = np.isin(names_a, list(rejected))
    others = ~none & ~ruled_out
    out = np.zeros(len(names))
    p_none = 0.0
    if none.any() and not ruled_out[none].any():
        s0 = np.where(ruled_out, -np.inf, log_prior + log_evidence(PRESENCE_TEMPERATURE))
        p_none = float(np.exp(s0[none][0] - logsumexp(s0))) if others.any() else 1.0
        out[none] = p_none
    if others.any():
        s = np.where(others, (log_prior + log_evidence(temperature)) / scale, -np.inf)
        ell = None if case_log_lik is None else np.asarray(case_log_lik(temperature))
        if ell is not None and resampled_over(ell.shape[1]):
            out[others] = (1.0 - p_none) * resampled(s, ell / scale, concentration)[others]
        else:
            out[others] = (1.0 - p_none) * np.exp(s[others] - logsumexp(s[others]))
    return out


def resampled_over(n_cases: int) -> bool:
    """Whether the question "which effect?" is resampled over ``n_cases`` roller cases (at least ``MIN_CASES``)."""
    return n_cases >= MIN_CASES
