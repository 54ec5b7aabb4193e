"""Which term does the model miss? Fit every candidate alone, rank by BIC, and name one only when it earns it.

Candidates are the physical effect terms (``labctl.physics.effects``) and the measurement-side terms
(``labctl.discrepancy.measurement``). Every statistic uses the residuals whitened with the noise model (seating
offsets and load-dependent point noise). A candidate is named only when, on its own:

- its BIC beats the current model's by at least ``DECISIVE_BIC`` (Kass & Raftery's "very strong");
- it explains at least ``MIN_SHARE`` of the discrepancy it is added to (the whitened misfit above the noise's
  expectation, n − p);
- when the residuals are still inconsistent with the noise after it (the effect's form may differ from the
  library's, or something else is missing), it must dominate: explain at least ``PARTIAL_SHARE`` of the
  discrepancy and leave at most ``PARTIAL_HELD_OUT`` of the held-out misfit; and when that leftover is not its
  own law's (bending the term's load dependence explains less than ``MIN_SHARE`` of it: something the library
  cannot name), it must also explain ``PARTIAL_SHARE`` of the held-out discrepancy (the held-out whitened misfit
  above the noise's expectation): a term that absorbs another effect in the rollers it was fitted to does not
  predict left-out ones that well;
- a further term (after the first) must complete the explanation (make the residuals consistent with the noise)
  and beat, by ``DECISIVE_BIC``, the model before it with its terms' load dependence bent
  (``labctl.discrepancy.form``): an imperfect first term leaves structure that any flexible term absorbs in
  part, and that is the first term's form, not a second effect, unless the second term explains it decisively
  better than the bent form does;
- it predicts held-out data better by a margin: folds refitted from scratch (no start from the all-data fit)
  leave out one roller geometry at a time when there are at least three, else one repetition at a time (then
  the check is marked weak: it tests the seating scatter, not generalisation to other rollers); the held-out
  whitened misfit must fall by at least ``HELD_OUT_MARGIN`` of itself and by at least ``DECISIVE_BIC``.

Each step's evidence is that step's alone: its term against the model before it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.form import bent_bic, own_form_share
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import FIT_ONLY_BOUNDS, Fit, ModelSpec, fit_model
from labctl.discrepancy.noise import NoiseFloor
from labctl.physics.effects import EFFECTS

DECISIVE_BIC = 10.0
MIN_SHARE = 0.5
"""A named term must explain at least this share of the discrepancy it is added to."""
HELD_OUT_MARGIN = 0.1
"""The held-out whitened misfit must fall by at least this fraction of itself."""
PARTIAL_SHARE = 0.85
"""A term that leaves the residuals inconsistent with the noise is named only when it explains at least this
share of the discrepancy ..."""
PARTIAL_HELD_OUT = 0.5
"""... and at most this fraction of the held-out misfit (rms, whitened) is left with it."""
SHAPE_STARTS: dict[str, tuple[dict[str, float], ...]] = {"misalignment": ({"transition": 0.15}, {"transition": 0.4})}
"""Starting values of the shape parameters when they are freed (from the default form's fitted parameters)."""
MIN_GEOMETRIES = 3
"""Roller geometries needed to leave one out at a time (else repetitions are left out: a weak check)."""
MAX_CHECKED = 3
"""Held-out checks run on at most this many eligible candidates per step."""
SEARCHED_MEASUREMENT = ("load_offset",)
DEPTH_ABSORBED = ("modulus_scale", "load_gain")
"""A modulus scale or load gain changes Tripp's curve almost as its depth does: they show by shape only slightly,
or when the depth is pinned at an end of its physical range."""


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

    def candidates(self, current: Fit, physical_only: bool = False, shapes: bool = True) -> list[Candidate]:
        """Every missing term alone, fitted to all points; best BIC first. ``shapes``: a first term's shape
        parameters may be freed (``shaped``)."""
        names = [n for n in EFFECTS if n not in current.spec.effects]
        if not physical_only:
            chain = SEARCHED_MEASUREMENT + DEPTH_ABSORBED
            names += [n for n in chain if n not in current.spec.measurement]
        out = []
        for n in names:
            fit = self.fit(current.spec.with_effects(n), warm=current)
            if shapes and not current.spec.terms:
                fit = self.shaped(fit, n)
            out.append(Candidate(n, fit, current.bic - fit.bic, share(current, fit), beyond(current, fit)))
        return sorted(out, key=lambda c: -c.delta_bic)

    def shaped(self, fit: Fit, name: str) -> Fit:
        """The term in its default form, or with its shape parameters (``FIT_ONLY_BOUNDS``) freed when that is a
        decisive improvement (nested models: BIC by ``DECISIVE_BIC``). A rounded tilt law is then not read as
        another effect; a small effect stays in its one-parameter form. Only a first term's shape is freed: a
        further term is tested in its library form, which cannot bend to absorb the leftover structure of an
        imperfect first term."""
        if name not in FIT_ONLY_BOUNDS:
            return fit
        spec = fit.spec.with_free_shape(name)
        values = fit.spec.decode(fit.x)[name]
        free = min((self.fit(spec, warm=fit, guess={name: {**values, **shape}}) for shape in SHAPE_STARTS[name]),
                   key=lambda f: f.bic)
        return free if fit.bic - free.bic >= DECISIVE_BIC else fit

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

    def consistent(self, fit: Fit) -> bool:
        return self.noise.consistent(self.data, fit.residuals, fit.sigma, fit.spec.n_params())

    def beats_bent_form(self, current: Fit, cand: Candidate) -> bool:
        """A term added to a model that already has one must beat, by ``DECISIVE_BIC``, that model with its terms'
        load dependence bent (``labctl.discrepancy.form``): the leftover of a named term whose true form differs
        from the library's is its form's, not evidence of another effect. True for a first term."""
        return not current.spec.terms or cand.fit.bic <= bent_bic(current, self.data, self.noise) - DECISIVE_BIC

    def dominates(self, cand: Candidate, check: HeldOut | None) -> bool:
        """A term that leaves structure explains nearly all of the discrepancy, and on held-out roller types too
        when the structure left is not its own law's (see the module doc)."""
        if cand.share < PARTIAL_SHARE or check is None or check.score_with > PARTIAL_HELD_OUT * check.score_without:
            return False
        return own_form_share(cand.fit, self.data, self.noise) >= MIN_SHARE or check.share >= PARTIAL_SHARE

    def select(self, current: Fit, baseline: Fit) -> tuple[list[Step], list[Candidate]]:
        """The term(s) to add next ([] when none earns it), and every single candidate as ranked.

        A further term (after the first) must also complete the explanation: with it the residuals are
        consistent with the noise. Otherwise a flexible term would be named for the structure an imperfect first
        term leaves (a real effect whose form differs from the library's). When no single term earns a name, two
        terms may, together: only if the pair makes the residuals consistent with the noise and each term passes
        its own held-out check (the first against the model before it, the second against the first alone).
        """
        ranked = self.candidates(current)
        eligible = [c for c in ranked if c.delta_bic >= DECISIVE_BIC and c.share >= MIN_SHARE
                    and (current is baseline or self.consistent(c.fit))]
        if any(c.name in c.fit.spec.free_shape for c in eligible):
            # The library's own forms first: a reshaped term only where no library term completes the explanation.
            library = self.candidates(current, shapes=False)
            for cand in [c for c in library if c.delta_bic >= DECISIVE_BIC and c.share >= MIN_SHARE
                         and self.consistent(c.fit)][:MAX_CHECKED]:
                check = self.held_out(current.spec, cand.fit.spec)
                if check is None or check.passed:
                    return [self._step(current, baseline, cand, check, library)], library
        for cand in eligible[:MAX_CHECKED]:
            check = self.held_out(current.spec, cand.fit.spec)
            if check is not None and not check.passed or not self.beats_bent_form(current, cand):
                continue
            if not self.consistent(cand.fit) and not self.dominates(cand, check):
                continue
            if cand.name in cand.fit.spec.free_shape:
                # A reshaped term has as many parameters as two library terms: when two library terms complete the
                # explanation at least as well, the library's own forms are the simpler reading.
                pair = self._pair(current, baseline, self.candidates(current, shapes=False))
                if pair and pair[-1].fit.bic <= cand.fit.bic:
                    return pair, ranked
            return [self._step(current, baseline, cand, check, ranked)], ranked
        return self._pair(current, baseline, ranked), ranked

    def _step(self, current: Fit, baseline: Fit, cand: Candidate, check: HeldOut | None,
              ranked: list[Candidate]) -> Step:
        rivals = [c for c in ranked if c.name != cand.name]
        lof = self.noise.lack_of_fit(self.data, cand.fit.residuals, cand.fit.sigma, cand.fit.spec.n_params())
        evidence = {
            "kind": kind(cand.name),
            "delta_bic": cand.delta_bic,
            "explained_noise_units": cand.explained,
            "explained_share": cand.share,
            "explained_share_of_baseline": share(baseline, cand.fit),
            "runner_up": rivals[0].name if rivals else None,
            "runner_up_delta_bic": cand.delta_bic - rivals[0].delta_bic if rivals else None,
            "held_out": None if check is None else check.to_dict(),
            "lack_of_fit_after": None if lof is None else lof.to_dict(),
            "candidates": {c.name: c.delta_bic for c in ranked},
        }
        return Step(cand.name, cand.fit, current, evidence)

    def _pair(self, current: Fit, baseline: Fit, ranked: list[Candidate]) -> list[Step]:
        """Two terms that complete the explanation together, each with its own evidence; [] if none."""
        firsts = [c for c in ranked if c.delta_bic >= DECISIVE_BIC and c.share >= MIN_SHARE][:2]
        for first in firsts:
            check1 = self.held_out(current.spec, first.fit.spec)
            if check1 is not None and not check1.passed or not self.beats_bent_form(current, first):
                continue
            seconds = sorted((c for c in self.candidates(first.fit) if c.name != first.name),
                             key=lambda c: -c.delta_bic)
            for second in seconds[:2]:
                if second.delta_bic < DECISIVE_BIC or second.share < MIN_SHARE or not self.consistent(second.fit):
                    continue
                check2 = self.held_out(first.fit.spec, second.fit.spec)
                if check2 is not None and not check2.passed or not self.beats_bent_form(first.fit, second):
                    continue
                one = self._step(current, baseline, first, check1, ranked)
                one.evidence["named_with"] = second.name
                two = self._step(first.fit, baseline, second, check2, seconds)
                two.evidence["named_with"] = first.name
                return [one, two]
        return []


def _folds(data: Dataset) -> tuple[str, bool, list[tuple[Dataset, Dataset]]]:
    keys = data.roller_keys()
    if len(keys) >= MIN_GEOMETRIES:
        def geometry(c: Any) -> tuple[float, float]:
            return (c.case.roller.diameter_m, c.case.roller.contact_length_m)

        folds = []
        for k in keys:
            test = [i for i, c in enumerate(data.cases) if geometry(c) == k]
            folds.append((data.subset(i for i in range(len(data.cases)) if i not in test), data.subset(test)))
        return "roller type", False, folds
    reps = data.repetitions()
    if len(reps) >= 2:
        return "repetition", True, [(data.select_repetitions(lambda r, k=k: r != k),
                                     data.select_repetitions(lambda r, k=k: r == k)) for k in reps]
    return "none", True, []
