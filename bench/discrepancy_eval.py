"""Evaluate the discrepancy workflow on randomized campaigns whose truth is known.

Each dataset is a simulated campaign of roller types 1-7 (3 repetitions × 11 load steps, 231 points; every
seating adds a load-independent factor): Tripp at a random evaluation depth (1-5 mm) with a hidden effect of
random parameters, log-normal point noise with σ drawn from 1-5 % at the preload and a third of that at the top
load, times the noise scale. An effect's size is the noise-free misfit left after the baseline (and any
background term) is refitted, in units of the point noise.

Suites (``--suite``, default ``acceptance`` = all but ``twin``):

- ``independent``: 7 scenarios (the five effects in functional forms unlike the library's, surface roughness
  plus a misalignment in such forms, and null data) × ``--seeds`` × noise scales ``--noise``;
- ``twin``: the library's own terms (parameter recovery);
- ``calibration``: a 10 % Young's modulus error, a load-cell gain of 1.08, a 15 N load-cell offset, each with
  and without surface roughness — must never be named as a physical effect;
- ``crowned``: crowned, end-relieved rollers on Ra 0.03 µm rails — end_effects or "unexplained" with an
  empirical term, never surface_roughness;
- ``robust``: one duplicated row with a wrong stiffness, 3 % gross outliers, stiffness given in N/mm — the
  finding reported and the verdict unchanged (or the input refused).

    python bench/discrepancy_eval.py [--suite acceptance] [--seeds 20] [--noise 0.5,1,2]
                                     [--workers 2 | --scheduler ADDRESS] [--out F]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from labctl.discrepancy import build_dataset, run_discrepancy
from labctl.discrepancy.model import ModelSpec, fit_model
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.errors import InputError
from labctl.physics import (
    EFFECTS,
    ContactCase,
    ContactLaw,
    EndEffects,
    MaterialHardness,
    Misalignment,
    SetupCompliance,
)
from labctl.physics import SurfaceRoughness as Roughness
from labctl.physics.materials import hardness_pa

NONE = "none"
LABELS = (*EFFECTS, NONE)


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_effect(name: str, rng: np.random.Generator) -> Any:
    """One library effect with parameters drawn over a plausible range (None for null data)."""
    if name == "surface_roughness":
        return Roughness(asperity_scale=_log_uniform(rng, 0.2, 3.0))
    if name == "end_effects":
        return EndEffects(edge_length_m=_log_uniform(rng, 0.02e-3, 0.4e-3))
    if name == "material_hardness":
        return MaterialHardness(gain=_log_uniform(rng, 0.1, 1.5), threshold=float(rng.uniform(0.15, 0.45)))
    if name == "misalignment":
        return Misalignment(tilt_rad=_log_uniform(rng, 3e-5, 1.5e-3))
    if name == "setup_compliance":
        return SetupCompliance(stiffness_factor=_log_uniform(rng, 0.5, 2.0))
    return None


Stiffness = Callable[[ContactCase, np.ndarray], np.ndarray]


def draw_independent(name: str, rng: np.random.Generator, inner: Stiffness) -> Stiffness:
    """The same physical effect in another functional form than the library's term, applied to ``inner``."""
    if name == "surface_roughness":  # asperity layer with stiffness per length ∝ (F/L)^m, m < 1
        kappa, m = _log_uniform(rng, 1e10, 1e11), float(rng.uniform(0.55, 0.85))

        def rough(case: ContactCase, f: np.ndarray) -> np.ndarray:
            length = case.roller.contact_length_m
            k_asp = kappa * length * (f / length / 1e4) ** m * (0.2e-6 / case.combined_ra_m)
            return 1.0 / (1.0 / inner(case, f) + 2.0 / k_asp)
        return rough
    if name == "end_effects":  # a constant spring at each roller end, in parallel
        k_edge = _log_uniform(rng, 0.5e6, 6e6)
        return lambda case, f: inner(case, f) + 2.0 * k_edge
    if name == "material_hardness":  # stiffness gain ∝ (p_max/H)², no threshold
        gain = _log_uniform(rng, 0.5, 4.0)

        def hard(case: ContactCase, f: np.ndarray) -> np.ndarray:
            h = hardness_pa(min(case.roller.material.hardness_hrc, case.rail.hardness_hrc))
            return inner(case, f) * (1.0 + gain * (case.peak_pressure_pa(f) / h) ** 2)
        return hard
    if name == "misalignment":  # contact length grows smoothly: L_c/L = (1 + x^-n)^(-1/n)
        tilt, n = _log_uniform(rng, 5e-5, 1.5e-3), float(rng.choice([2.0, 4.0]))

        def tilted(case: ContactCase, f: np.ndarray) -> np.ndarray:
            k, length = inner(case, f), case.roller.contact_length_m
            x = np.sqrt(2.0 * f / (k / length * tilt)) / length
            return k * (1.0 + x**-n) ** (-1.0 / n)
        return tilted
    if name == "setup_compliance":  # an extra joint spring in series, stiffening with load
        k_joint, beta = _log_uniform(rng, 2e8, 2e9), float(rng.uniform(0.0, 0.2))
        return lambda case, f: 1.0 / (1.0 / inner(case, f) + 1.0 / (k_joint * (f / 100.0) ** beta))
    return inner


