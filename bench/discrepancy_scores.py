"""Scores of the discrepancy evaluation (``bench/discrepancy_eval.py``): top-1, wrong extra names, false
positives, honest verdicts and gap shrink per suite, as Markdown tables; per-dataset detail on request."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np
from discrepancy_worlds import CALIBRATION
from intervals import RELIABILITY_BINS, wilson

from labctl.discrepancy.design import DesignLimit, decide
from labctl.discrepancy.noise import lack_of_fit_rejects
from labctl.discrepancy.posterior import Explanation, rejected_explanations
from labctl.discrepancy.questions import probabilities
from labctl.physics import EFFECTS


def _table(rows: list[list[str]], header: list[str]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _truth_set(r: dict[str, Any]) -> set[str]:
    truth = {"surface_roughness"} if r["background"] else set()
    if r["truth"] == "roughness+misalignment":
        return truth | {"surface_roughness", "misalignment"}
    return truth | ({r["truth"]} if r["truth"] in EFFECTS else set())


def _frac(num: int, den: int) -> str:
    return f"{num / den:.3f} ({num}/{den})" if den else "-"


def summarize_effects(results: list[dict[str, Any]], title: str) -> str:
    """Top-1, wrong extra names, false positives, honest verdicts and gap shrink per noise scale."""
    rows = []
    for scale in sorted({r["noise_scale"] for r in results}):
        rs = [r for r in results if r["noise_scale"] == scale]
        big = [r for r in rs if _truth_set(r) and r["size"] >= 3.0]
        top1 = sum(bool(r["named"]) and r["named"][0] in _truth_set(r) for r in big)
        wrong = sum(any(n not in _truth_set(r) for n in r["named"]) for r in rs if _truth_set(r))
        n_eff = sum(bool(_truth_set(r)) for r in rs)
        nulls = [r for r in rs if not _truth_set(r)]
        fp = sum(bool(r["named"] or r["measurement"]) for r in nulls)
        structured = [r for r in rs if lack_of_fit_rejects(r["lack_of_fit_p"])]
        stated = sum(r["structured_stated"] for r in structured)
        unexplained = sum(r["verdict"] == "unexplained" for r in big)
        shrink = [r["gap_after"] / r["gap_before"] for r in big if r["named"]]
        held = [r["held_out"] for r in big if r["held_out"]]
        seconds = [r["seconds"] for r in rs]
        rows.append([f"{scale:g}×", _frac(top1, len(big)), _frac(wrong, n_eff), _frac(fp, len(nulls)),
                     _frac(stated, len(structured)), _frac(unexplained, len(big)),
                     f"{np.median(shrink):.2f}" if shrink else "-",
                     f"{np.median([h['gap_with'] / h['gap_without'] for h in held]):.2f}" if held else "-",
                     f"{np.mean(seconds):.2f} / {np.max(seconds):.2f} s"])
    header = ["noise", "top-1 (size ≥ 3σ)", "wrong extra names", "FPR (null)", "structured residual stated",
              "honest 'unexplained' (size ≥ 3σ)", "gap after/before", "held-out gap ratio", "time mean / max"]
    confusion = []
    labels = [*EFFECTS, "none"]
    for truth in sorted({r["truth"] for r in results}):
        rs = [r for r in results if r["truth"] == truth and (r["size"] >= 3.0 or not _truth_set(r))]
        confusion.append([truth, str(len(rs))] + [str(sum((r["named"] or ["none"])[0] == lab for r in rs))
                                                  for lab in labels])
    return (f"{title}\n\n" + _table(rows, header) + "\n\nFirst named physical effect (size ≥ 3σ, all nulls; all "
            "noise scales)\n\n" + _table(confusion, ["hidden", "n", *labels]))


def summarize_calibration(results: list[dict[str, Any]]) -> str:
    rows = []
    for truth in CALIBRATION:
        for bg in (False, True):
            rs = [r for r in results if r["truth"] == truth and r["background"] == bg]
            wrong = sum(any(n not in _truth_set(r) for n in r["named"]) for r in rs)
            chain = sum(bool(r["measurement"]) for r in rs)
            right = sum(truth in r["measurement"] for r in rs)
            cons = [r for r in rs if not r["measurement"] and r["verdict"] in ("consistent", "explained")]
            below = sum(r["size"] < 2.0 for r in cons)
            warned = sum(r["verdict"] in ("partly_explained", "unexplained") and not r["measurement"] for r in rs)
            rows.append([truth + (" + roughness" if bg else ""), str(len(rs)), str(wrong), str(chain), str(right),
                         f"{len(cons)} ({below} below 2σ)", str(warned),
                         f"{np.median([r['size'] for r in rs]):.1f}"])
    return ("Calibration errors (never a physical effect)\n\n"
            + _table(rows, ["error", "n", "wrong physical name", "measurement-side named", "the right one",
                            "consistent (size < 2σ)", "structured, unnamed", "median size [σ]"]))


def summarize_crowned(results: list[dict[str, Any]]) -> str:
    n = len(results)
    rough = sum("surface_roughness" in r["named"] for r in results)
    end = sum(r["named"][:1] == ["end_effects"] for r in results)
    unexplained = sum(r["verdict"] in ("unexplained", "partly_explained") and r["empirical"] for r in results)
    gen = sum(r["empirical_generalises"] for r in results)
    other = [r["named"] for r in results if r["named"] and r["named"][0] != "end_effects"]
    return ("Crowned rollers on Ra 0.03 µm rails\n\n" + _table([[
        str(n), str(rough), str(end), str(unexplained), str(gen),
        str(sum(r["verdict"] == "consistent" for r in results)),
        ", ".join(sorted({"+".join(o) for o in other})) or "-",
        f"{np.median([r['size'] for r in results]):.1f}"]],
        ["n", "surface_roughness named", "end_effects", "unexplained + empirical term", "empirical term generalises",
         "consistent", "other names", "median size [σ]"]))


def summarize_robust(results: list[dict[str, Any]]) -> str:
    rows = []
    for variant in ("duplicate", "outliers", "units"):
        rs = [r for r in results if r["variant"] == variant]
        if not rs:
            continue
        reported = sum(r["bad"].get("refused") or any(r["bad"]["input_checks"].values()) for r in rs)
        refused = sum(bool(r["bad"].get("refused")) for r in rs)
        same = sum(bool(r["bad"]["verdict_unchanged"]) for r in rs)
        rows.append([variant, str(len(rs)), str(reported), str(refused), str(same)])
    return ("Bad input (verdict compared with the same campaign without it)\n\n"
            + _table(rows, ["bad input", "n", "reported or refused", "refused", "verdict unchanged or refused"]))


def misses(r: dict[str, Any]) -> list[str]:
    """What a dataset's answer gets wrong against the acceptance targets ([] when nothing)."""
    truth = _truth_set(r)
    out = []
    if r["suite"] in ("independent", "twin"):
        if truth and r["size"] >= 3.0 and not (r["named"] and r["named"][0] in truth):
            out.append("top-1 miss")
        if truth and any(n not in truth for n in r["named"]):
            out.append("wrong extra name")
        if not truth and (r["named"] or r["measurement"]):
            out.append("false positive")
    elif r["suite"] == "calibration" and any(n not in truth for n in r["named"]):
        out.append("physical name for a calibration error")
    elif r["suite"] == "crowned" and "surface_roughness" in r["named"]:
        out.append("crowned named surface_roughness")
    elif r["suite"] == "robust" and not r["bad"]["verdict_unchanged"]:
        out.append(f"{r['variant']} changed the verdict to {r['bad']['named']} + {r['bad']['measurement']}")
    if lack_of_fit_rejects(r.get("lack_of_fit_p")) and not r["structured_stated"]:
        out.append("structured residual not stated")
    return out


