"""The candidate models still in play: the workflow's final model and its neighbours, each fitted to the data.

Neighbours of the final model are: the final model plus one candidate term, the final model with one named
term removed, and with one named term swapped for a candidate term; the workflow's unnamed empirical term,
when it proposed one, is a neighbour too. A model is *in play* when its BIC is within ``DECISIVE_BIC`` of the
best (the data do not yet decide against it). Each model carries its parameter covariance from the data
(linearised, whitened with the noise model) with a weak prior: half of each term's bounded range, half a
decade for Tripp's depth, so a parameter the data do not determine keeps its plausible spread instead of
collapsing to zero.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.empirical import EmpiricalTerm, features
from labctl.discrepancy.model import Fit, ModelSpec, predict_ln
from labctl.discrepancy.search import DECISIVE_BIC, Search
from labctl.discrepancy.workflow import DiscrepancyResult

PRIOR_SD_SCALED = 0.5
"""Prior σ of a term's parameter, as a fraction of its bounded range."""
PRIOR_SD_LOG10_DEPTH = 0.5
PRIOR_SD_EMPIRICAL = 1.0
"""Prior σ of an empirical coefficient (ln k per unit of its feature)."""
FD_STEP = 1e-4

Predictor = Callable[[Dataset, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Rival:
    """One candidate model: its terms, how it predicts ln k, its fitted parameters and their covariance."""

    terms: tuple[str, ...]
    predict: Predictor
    theta: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    prior_sd: np.ndarray
    bic: float
    covariance: np.ndarray | None = None

    @property
    def label(self) -> str:
        return " + ".join(self.terms) if self.terms else "baseline"

    def jacobian(self, data: Dataset) -> tuple[np.ndarray, np.ndarray]:
        """Predictions at ``data`` and their derivatives by each parameter (one-sided inside the bounds)."""
        mu = self.predict(data, self.theta)
        jac = np.empty((mu.size, self.theta.size))
        for k in range(self.theta.size):
            h = FD_STEP if self.theta[k] + FD_STEP <= self.upper[k] else -FD_STEP
            x = self.theta.copy()
            x[k] += h
            jac[:, k] = (self.predict(data, x) - mu) / h
        return mu, jac

    def with_covariance(self, data: Dataset, whiten: Callable[[np.ndarray], np.ndarray]) -> Rival:
        """The posterior covariance of the parameters given the data (Laplace: whitened Jacobian + prior)."""
        _, jac = self.jacobian(data)
        jw = whiten(jac)
        precision = jw.T @ jw + np.diag(1.0 / self.prior_sd**2)
        return Rival(self.terms, self.predict, self.theta, self.lower, self.upper, self.prior_sd, self.bic,
                     np.linalg.inv(precision))


def _spec_predictor(spec: ModelSpec) -> Predictor:
    def predict(data: Dataset, x: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            return predict_ln(data, spec.law(x), spec.chain(x))
    return predict


def _prior(spec: ModelSpec) -> np.ndarray:
    head = [PRIOR_SD_LOG10_DEPTH] if spec.fits_depth else []
    return np.array(head + [PRIOR_SD_SCALED] * len(spec.slots()), dtype=float)


def from_fit(fit: Fit) -> Rival:
    lo, hi = fit.spec.bounds()
    return Rival(fit.spec.terms, _spec_predictor(fit.spec), np.asarray(fit.x, dtype=float), lo, hi,
                 _prior(fit.spec), fit.bic)


def from_empirical(final: Fit, term: EmpiricalTerm, data: Dataset, whiten: Callable[[np.ndarray], np.ndarray]
                   ) -> Rival:
    """The final model times exp(Σ coefficient·feature), its depth re-adjusted as the term's fit did."""
    names = list(term.features)
    base = _spec_predictor(final.spec)
    p = final.x.size

    def predict(d: Dataset, x: np.ndarray) -> np.ndarray:
        _, cols = features(d, names)
        return base(d, x[:p]) + cols @ x[p:]

    x = np.concatenate([final.x, np.asarray(term.coefficients, dtype=float)])
    if final.spec.fits_depth:
        x[0] += math.log10(term.depth_factor)
    lo, hi = final.spec.bounds()
    k = len(names)
    lower, upper = np.concatenate([lo, np.full(k, -np.inf)]), np.concatenate([hi, np.full(k, np.inf)])
    z = whiten(predict(data, x) - data.ln_stiffness)
    n = z.size
    bic = n * math.log(max(float(np.mean(z**2)), 1e-300)) + (p + k) * math.log(n)
    prior = np.concatenate([_prior(final.spec), np.full(k, PRIOR_SD_EMPIRICAL)])
    label = f"unnamed empirical term ({', '.join(names)})"
    return Rival((*final.spec.terms, label), predict, x, lower, upper, prior, bic)


def _without(spec: ModelSpec, name: str) -> ModelSpec:
    return ModelSpec(spec.baseline, tuple(e for e in spec.effects if e != name), spec.fixed,
                     tuple(m for m in spec.measurement if m != name), spec.depth_bounds_m)


def neighbour_specs(final: ModelSpec, candidates: Sequence[str]) -> list[ModelSpec]:
    """The final model's neighbours: one candidate term added, one named term removed or swapped."""
    out: list[ModelSpec] = []
    for name in candidates:
        if name not in final.terms:
            out.append(final.with_effects(name))
    for named in final.terms:
        less = _without(final, named)
        out.append(less)
        out.extend(less.with_effects(name) for name in candidates if name not in final.terms)
    unique: list[ModelSpec] = []
    for s in out:
        if s.terms != final.terms and all(s.terms != u.terms for u in unique):
            unique.append(s)
    return unique


def rivals_in_play(result: DiscrepancyResult, candidates: Sequence[str], empirical: bool = True
                   ) -> tuple[Rival, list[Rival]]:
    """The final model and every model in play (the final one first), each with its parameter covariance."""
    data, noise = result.data, result.noise
    search = Search(data, noise)
    sigma = search.sigma

    def whiten(a: np.ndarray) -> np.ndarray:
        return noise.whiten(data, a, sigma)

    final = from_fit(result.final)
    models = [final] + [from_fit(search.fit(s, warm=result.final)) for s in neighbour_specs(result.final.spec,
                                                                                           candidates)]
    if empirical and result.empirical is not None:
        models.append(from_empirical(result.final, result.empirical, data, whiten))
    best = min(m.bic for m in models)
    play = [m for m in models if m.bic <= best + DECISIVE_BIC]
    if final not in play:
        play.insert(0, final)
    return final.with_covariance(data, whiten), [m.with_covariance(data, whiten) for m in play]
