"""Other decision rules on the evidence a blind run stored: does a different Occam factor, noise inflation or
confidence scale rank the truth first more often, or state probabilities that mean what they say?

Reads the files ``bench/discrepancy_eval.py --out F`` wrote (each candidate's log evidence at every noise
inflation T of the grid) and decides every dataset again under each rule, without running the workflow:

- ``occam``: ``hyper-g`` (the workflow's: Zellner's g prior on the parameters a candidate adds to the baseline,
  with the hyper-g mixture over g, a = 3, ``labctl.discrepancy.occam``; the penalty follows the fit's gain) or
  ``bic`` (−½·k·ln n charged on each candidate's stored fit, what the workflow charged before); ``presence``
  applies it to the question "is there any effect?" alone (the other question keeps the workflow's), ``all`` to
  both questions;
- ``T``: the noise inflation of the question "which effect?", or ``c-hat``: each dataset's own, QAIC's ĉ (the
  whitened sum of squares per degree of freedom of the best-fitting candidate, at least 1: the lack of fit the most
  flexible explanation still leaves, taken as the dispersion every comparison is scaled by);
- ``λ``: a confidence scale — the log posterior of that question divided by λ (order-preserving: the ranking within
  it is unchanged, its probabilities spread);
- ``prior``: ``classes`` (the workflow's ``PRIOR_MASS``), ``equal-single`` (every single-term explanation,
  physical or measurement-side, the same prior: the classes' 0.35 + 0.10 split over their 8 members) or
  ``unlisted=X`` or ``pair=X`` (that class's mass X instead of its 0.10, the other classes as they are);
  ``judge-mix`` is a diagnostic no method may use: every candidate's prior is the share of the file's worlds whose
  truth it is (10⁻⁴ for one that is no world's truth), the judge's own mix of worlds. If the stated probabilities
  are still unreliable with it, what makes them so is the evidence (the library's laws against the judge's), not
  the prior;
- ``unlisted-T``: "unlisted"'s gain over "none" counted at that many times the inflation every other candidate is
  decided at (its evidence and each roller case's part of it, from the stored grid): the stand-in picks its
  features on the data, so its wins may be the overconfident ones;
- ``ε``: the probabilities mixed with the prior afterwards, (1 − ε)·p + ε·prior (the prior renormalised over the
  candidates not ruled out): a recalibration map that keeps the ranking and pulls every probability toward it;
- ``cases``: ``resampled`` (the question "which effect?" resampled over roller cases, as the workflow asks it with
  three cases or more: ``labctl.discrepancy.questions``) or ``pooled`` (the evidence alone, as before);
- ``a``: the resampling's Dirichlet concentration (1, the workflow's: the Bayesian bootstrap; below 1 the case
  weights spread further, so a lead that rests on a few roller cases counts for less);
- ``map``: ``isotonic`` — the top explanation's probability recalibrated by the isotonic regression of "right"
  on it over the first file (``scipy.optimize.isotonic_regression``; the other candidates scaled to keep the sum):
  the standard recalibration map, fitted where a rule would be chosen and judged on the other files (on the first
  it is in-sample and passes by construction).

The first file is the one a rule would be chosen on (calibration seeds); the others show what it does elsewhere.
Per file: top explanation = truth, log loss of the truth's probability, expected calibration error over the
reliability bins, whether every bin with ≥ 30 cases is within 0.05, names that are exactly the truth (both terms
of a pair; library or measurement-side truths of size ≥ 3σ: stricter than the evaluation's top-1, which counts
the first term named), wrong names (an effect outside the library named counts), top probabilities ≥ 0.5, and how
often an effect (named or unlisted) stated at ≥ 0.9 is the truth. Then what ``judge-mix`` states wrongly at ≥ 0.97,
and last the reliability table of the workflow's own rule (the stated probabilities the files hold) pooled over all
the files.

    python bench/discrepancy_rescale.py CAL.json EVAL.json [BLIND2.json …]
"""

from __future__ import annotations

import argparse
import json
import math
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np
from discrepancy_scores import binned, decided, holds_within, reliability, tempered
from scipy.optimize import isotonic_regression

