"""Evaluate the discrepancy workflow on randomized campaigns whose truth is known.

Each dataset is a simulated campaign of roller types 1-7 (3 repetitions × 11 load steps, 231 points; every
seating adds a load-independent factor): Tripp at a random evaluation depth (1-5 mm) with a hidden effect of
random parameters, log-normal point noise with σ drawn from 1-5 % at the preload and a third of that at the top
load, times the noise scale. An effect's size is the noise-free misfit left after the baseline (and any
background term) is refitted, in units of the point noise.

Suites (``--suite``, default ``acceptance`` = all but ``twin``):

- ``independent``: 7 scenarios (the five effects in functional forms unlike the library's, surface roughness
  plus a misalignment in such forms, and null data) × ``--seeds`` × noise scales ``--noise``, and a second tilt
  law the library does not share (``misalignment/bed``: a wedge on a bed that stiffens with load), scored apart;
- ``twin``: the library's own terms (parameter recovery);
- ``calibration``: a 10 % Young's modulus error, a load-cell gain of 1.08, a 15 N load-cell offset, each with
  and without surface roughness — must never be named as a physical effect;
- ``crowned``: crowned, end-relieved rollers on Ra 0.03 µm rails — end_effects or "unexplained" with an
  empirical term, never surface_roughness;
- ``robust``: one duplicated row with a wrong stiffness, 3 % gross outliers, stiffness given in N/mm — the
  finding reported and the verdict unchanged (or the input refused);
- ``blind`` / ``blind-calibrate``: the worlds of ``bench/blind/`` written blind to the workflow, on evaluation seeds
  (below ``CALIBRATION_SEEDS``) or on the calibration seeds; prints the acceptance numbers, a reliability table
  (stated probability vs share right, Wilson intervals) and, on calibration seeds, the temperature calibration.

    python bench/discrepancy_eval.py [--suite acceptance] [--seeds 20] [--noise 0.5,1,2]
                                     [--workers 2 | --scheduler ADDRESS] [--only TRUTHS] [--detail] [--out F]
                                     [--temperature T] [--rescore F]
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from discrepancy_blind import CALIBRATION_SEEDS, JUDGES, blind_worlds, csv_points, truth_name, visible_size
from discrepancy_features import features_by_truth, unlisted_leads
from discrepancy_scores import (
    calibrate,
    detail,
    reliability,
    reliability_by_kind,
    retemper,
    summarize_blind,
    summarize_calibration,
    summarize_crowned,
    summarize_effects,
    summarize_robust,
)
from discrepancy_worlds import (
    CALIBRATION,
    NONE,
    Stiffness,
    bad_input,
    crowned,
    draw_calibration,
    draw_effect,
    draw_independent,
    log_uniform,
)

from labctl.discrepancy import build_dataset, run_discrepancy
from labctl.discrepancy.model import ModelSpec, fit_model
from labctl.discrepancy.posterior import TEMPERATURES
from labctl.discrepancy.questions import TEMPERATURE
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.errors import InputError
from labctl.physics import EFFECTS, ContactLaw
from labctl.physics import SurfaceRoughness as Roughness


@dataclass(frozen=True)
class Task:
    suite: str
    truth: str
    seed: int
    noise_scale: float = 1.0
    background: bool = False
    variant: str = ""


def _named(result: Any) -> tuple[list[str], list[str]]:
    doc_steps = result.steps
    return [s.name for s in doc_steps if s.kind == "physical"], [s.name for s in doc_steps if s.kind == "measurement"]


def _outcome(result: Any) -> dict[str, Any]:
    doc = result.to_dict()
    physical, chain = _named(result)
    return {"named": physical, "measurement": chain, "verdict": doc["verdict"],
            "structured_stated": "NOT consistent" in doc["verdict_text"], "lack_of_fit_p": doc["lack_of_fit_p"],
            "empirical": doc["empirical_term"] is not None,
            "empirical_generalises": bool(doc["empirical_term"] and doc["empirical_term"]["generalises"]),
            "gap_before": doc["gap_before"], "gap_after": doc["gap_after"],
            "held_out": (doc["effects"] + doc["measurement_effects"] or [{}])[0].get("evidence", {}).get("held_out"),
            "closest": doc["closest_library_term"],
            "input_checks": {k: len(v) for k, v in doc["input_checks"].items()}, "verdict_text": doc["verdict_text"],
            "steps": [{"name": s.name, **{k: s.evidence.get(k) for k in _EVIDENCE}} for s in result.steps]}


_EVIDENCE = ("delta_bic", "explained_share", "explained_share_of_baseline", "held_out", "lack_of_fit_after",
             "named_with")


@dataclass(frozen=True)
class Campaign:
    """One task's simulated campaign: the noisy points, the truth's size and what scoring needs."""

    points: list[Any]
    size: float
    noise_low: float
    effect: Any
    rng: np.random.Generator


def campaign(task: Task) -> Campaign:
    """Generate one task's dataset and measure its effect size (the noise-free misfit the baseline leaves)."""
    rng = np.random.default_rng(task.seed)
    depth_m = log_uniform(rng, 1e-3, 5e-3)
    low = float(rng.uniform(0.01, 0.05)) * task.noise_scale
    noise = NoiseModel(low=low, high=low / 3.0)
    seating = 0.3 * low / 3.0
    background = (Roughness(asperity_scale=log_uniform(rng, 1.0, 2.0)),) if task.background else ()
    inner = ContactLaw("tripp", depth_m, background).stiffness_n_per_m
    rail_ra = 0.2e-6
    effect = None
    if task.suite == "twin":
        effect = draw_effect(task.truth, rng)
        truth: Stiffness = ContactLaw("tripp", depth_m, background + (() if effect is None else (effect,))
                                      ).stiffness_n_per_m
    elif task.suite == "calibration":
        truth = draw_calibration(task.truth, inner)
    elif task.suite == "crowned":
        rail_ra = 0.03e-6
        truth = crowned(rng, inner)
    else:
        truth = draw_independent(task.truth, rng, inner, task.variant)
    points = synthesize(truth, rail_ra_m=rail_ra, noise=noise, seed=task.seed + 1, seating_rel=seating)
    clean_data = build_dataset(synthesize(truth, rail_ra_m=rail_ra, noise=NoiseModel(1e-12, 1e-12, 0.0), seed=0))
    sigma = np.concatenate([noise.sigma(c.load_n, c.load_n.max()) for c in clean_data.cases])
    spec = ModelSpec(effects=tuple(e.name for e in background))
    size = fit_model(clean_data, spec, sigma=sigma).score
    return Campaign(points, size, low, effect, rng)


