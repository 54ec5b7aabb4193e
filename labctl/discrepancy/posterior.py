"""One decision procedure: every candidate explanation scored by an approximate marginal likelihood.

Candidates (``explanations``): none; each physical term; each pair of physical terms; each measurement-side term
alone or with one physical term; and *unlisted* — an effect outside the library, stood in for by the unnamed
empirical basis (``labctl.discrepancy.empirical.BASIS``, at most ``MAX_FEATURES`` features). Each is fitted on
the data's own structure (residuals whitened for the seating random effect and the load-dependent point noise).

The *form* of every term is uncertain: each candidate carries a smooth discrepancy per roller case in the spirit
of Kennedy–O'Hagan, δ_c(ln p) = Σ_j β_cj·P_j(u) (Legendre P_0..P_2 of ln p scaled to [−1, 1] over the case's
loads), β ~ N(0, τ²), τ log-uniform on ``TAU_GRID``; it is integrated out exactly (linear Gaussian), and the
term's parameters are refitted with it. A term whose law differs from the truth but explains most of the
structure across roller types then needs only a small δ; a term that absorbs another effect in some cases and
not in others needs a large one and loses to the others.

Evidence: log p(D|M) ≈ −½·e'(I + τ²AA')⁻¹e − ½·log det(I + τ²AA') (averaged over τ), the parameters a candidate
adds to the baseline charged the hyper-g Occam factor at their fit's gain (``labctl.discrepancy.occam``: a gain
within the noise costs little, so an effect too small to see is not ruled out), plus for *unlisted* −ln C(F, m) for
choosing m of F features.
Posterior (``labctl.discrepancy.questions.probabilities``): "none" against every effect at the noise model's own
scale, then the effects against each other at p(M|D, effect) ∝ prior(M)·p(D|M, T), resampled over roller cases.
The temperature T (``TEMPERATURE``) inflates the noise variance of the whitened residuals (e ~ N(Aβ + Bγ, T·I)):
what no finite candidate list removes — every real law differs from every library term — is treated as extra
scatter, so a fit's gain counts 1/T as much while every Occam factor (the −½·k·ln n and the discrepancy's log det)
keeps its strength. T is chosen on the blind worlds; no T makes the
probabilities reliable there (docs/discrepancy.md). Priors (``PRIOR_MASS``) are split evenly within each class.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.empirical import MAX_FEATURES, features
from labctl.discrepancy.form import FormPrior, contribution
from labctl.discrepancy.instrument import check_instrument, rig_level
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import FIT_ONLY_BOUNDS, SHAPE_STARTS, Fit, ModelSpec, depth_column, fit_model
from labctl.discrepancy.noise import NoiseFloor, lack_of_fit_rejects
from labctl.discrepancy.occam import log_bayes_factor
from labctl.discrepancy.questions import PRESENCE_TEMPERATURE, TEMPERATURE, probabilities
from labctl.physics.effects import EFFECTS

PRIOR_MASS = {"none": 0.25, "physical": 0.35, "pair": 0.10, "measurement": 0.10, "mixed": 0.10, "unlisted": 0.10}
"""Prior probability of each class of explanation, split evenly among its members."""
TEMPERATURES = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0, 48.0, 64.0)
"""The noise-variance inflations a bench stores every candidate's evidence at (``--rescore`` decides again)."""
INSTRUMENT_CHECK_FROM = 1e-3
"""A candidate with a rig-level term (a measurement-side one, or the rig's own compliance) has its instrument check
(``labctl.discrepancy.instrument``) once its probability reaches this; the probabilities are then worked out again
without those that fail, until none is due."""
SHAPE_DOUBT = 1.0 / 3.0
"""Prior probability that a term's shape (``FIT_ONLY_BOUNDS``) is not the library's: the library's law is taken as
twice as likely as the departure (each of its shape parameters freed alone), so where it fits exactly a candidate
loses ln 1.5 to the doubt."""
NAME_AT = 0.9
LIKELY_AT = 0.5