CALIBRATION = {"modulus_scale": 0.9, "load_gain": 1.08, "load_offset": 15.0}
"""Calibration errors: true moduli 0.9 × the catalogue's; recorded load 1.08 × the true one; recorded load the
true one + 15 N."""


def draw_calibration(name: str, inner: Stiffness) -> Stiffness:
    """The measured stiffness when the recorded load or the model's modulus is wrong (written here, not with
    the workflow's measurement terms)."""
    value = CALIBRATION[name]
    if name == "modulus_scale":
        def soft(case: ContactCase, f: np.ndarray) -> np.ndarray:
            r = case.roller
            mat = dataclasses.replace(r.material, youngs_modulus_pa=r.material.youngs_modulus_pa * value)
            rail = dataclasses.replace(case.rail, youngs_modulus_pa=case.rail.youngs_modulus_pa * value)
            return inner(dataclasses.replace(case, roller=dataclasses.replace(r, material=mat), rail=rail), f)
        return soft
    if name == "load_gain":
        return lambda case, f: inner(case, f / value)
    return lambda case, f: inner(case, f - value)


def crowned(rng: np.random.Generator, inner: Stiffness) -> Stiffness:
    """A crowned roller: a flat middle and parabolic end reliefs (relief fraction q of L_we per end, drop δc at
    the end) on an elastic bed of the line contact's stiffness per length; contact length grows with load."""
    q, drop = float(rng.uniform(0.1, 0.25)), _log_uniform(rng, 2e-6, 8e-6)

    def k(case: ContactCase, f: np.ndarray) -> np.ndarray:
        length = case.roller.contact_length_m
        per_length = inner(case, f) / length
        flat, relief = length * (1 - 2 * q), length * q
        need = f / per_length  # ∫ max(0, δ − gap(x)) dx
        out = np.empty_like(f)
        for i, n in enumerate(need):
            def area(d: float) -> float:
                u = relief * math.sqrt(min(d / drop, 1.0))
                return d * flat + 2.0 * (d * u - drop * u**3 / (3.0 * relief**2))
            lo, hi = 0.0, n / flat
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if area(mid) < n else (lo, mid)
            d = 0.5 * (lo + hi)
            out[i] = per_length[i] * (flat + 2.0 * relief * math.sqrt(min(d / drop, 1.0)))
        return out
    return k


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
            "input_checks": {k: len(v) for k, v in doc["input_checks"].items()}, "verdict_text": doc["verdict_text"]}


def run_task(task: Task) -> dict[str, Any]:
    """Generate one dataset, measure its effect size, run the workflow, score the answer."""
    rng = np.random.default_rng(task.seed)
    depth_m = _log_uniform(rng, 1e-3, 5e-3)
    low = float(rng.uniform(0.01, 0.05)) * task.noise_scale
    noise = NoiseModel(low=low, high=low / 3.0)
    seating = 0.3 * low / 3.0
    background = (Roughness(asperity_scale=_log_uniform(rng, 1.0, 2.0)),) if task.background else ()
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
        truth = draw_independent(task.truth, rng, inner)
    points = synthesize(truth, rail_ra_m=rail_ra, noise=noise, seed=task.seed + 1, seating_rel=seating)
    clean_data = build_dataset(synthesize(truth, rail_ra_m=rail_ra, noise=NoiseModel(1e-12, 1e-12, 0.0), seed=0))
    sigma = np.concatenate([noise.sigma(c.load_n, c.load_n.max()) for c in clean_data.cases])
    spec = ModelSpec(effects=tuple(e.name for e in background))
    size = fit_model(clean_data, spec, sigma=sigma).score
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
        out["bad"] = _robust_variant(task.variant, points, rng)
        out["bad"]["verdict_unchanged"] = out["bad"].get("refused") or (
            out["bad"]["named"] == out["named"] and out["bad"]["measurement"] == out["measurement"])
    return out