def detail(results: list[dict[str, Any]]) -> str:
    """One line per dataset whose answer misses an acceptance item: which, and what the workflow said."""
    lines = []
    for r in sorted(results, key=lambda r: (r["suite"], r["truth"], r["noise_scale"], r["seed"])):
        found = misses(r)
        if not found:
            continue
        bg = "+roughness" if r["background"] else ""
        lines.append(f"- {r['suite']} {r['truth']}{bg} {r['variant']} seed {r['seed']} noise {r['noise_scale']:g}× "
                     f"size {r['size']:.1f}σ: {'; '.join(found)}; named {r['named']} {r['measurement']}, "
                     f"lack-of-fit p {r['lack_of_fit_p']}, {r['verdict']}")
    return "Datasets that miss an acceptance item\n\n" + ("\n".join(lines) or "none")


# --- blind worlds: acceptance numbers and the reliability of the stated probabilities -------------------------

CALIBRATED_DRAWS = 4000
"""Draws of a calibrated forecaster's outcomes behind the reliability table's chance column."""


def n_cases(r: dict[str, Any]) -> int:
    """The roller cases of a stored result (0 if it stored no per-case parts)."""
    parts = r["candidates"][0].get("case_log_lik_by_temperature") or {}
    return len(next(iter(parts.values()), []))