from labctl.discrepancy.posterior import (
    LIKELY_AT,
    NAME_AT,
    PRIOR_MASS,
    TEMPERATURES,
    explanations,
)
from labctl.discrepancy.questions import PRESENCE_TEMPERATURE, TEMPERATURE


def log_evidence(r: dict[str, Any], t: float, occam: str) -> np.ndarray:
    """Each candidate's stored log evidence at T (the workflow's hyper-g Occam factor), or with BIC's −½·k·ln n
    charged on its stored fit instead (``bic``)."""
    c, key = r["candidates"], f"{t:g}"
    if occam == "hyper-g":
        return np.array([x["log_evidence_by_temperature"][key] for x in c])
    n = r["n_points"]
    return np.array([x["log_fit_by_temperature"][key] - 0.5 * x["n_params"] * math.log(n) for x in c])


Rule = Callable[[dict[str, Any]], list[tuple[str, float]]]
_KIND = {e.name: e.kind for e in explanations()}


def log_priors(r: dict[str, Any], prior: str, world_mix: dict[str, float] | None = None) -> np.ndarray:
    """The stored priors, every single-term explanation's prior made equal (``equal-single``), one class's mass
    changed, or the judge's mix of worlds (``judge-mix``: ``world_mix``, each truth's share of the file)."""
    stored = np.array([x["log_prior"] for x in r["candidates"]])
    if prior == "classes":
        return stored
    if prior == "judge-mix":
        return np.log([max((world_mix or {}).get(x["explanation"], 0.0), 1e-4) for x in r["candidates"]])
    if "=" in prior:  # one class's mass changed, the others as they are
        kind, mass = prior.split("=")
        shift = math.log(float(mass) / PRIOR_MASS[kind])
        return stored + np.array([shift if _KIND[x["explanation"]] == kind else 0.0 for x in r["candidates"]])
    single = ("physical", "measurement")
    kinds = [_KIND[x["explanation"]] for x in r["candidates"]]
    share = sum(PRIOR_MASS[k] for k in single) / sum(k in single for k in kinds)
    return np.array([math.log(share) if k in single else v for k, v in zip(kinds, stored, strict=True)])


def c_hat_temperature(r: dict[str, Any]) -> float:
    """The dataset's own inflation, QAIC's ĉ: the whitened sum of squares per degree of freedom of the candidate that
    fits best (at least 1), rounded to the nearest T of the stored grid (in log)."""
    n = r["n_points"]
    c_hat = max(1.0, min(x["chi2"] / max(n - x["n_params"], 1) for x in r["candidates"] if x["explanation"] != "none"))
    return min(TEMPERATURES, key=lambda t: abs(math.log(t / c_hat)))


def unlisted_at(r: dict[str, Any], temperature: float, factor: float) -> dict[str, Any]:
    """``r`` with "unlisted"'s stored evidence (and each case's part) at ``temperature`` replaced by that of "none"
    there plus the stand-in's gain over "none" at ``factor`` times it."""
    def moved(c: dict[str, Any], none: dict[str, Any], key: str) -> dict[str, Any]:
        at, far = f"{temperature:g}", f"{factor * temperature:g}"
        gain = np.asarray(c[key][far]) - np.asarray(none[key][far])
        return {**c[key], at: (np.asarray(none[key][at]) + gain).tolist()}

    none = next(c for c in r["candidates"] if c["explanation"] == "none")
    keys = [k for k in ("log_evidence_by_temperature", "case_log_lik_by_temperature") if k in none]
    cands = [{**c, **{k: moved(c, none, k) for k in keys}} if c["explanation"] == "unlisted" else c
             for c in r["candidates"]]
    return {**r, "candidates": cands}


WORKFLOW_RULE: dict[str, Any] = {"occam": "hyper-g", "scope": "all", "t": TEMPERATURE, "lam": 1.0,
                                 "prior": "classes", "cases": "resampled", "mix": 0.0, "concentration": 1.0,
                                 "unlisted_t": 1.0}
"""The workflow's own decision rule, as ``rule``'s settings: every other rule is a change of some of them."""


