"""``labctl plan``: from the data so far, which specimen and which loads to measure next, and whether to stop.

Runs the discrepancy workflow on the data, takes the models still in play (``labctl.planning.rivals``), and
for every catalogue roller on every rail the lab has (``labctl.planning.specimens``) picks the loads that
maximise the expected information (``labctl.planning.criterion``). Specimens are ranked by that score.

``enough`` (no measurement would change the verdict): for every candidate specimen with its chosen loads and
every model i in play other than the final one, 2·KL(i‖final) — the expected shift of their BIC difference in
i's favour if i were true — stays below max(1, DECISIVE_BIC + BIC_i − BIC_final): no rival could be brought
decisively ahead of the final model by one more mounting within the budget.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from labctl.discrepancy.data import CaseData, Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.search import DECISIVE_BIC
from labctl.discrepancy.workflow import DiscrepancyResult, run_discrepancy
from labctl.errors import InputError
from labctl.physics.effects import EFFECTS
from labctl.physics.rig_config import RigConfig, load_rig
from labctl.planning.criterion import ModelAt, Score, greedy_loads
from labctl.planning.rivals import Rival, kink_words, rivals_in_play, spread_kinks, whitener
from labctl.planning.specimens import RAIL_RA_UM, Specimen, candidate_specimens
from labctl.protocol import Protocol, load_protocol
from labctl.stiffness_table import StiffnessPoint

DEFAULT_BUDGET_STEPS = 5
DEFAULT_PROTOCOL = "roller_stiffness"
TOP = 5
"""Recommendations listed (best first)."""
SAME_LENGTH = 0.05
"""Contact lengths within this relative distance count as the same."""


def candidate_terms() -> tuple[str, ...]:
    """Every term the workflow can name: the physical effects, then the measurement-side terms."""
    return (*EFFECTS, *MEASUREMENT)


def parse_candidates(text: str) -> tuple[str, ...]:
    """``all`` or a comma-separated list of term names; an unknown name is an input error naming the valid ones."""
    known = candidate_terms()
    if text.strip() == "all":
        return known
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise InputError(f"--candidates {text!r}: expected 'all' or a comma-separated list of {', '.join(known)}")
    for n in names:
        if n not in known:
            raise InputError(f"--candidates: unknown term {n!r}; expected 'all' or names from {', '.join(known)}")
    return tuple(n for n in known if n in names)


@dataclass(frozen=True)
class Recommendation:
    roller_type: int
    rail_ra_um: float
    loads_n: tuple[float, ...]
    reason: str
    score: float

    def to_dict(self) -> dict[str, Any]:
        return {"roller_type": self.roller_type, "rail_ra_um": self.rail_ra_um, "loads_n": list(self.loads_n),
                "reason": self.reason, "score": self.score}


@dataclass(frozen=True)
class Plan:
    recommendations: tuple[Recommendation, ...]
    enough: bool
    result: DiscrepancyResult
    in_play: tuple[str, ...]
    """Labels of the models in play (the final model first)."""

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of ``labctl plan --json``."""
        return {"recommendations": [r.to_dict() for r in self.recommendations], "enough": self.enough}

    def summary_text(self) -> str:
        lines = [f"verdict: {self.result.verdict_text()}",
                 f"models in play: {'; '.join(self.in_play)}",
                 "enough data: " + ("yes, no candidate measurement would change the verdict" if self.enough
                                    else "no, a further measurement could change the verdict")]
        for i, r in enumerate(self.recommendations, 1):
            loads = ", ".join(f"{f:g}" for f in r.loads_n)
            lines.append(f"{i}. type {r.roller_type} on Ra {r.rail_ra_um:g} µm rails at {loads} N "
                         f"(score {r.score:.3g}): {r.reason}")
        return "\n".join(lines)


def _design_data(spec: Specimen) -> Dataset:
    loads = spec.loads_n
    return Dataset((CaseData(spec.case, loads, np.zeros(loads.size), np.ones(loads.size, dtype=int)),))


def _term_rows(rival: Rival, fits_depth: bool) -> np.ndarray:
    return np.arange(int(fits_depth), rival.theta.size)