@dataclass(frozen=True)
class Explanation:
    """A candidate explanation: physical terms, measurement-side terms, or an effect outside the library."""

    physical: tuple[str, ...] = ()
    measurement: tuple[str, ...] = ()
    unlisted: bool = False

    @property
    def name(self) -> str:
        if self.unlisted:
            return "unlisted"
        return " + ".join((*self.physical, *self.measurement)) or "none"

    @property
    def terms(self) -> tuple[str, ...]:
        return (*self.physical, *self.measurement)

    @property
    def kind(self) -> str:
        if self.unlisted:
            return "unlisted"
        if not self.terms:
            return "none"
        if not self.measurement:
            return "physical" if len(self.physical) == 1 else "pair"
        return "measurement" if not self.physical else "mixed"


def _one_shape_at_a_time(terms: list[str]) -> list[tuple[tuple[str, str], ...]]:
    """The shape doubt's departures from the library's law: the j-th shape parameter of each term freed alone (a term
    with fewer keeps its last), so a law that needs one departure is not charged for the others."""
    params = {n: list(FIT_ONLY_BOUNDS[n]) for n in terms}
    width = max(len(ps) for ps in params.values())
    return list(dict.fromkeys(tuple((n, ps[min(j, len(ps) - 1)]) for n, ps in params.items()) for j in range(width)))


def explanations() -> list[Explanation]:
    """Every candidate: none, each physical term, pairs, each measurement term alone or with one physical term,
    unlisted."""
    phys, meas = list(EFFECTS), list(MEASUREMENT)
    out = [Explanation()] + [Explanation((p,)) for p in phys]
    out += [Explanation(pair) for pair in itertools.combinations(phys, 2)]
    out += [Explanation((), (m,)) for m in meas]
    out += [Explanation((p,), (m,)) for m in meas for p in phys]
    return out + [Explanation(unlisted=True)]


def log_prior(expl: Explanation, candidates: list[Explanation]) -> float:
    members = sum(1 for c in candidates if c.kind == expl.kind)
    return math.log(PRIOR_MASS[expl.kind] / members)


@dataclass
class Scored:
    """One candidate explanation with its fit, evidence and posterior probability."""

    explanation: Explanation
    fit: Fit | None
    log_evidence_by_t: dict[float, float]
    """log p(D | M) at the decision's noise inflation and each other one asked for (``TEMPERATURES`` in the bench)."""
    log_fit_by_t: dict[float, float]
    """… before the Occam factor of its parameters (a bench can charge another one)."""
    log_prior: float
    n_params: int
    tau: float
    chi2: float
    """Whitened sum of squares of the parametric fit alone."""
    form_chi2: float
    """… after the posterior-mean form discrepancy is taken off: what neither explains."""
    probability: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)
    case_log_lik_by_t: dict[float, list[float]] = field(default_factory=dict)
    """At each inflation T, each roller case's part of the log likelihood (the resampling's units)."""

    @property
    def failed_instrument(self) -> list[dict[str, Any]]:
        """The instrument checks (``labctl.discrepancy.instrument``) its rig-level terms failed."""
        return [c for c in self.extra.get("instrument", []) if not c["passed"]]

    @property
    def log_evidence(self) -> float:
        """log p(D | M) at the decision's inflation."""
        return self.log_evidence_by_t[TEMPERATURE]

    def to_dict(self) -> dict[str, Any]:
        return {"explanation": self.explanation.name, "probability": self.probability,
                "log_evidence": self.log_evidence, "log_prior": self.log_prior,
                "log_evidence_by_temperature": {f"{t:g}": v for t, v in self.log_evidence_by_t.items()},
                "log_fit_by_temperature": {f"{t:g}": v for t, v in self.log_fit_by_t.items()},
                "n_params": self.n_params, "form_sigma": self.tau, **self.extra,
                "case_log_lik_by_temperature": {f"{t:g}": v for t, v in self.case_log_lik_by_t.items()}}


def rejected_explanations(baseline_lof_p: float | None, not_instrument: Sequence[str] = ()) -> frozenset[str]:
    """The explanations the data have already ruled out: "none" when the lack-of-fit test at level ``CONSISTENT_P``
    rejects the baseline (the tempered evidence shrinks a decisive misfit to less than "none"'s prior lead; without
    repetitions there is no test); and ``not_instrument``, the explanations whose rig-level term differs by
    roller type (``labctl.discrepancy.instrument``: it mends a law's form, it is no instrument or rig error)."""
    return frozenset(not_instrument) | (frozenset({"none"}) if lack_of_fit_rejects(baseline_lof_p) else frozenset())