def rule(occam: str, scope: str, t: float | str, lam: float, prior: str = "classes", cases: str = "resampled",
         mix: float = 0.0, concentration: float = 1.0, world_mix: dict[str, float] | None = None,
         unlisted_t: float = 1.0) -> Rule:
    """The decision's two questions (``labctl.discrepancy.questions.probabilities``) under another rule; ``t``:
    a fixed T, or ``c-hat`` (each dataset's own, ``c_hat_temperature``); ``mix``: ε of the map toward the prior;
    ``concentration``: the resampling's; ``world_mix``: the file's truths' shares (``judge-mix``); ``unlisted_t``:
    the factor on the inflation "unlisted"'s gain is counted at."""
    def decide(r: dict[str, Any]) -> list[tuple[str, float]]:
        def evidence(temp: float) -> np.ndarray:  # the presence question takes the rule's Occam factor either way
            return log_evidence(r, temp, occam if scope == "all" or temp == PRESENCE_TEMPERATURE else "hyper-g")

        temperature = c_hat_temperature(r) if t == "c-hat" else float(t)
        if unlisted_t != 1.0:
            r = unlisted_at(r, temperature, unlisted_t)
        priors = log_priors(r, prior, world_mix)
        probs = tempered(r, temperature, priors, evidence, lam, resample=cases == "resampled",
                         concentration=concentration)
        if not mix:
            return probs
        by_name = dict(zip((x["explanation"] for x in r["candidates"]), priors, strict=True))
        weight = np.exp([by_name[name] for name, _ in probs])
        mixed = [(name, (1.0 - mix) * p + mix * w) for (name, p), w in zip(probs, weight / weight.sum(), strict=True)]
        return sorted(mixed, key=lambda item: -item[1])
    return decide


def isotonic(decide: Rule, results: list[dict[str, Any]]) -> Rule:
    """``decide`` with its top probability mapped by the isotonic regression of "right" on it over ``results``
    (the other candidates scaled so the probabilities still sum to one)."""
    pairs = sorted((probs[0][1], float(probs[0][0] == r["truth_name"])) for r in results for probs in [decide(r)])
    stated = np.array([p for p, _ in pairs])
    fitted = isotonic_regression(np.array([y for _, y in pairs])).x

    def mapped(r: dict[str, Any]) -> list[tuple[str, float]]:
        probs = decide(r)
        top = probs[0][1]
        new = float(np.interp(top, stated, fitted))
        rest = (1.0 - new) / (1.0 - top) if top < 1.0 else 0.0
        return sorted([(probs[0][0], new), *((n, p * rest) for n, p in probs[1:])], key=lambda item: -item[1])
    return mapped


def world_mix(results: list[dict[str, Any]]) -> dict[str, float]:
    """Each truth's share of a file's worlds: the judge's own mix (``judge-mix``)."""
    return {k: v / len(results) for k, v in Counter(r["truth_name"] for r in results).items()}


def remembered(decide: Rule) -> Rule:
    """``decide`` with each dataset's decision kept, so a second look at the same results costs nothing."""
    seen: dict[int, list[tuple[str, float]]] = {}

    def again(r: dict[str, Any]) -> list[tuple[str, float]]:
        if id(r) not in seen:
            seen[id(r)] = decide(r)
        return seen[id(r)]
    return again


def confident_misses(results: list[dict[str, Any]], decide: Rule, at: float = 0.97) -> str:
    """The wrong tops a rule states at ≥ ``at``, counted by (top, truth), most common first."""
    misses = Counter((top, r["truth_name"]) for r in results for top, p in [decide(r)[0]]
                     if p >= at and top != r["truth_name"])
    return f"{sum(misses.values())}: " + ", ".join(f"{t} for {w} {n}" for (t, w), n in misses.most_common(6))