def case_log_lik(r: dict[str, Any]) -> Callable[[float], np.ndarray] | None:
    """Each candidate's stored per-case log likelihood at T (None if the result stored none)."""
    if not n_cases(r):
        return None
    return lambda t: np.array([c["case_log_lik_by_temperature"][f"{t:g}"] for c in r["candidates"]])


def tempered(r: dict[str, Any], temperature: float, log_prior: np.ndarray | None = None,
             log_evidence: Callable[[float], np.ndarray] | None = None, scale: float = 1.0,
             resample: bool = True, concentration: float = 1.0) -> list[tuple[str, float]]:
    """Every candidate's probability at another noise inflation T (from the evidence stored at each T of the
    workflow's grid), most probable first, resampled over roller cases as the workflow does; without the
    explanations the workflow rules out (``rejected_explanations``). A bench's other rule may give its own priors,
    evidence, confidence scale, resampling concentration, or decide on the pooled evidence (``resample`` false)."""
    cands, ruled_out = r["candidates"], rejected_explanations(r.get("baseline_lof_p"), r.get("not_instrument", ()))
    names = [c["explanation"] for c in cands]
    p = probabilities(names, np.array([c["log_prior"] for c in cands]) if log_prior is None else log_prior,
                      log_evidence or (lambda t: np.array([c["log_evidence_by_temperature"][f"{t:g}"] for c in cands])),
                      temperature, ruled_out, scale=scale, case_log_lik=case_log_lik(r) if resample else None,
                      concentration=concentration)
    return sorted(((n, float(v)) for n, v in zip(names, p, strict=True) if n not in ruled_out), key=lambda t: -t[1])


def decided(r: dict[str, Any], top: str, probability: float) -> tuple[str, list[str]]:
    """What the workflow's rule (``labctl.discrepancy.design.decide``) does with a stored result's most probable
    explanation at this probability: named, likely or none, and the terms named; under the design limits the run
    stored (a file without them: none)."""
    terms = () if top in ("none", "unlisted") else tuple(top.split(" + "))
    limits = [DesignLimit.from_dict(d) for d in r.get("design_limits", ())]
    action = decide(Explanation(terms), probability, limits)
    return action, list(terms) if action == "named" else []


def retemper(r: dict[str, Any], temperature: float) -> dict[str, Any]:
    """A blind result decided again at another temperature from its stored evidence — the workflow's own rule:
    name the top explanation at ≥ 0.9 (unless the design holds its pair back), 'likely' at 0.5-0.9, else
    consistent (baseline passes the lack-of-fit test and nothing is likely) or unexplained."""
    probs = tempered(r, temperature)
    top, p = probs[0]
    action, named = decided(r, top, p)
    if action in ("named", "likely"):
        verdict = action
    else:
        verdict = "consistent" if (r.get("baseline_lof_p") or 0.0) >= 0.01 else "unexplained"
    return {**r, "top": top, "top_probability": p, "verdict": verdict,
            "named": [n for n in named if n in EFFECTS], "measurement": [n for n in named if n not in EFFECTS]}