def _robust_variant(variant: str, points: list[Any], rng: np.random.Generator) -> dict[str, Any]:
    """The same campaign with one kind of bad input."""
    if variant == "duplicate":
        i = int(rng.integers(len(points)))
        bad = [*points, dataclasses.replace(points[i], stiffness_n_per_m=points[i].stiffness_n_per_m * 1.5)]
    elif variant == "outliers":
        bad = list(points)
        for i in rng.choice(len(points), size=max(1, round(0.03 * len(points))), replace=False):
            factor = math.exp(float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.2, 0.5)))
            bad[i] = dataclasses.replace(bad[i], stiffness_n_per_m=bad[i].stiffness_n_per_m * factor)
    else:  # stiffness in N/mm
        bad = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * 1e-3) for p in points]
    try:
        result = run_discrepancy(bad)
    except InputError as exc:
        return {"refused": True, "message": str(exc)}
    out = _outcome(result)
    out["refused"] = False
    return out


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
        structured = [r for r in rs if r["lack_of_fit_p"] is not None and r["lack_of_fit_p"] < 0.01]
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


INDEPENDENT_SCENARIOS = (*EFFECTS, "roughness+misalignment", NONE)


def tasks_for(suite: str, seeds: int, scales: list[float], seed: int) -> list[Task]:
    base = seed * 1_000_000
    out: list[Task] = []
    if suite in ("independent", "acceptance"):
        for k, scale in enumerate(scales):
            for i, name in enumerate(INDEPENDENT_SCENARIOS):
                for j in range(seeds):
                    s = base + 10_000 * k + 100 * i + j
                    if name == "roughness+misalignment":
                        out.append(Task("independent", "misalignment", s, scale, background=True))
                    else:
                        out.append(Task("independent", name, s, scale))
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
    if suite in ("robust", "acceptance"):
        for i, variant in enumerate(("duplicate", "outliers", "units")):
            for j in range(max(1, seeds // 2)):
                truth = "setup_compliance" if j % 2 else NONE
                out.append(Task("robust", truth, base + 400_000 + 1000 * i + j, 1.0, variant=variant))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--suite", default="acceptance",
                        choices=("acceptance", "independent", "twin", "calibration", "crowned", "robust"))
    parser.add_argument("--seeds", type=int, default=20, help="datasets per scenario and noise scale (default 20)")
    parser.add_argument("--noise", default="0.5,1,2", help="noise scales (default 0.5,1,2)")
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run the datasets on this Dask scheduler (tcp://host:8786) instead of local processes")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", help="write every dataset's result as JSON here")
    args = parser.parse_args()
    scales = [float(v) for v in args.noise.split(",")]
    tasks = tasks_for(args.suite, args.seeds, scales, args.seed)
    start = time.perf_counter()
    if args.scheduler:
        from labctl.archive.runner import dask_map

        results = dask_map(run_task, tasks, scheduler=args.scheduler)
    else:
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            results = list(pool.map(run_task, tasks, chunksize=2))
    parts = []
    for suite, title in (("independent", "Hidden effects in functional forms unlike the library's"),
                         ("twin", "Hidden effects in the library's own forms")):
        rs = [r for r in results if r["suite"] == suite]
        if rs:
            parts.append(summarize_effects(rs, title))
    if any(r["suite"] == "calibration" for r in results):
        parts.append(summarize_calibration([r for r in results if r["suite"] == "calibration"]))
    if any(r["suite"] == "crowned" for r in results):
        parts.append(summarize_crowned([r for r in results if r["suite"] == "crowned"]))
    if any(r["suite"] == "robust" for r in results):
        parts.append(summarize_robust([r for r in results if r["suite"] == "robust"]))
    print("\n\n".join(parts))
    seconds = [r["seconds"] for r in results]
    where = args.scheduler or f"{args.workers} workers"
    print(f"\n{len(results)} datasets in {time.perf_counter() - start:.0f} s with {where}; "
          f"workflow time per 231-point dataset: mean {np.mean(seconds):.2f} s, max {np.max(seconds):.2f} s")
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            json.dump(results, fh, indent=1, default=str)


if __name__ == "__main__":
    main()