def score(results: list[dict[str, Any]], decide: Rule) -> str:
    stated, loss, named_right, big, wrong, effects, sure = [], 0.0, 0, 0, 0, 0, []
    for r in results:
        probs = decide(r)
        top, p = probs[0]
        stated.append((p, top == r["truth_name"]))
        if p >= NAME_AT and top != "none":
            sure.append(top == r["truth_name"])
        loss -= math.log(max(dict(probs).get(r["truth_name"], 0.0), 1e-12))
        _, named = decided(r, top, p)
        truth = set() if r["truth_name"] in ("none", "unlisted") else set(r["truth_name"].split(" + "))
        if r["truth_name"] != "none":
            effects += 1
            wrong += bool(named) and not set(named) <= truth
        if r["truth_name"] not in ("none", "unlisted") and r["size_sigma"] >= 3:
            big += 1
            named_right += bool(named) and top == r["truth_name"]
    ece, ok = 0.0, True
    p_all, right = np.array([p for p, _ in stated]), np.array([k for _, k in stated])
    for _, _, inside in binned(stated):
        if inside.any():
            mean_p, share, n = float(p_all[inside].mean()), float(right[inside].mean()), int(inside.sum())
            ece += abs(mean_p - share) * n / len(stated)
            ok = ok and holds_within(mean_p, share, n)
    top_right = sum(k for _, k in stated)
    likely = sum(p >= LIKELY_AT for p, _ in stated)
    return (f"{top_right}/{len(results)} | {loss / len(results):.2f} | {ece:.3f} | {'yes' if ok else 'no'} | "
            f"{named_right}/{big} | {wrong}/{effects} | {likely} | {sum(sure)}/{len(sure)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+", help="results saved by discrepancy_eval.py --out (calibration first)")
    args = parser.parse_args()
    runs = []
    for path in args.files:
        with open(path, encoding="utf-8") as fh:
            runs.append((path, json.load(fh)))
    changes: list[dict[str, Any]] = [{}]
    changes += [{"t": t} for t in (2.0, 8.0, 32.0, "c-hat")]
    changes += [{"cases": "pooled", "t": t} for t in (TEMPERATURE, 8.0, 32.0)]
    changes += [{"cases": "pooled", "lam": 2.0}, {"cases": "pooled", "occam": "bic"},
                {"cases": "pooled", "occam": "bic", "t": 2.0}]
    changes += [{"prior": prior} for prior in ("equal-single", "unlisted=0.05", "unlisted=0.025", "pair=0.2",
                                               "pair=0.05")]
    changes += [{"prior": "judge-mix"}, {"unlisted_t": 2.0}, {"unlisted_t": 4.0}]
    changes += [{"mix": eps} for eps in (0.1, 0.2)]  # the workflow's rule, mapped toward the prior
    changes += [{"concentration": a} for a in (0.5, 0.25, 0.1)]
    changes += [{"map": "isotonic"}, {"map": "isotonic", "concentration": 0.25}]
    print("| occam | scope | T | λ | prior | cases | ε | a | map | file | top = truth | log loss | ECE | "
          "bins ≥ 30 within 0.05 | named = truth (≥ 3σ) | wrong names | top ≥ 0.5 | effect at ≥ 0.9 right |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    judged: list[Rule] = []  # the judge-mix row's decisions, one per file
    for change in changes:
        row = {**WORKFLOW_RULE, **change}
        recalibration = row.pop("map", "none")
        t = row["t"]
        shown = t if isinstance(t, str) else f"{t:g}"
        if row["unlisted_t"] != 1.0:
            shown += f", unlisted ×{row['unlisted_t']:g}"
        if recalibration == "isotonic":  # fitted on the first file, judged on the others
            fitted = isotonic(rule(**row, world_mix=world_mix(runs[0][1])), runs[0][1])
        for path, results in runs:
            decide = fitted if recalibration == "isotonic" else rule(**row, world_mix=world_mix(results))
            if change == {"prior": "judge-mix"}:  # its decisions kept for the list of its confident misses
                decide = remembered(decide)
                judged.append(decide)
            print(f"| {row['occam']} | {row['scope']} | {shown} | {row['lam']:g} | {row['prior']} | {row['cases']} | "
                  f"{row['mix']:g} | {row['concentration']:g} | {recalibration} | {path.rsplit('/', 1)[-1]} | "
                  f"{score(results, decide)} |")
    print("\nWrong at ≥ 0.97 with the judge's own mix as the prior (judge-mix), per file:")
    for (path, results), decide in zip(runs, judged, strict=True):
        print(f"- {path.rsplit('/', 1)[-1]}: {confident_misses(results, decide)}")
    pooled = [r for _, results in runs for r in results]
    print(f"\nThe workflow's rule, pooled over the {len(runs)} files ({len(pooled)} datasets)\n")
    print(reliability(pooled)[0])

if __name__ == "__main__":
    main()