def binned(stated: list[tuple[float, bool]]) -> list[tuple[float, float, np.ndarray]]:
    """Each reliability bin (``intervals.RELIABILITY_BINS``) with the mask of the stated (probability, right) pairs
    inside it."""
    p = np.array([x for x, _ in stated])
    return [(lo, hi, (p >= lo) & (p < hi)) for lo, hi in RELIABILITY_BINS]


def holds_within(mean_stated: float, share_right: float, n: int) -> bool:
    """The reliability criterion for one bin: within 0.05, or fewer than 30 cases."""
    return abs(mean_stated - share_right) <= 0.05 or n < 30


def reliability(results: list[dict[str, Any]], temperature: float | None = None) -> tuple[str, bool]:
    """Stated probability of the top explanation against the share of datasets where it is the truth, per bin;
    the second value: every bin with ≥ 30 cases within 0.05. Beside each bin, how often a forecaster whose stated
    probabilities are exactly right would be at least this far off (each dataset right with its stated probability;
    ``CALIBRATED_DRAWS`` draws), and below the table how often it would pass the criterion on these datasets: with a
    few dozen cases in a bin, "within 0.05" can fail by chance alone."""
    rows, ok = [], True
    stated, seen = [], []
    for r in results:
        top = tempered(r, temperature)[0] if temperature else (r["top"], r["top_probability"])
        stated.append((top[1], top[0] == r["truth_name"]))
        seen.append(top[0] in (r["truth_name"], seen_truth(r)))
    p_all, right, seen_right = np.array([p for p, _ in stated]), np.array([k for _, k in stated]), np.array(seen)
    right_draws = np.random.default_rng(0).random((CALIBRATED_DRAWS, p_all.size)) < p_all  # a calibrated forecaster
    passes = np.ones(CALIBRATED_DRAWS, dtype=bool)
    for lo, hi, inside in binned(stated):
        if not inside.any():
            rows.append([f"{lo:.3g}-{min(hi, 1):.3g}", "0", "-", "-", "-", "-", "", "-"])
            continue
        n, k = int(inside.sum()), int(right[inside].sum())
        mean_p = float(p_all[inside].mean())
        _, a, b = wilson(k, n)
        holds = abs(mean_p - k / n) <= 0.05
        ok = ok and holds_within(mean_p, k / n, n)
        drawn_gap = np.abs(right_draws[:, inside].mean(axis=1) - mean_p)
        if n >= 30:
            passes &= drawn_gap <= 0.05
        chance = float(np.mean(drawn_gap >= abs(mean_p - k / n) - 1e-12))
        k_seen = int(seen_right[inside].sum())
        rows.append([f"{lo:.3g}-{min(hi, 1):.3g}", str(n), f"{mean_p:.3f}", f"{k / n:.3f} ({k}/{n})",
                     f"{a:.3f}-{b:.3f}", f"{k_seen / n:.3f} ({k_seen}/{n})",
                     ("within 0.05" if holds else "OFF by > 0.05") if n >= 30 else "n < 30", f"{chance:.3f}"])
    header = ["stated probability", "n", "mean stated", "share right", "Wilson 95 %",
              "right, its terms ≥ 3σ", "≥ 30 cases: stated vs right", "calibrated: chance of a gap this large"]
    footer = (f"a forecaster whose stated probabilities are exactly right would pass (every bin with ≥ 30 cases "
              f"within 0.05) on these {len(stated)} datasets with probability {np.mean(passes):.2f}")
    return _table(rows, header) + "\n\n" + footer, ok