def _weights(models: list[Rival]) -> np.ndarray:
    bic = np.array([m.bic for m in models])
    w = np.exp(-0.5 * (bic - bic.min()))
    return w / w.sum()


def _differs(a: tuple[str, ...], b: tuple[str, ...]) -> str:
    only_a = [t for t in a if t not in b]
    only_b = [t for t in b if t not in a]
    if only_a and only_b:
        return f"separates {' + '.join(only_a)} from {' + '.join(only_b)}"
    extra = only_a or only_b
    return f"tells whether {' + '.join(extra)} is present"


def _length_words(spec: Specimen, measured: list[float], materials: set[str]) -> str:
    length = spec.roller.contact_length_m
    kind = "roller" if spec.roller.material.name in materials else \
        f"{spec.roller.material.name} roller (a material not measured yet)"
    nearest = min(measured, key=lambda m: abs(math.log(length / m)))
    ratio = length / nearest
    name = f"type {spec.type_id} (L_we {length * 1e3:.3g} mm, D {spec.roller.diameter_m * 1e3:.3g} mm)"
    if abs(ratio - 1) <= SAME_LENGTH:
        return f"a {kind} of the measured length, {name},"
    word = "longer" if ratio > 1 else "shorter"
    return f"a {word} {kind}, {name} at {ratio:.2g}× the nearest measured L_we,"


def _load_words(loads: np.ndarray, spec: Specimen, data: Dataset) -> str:
    p = loads / spec.roller.contact_length_m
    measured = data.load_per_length_n_per_m
    lo, hi = np.log(measured.min()), np.log(measured.max())
    span = max(hi - lo, 1e-9)
    u = (np.log(p) - lo) / span
    if np.ptp(u) > 0.6:
        word = "low and high"
    elif np.median(u) < 0.4:
        word = "low"
    elif np.median(u) > 0.6:
        word = "high"
    else:
        word = "medium"
    lo_text, hi_text = f"{p.min() * 1e-3:.3g}", f"{p.max() * 1e-3:.3g}"
    where = lo_text if lo_text == hi_text else f"{lo_text}–{hi_text}"
    return f"at {word} line load ({where} N/mm)"


def _reason(spec: Specimen, loads: np.ndarray, score: Score, models: list[ModelAt], data: Dataset) -> str:
    lengths = sorted({c.case.roller.contact_length_m for c in data.cases})
    rails = {round(c.case.rail_ra_m * 1e6, 6) for c in data.cases}
    rail = round(spec.rail_ra_m * 1e6, 6)
    rail_words = f" on Ra {rail:g} µm rails" + ("" if rail in rails else " (not measured yet)")
    materials = {c.case.roller.material.name for c in data.cases}
    where = f"{_length_words(spec, lengths, materials)}{rail_words} {_load_words(loads, spec, data)}"
    if score.pair_terms and float(score.discrimination[0]) >= float(score.parameters[0]):
        (i, j), _ = max(score.pair_terms.items(), key=lambda kv: float(kv[1][0]))
        a, b = models[i].rival.terms, models[j].rival.terms
        what = f"locates {kink_words(a)}" if a == b else _differs(a, b)
    elif score.param_terms:
        k, _ = max(score.param_terms.items(), key=lambda kv: float(kv[1][0]))
        what = f"pins down the parameters of {models[k].rival.label}"
    else:
        what = "pins down the baseline's depth (no effect term is in play)"
    return f"{where} {what}"


def _predictable(spec: Specimen, play: list[Rival]) -> Specimen | None:
    """The specimen with only the loads every model in play can predict (a load offset larger than a load
    leaves that model without a prediction there); None when no load is left."""
    design = _design_data(spec)
    ok = np.ones(spec.loads_n.size, dtype=bool)
    for rival in play:
        mu, jac = rival.jacobian(design)
        ok &= np.isfinite(mu) & np.all(np.isfinite(jac), axis=1)
    if not np.any(ok):
        return None
    return replace(spec, loads_n=spec.loads_n[ok])


def _would_change(score: Score, models: list[ModelAt]) -> bool:
    final = models[0].rival
    for i in range(1, len(models)):
        if models[i].rival.terms == final.terms:
            continue  # the final model at another kink position: not a rival verdict
        need = max(1.0, DECISIVE_BIC + models[i].rival.bic - final.bic)
        if 2.0 * float(score.kl[(i, 0)][0]) >= need:
            return True
    return False


