"""The candidate fits and held-out folds the workflow shares: every missing term alone fitted to all points and
ranked by BIC (the closest library term when nothing is named), and the roller-type folds the empirical term's
held-out check uses. Naming is decided elsewhere, by the posterior over explanations
(``labctl.discrepancy.posterior``); every statistic here uses residuals whitened with the noise model."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import Fit, ModelSpec, fit_model
from labctl.discrepancy.noise import NoiseFloor
from labctl.physics.effects import EFFECTS

DECISIVE_BIC = 10.0
"""Kass & Raftery's "very strong" BIC difference: the empirical term's features and held-out gain must reach it."""
HELD_OUT_MARGIN = 0.1
"""The held-out whitened misfit must fall by at least this fraction of itself."""
MIN_GEOMETRIES = 3
"""Roller geometries needed to leave one out at a time (else repetitions are left out: a weak check)."""
CHAIN = ("load_offset", "modulus_scale", "load_gain")
"""Measurement-side terms ranked with the physical ones."""


def discrepancy(fit: Fit) -> float:
    """The systematic part of the whitened misfit: its sum of squares above what the noise alone gives."""
    return max(0.0, float(np.sum(fit.z**2)) - (fit.n_points - fit.spec.n_params()))


def share(before: Fit, after: Fit) -> float:
    """Share of ``before``'s discrepancy that ``after`` explains (0 when there is none)."""
    d = discrepancy(before)
    return 0.0 if d <= 0 else max(0.0, min(1.0, (d - discrepancy(after)) / d))


def beyond(before: Fit, after: Fit) -> float:
    """How much of the misfit ``after`` explains beyond ``before``, in units of the noise."""
    return math.sqrt(max(0.0, before.score**2 - after.score**2))


def kind(name: str) -> str:
    return "measurement" if name in MEASUREMENT else "physical"


@dataclass(frozen=True)
class Candidate:
    """The current model plus one term, fitted to all points."""

    name: str
    fit: Fit
    delta_bic: float
    """BIC(current) - BIC(candidate): positive favours the candidate."""
    share: float
    explained: float


@dataclass(frozen=True)
class HeldOut:
    """Fit without each left-out fold, refitted from scratch, and predict it: gaps and whitened misfits."""

    by: str
    folds: int
    weak: bool
    gap_without: float
    gap_with: float
    score_without: float
    score_with: float
    ss_without: float
    ss_with: float
    n: int
    """Held-out points (whitened: each adds about 1 to the sums of squares when the model is right)."""

    @property
    def share(self) -> float:
        """Share of the held-out discrepancy (whitened misfit above the noise's expectation) the term explains."""
        before = self.ss_without - self.n
        return 0.0 if before <= 0 else max(0.0, min(1.0, 1.0 - max(0.0, self.ss_with - self.n) / before))

    @property
    def gain(self) -> float:
        """How much the held-out whitened sum of squares falls with the term."""
        return self.ss_without - self.ss_with

    @property
    def passed(self) -> bool:
        return self.gain >= HELD_OUT_MARGIN * self.ss_without and self.gain >= DECISIVE_BIC

    def to_dict(self) -> dict[str, Any]:
        return {"by": self.by, "folds": self.folds, "weak": self.weak, "gap_without": self.gap_without,
                "gap_with": self.gap_with, "score_without": self.score_without, "score_with": self.score_with,
                "passed": self.passed}


@dataclass(frozen=True)
class Step:
    """One term added to the model, with the evidence that named it."""

    name: str
    fit: Fit
    before: Fit
    evidence: dict[str, Any]

    @property
    def kind(self) -> str:
        return kind(self.name)


class Search:
    """The candidate search on one dataset and noise model (caches held-out refits of unchanged models)."""

    def __init__(self, data: Dataset, noise: NoiseFloor) -> None:
        self.data = data
        self.noise = noise
        self.sigma = noise.sigma_at(data)
        self.folds = _folds(data)
        self._fold_cache: dict[tuple[str, ...], list[tuple[Fit, np.ndarray]]] = {}

    def fit(self, spec: ModelSpec, warm: Fit | None = None, guess: dict[str, dict[str, float]] | None = None) -> Fit:
        return fit_model(self.data, spec, warm=warm, sigma=self.sigma, guess=guess,
                         seating_sigma=self.noise.seating_sigma)

    def candidates(self, current: Fit, physical_only: bool = False) -> list[Candidate]:
        """Every missing term alone, fitted to all points; best BIC first."""
        names = [n for n in EFFECTS if n not in current.spec.effects]
        if not physical_only:
            names += [n for n in CHAIN if n not in current.spec.measurement]
        out = []
        for n in names:
            fit = self.fit(current.spec.with_effects(n), warm=current)
            out.append(Candidate(n, fit, current.bic - fit.bic, share(current, fit), beyond(current, fit)))
        return sorted(out, key=lambda c: -c.delta_bic)

    def fold_fits(self, spec: ModelSpec) -> list[tuple[Fit, np.ndarray]]:
        """Per fold: the model fitted from scratch to the training part, and its residuals on the left-out part."""
        key = (spec.baseline, *spec.terms)
        if key not in self._fold_cache:
            res = []
            for train, test in self.folds[2]:
                fit = fit_model(train, spec, sigma=self.noise.sigma_at(train),
                                seating_sigma=self.noise.seating_sigma)
                res.append((fit, fit.predict(test) - test.ln_stiffness))
            self._fold_cache[key] = res
        return self._fold_cache[key]

    def held_out(self, without: ModelSpec, with_: ModelSpec) -> HeldOut | None:
        """Held-out prediction of two models, every fold refitted from scratch; None if no folds exist."""
        by, weak, folds = self.folds
        if not folds:
            return None
        stats: dict[str, tuple[float, float, float]] = {}
        for key, spec in (("without", without), ("with", with_)):
            ss, sq, n = 0.0, 0.0, 0
            for (_, test), (_, r) in zip(folds, self.fold_fits(spec), strict=True):
                e = self.noise.whiten(test, r, self.noise.sigma_at(test))
                ss += float(e @ e)
                sq += float(r @ r)
                n += r.size
            stats[key] = (ss, math.sqrt(sq / n), math.sqrt(ss / n))
        return HeldOut(by, len(folds), weak, stats["without"][1], stats["with"][1], stats["without"][2],
                       stats["with"][2], stats["without"][0], stats["with"][0], n)

def _folds(data: Dataset) -> tuple[str, bool, list[tuple[Dataset, Dataset]]]:
    groups = data.roller_groups()
    if len(groups) >= MIN_GEOMETRIES:
        folds = [(data.subset(i for i in range(len(data.cases)) if i not in test), data.subset(test))
                 for test in groups]
        return "roller type", False, folds
    reps = data.repetitions()
    if len(reps) >= 2:
        return "repetition", True, [(data.select_repetitions(lambda r, k=k: r != k),
                                     data.select_repetitions(lambda r, k=k: r == k)) for k in reps]
    return "none", True, []
