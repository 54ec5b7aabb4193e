"""The candidate models still in play: the workflow's final model and its neighbours, each fitted to the data.

Neighbours of the final model are: the final model plus one candidate term, the final model with one named
term removed, and with one named term swapped for a candidate term; the workflow's unnamed empirical term,
when it proposed one, is a neighbour too. A model is *in play* when its BIC is within ``DECISIVE_BIC`` of the
best (the data do not yet decide against it). Each model carries its parameter covariance from the data
(linearised, whitened with the noise model) with a weak prior: half of each term's bounded range, half a
decade for Tripp's depth, so a parameter the data do not determine keeps its plausible spread instead of
collapsing to zero.

A term with a kink in k(F) (``KINK`` of the effect: the hardness onset) is not described by one linearisation:
fitted just past a measured load, the kink makes its parameters look determined when the data only bracket it. Such
a model is spread over the kink positions the data still allow (``spread_kinks``): its best fit with the kink held
where it was fitted, and the model held at each value of a grid across the kink parameter's range (the other
parameters refitted), every one whose BIC is within ``DECISIVE_BIC`` of the best model in play, the model's weight
shared among them in proportion to exp(−BIC/2) (a discretised posterior over the kink). The criterion then values
loads that tell the kink positions apart as it values loads that tell models apart.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.empirical import EmpiricalTerm, features
from labctl.discrepancy.lsq import bounded_least_squares
from labctl.discrepancy.model import BAD_RESIDUAL, FIT_FTOL, Fit, ModelSpec, predict_ln
from labctl.discrepancy.search import DECISIVE_BIC, Search
from labctl.discrepancy.workflow import DiscrepancyResult
from labctl.physics.effects import EFFECTS

PRIOR_SD_SCALED = 0.5
"""Prior σ of a term's parameter, as a fraction of its bounded range."""
PRIOR_SD_LOG10_DEPTH = 0.5
PRIOR_SD_EMPIRICAL = 1.0
"""Prior σ of an empirical coefficient (ln k per unit of its feature)."""
FD_STEP = 1e-4
KINK_GRID = 96
"""Values of a kink parameter tried across its bounded range (steps of about 1 % of the range)."""

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
    kink: int | None = None
    """Row in ``theta`` of the parameter that places a kink in k(F) (``KINK`` of an effect), if any."""

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
        return replace(self, covariance=np.linalg.inv(precision))


