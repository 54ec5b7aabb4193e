"""Which physical effect does the model miss? Fit every candidate term and pair, rank by BIC, check held out.

A candidate is named only when the evidence is decisive: its BIC beats the current model's by at least
``DECISIVE_BIC`` (Kass & Raftery's "very strong"); it either accounts for at least twice the noise (rms,
noise-weighted) or brings the residuals down to the noise; and it predicts roller cases it was not fitted
on better than the current model does.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.model import Fit, fit_model, predict_ln
from labctl.discrepancy.noise import NoiseFloor
from labctl.physics.effects import EFFECTS

DECISIVE_BIC = 10.0
MIN_EXPLAINED = 2.0
"""A named term must account for at least this much misfit, in units of the noise."""
MAX_CHECKED = 3
"""Held-out checks run on at most this many eligible candidates per step."""


def beyond(before: Fit, after: Fit) -> float:
    """How much of the misfit ``after`` explains beyond ``before``, in units of the noise (≥ 1: above it)."""
    return math.sqrt(max(0.0, before.score**2 - after.score**2))


@dataclass(frozen=True)
class Candidate:
    """The current model plus one or two effect terms, fitted to all points."""

    added: tuple[str, ...]
    fit: Fit
    delta_bic: float
    """BIC(current) - BIC(candidate): positive favours the candidate."""
    explained: float
    """Noise-weighted misfit the term accounts for, in units of the noise."""


@dataclass(frozen=True)
class HeldOut:
    """Fit without each roller case (or repetition) in turn, predict it: gap and noise-weighted score."""

    by: str
    folds: int
    gap_without: float
    gap_with: float
    score_without: float
    score_with: float

    @property
    def passed(self) -> bool:
        return self.score_with < self.score_without

    def to_dict(self) -> dict[str, Any]:
        return {"by": self.by, "folds": self.folds, "gap_without": self.gap_without, "gap_with": self.gap_with,
                "score_without": self.score_without, "score_with": self.score_with}


@dataclass(frozen=True)
class Step:
    """One effect added to the model, with the evidence that named it."""

    name: str
    fit: Fit
    before: Fit
    evidence: dict[str, Any]


def _candidate(data: Dataset, current: Fit, added: tuple[str, ...],
               guess: dict[str, dict[str, float]] | None = None) -> Candidate:
    fit = fit_model(data, current.spec.with_effects(*added), warm=current, sigma=current.sigma, guess=guess)
    return Candidate(added, fit, current.bic - fit.bic, beyond(current, fit))


def rank_candidates(data: Dataset, current: Fit, noise: NoiseFloor) -> list[Candidate]:
    """Every missing effect alone and every pair of them; best BIC first.

    Pairs are skipped when the best single term already brings the residuals down to the noise: no pair could
    then explain a further twice the noise, so none could be named.
    """
    remaining = [n for n in EFFECTS if n not in current.spec.effects]
    singles = sorted((_candidate(data, current, (n,)) for n in remaining), key=lambda c: -c.delta_bic)
    if singles and noise.consistent(singles[0].fit.z, singles[0].fit.spec.n_params()):
        return singles
    alone = {c.added[0]: c.fit.effect_parameters()[c.added[0]] for c in singles}
    pairs = [_candidate(data, current, p, {n: alone[n] for n in p}) for p in itertools.combinations(remaining, 2)]
    return sorted(singles + pairs, key=lambda c: -c.delta_bic)


def _folds(data: Dataset) -> tuple[str, list[tuple[Dataset, Dataset]]]:
    if len(data.cases) >= 3:
        idx = range(len(data.cases))
        return "roller case", [(data.subset(i for i in idx if i != k), data.subset([k])) for k in idx]
    reps = data.repetitions()
    if len(reps) >= 2:
        return "repetition", [(data.select_repetitions(lambda r, k=k: r != k),
                               data.select_repetitions(lambda r, k=k: r == k)) for k in reps]
    return "none", []


def held_out(data: Dataset, noise: NoiseFloor, without: Fit, with_: Fit) -> HeldOut | None:
    """Leave-one-case-out (else leave-one-repetition-out) prediction of two models; None if no folds exist."""
    by, folds = _folds(data)
    if not folds:
        return None
    res: dict[str, list[np.ndarray]] = {"without": [], "with": []}
    sig: list[np.ndarray] = []
    for train, test in folds:
        sig.append(noise.sigma_at(test))
        for key, fit in (("without", without), ("with", with_)):
            refit = fit_model(train, fit.spec, warm=fit, sigma=noise.sigma_at(train))
            res[key].append(predict_ln(test, refit.law) - test.ln_stiffness)
    s = np.concatenate(sig)
    r = {k: np.concatenate(v) for k, v in res.items()}
    gap = {k: float(np.sqrt(np.mean(v**2))) for k, v in r.items()}
    score = {k: float(np.sqrt(np.mean((v / s) ** 2))) for k, v in r.items()}
    return HeldOut(by, len(folds), gap["without"], gap["with"], score["without"], score["with"])


def _eligible(ranked: list[Candidate], noise: NoiseFloor) -> list[Candidate]:
    """Decisive in BIC and either large (≥ MIN_EXPLAINED) or closing the gap down to the noise."""

    def closes(fit: Fit) -> bool:
        return noise.consistent(fit.z, fit.spec.n_params())

    ok = [c for c in ranked if c.delta_bic >= DECISIVE_BIC and (c.explained >= MIN_EXPLAINED or closes(c.fit))]
    singles = [c for c in ok if len(c.added) == 1]
    if not singles:
        return []
    best = singles[0]
    return [c for c in ok if len(c.added) == 1 or c.delta_bic - best.delta_bic >= DECISIVE_BIC
            and (beyond(best.fit, c.fit) >= MIN_EXPLAINED or closes(c.fit) and not closes(best.fit))]


def select_step(data: Dataset, current: Fit, noise: NoiseFloor) -> list[Step]:
    """The effect(s) to add next, or [] when no candidate's evidence is decisive."""
    ranked = rank_candidates(data, current, noise)
    for cand in _eligible(ranked, noise)[:MAX_CHECKED]:
        check = held_out(data, noise, current, cand.fit)
        if check is not None and not check.passed:
            continue
        rivals = [c for c in ranked if not set(c.added) & set(cand.added)]
        evidence = {
            "delta_bic": cand.delta_bic,
            "explained_noise_units": cand.explained,
            "runner_up": "+".join(rivals[0].added) if rivals else None,
            "runner_up_delta_bic": cand.delta_bic - rivals[0].delta_bic if rivals else None,
            "held_out": None if check is None else check.to_dict(),
            "candidates": {"+".join(c.added): c.delta_bic for c in ranked},
        }
        if len(cand.added) == 1:
            return [Step(cand.added[0], cand.fit, current, evidence)]
        return _pair_steps(data, noise, current, cand, ranked, evidence)
    return []


def _pair_steps(data: Dataset, noise: NoiseFloor, current: Fit, cand: Candidate, ranked: list[Candidate],
                evidence: dict[str, Any]) -> list[Step]:
    """A winning pair is added one term at a time; the second only if it also holds up on held-out data."""
    singles = {c.added[0]: c for c in ranked if len(c.added) == 1}
    first, second = sorted(cand.added, key=lambda n: -singles[n].delta_bic)
    via = singles[first].fit
    steps = [Step(first, via, current, {**evidence, "added_as_pair": [first, second]})]
    check = held_out(data, noise, via, cand.fit)
    if check is None or check.passed:
        steps.append(Step(second, cand.fit, via, {**evidence, "added_as_pair": [first, second],
                                                  "delta_bic": via.bic - cand.fit.bic,
                                                  "explained_noise_units": beyond(via, cand.fit),
                                                  "held_out": None if check is None else check.to_dict()}))
    return steps