def run_task(task: Task) -> dict[str, Any]:
    """Generate one dataset, run the workflow, score the answer."""
    if task.suite == "blind":
        return run_blind(task)
    camp = campaign(task)
    points, effect, rng, size, low = camp.points, camp.effect, camp.rng, camp.size, camp.noise_low
    out: dict[str, Any] = {"suite": task.suite, "truth": task.truth, "seed": task.seed, "noise_scale": task.noise_scale,
                           "background": task.background, "variant": task.variant, "size": size, "noise_low": low}
    start = time.perf_counter()
    clean = run_discrepancy(points)
    out["seconds"] = time.perf_counter() - start
    out.update(_outcome(clean))
    if effect is not None and task.truth in out["named"]:
        fitted = clean.final.effect_parameters()[task.truth]
        out["param_rel_error"] = {k: fitted[k] / v - 1.0 for k, v in effect.parameters().items()}
    if task.suite == "robust":
        out["bad"] = _run_bad(bad_input(task.variant, points, rng))
        out["bad"]["verdict_unchanged"] = out["bad"].get("refused") or (
            out["bad"]["named"] == out["named"] and out["bad"]["measurement"] == out["measurement"])
    return out



def run_blind(task: Task) -> dict[str, Any]:
    """One blind dataset through the CSV contract and the workflow; the answer with every candidate's evidence."""
    world = blind_worlds(task.variant or "blind").generate(task.truth, task.seed, task.noise_scale)
    truth = world.truth
    points = csv_points(world.rows)
    start = time.process_time()
    try:
        result = run_discrepancy(points, temperatures=TEMPERATURES)  # every T stored: --rescore decides again
    except InputError as exc:
        return {"suite": "blind", "scenario": task.truth, "seed": task.seed, "noise_scale": task.noise_scale,
                "refused": str(exc), "truth_name": truth_name(truth)}
    cpu = time.process_time() - start
    physical, chain = _named(result)
    visible = visible_size(task.truth, task.seed, truth) if not task.variant else float(truth["size_sigma"])
    return {"suite": "blind", "judge": task.variant or "blind", "scenario": task.truth, "seed": task.seed,
            "noise_scale": task.noise_scale, "truth_name": truth_name(truth),
            "truth_effects": list(truth.get("effects", [])),
            "truth_measurement": list(truth.get("measurement_effects", [])),
            "outside_library": bool(truth.get("outside_library")), "size_sigma": float(truth.get("size_sigma", 0.0)),
            "size_sigma_by_effect": {k: float(v) for k, v in (truth.get("size_sigma_by_effect") or {}).items()},
            "visible_sigma": visible,
            "family": truth.get("family"), "faults": truth.get("faults"), "cpu_seconds": cpu,
            "named": physical, "measurement": chain, "verdict": result.verdict, "verdict_text": result.verdict_text(),
            "top": result.scored[0].explanation.name, "top_probability": result.scored[0].probability,
            "outliers": len(result.screening.outliers), "lack_of_fit_p": result.to_dict()["lack_of_fit_p"],
            "design_limits": [limit.to_dict() for limit in result.limits],
            "baseline_lof_p": result.baseline_lack_of_fit_p,
            "closest": None if result.closest is None else result.closest.name,
            "not_instrument": [c.explanation.name for c in result.scored if c.failed_instrument],
            "n_points": result.data.n_points,
            "candidates": [{"explanation": c.explanation.name, "log_prior": c.log_prior, "chi2": c.chi2,
                            "form_chi2": c.form_chi2, "n_params": c.n_params, "features": c.extra.get("features"),
                            "case_log_lik_by_temperature": c.to_dict()["case_log_lik_by_temperature"],
                            "log_evidence_by_temperature": {f"{t:g}": v for t, v in c.log_evidence_by_t.items()},
                            "log_fit_by_temperature": {f"{t:g}": v for t, v in c.log_fit_by_t.items()}}
                           for c in result.scored]}