def reliability_by_kind(results: list[dict[str, Any]]) -> str:
    """The reliability table split by what the top explanation is: "none" (no effect), a library or
    measurement-side explanation, or "unlisted" (outside the library); each row also counts its wrong cases whose
    effect is under 3σ (too small for the acceptance's top-1 to count it), or has a term under 3σ (a pair or a
    calibration error whose second term is that small: the data can show one term at most)."""
    rows = []
    kinds = (("none", lambda r: r["top"] == "none"), ("named", lambda r: r["top"] not in ("none", "unlisted")),
             ("unlisted", lambda r: r["top"] == "unlisted"))
    for kind, is_kind in kinds:
        mine = [r for r in results if is_kind(r)]
        for lo, hi in RELIABILITY_BINS:
            inside = [r for r in mine if lo <= r["top_probability"] < hi]
            if not inside:
                continue
            k = sum(r["top"] == r["truth_name"] for r in inside)
            small = sum(r["top"] != r["truth_name"] and _small(r) for r in inside)
            rows.append([kind, f"{lo:.3g}-{min(hi, 1):.3g}", str(len(inside)),
                         f"{np.mean([r['top_probability'] for r in inside]):.3f}",
                         _frac(k, len(inside)), str(small)])
    return _table(rows, ["top explanation", "stated probability", "n", "mean stated", "share right",
                         "wrong, the effect or a term of it under 3σ"])


def _small(r: dict[str, Any]) -> bool:
    """The world's effect, or one of its terms (``size_sigma_by_effect``, where the run stored it), is under 3σ."""
    if r["truth_name"] == "none":
        return False
    return r["size_sigma"] < 3.0 or min((r.get("size_sigma_by_effect") or {}).values(), default=3.0) < 3.0


def seen_truth(r: dict[str, Any]) -> str:
    """The truth's terms of size ≥ 3σ (``size_sigma_by_effect``): the one term of a pair that reaches 3σ alone,
    else the whole truth (``truth_name``). The acceptance asks the top-1 "for effects ≥ 3σ": a
    term under it (a roughness of 1σ beside a tilt of 80σ) is one no method need name."""
    by = r.get("size_sigma_by_effect") or {}
    terms = [*r["truth_effects"], *r["truth_measurement"]]
    seen = [t for t in terms if by.get(t, 0.0) >= 3.0]
    one_of_two = len(seen) == 1 and len(terms) == 2 and not r["outside_library"]
    return seen[0] if one_of_two else r["truth_name"]


def calibrate(results: list[dict[str, Any]], grid: tuple[float, ...]) -> tuple[str, float, float]:
    """Each T's score; the temperature minimising the mean log loss of the true explanation's probability; and the
    largest T whose log loss is within one standard error of that lowest (of the per-dataset difference: the
    one-standard-error rule, the most cautious inflation these datasets cannot tell from the best)."""
    losses, rows = {}, []
    for t in grid:
        loss, brier = [], 0.0
        for r in results:
            probs = dict(tempered(r, t))
            loss.append(-math.log(max(probs.get(r["truth_name"], 0.0), 1e-12)))
            brier += sum((p - (name == r["truth_name"])) ** 2 for name, p in probs.items())
        losses[t] = np.array(loss)
        _, ok = reliability(results, t)
        rows.append([f"{t:g}", f"{np.mean(loss):.3f}", f"{brier / len(results):.3f}", "yes" if ok else "no"])
    best = min(grid, key=lambda t: float(losses[t].mean()))
    within = []
    for row, t in zip(rows, grid, strict=True):
        d = losses[t] - losses[best]
        se = float(d.std(ddof=1) / math.sqrt(d.size)) if d.size > 1 else 0.0
        row.insert(2, f"{d.mean():+.3f} ± {se:.3f}")
        if d.mean() <= se:
            within.append(t)
    return (_table(rows, ["temperature", "log loss (truth)", "− lowest (± s.e.)", "Brier", "reliability holds"]),
            best, max(within))