def posterior(scored: list[Scored], rejected: frozenset[str] = frozenset()) -> None:
    """Fill in every candidate's probability (``probabilities``, resampled over roller cases when there are
    enough)."""
    p = probabilities([s.explanation.name for s in scored], np.array([s.log_prior for s in scored]),
                      lambda t: np.array([s.log_evidence_by_t[t] for s in scored]), TEMPERATURE, rejected,
                      case_log_lik=lambda t: np.array([s.case_log_lik_by_t[t] for s in scored]))
    for s, v in zip(scored, p, strict=True):
        s.probability = float(v)


class Evidence:
    """Fits and scores every candidate explanation on one dataset."""

    def __init__(self, data: Dataset, noise: NoiseFloor, sigma: np.ndarray,
                 temperatures: Sequence[float] = (TEMPERATURE,)) -> None:
        self.data, self.noise, self.sigma = data, noise, sigma
        self.temperatures = tuple(dict.fromkeys((TEMPERATURE, PRESENCE_TEMPERATURE, *temperatures)))
        """Noise inflations the evidence is computed at: the decision's, and any a bench rescores at."""
        self.form = FormPrior.of(data, noise, sigma)
        self.n = data.n_points
        self.fits: dict[tuple[str, ...], Fit] = {}
        """Fitted models by their terms (each with the plain whitened least squares)."""
        self.reference: tuple[dict[float, float], int] | None = None
        """The baseline's log evidence before its Occam factor, by inflation, and its parameter count, set when the
        baseline (the explanation "none") is scored: what every candidate's added parameters are charged against
        (``charged``)."""

    def fit(self, spec: ModelSpec, warm: Fit | None = None, guess: dict[str, dict[str, float]] | None = None,
            tau: float | None = None) -> Fit:
        post = None if tau is None else self.form.transform(tau)
        return fit_model(self.data, spec, warm=warm, sigma=self.sigma, guess=guess,
                         seating_sigma=self.noise.seating_sigma, post=post)

    def bend(self, fit: Fit) -> np.ndarray:
        """Whitened columns d_t·u, d_t·u² of every term t of the fit (u = ln(p/p̄), centred over all points)."""
        u = np.log(self.data.load_per_length_n_per_m)
        u = u - u.mean()
        cols = []
        for name in fit.spec.terms:
            d = contribution(fit, self.data, name)
            cols += [d * u, d * u**2]
        if not cols:
            return np.zeros((self.n, 0))
        return self.noise.whiten(self.data, np.column_stack(cols), self.sigma)

    def form_evidence(self, e: np.ndarray, bend: np.ndarray) -> dict[float, tuple[float, float, float]]:
        """At each of the evidence's temperatures: the term's form is the library's (probability ½) or bent (½),
        the evidence averaged over both, so an exact law pays at most ln 2 for the doubt and an approximate one is
        not judged by its exponent; the discrepancy scale τ the bent form (the exact one, without bend columns)
        favours; and the bent form's posterior share."""
        exact = self.form.log_marginals(e, None, self.temperatures)
        if bend.shape[1] == 0:
            return {t: (v, tau, 0.0) for t, (v, tau) in zip(self.temperatures, exact, strict=True)}
        bent = self.form.log_marginals(e, bend, self.temperatures)
        return {t: (float(np.logaddexp(x[0], b[0]) - math.log(2.0)), b[1], float(1.0 / (1.0 + np.exp(x[0] - b[0]))))
                for t, x, b in zip(self.temperatures, exact, bent, strict=True)}

    def case_parts(self, e: np.ndarray, bend: np.ndarray, evidence: dict[float, tuple[float, float, float]]
                   ) -> dict[float, list[float]]:
        """At each temperature, each roller case's part of the log likelihood: the residuals less the bend's
        posterior mean (weighted by the bent form's share), under the discrepancy at the favoured τ."""
        out = {}
        for t, (_, tau, bent) in evidence.items():
            z = e - bent * self.form.bend_mean(e, bend, t, tau) if bent > 0 else e
            out[t] = self.form.case_log_marginals(z, t, tau)
        return out

    def score(self, expl: Explanation, fit: Fit, candidates: list[Explanation]) -> Scored:
        """Refit at the discrepancy scale the first fit favours, then the evidence of the refit (each term's
        bend integrated out with the per-case discrepancy)."""
        first, tau = self.form.log_marginal(fit.z)
        if fit.spec.n_params() > 0:
            refit = self.fit(fit.spec, warm=fit, tau=tau)
            if self.form.log_marginal(refit.z)[0] > first:
                fit = refit
        bend = self.bend(fit)
        k = fit.spec.n_params()
        evidence = self.form_evidence(fit.z, bend)
        fit_by_t = {t: v for t, (v, _, _) in evidence.items()}
        if expl == Explanation():
            self.reference = fit_by_t, k
        tau = evidence[TEMPERATURE][1]
        smooth = self.form.smooth(fit.z, tau)
        return Scored(expl, fit, {t: self.charged(v, k, t) for t, v in fit_by_t.items()}, fit_by_t,
                      log_prior(expl, candidates), k, tau, float(fit.z @ fit.z), float(np.sum((fit.z - smooth) ** 2)),
                      case_log_lik_by_t=self.case_parts(fit.z, bend, evidence))

    def charged(self, log_fit: float, k: int, t: float) -> float:
        """The log evidence at inflation T of a candidate with ``k`` parameters whose evidence before its Occam
        factor is ``log_fit``: the baseline's, times the hyper-g Bayes factor of the parameters it adds
        (``labctl.discrepancy.occam``; the gain counted 1/T). The baseline's own parameters, common to every
        candidate, are charged ½·k·ln n (BIC)."""
        assert self.reference is not None, "the baseline is scored first"
        base, k0 = self.reference
        return base[t] - 0.5 * k0 * math.log(self.n) + log_bayes_factor(2.0 * (log_fit - base[t]), k - k0)

    def shape_doubt(self, library: Scored, candidates: list[Explanation]) -> Scored:
        """A term with a shape parameter (``FIT_ONLY_BOUNDS``: the tilt law's rounded closing, the yield term's
        roughness exponent, the end term's half-width and radius shares, the asperities' load exponent) has its form
        in doubt too: the evidence averaged over the library's law and the law with one shape parameter of each term
        fitted (``SHAPE_DOUBT``, split evenly among the parameters), the fit kept the one with most evidence."""
        fit = library.fit
        shaped = [n for n in FIT_ONLY_BOUNDS if fit is not None and n in fit.spec.effects]
        if fit is None or not shaped:
            return library
        values = fit.spec.decode(fit.x)
        freed = []
        for variant in _one_shape_at_a_time(shaped):
            spec = fit.spec
            for name, parameter in variant:
                spec = spec.with_free_shape(name, parameter)
            freed.append(self.score(library.explanation, self.fit(spec, warm=fit, guess={
                n: {**values[n], p: SHAPE_STARTS[n][p]} for n, p in variant}), candidates))
        best = max([library, *freed], key=lambda c: c.log_evidence)
        each = math.log(SHAPE_DOUBT / len(freed))

        def doubted(law: dict[float, float], shaped: list[dict[float, float]]) -> dict[float, float]:
            return {t: float(np.logaddexp.reduce([math.log1p(-SHAPE_DOUBT) + law[t], *(each + v[t] for v in shaped)]))
                    for t in self.temperatures}
        return replace(best, log_evidence_by_t=doubted(library.log_evidence_by_t, [f.log_evidence_by_t for f in freed]),
                       log_fit_by_t=doubted(library.log_fit_by_t, [f.log_fit_by_t for f in freed]))

    def unlisted(self, base: Fit, expl: Explanation, candidates: list[Explanation]) -> Scored:
        """The baseline plus up to MAX_FEATURES empirical features (forward selection by evidence)."""
        names, x = features(self.data)
        if len(self.data.roller_keys()) < 3:  # a per-geometry feature cannot be told from the seating offsets
            keep = [i for i, n in enumerate(names) if np.unique(x[:, i]).size > len(self.data.cases)]
            names, x = [names[i] for i in keep], x[:, keep]
        j = depth_column(base, self.data)
        head = np.zeros((self.n, 0)) if j is None else self.noise.whiten(self.data, j[:, None], self.sigma)
        xw = self.noise.whiten(self.data, x, self.sigma)
        y = base.z
        k0 = base.spec.n_params()

        def evaluate(chosen: list[int], t: float) -> tuple[float, float, np.ndarray]:
            a = np.column_stack([head, xw[:, chosen]])
            coef, *_ = np.linalg.lstsq(a, y, rcond=None)
            e = y - a @ coef
            log_m, tau = self.form.log_marginal(e, inflation=t)
            log_fit = log_m - math.log(math.comb(len(names), len(chosen)))
            return log_fit, tau, e

        def select(t: float) -> tuple[list[int], tuple[float, float, np.ndarray]]:
            # at least one feature: with none, "unlisted" is the baseline itself — "none" under another name, which
            # would take "none"'s place (at no Occam cost) where the lack-of-fit test has rejected it
            chosen: list[int] = []
            best = (-math.inf, 0.0, y)
            while len(chosen) < min(MAX_FEATURES, len(names)):
                trial = [(evaluate([*chosen, i], t), i) for i in range(len(names)) if i not in chosen]
                top = max(trial, key=lambda r: evidence(r[0][0], len(chosen) + 1, t))
                if evidence(top[0][0], len(chosen) + 1, t) <= evidence(best[0], len(chosen), t):
                    break
                best, chosen = top[0], [*chosen, top[1]]
            return chosen, best

        def evidence(log_fit: float, m: int, t: float) -> float:
            return self.charged(log_fit, k0 + m, t) if m else -math.inf

        selected = {t: select(t) for t in self.temperatures}
        fit_by_t = {t: best[0] for t, (_, best) in selected.items()}
        by_t = {t: evidence(best[0], len(chosen), t) for t, (chosen, best) in selected.items()}
        chosen, (_, tau, e) = selected[TEMPERATURE]
        smooth = self.form.smooth(e, tau)
        parts = {t: self.form.case_log_marginals(best[2], t, best[1]) for t, (_, best) in selected.items()}
        return Scored(expl, None, by_t, fit_by_t, log_prior(expl, candidates), k0 + len(chosen), tau, float(e @ e),
                      float(np.sum((e - smooth) ** 2)), extra={"features": [names[i] for i in chosen]},
                      case_log_lik_by_t=parts)

    def all(self, base_spec: ModelSpec, max_terms: int = 2) -> tuple[Fit, list[Scored]]:
        """The baseline fit and every candidate of at most ``max_terms`` terms scored (probabilities filled in)."""
        candidates = [c for c in explanations() if len(c.terms) <= max_terms and (max_terms > 0 or not c.unlisted)]
        base = self.fit(base_spec)
        fits = self.fits
        fits[()] = base
        baseline = self.score(Explanation(), base, candidates)
        for name in [c.terms[0] for c in candidates if len(c.terms) == 1]:
            fits[(name,)] = self.fit(base_spec.with_effects(name), warm=base)
        scored = []
        for expl in candidates:
            if expl.unlisted:
                scored.append(self.unlisted(base, expl, candidates))
                continue
            key = expl.terms
            if not key:
                scored.append(baseline)
                continue
            if key not in fits:
                a, b = key
                one = self.fit(base_spec.with_effects(a, b), warm=fits[(a,)], guess=fits[(b,)].spec.decode(
                    fits[(b,)].x))
                two = self.fit(base_spec.with_effects(a, b), warm=fits[(b,)], guess=fits[(a,)].spec.decode(
                    fits[(a,)].x))
                fits[key] = min(one, two, key=lambda f: float(f.z @ f.z))
            scored.append(self.shape_doubt(self.score(expl, fits[key], candidates), candidates))
        lof_p = base.lack_of_fit_p(self.data, self.noise)
        not_instrument: list[str] = []
        while True:
            posterior(scored, rejected=rejected_explanations(lof_p, not_instrument))
            due = [s for s in scored if s.fit is not None and any(rig_level(t) for t in s.explanation.terms) and
                   "instrument" not in s.extra and s.probability >= INSTRUMENT_CHECK_FROM]
            if not due:
                return base, scored
            for s in due:
                assert s.fit is not None
                s.extra["instrument"] = [c.to_dict() for c in check_instrument(self.data, s.fit, self.noise)]
                if s.failed_instrument:
                    not_instrument.append(s.explanation.name)