def _run_bad(bad: list[Any]) -> dict[str, Any]:
    """The workflow on a campaign with bad input: its outcome, or the refusal."""
    try:
        result = run_discrepancy(bad)
    except InputError as exc:
        return {"refused": True, "message": str(exc)}
    return {**_outcome(result), "refused": False}

INDEPENDENT_SCENARIOS = (*EFFECTS, "roughness+misalignment", NONE)
"""The seven scenarios of the acceptance; ``"misalignment/bed"`` (a second tilt law, ``tilt_on_stiffening_bed``)
is run with them and scored apart."""
SECOND_LAWS = ("misalignment/bed",)


def tasks_for(suite: str, seeds: int, scales: list[float], seed: int) -> list[Task]:
    base = seed * 1_000_000
    out: list[Task] = []
    if suite in ("independent", "acceptance"):
        for k, scale in enumerate(scales):
            for i, name in enumerate((*INDEPENDENT_SCENARIOS, *SECOND_LAWS)):
                for j in range(seeds):
                    s = base + 10_000 * k + 100 * i + j
                    if name == "roughness+misalignment":
                        out.append(Task("independent", "misalignment", s, scale, background=True))
                    else:
                        truth, _, law = name.partition("/")
                        out.append(Task("independent", truth, s, scale, variant=law))
    if suite == "twin":
        for k, scale in enumerate(scales):
            for i, name in enumerate((*EFFECTS, NONE)):
                out += [Task("twin", name, base + 10_000 * k + 100 * i + j, scale) for j in range(seeds)]
    if suite in ("calibration", "acceptance"):
        for i, name in enumerate(CALIBRATION):
            for bg in (False, True):
                out += [Task("calibration", name, base + 200_000 + 1000 * i + 100 * bg + j, 1.0, background=bg)
                        for j in range(max(1, seeds // 2))]
    if suite in ("crowned", "acceptance"):
        out += [Task("crowned", NONE, base + 300_000 + j, 1.0) for j in range(seeds)]
    if suite in ("blind", "blind-calibrate"):
        first = CALIBRATION_SEEDS if suite == "blind-calibrate" else seed * 1000
        if suite == "blind" and first + seeds > CALIBRATION_SEEDS:
            raise SystemExit("--seed/--seeds reach into the calibration seeds: evaluate below "
                             f"{CALIBRATION_SEEDS}")
        for scenario in blind_worlds().SCENARIOS:
            out += [Task("blind", scenario, first + j, scale) for scale in scales for j in range(seeds)]
    if suite in ("blind2", "blind3"):  # the held-out judges: evaluation seeds only, never used to calibrate
        if seed * 1000 + seeds > CALIBRATION_SEEDS:
            raise SystemExit(f"--seed/--seeds reach beyond the evaluation seeds 0-{CALIBRATION_SEEDS - 1}")
        for scenario in blind_worlds(suite).SCENARIOS:
            out += [Task("blind", scenario, seed * 1000 + j, scale, variant=suite) for scale in scales
                    for j in range(seeds)]
    if suite in ("robust", "acceptance"):
        for i, variant in enumerate(("duplicate", "outliers", "units")):
            for j in range(max(1, seeds // 2)):
                truth = "setup_compliance" if j % 2 else NONE
                out.append(Task("robust", truth, base + 400_000 + 1000 * i + j, 1.0, variant=variant))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--suite", default="acceptance",
                        choices=("acceptance", "independent", "twin", "calibration", "crowned", "robust", "blind",
                                 "blind-calibrate", "blind2", "blind3"))
    parser.add_argument("--seeds", type=int, default=20, help="datasets per scenario and noise scale (default 20)")
    parser.add_argument("--noise", default="0.5,1,2", help="noise scales (default 0.5,1,2)")
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run the datasets on this Dask scheduler (tcp://host:8786) instead of local processes")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--only", help="comma-separated hidden truths to run (e.g. setup_compliance,misalignment/bed)")
    parser.add_argument("--detail", action="store_true", help="list every dataset that misses an acceptance item")
    parser.add_argument("--out", help="write every dataset's result as JSON here")
    parser.add_argument("--temperature", type=float, default=TEMPERATURE,
                        help=f"decide the blind datasets at this temperature (default the workflow's, {TEMPERATURE:g})")
    parser.add_argument("--rescore", metavar="FILE", help="score the results saved with --out instead of running")
    args = parser.parse_args()
    scales = [float(v) for v in args.noise.split(",")]
    tasks = tasks_for(args.suite, args.seeds, scales, args.seed)
    if args.only:
        only = args.only.split(",")
        tasks = [t for t in tasks if t.truth in only or f"{t.truth}/{t.variant}" in only]
    start = time.perf_counter()
    if args.rescore:
        with open(args.rescore, encoding="utf-8") as fh:
            results = json.load(fh)
        tasks = []
    elif args.scheduler:
        import cloudpickle
        import discrepancy_scores
        import discrepancy_worlds

        from labctl.archive.runner import dask_map

        for module in (discrepancy_worlds, discrepancy_scores):  # the workers need not have bench/ on their path
            cloudpickle.register_pickle_by_value(module)
        results = dask_map(run_task, tasks, scheduler=args.scheduler)
    else:
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            results = list(pool.map(run_task, tasks, chunksize=2))
    results = [retemper(r, args.temperature) if r["suite"] == "blind" and "refused" not in r else r for r in results]
    parts = []
    for suite, law, title in (
            ("independent", "", "Hidden effects in functional forms unlike the library's (the 7 scenarios)"),
            ("independent", "bed", "Misalignment in a second law: a wedge on a bed that stiffens with load "
                                   "(tilt_on_stiffening_bed)"),
            ("twin", "", "Hidden effects in the library's own forms")):
        rs = [r for r in results if r["suite"] == suite and r["variant"] == law]
        if rs:
            parts.append(summarize_effects(rs, title))
    if any(r["suite"] == "calibration" for r in results):
        parts.append(summarize_calibration([r for r in results if r["suite"] == "calibration"]))
    if any(r["suite"] == "crowned" for r in results):
        parts.append(summarize_crowned([r for r in results if r["suite"] == "crowned"]))
    if any(r["suite"] == "robust" for r in results):
        parts.append(summarize_robust([r for r in results if r["suite"] == "robust"]))
    blind = [r for r in results if r["suite"] == "blind" and "refused" not in r]
    if blind:
        calibrating = min(r["seed"] for r in blind) >= CALIBRATION_SEEDS
        judge = JUDGES[blind[0].get("judge") or "blind"][2]
        parts.append(f"Blind worlds ({judge}; {'calibration' if calibrating else 'evaluation'} seeds "
                     f"{min(r['seed'] for r in blind)}-{max(r['seed'] for r in blind)}; {len(blind)} datasets; "
                     f"temperature {args.temperature:g})\n\n" + summarize_blind(blind))
        table, holds = reliability(blind)
        parts.append("Reliability of the top explanation's stated probability\n\n" + table +
                     f"\n\nevery bin with ≥ 30 cases within 0.05: {'yes' if holds else 'NO'}")
        parts.append("The same, by the kind of top explanation\n\n" + reliability_by_kind(blind))
        parts.append("What the unlisted stand-in's features carry, by the truth (a library term's quantity or not)\n\n"
                     + features_by_truth(blind) + "\n\n" + unlisted_leads(blind) + "\n" + unlisted_leads(blind, 0.9))
        if calibrating:
            table, best, cautious = calibrate(blind, TEMPERATURES)
            parts.append("Temperature calibration\n\n" + table + f"\n\nlowest log loss at T = {best:g}; the largest T "
                         f"within one standard error of it: {cautious:g}")
    refused = [r for r in results if "refused" in r]
    if refused:
        parts.append("Refused blind datasets: " + "; ".join(f"{r['scenario']} seed {r['seed']}: {r['refused']}"
                                                           for r in refused))
    if args.detail:
        parts.append(detail([r for r in results if r["suite"] != "blind"]))
    print("\n\n".join(parts))
    seconds = [r.get("seconds", r.get("cpu_seconds", 0.0)) for r in results] or [0.0]
    where = args.scheduler or f"{args.workers} workers"
    print(f"\n{len(results)} datasets in {time.perf_counter() - start:.0f} s with {where}; "
          f"workflow time per 231-point dataset: mean {np.mean(seconds):.2f} s, max {np.max(seconds):.2f} s")
    if args.out and not args.rescore:
        with open(args.out, "w", encoding="utf-8") as fh:
            json.dump(results, fh, indent=1, default=str)


if __name__ == "__main__":
    main()
