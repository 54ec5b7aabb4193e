"""The discrepancy workflow: screen the input, fit the baseline, model the noise, name what earns it.

Steps: (0) screen the rows (duplicates, conflicting duplicates, unit slips); (1) the noise model from the
repetitions (load-dependent point noise, seating offsets, gross outliers set aside); (2) the baseline with its
nuisance parameter fitted (Tripp's depth); (3) regions where residuals exceed the noise; (4) physical and
measurement-side candidates, each named only when it earns it on its own (``labctl.discrepancy.search``);
(5) repeat until the lack-of-fit test at level 0.01 finds no structure; (6) when structure remains, the closest
library term and an unnamed empirical term (``labctl.discrepancy.empirical``); (7) the gap at each step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from labctl.discrepancy.absorbed import absorbed_reasons
from labctl.discrepancy.caveats import caveats, end_step_words
from labctl.discrepancy.data import Dataset, campaign_setup_stiffness, load_points
from labctl.discrepancy.design import DesignLimit, decide, design_limits, not_named_words, unseparated
from labctl.discrepancy.empirical import EmpiricalTerm, propose
from labctl.discrepancy.locate import locate, trends
from labctl.discrepancy.measurement import MEASUREMENT, TRIPP_DEPTH_RANGE_M
from labctl.discrepancy.model import DEPTH_BOUNDS_M, Fit, ModelSpec
from labctl.discrepancy.noise import CONSISTENT_P, NoiseFloor
from labctl.discrepancy.posterior import LIKELY_AT, NAME_AT, Evidence, Scored
from labctl.discrepancy.questions import TEMPERATURE, resampled_over
from labctl.discrepancy.screen import Screening
from labctl.discrepancy.search import Candidate, Search, Step, discrepancy, kind, share
from labctl.discrepancy.set_aside import consistent_with_noise, screened, set_aside_step
from labctl.errors import InputError
from labctl.physics.effects import EFFECTS
from labctl.physics.law import BASELINES
from labctl.physics.rig_config import load_rig
from labctl.stiffness_table import StiffnessPoint

MAX_TERMS = len(EFFECTS) + len(MEASUREMENT)
PINNED_DEPTH_BIC = 10.0
"""A pinned depth is called a sign of a measurement-side error only when freeing it gains this much BIC (Kass &
Raftery's "very strong"); below, the warning says the evidence is weak."""


@dataclass(frozen=True)
class DiscrepancyResult:
    """Everything the workflow found: the fits before and after, the steps, the noise and the regions."""

    data: Dataset
    baseline: Fit
    final: Fit
    noise: NoiseFloor
    steps: tuple[Step, ...]
    regions: list[dict[str, Any]]
    """Where the fitted baseline disagrees with the data beyond the noise."""
    regions_after: list[dict[str, Any]]
    """Where the final model still does."""
    trends: list[dict[str, Any]]
    screening: Screening
    closest: Candidate | None = None
    """When structure remains: the best library term not named (or the last named one's share)."""
    empirical: EmpiricalTerm | None = None
    nuisance: tuple[dict[str, Any], ...] = ()
    trends_after: tuple[dict[str, Any], ...] = ()
    scored: tuple[Scored, ...] = ()
    """Every candidate explanation with its posterior probability, most probable first."""
    likely: Scored | None = None
    """The most probable explanation when it is not named: its probability is 0.5-0.9, or it is held back
    (``held_by``: the design cannot separate its two terms, or it has a measurement-side term)."""
    limits: tuple[DesignLimit, ...] = ()
    """What in the data's design limits which candidates can be told apart."""
    absorbed: tuple[str, ...] = ()
    """Measurement-side terms the baseline's fitted depth takes up (``labctl.discrepancy.absorbed``): untested."""

    @property
    def reasons(self) -> tuple[str, ...]:
        """The design's limits in words."""
        return tuple(limit.text for limit in self.limits)

    @property
    def held_by(self) -> DesignLimit | None:
        """What kept an explanation of probability ≥ 0.9 from being named (a design limit on one of its terms, or
        ``AT_ITS_SOURCE``), if anything."""
        if self.likely is None or self.likely.probability < NAME_AT:
            return None
        return unseparated(self.likely.explanation, self.limits)

    @property
    def not_named(self) -> str:
        """What held the most probable explanation back, in a few words ("one rail roughness"), or ""."""
        return "" if self.held_by is None else self.held_by.short

    @property
    def consistent(self) -> bool:
        return consistent_with_noise(self.final, self.noise, self.data)

    @property
    def baseline_lack_of_fit_p(self) -> float | None:
        """The lack-of-fit test's p-value for the baseline alone (None without a test)."""
        return self.baseline.lack_of_fit_p(self.data, self.noise)

    @property
    def physical_steps(self) -> list[Step]:
        return [s for s in self.steps if s.kind == "physical"]

    @property
    def measurement_steps(self) -> list[Step]:
        return [s for s in self.steps if s.kind == "measurement"]

    @property
    def verdict(self) -> str:
        """consistent | explained | partly_explained | likely | unexplained."""
        if self.steps:
            return "explained" if self.consistent else "partly_explained"
        if self.likely is not None:
            return "likely"
        top = self.scored[0] if self.scored else None
        if self.consistent and (top is None or top.explanation.name == "none" or top.probability < LIKELY_AT):
            return "consistent"
        return "unexplained"

    def _top(self, k: int = 3) -> str:
        return ", ".join(f"{s.explanation.name} {s.probability:.2f}" for s in self.scored[:k])

    def verdict_text(self) -> str:
        """The verdict in words: the explanation and its probability, the structure it leaves, what the data
        cannot separate."""
        level = f"lack-of-fit test at level {CONSISTENT_P:g}"
        residual = _residual_words(list(self.trends_after))
        top = self.scored[0] if self.scored else None
        parts = []
        if self.verdict == "consistent":
            parts.append(f"the baseline agrees with the data within the noise ({level}); an effect below the "
                         "detection limit is not ruled out")
            if top is not None:
                parts.append(f"most probable explanations: {self._top()}")
        elif self.steps:
            assert top is not None
            parts.append(f"{top.explanation.name} (probability {top.probability:.2f})")
            if self.consistent:
                parts.append(f"residuals consistent with the noise ({level})")
            else:
                parts.append(f"form differs: the residual is NOT consistent with the noise ({level}) and still "
                             f"{residual}")
        else:
            if self.likely is not None:
                why = not_named_words(self.likely.explanation, self.held_by, self._likely_parameters())
                why = f"not named: {why}" if why else f"below the {NAME_AT:g} needed to name it"
                parts.append(f"likely {self.likely.explanation.name} (probability {self.likely.probability:.2f}, "
                             f"{why}); candidates: {self._top()}")
            elif top is not None and top.explanation.unlisted and top.probability >= LIKELY_AT:
                parts.append(f"unexplained: most probably an effect outside the library (unlisted "
                             f"{top.probability:.2f}); candidates: {self._top()}")
            else:
                parts.append(f"unexplained: no explanation reaches probability {LIKELY_AT:g}; candidates: "
                             f"{self._top()}")
            if not self.consistent:
                parts.append(f"the residual is NOT consistent with the noise ({level}) and still {residual}")
            if len(self.scored) > 1 and self.scored[0].probability + self.scored[1].probability >= 0.6 and \
                    self.scored[1].probability >= 0.15:
                why = "the design's limits below" if self.reasons else \
                    "their signatures are alike over these loads and rollers"
                parts.append(f"the data cannot separate {self.scored[0].explanation.name} from "
                             f"{self.scored[1].explanation.name}: {why}")
            if self.empirical is not None:
                held = self.empirical.held_out
                gen = ("generalises to left-out roller types" if self.empirical.generalises else
                       "does not generalise on held-out data") if held is None or not held.get("weak") else \
                    f"held-out check weak: left out {held['by']}s, not roller types"
                parts.append(f"unnamed empirical term {self.empirical.formula} closes the gap "
                             f"{self.empirical.gap_before:.4f} -> {self.empirical.gap_after:.4f} ({gen})")
        parts += [end_step_words(note) for note in self.screening.end_steps]
        if self.verdict != "consistent":
            parts += caveats(top, self.closest)
        if self.reasons or self.absorbed:
            parts.append("what this campaign's design cannot test, whatever the probabilities above: "
                         + "; ".join(self.reasons + self.absorbed))
        stretched = self.not_instrument()
        if stretched:
            parts.append("ruled out as instrument or rig errors (a term that mends a law's form is no load cell, "
                         "modulus or rig-stiffness error): " + "; ".join(stretched))
        if self.screening.drifted:
            loads = ", ".join(f"{d['load_n']:.1f}->{d['load_after_n']:.1f} N" if d["load_after_n"] is not None
                              else f"{d['load_n']:.1f} N" for d in self.screening.drifted)
            parts.append(f"{len(self.screening.drifted)} point(s) measured while the load drifted set aside "
                         f"({loads}): their load is not known; re-measure those steps to use them")
        return "; ".join(parts)

    def not_instrument(self, k: int = 2) -> list[str]:
        """The explanations ruled out because a rig-level term failed its instrument check
        (``labctl.discrepancy.instrument``) that the evidence alone would have ranked above the most probable one."""
        top = self.scored[0] if self.scored else None
        lead = -np.inf if top is None else top.log_prior + top.log_evidence
        out = []
        for s in sorted(self.scored, key=lambda s: -(s.log_prior + s.log_evidence)):
            if s.failed_instrument and s.log_prior + s.log_evidence > lead and len(out) < k:
                out.append(f"{s.explanation.name} ({', '.join(c['description'] for c in s.failed_instrument)})")
        return out

    def _likely_parameters(self) -> dict[str, dict[str, float]]:
        """The likely explanation's measurement-side parameters (SI): what to check at their source."""
        fit = None if self.likely is None else self.likely.fit
        return {} if fit is None else fit.measurement_parameters()

    def _step_doc(self, s: Step) -> dict[str, Any]:
        params = {**self.final.effect_parameters(), **self.final.measurement_parameters()}
        return {"name": s.name, "parameters": params[s.name], "evidence": s.evidence,
                "gap_before": s.before.gap, "gap_after": s.fit.gap}

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of ``labctl discrepancy --json``."""
        lof = self.noise.lack_of_fit(self.data, self.final.residuals, self.final.sigma, self.final.spec.n_params())
        return {
            "baseline": self.baseline.spec.baseline,
            "baseline_parameters": self.baseline.baseline_parameters(),
            "final_baseline_parameters": self.final.baseline_parameters(),
            "nominal_setup_stiffness_n_per_m":
                self.baseline.spec.fixed.get("setup_compliance", {}).get("nominal_setup_n_per_m"),
            "n_points": self.data.n_points,
            "n_cases": len(self.data.cases),
            "gap_before": self.baseline.gap,
            "gap_after": self.final.gap,
            "noise_floor": self.noise.sigma,
            "noise_method": self.noise.method,
            "seating_sigma": self.noise.seating_sigma,
            "consistent_with_noise": self.consistent,
            "consistency_test": {"test": "lack-of-fit F test (generalised least squares: seating offsets, "
                                         "load-dependent point noise)", "level": CONSISTENT_P,
                                 **({} if lof is None else lof.to_dict())},
            "verdict": self.verdict,
            "verdict_text": self.verdict_text(),
            "noise_by_load": self.noise.bands(),
            "lack_of_fit_p": None if lof is None else lof.p,
            "effects": [self._step_doc(s) for s in self.physical_steps],
            "measurement_effects": [self._step_doc(s) for s in self.measurement_steps],
            "explanations": [x.to_dict() for x in self.scored],
            "decision": {"named_at": NAME_AT, "likely_at": LIKELY_AT, "temperature": TEMPERATURE,
                         "resampled_over_cases": resampled_over(len(self.data.cases)),
                         "top": self.scored[0].to_dict() if self.scored else None,
                         "likely": None if self.likely is None else
                         {**self.likely.to_dict(), "measurement_parameters": self._likely_parameters()},
                         "not_named_because": self.not_named or None,
                         "design_limits": [limit.to_dict() for limit in self.limits],
                         "identifiability": [*self.reasons, *self.absorbed]},
            "closest_library_term": None if self.closest is None else
            {"name": self.closest.name, "explained_share": self.closest.share, "delta_bic": self.closest.delta_bic},
            "empirical_term": None if self.empirical is None else self.empirical.to_dict(),
            "nuisance_warnings": list(self.nuisance),
            "input_checks": self.screening.to_dict(),
            "regions": self.regions,
            "regions_after": self.regions_after,
            "trends": self.trends,
            "trends_after": list(self.trends_after),
        }


def _pct(fraction: float) -> str:
    return f"{fraction * 100:.1f} %" if fraction >= 0.99 else f"{fraction * 100:.0f} %"


def _residual_words(found: list[dict[str, Any]]) -> str:
    words = []
    for t in found:
        if t["variable"] == "material":
            words.append("differs between materials")
        elif t.get("trend", "flat") != "flat":
            what = {"load_n": "load", "contact_length_mm": "contact length", "diameter_mm": "diameter",
                    "rail_ra_um": "rail Ra"}.get(t["variable"], t["variable"])
            words.append(f"depends on {what} ({t['trend']}, {t['slope_per_decade']:+.3g} per decade)")
    return "; ".join(words) if words else "shows structure within the load range of each roller case"


def _nuisance(search: Search, fits: list[Fit]) -> list[dict[str, Any]]:
    """A depth pinned at an end of its physical range: what depth a free fit would want, and what that means."""
    out = []
    for fit in fits:
        if not fit.spec.depth_at_bound(fit.depth_m) or any(w["model"] == fit.spec.terms for w in out):
            continue
        free = search.fit(replace(fit.spec, depth_bounds_m=DEPTH_BOUNDS_M), warm=fit)
        lo, hi = TRIPP_DEPTH_RANGE_M
        gain = fit.bic - free.bic
        where = (f"Tripp's evaluation depth is pinned at {fit.depth_m * 1e3:.3g} mm, the end of its physical range "
                 f"{lo * 1e3:g}-{hi * 1e3:g} mm (a free fit wants {free.depth_m * 1e3:.3g} mm, ΔBIC {gain:.1f})")
        meaning = (": a sign of a measurement-side error (Young's modulus or its unit, load-cell gain), not of a "
                   "physical effect; check the inputs" if gain >= PINNED_DEPTH_BIC else
                   ": the data barely prefer the free depth, so this is no evidence of a measurement-side error")
        out.append({
            "parameter": "depth_m", "model": fit.spec.terms, "value": fit.depth_m, "free_fit_value": free.depth_m,
            "physical_range": [lo, hi], "free_fit_delta_bic": gain, "message": where + meaning})
    return out


def _steps(scored: list[Scored], top: Scored, base: Fit, fits: dict[tuple[str, ...], Fit]) -> list[Step]:
    """The named explanation as steps: each term against the model before it, every step carrying the decision."""
    steps, before = [], base
    terms = top.explanation.terms
    for i, name in enumerate(terms):
        fit = top.fit if i == len(terms) - 1 else fits.get(terms[: i + 1], top.fit)
        assert fit is not None
        evidence = {
            "kind": kind(name), "explanation": top.explanation.name, "probability": top.probability,
            "delta_bic": before.bic - fit.bic, "explained_share": share(before, fit),
            "explained_share_of_baseline": share(base, fit), "form_sigma": top.tau,
            "candidates": {s.explanation.name: s.probability for s in scored[:6]},
        }
        if len(terms) > 1:
            evidence["named_with"] = [t for t in terms if t != name]
        steps.append(Step(name, fit, before, evidence))
        before = fit
    return steps


def baseline_spec(baseline: str, setup_stiffness_n_per_m: float | None = None) -> ModelSpec:
    """The baseline with no term added; K_setup defaults to the shipped rig file's nominal value."""
    k_setup = setup_stiffness_n_per_m or load_rig().setup_stiffness_n_per_m
    return ModelSpec(baseline, (), {"setup_compliance": {"nominal_setup_n_per_m": k_setup}})


def _scored(data: Dataset, noise: NoiseFloor, spec: ModelSpec, temperatures: Sequence[float], max_terms: int
            ) -> tuple[Search, Evidence, Fit, list[Scored]]:
    """Every candidate explanation scored on the screened data, the most probable first."""
    search = Search(data, noise)
    evidence = Evidence(data, noise, search.sigma, temperatures)
    base, scored = evidence.all(spec, max_terms=max_terms)
    scored.sort(key=lambda s: -s.probability)
    return search, evidence, base, scored


def run_discrepancy(points: Sequence[StiffnessPoint], baseline: str = "tripp", *,
                    setup_stiffness_n_per_m: float | None = None, max_effects: int = MAX_TERMS,
                    temperatures: Sequence[float] = ()) -> DiscrepancyResult:
    """Run the whole workflow on measured points; K_setup defaults to the shipped rig file's nominal value.

    ``temperatures``: further noise inflations to store every candidate's evidence at (a bench's rescoring), besides
    the decision's."""
    if baseline not in BASELINES:
        raise InputError(f"unknown baseline {baseline!r}; expected one of {', '.join(BASELINES)}")
    spec = baseline_spec(baseline, setup_stiffness_n_per_m)
    data, noise, screening = screened(points, spec)
    search, evidence, base, scored = _scored(data, noise, spec, temperatures, max_effects)
    top = scored[0]
    if top.fit is not None and top.explanation.terms and not top.explanation.unlisted:
        fewer, less = set_aside_step(data, noise, top.fit.spec, screening, warm=top.fit,  # against the best one
                                     against=top.explanation.name)
        if fewer is not data:
            data, noise = fewer, less
            search, evidence, base, scored = _scored(data, noise, spec, temperatures, max_effects)
            top = scored[0]
    limits = design_limits(data)
    action = decide(top.explanation, top.probability, limits)
    steps = _steps(scored, top, base, evidence.fits) if action == "named" else []
    likely = top if action == "likely" else None
    current = steps[-1].fit if steps else base
    nuisance = _nuisance(search, [base, current])
    closest = empirical = None
    if not consistent_with_noise(current, noise, data) and discrepancy(current) > 0:
        if not steps:
            physical = [c for c in search.candidates(current, physical_only=True)
                        if c.name in EFFECTS]
            closest = physical[0] if physical else None
        empirical = propose(search, current)
    sigma = noise.sigma
    return DiscrepancyResult(
        data=data, baseline=base, final=current, noise=noise, steps=tuple(steps),
        regions=locate(data, base.residuals, base.sigma), regions_after=locate(data, current.residuals, current.sigma),
        trends=trends(data, base.residuals, sigma), screening=screening, closest=closest, empirical=empirical,
        nuisance=tuple(nuisance), trends_after=tuple(trends(data, current.residuals, sigma)),
        scored=tuple(scored), likely=likely, limits=tuple(limits),
        absorbed=tuple(absorbed_reasons(data, base)),
    )


def run_files(paths: Sequence[str | Path], baseline: str = "tripp", *, rig: str | Path | None = None,
              max_effects: int = MAX_TERMS) -> DiscrepancyResult:
    """The workflow on stiffness tables and campaign files: the entry point of ``labctl discrepancy``.

    K_setup comes from ``rig`` when given, else from the rig stored in the campaign files, else the shipped rig.
    """
    k_setup = load_rig(rig).setup_stiffness_n_per_m if rig is not None else campaign_setup_stiffness(paths)
    return run_discrepancy(load_points(paths), baseline, setup_stiffness_n_per_m=k_setup, max_effects=max_effects)