def _spec_predictor(spec: ModelSpec) -> Predictor:
    def predict(data: Dataset, x: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            return predict_ln(data, spec.law(x), spec.chain(x))
    return predict


def _prior(spec: ModelSpec) -> np.ndarray:
    head = [PRIOR_SD_LOG10_DEPTH] if spec.fits_depth else []
    return np.array(head + [PRIOR_SD_SCALED] * len(spec.slots()), dtype=float)


def kink_row(spec: ModelSpec) -> int | None:
    """Row of the first kink parameter (``KINK`` of an effect) in the spec's parameter vector, if any."""
    for i, (name, key, _, _) in enumerate(spec.slots()):
        if name in EFFECTS and getattr(EFFECTS[name], "KINK", None) == key:
            return int(spec.fits_depth) + i
    return None


def kink_words(terms: Sequence[str]) -> str:
    """Which kink a model's terms place, in words (e.g. "the threshold of material_hardness")."""
    names = [f"the {EFFECTS[t].KINK} of {t}" for t in terms if t in EFFECTS and getattr(EFFECTS[t], "KINK", None)]
    return names[0] if names else "its kink"


def from_fit(fit: Fit) -> Rival:
    lo, hi = fit.spec.bounds()
    return Rival(fit.spec.terms, _spec_predictor(fit.spec), np.asarray(fit.x, dtype=float), lo, hi,
                 _prior(fit.spec), fit.bic, kink=kink_row(fit.spec))


def _held(predict: Predictor, row: int, value: float) -> Predictor:
    def held(data: Dataset, x: np.ndarray) -> np.ndarray:
        return predict(data, np.insert(x, row, value))
    return held


def held_at_fit(rival: Rival) -> Rival:
    """The rival with its kink parameter held at its fitted value (the others keep their fit and prior)."""
    j = rival.kink
    assert j is not None
    free = np.arange(rival.theta.size) != j
    return Rival(rival.terms, _held(rival.predict, j, float(rival.theta[j])), rival.theta[free], rival.lower[free],
                 rival.upper[free], rival.prior_sd[free], rival.bic)


@dataclass(frozen=True)
class KinkSlice:
    """The rival held at one value of its kink parameter, its other parameters refitted."""

    value: float
    """The kink parameter's value (fitted coordinate)."""
    rival: Rival
    chi2: float
    """Sum of the whitened residuals' squares at the refit."""


def kink_grid(rival: Rival) -> np.ndarray:
    """The ``KINK_GRID`` values of the rival's kink parameter (bin centres across its bounded range)."""
    j = rival.kink
    assert j is not None
    return rival.lower[j] + (rival.upper[j] - rival.lower[j]) * (np.arange(KINK_GRID) + 0.5) / KINK_GRID


def _slice(rival: Rival, data: Dataset, whiten: Callable[[np.ndarray], np.ndarray], u: float) -> KinkSlice:
    """The rival held at kink value ``u``, its other parameters refitted by the workflow's whitened least squares,
    with its BIC (same n, same count of parameters as the rival: the kink's value is fitted, by the grid)."""
    j = rival.kink
    assert j is not None
    free = np.arange(rival.theta.size) != j
    lo, hi = rival.lower[free], rival.upper[free]
    measured = data.ln_stiffness
    n = measured.size
    predict = _held(rival.predict, j, u)

    def residuals(x: np.ndarray) -> np.ndarray:
        r = predict(data, x) - measured
        return whiten(np.where(np.isfinite(r), r, BAD_RESIDUAL))

    sol = bounded_least_squares(residuals, np.clip(rival.theta[free], lo, hi), lo, hi, ftol=FIT_FTOL)
    chi2 = float(np.sum(sol.fun**2))
    bic = n * math.log(max(chi2 / n, 1e-300)) + rival.theta.size * math.log(n)
    return KinkSlice(u, Rival(rival.terms, predict, sol.x, lo, hi, rival.prior_sd[free], bic), chi2)


def kink_slices(rival: Rival, data: Dataset, whiten: Callable[[np.ndarray], np.ndarray]) -> list[KinkSlice]:
    """The rival held at each value of ``kink_grid``, its other parameters refitted, each with its BIC and χ²;
    none for a rival without a kink."""
    if rival.kink is None:
        return []
    return [_slice(rival, data, whiten, float(u)) for u in kink_grid(rival)]


def kink_particles(rival: Rival, data: Dataset, whiten: Callable[[np.ndarray], np.ndarray]) -> list[Rival]:
    """The rival held at each of ``KINK_GRID`` values of its kink parameter, refitted (``kink_slices``)."""
    return [s.rival for s in kink_slices(rival, data, whiten)]


@dataclass(frozen=True)
class KinkPosterior:
    """Mean and standard deviation of one parameter of a kinked model, and of its kink parameter, over the kink
    grid (fitted coordinates)."""

    mean: float
    sd: float
    kink_mean: float
    kink_sd: float


KINK_REFINE = 4
"""Sub-cells a kink cell is split into when the posterior is too concentrated for the grid."""
KINK_MAX_SHARE = 0.25
"""Largest share of the posterior one cell may hold before the cells holding it are split."""


def kink_posterior(rival: Rival, row: int, data: Dataset, whiten: Callable[[np.ndarray], np.ndarray],
                   misfit_scaled: bool = False) -> KinkPosterior:
    """Parameter ``row`` of a kinked rival, never linearised across the kink: the rival held at each value of its
    kink grid (``kink_slices``), each slice weighted by its likelihood exp(−χ²/2) (the whitened residuals, a
    uniform prior over the kink's range) and carrying its Laplace covariance (with the rivals' weak prior); the
    result is the mixture's mean and SD, Var = Σ w_j (SE_j² + (x_j − x̄)²). While one cell of the grid holds more
    than ``KINK_MAX_SHARE`` of the weight (data that place the kink more finely than the grid), the cells holding
    any of it are split into ``KINK_REFINE`` (each slice's weight is its likelihood times its cell's width). For
    ``row`` the kink parameter itself, its spread over the cells.

    ``misfit_scaled``: the noise model scaled by the best slice's misfit when that exceeds it (σ × s,
    s² = max(1, χ²_min/(n − p)), p the rival's parameters with the kink): for a model that misses the points by
    more than their noise, both the weights and the slices' covariances widen accordingly."""
    return kink_posteriors(rival, row, data, whiten, (misfit_scaled,))[0]


def kink_posteriors(rival: Rival, row: int, data: Dataset, whiten: Callable[[np.ndarray], np.ndarray],
                    misfit_scaled: Sequence[bool] = (False, True)) -> list[KinkPosterior]:
    """``kink_posterior`` for each setting of ``misfit_scaled``, the refitted slices shared among them."""
    j = rival.kink
    assert j is not None
    refits: dict[float, KinkSlice] = {}

    def at(u: float) -> KinkSlice:
        if u not in refits:
            refits[u] = _slice(rival, data, whiten, u)
        return refits[u]

    return [_kink_mixture(rival, row, data, whiten, at, scaled) for scaled in misfit_scaled]


def _kink_mixture(rival: Rival, row: int, data: Dataset, whiten: Callable[[np.ndarray], np.ndarray],
                  at: Callable[[float], KinkSlice], misfit_scaled: bool) -> KinkPosterior:
    """The mixture of ``kink_posterior`` over slices refitted by ``at`` (kink value → slice)."""
    j = rival.kink
    assert j is not None
    slices = [at(float(u)) for u in kink_grid(rival)]
    width = np.full(len(slices), (rival.upper[j] - rival.lower[j]) / KINK_GRID)
    dof = data.n_points - rival.theta.size

    def weights() -> tuple[np.ndarray, float]:
        chi2 = np.array([s.chi2 for s in slices])
        scale2 = max(1.0, float(chi2.min()) / dof) if misfit_scaled and dof > 0 else 1.0
        w = width * np.exp(-0.5 * (chi2 - chi2.min()) / scale2)
        return w / w.sum(), scale2

    w, scale2 = weights()
    while w.max() > KINK_MAX_SHARE and width[np.argmax(w)] > 1e-6:
        split = np.flatnonzero(w > 1e-3 * w.max())
        keep = np.setdiff1d(np.arange(len(slices)), split)
        new = [(slices[k].value + width[k] * ((m + 0.5) / KINK_REFINE - 0.5), width[k] / KINK_REFINE)
               for k in split for m in range(KINK_REFINE)]
        slices = [slices[k] for k in keep] + [at(float(u)) for u, _ in new]
        width = np.concatenate([width[keep], [h for _, h in new]])
        w, scale2 = weights()
    u = np.array([s.value for s in slices])
    kink_mean = float(w @ u)
    kink_sd = float(np.sqrt(w @ (u - kink_mean) ** 2 + w @ width**2 / 12.0))
    if row == j:
        return KinkPosterior(kink_mean, kink_sd, kink_mean, kink_sd)
    i = row - int(row > j)
    x = np.array([s.rival.theta[i] for s in slices])
    var = np.zeros(x.size)
    for k in np.flatnonzero(w > 1e-12 * w.max()):
        cov = slices[k].rival.with_covariance(data, lambda a: whiten(a) / math.sqrt(scale2)).covariance
        assert cov is not None
        var[k] = cov[i, i]
    mean = float(w @ x)
    return KinkPosterior(mean, float(np.sqrt(w @ (var + (x - mean) ** 2))), kink_mean, kink_sd)


def spread_kinks(models: Sequence[Rival], weights: np.ndarray, data: Dataset,
                 whiten: Callable[[np.ndarray], np.ndarray]) -> tuple[list[Rival], np.ndarray]:
    """Each model with a kink replaced by itself held at its fitted kink and by its kink particles still in play
    (BIC within ``DECISIVE_BIC`` of the best model), with covariances; the model's weight is shared among them
    in proportion to exp(−BIC/2). A linearisation across the kink is never used: the kink is represented by
    the particles alone."""
    best = min(m.bic for m in models)
    out: list[Rival] = []
    out_w: list[float] = []
    for m, w in zip(models, weights, strict=True):
        if m.kink is None:
            out.append(m)
            out_w.append(float(w))
            continue
        parts = [held_at_fit(m).with_covariance(data, whiten)]
        parts += [p.with_covariance(data, whiten) for p in kink_particles(m, data, whiten)
                  if p.bic <= best + DECISIVE_BIC]
        bic = np.array([p.bic for p in parts])
        share = np.exp(-0.5 * (bic - bic.min()))
        out.extend(parts)
        out_w.extend(float(w) * share / share.sum())
    return out, np.array(out_w)


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


def whitener(result: DiscrepancyResult) -> Callable[[np.ndarray], np.ndarray]:
    """Whitening of residuals (n or n×k) at the result's points with its noise model."""
    data, noise = result.data, result.noise
    sigma = noise.sigma_at(data)

    def whiten(a: np.ndarray) -> np.ndarray:
        return noise.whiten(data, a, sigma)
    return whiten


def rivals_in_play(result: DiscrepancyResult, candidates: Sequence[str], empirical: bool = True
                   ) -> tuple[Rival, list[Rival]]:
    """The final model and every model in play (the final one first), each with its parameter covariance."""
    data = result.data
    search = Search(data, result.noise)
    whiten = whitener(result)
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