def score_specimen(result: DiscrepancyResult, play: list[Rival], weights: np.ndarray, spec: Specimen,
                   budget_steps: int, repeat: bool = False) -> tuple[Recommendation, float, bool] | None:
    """The best ``budget_steps`` loads of one specimen for the models in play (a load repeated when that scores
    best, with ``repeat``): the recommendation, its score and whether it could change the verdict (None when no
    model in play predicts any of its loads)."""
    spec_ok = _predictable(spec, play)
    if spec_ok is None:
        return None
    design = _design_data(spec_ok)
    sigma = result.noise.sigma_at(design)
    noise_cov = np.diag(sigma**2) + result.noise.seating_sigma**2
    models = []
    for rival, w in zip(play, weights, strict=True):
        mu, jac = rival.jacobian(design)
        models.append(ModelAt(rival, float(w), mu, jac, _term_rows(rival, result.final.spec.fits_depth)))
    idx, score = greedy_loads(models, noise_cov, budget_steps, repeat, sigma**2)
    loads = spec_ok.loads_n[idx]
    rec = Recommendation(spec_ok.type_id, round(spec_ok.rail_ra_m * 1e6, 6), tuple(round(float(f), 1) for f in loads),
                         _reason(spec_ok, loads, score, models, result.data), float(f"{float(score.total[0]):.4g}"))
    return rec, float(score.total[0]), _would_change(score, models)


def models_in_play(result: DiscrepancyResult, candidates: Sequence[str] | None = None
                   ) -> tuple[list[Rival], np.ndarray]:
    """The final model first, then its rivals still in play, with their BIC weights; a model with a kink is
    followed by its other kink positions still in play (``spread_kinks``), sharing its weight."""
    final, play = rivals_in_play(result, candidate_terms() if candidates is None else candidates)
    play = [final, *play[1:]]
    return spread_kinks(play, _weights(play), result.data, whitener(result))


def plan_from_result(result: DiscrepancyResult, *, candidates: Sequence[str] | None = None,
                     budget_steps: int = DEFAULT_BUDGET_STEPS, rig: RigConfig | None = None,
                     protocol: Protocol | None = None, top: int = TOP) -> Plan:
    """Rank the next measurements for a finished discrepancy analysis."""
    if budget_steps < 1:
        raise InputError(f"--budget-steps {budget_steps}: expected at least 1 load step")
    rig = rig or load_rig()
    protocol = protocol or load_protocol(DEFAULT_PROTOCOL)
    play, weights = models_in_play(result, candidates)
    rail = result.data.cases[0].case.rail
    ranked: list[tuple[float, Recommendation]] = []
    change = False
    for spec in candidate_specimens(protocol, rig, rail, RAIL_RA_UM):
        scored = score_specimen(result, play, weights, spec, budget_steps)
        if scored is None:
            continue
        rec, total, would_change = scored
        change = change or would_change
        ranked.append((total, rec))
    ranked.sort(key=lambda t: -t[0])
    return Plan(tuple(r for _, r in ranked[:top]), not change, result, tuple(dict.fromkeys(m.label for m in play)))


def plan_measurements(points: Sequence[StiffnessPoint], *, baseline: str = "tripp",
                      setup_stiffness_n_per_m: float | None = None, candidates: Sequence[str] | None = None,
                      budget_steps: int = DEFAULT_BUDGET_STEPS, rig: RigConfig | None = None,
                      protocol: Protocol | None = None, top: int = TOP) -> Plan:
    """The discrepancy workflow on ``points``, then the ranked next measurements (see the module doc)."""
    if budget_steps < 1:
        raise InputError(f"--budget-steps {budget_steps}: expected at least 1 load step")
    rig = rig or load_rig()
    result = run_discrepancy(points, baseline, setup_stiffness_n_per_m=setup_stiffness_n_per_m
                             or rig.setup_stiffness_n_per_m)
    return plan_from_result(result, candidates=candidates, budget_steps=budget_steps, rig=rig, protocol=protocol,
                            top=top)