def summarize_blind(results: list[dict[str, Any]]) -> str:
    """Acceptance numbers on the blind worlds, per noise scale, and what each scenario was answered."""
    rows = []
    for scale in sorted({r["noise_scale"] for r in results}):
        rs = [r for r in results if r["noise_scale"] == scale]
        lib = [r for r in rs if r["truth_effects"] or r["truth_measurement"]]
        lib = [r for r in lib if not r["outside_library"]]
        big = [r for r in lib if r["truth_effects"] and r["size_sigma"] >= 3.0]
        top1 = sum(bool(r["named"]) and r["named"][0] in r["truth_effects"] for r in big)
        ranked = [r for r in lib if r["size_sigma"] >= 3.0]
        vis = [r for r in lib if r["truth_effects"] and r.get("visible_sigma", 0.0) >= 3.0]
        top1_vis = sum(bool(r["named"]) and r["named"][0] in r["truth_effects"] for r in vis)
        likely = sum(bool(r["named"]) and r["named"][0] in r["truth_effects"] or
                     r["verdict"] == "likely" and r["top"].split(" + ")[0] in r["truth_effects"] for r in vis)
        wrong = sum(any(n not in r["truth_effects"] for n in r["named"]) or
                    any(m not in r["truth_measurement"] for m in r["measurement"]) for r in lib)
        nulls = [r for r in rs if r["truth_name"] == "none"]
        fp = sum(bool(r["named"] or r["measurement"]) for r in nulls)
        outside = [r for r in rs if r["outside_library"]]
        out_named = sum(bool(r["named"] or r["measurement"]) for r in outside)
        seconds = [r["cpu_seconds"] for r in rs]
        rows.append([f"{scale:g}×", _frac(top1, len(big)),
                     _frac(sum(r["top"] == r["truth_name"] for r in ranked), len(ranked)),
                     _frac(sum(r["top"] in (r["truth_name"], seen_truth(r)) for r in ranked), len(ranked)),
                     _frac(top1_vis, len(vis)), _frac(likely, len(vis)),
                     _frac(wrong, len(lib)), _frac(fp, len(nulls)),
                     _frac(out_named, len(outside)), _frac(sum(r["top"] == r["truth_name"] for r in rs), len(rs)),
                     f"{np.mean(seconds):.2f} / {np.max(seconds):.2f} s"])
    header = ["noise", "top-1 named (size ≥ 3σ)", "top = truth (size ≥ 3σ)", "top = its terms ≥ 3σ",
              "top-1 named (visible ≥ 3σ)", "named or likely (visible ≥ 3σ)",
              "wrong names (phys. or meas.)", "any name on null",
              "outside library named", "top explanation = truth (all)", "CPU mean / max"]
    out = [_table(rows, header)]
    scen = []
    for s in sorted({r["scenario"] for r in results}):
        rs = [r for r in results if r["scenario"] == s]
        verdicts = {v: sum(r["verdict"] == v for r in rs) for v in ("consistent", "named", "likely", "unexplained")}
        named = {}
        for r in rs:
            key = " + ".join(r["named"] + r["measurement"]) or "-"
            named[key] = named.get(key, 0) + 1
        common = ", ".join(f"{k} {v}" for k, v in sorted(named.items(), key=lambda t: -t[1])[:3])
        tops = Counter(r["top"] for r in rs if r["size_sigma"] >= 3.0 or r["truth_name"] == "none")
        top_common = ", ".join(f"{k} {v}" for k, v in tops.most_common(3)) or "-"
        scen.append([s, str(len(rs)), rs[0]["truth_name"] if len({r["truth_name"] for r in rs}) == 1 else "mixed",
                     " / ".join(str(verdicts[v]) for v in verdicts), common, top_common,
                     f"{np.median([r['size_sigma'] for r in rs]):.1f} / "
                     f"{np.median([r.get('visible_sigma', np.nan) for r in rs]):.1f}"])
    out.append(_table(scen, ["scenario", "n", "truth", "consistent / named / likely / unexplained",
                             "named (most common)", "most probable, size ≥ 3σ (most common)",
                             "median size / visible [σ]"]))
    return "\n\n".join(out)
