"""What the discrepancy workflow's outlier screen sets aside on worlds written blind to it, against what was put in.

The blind judge (``bench/blind/``) puts two gross outliers (a factor 1 ± 8–15 %) into one load step of one roller
type in 30 % of its worlds, in two of the three repetitions. Each world goes through the CSV contract and the
workflow's own screen (``screened``: the rows checked, the noise model's neighbour test, then the step tests
against the baseline: one load step's mean or spread out of line). An injected point's size is |ln factor| over
the point σ the judge states for it (its ``stiffness_std_n_per_m``, seating included): how far it sits outside the
noise it came with.

Printed: per size band, the injected points set aside (and beyond 8 σ, at an end load step or elsewhere); per
world, clean points set aside (false alarms), with and without injected outliers; and worlds where a clean
repetition of an injected step was set aside in place of a bad one. With ``--verdicts``, each world with outliers
also goes through the whole workflow twice, as written and without the injected points: the acceptance that two bad
points of one step never change the verdict, judged on worlds written blind to the workflow. Null worlds with
outliers are also run through the whole workflow: the acceptance "consistent, the outliers reported".

    python bench/discrepancy_outliers.py [--seeds 8] [--calibration] [--verdicts]
    python bench/discrepancy_outliers.py --own    # two outliers in null data of the project's own generator
    python bench/discrepancy_outliers.py --scenarios none --seeds 100    # the null worlds alone, more of them
    python bench/discrepancy_outliers.py --third --seeds 30    # the third judge's null worlds with outliers

Run by hand (not a test); about 20 s for the default 384 worlds, a few minutes more with ``--verdicts``.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from discrepancy_blind import CALIBRATION_SEEDS, blind_worlds, csv_points, truth_name  # noqa: E402

from labctl.discrepancy import run_discrepancy  # noqa: E402
from labctl.discrepancy.set_aside import screened  # noqa: E402
from labctl.discrepancy.synthetic import NoiseModel, synthesize  # noqa: E402
from labctl.discrepancy.workflow import baseline_spec  # noqa: E402
from labctl.physics import ContactLaw  # noqa: E402

SCALES = (0.5, 1.0, 2.0)
SIZE_BANDS = ((0.0, 3.0), (3.0, 5.0), (5.0, 8.0), (8.0, math.inf))
"""Injected outliers by size, in the point σ the judge states for them."""

FACTOR_PAIRS = ((0.9, 1.1), (0.88, 0.88), (1.12, 1.12), (0.92, 1.08))
"""The own-generator probes' factors on two repetitions of one step (12 % is 6 σ at the lowest loads)."""

Key = tuple[int, int, float]
"""A point as the screen reports it and the judge wrote it: roller type, repetition, load (N, 6 digits)."""


def _key(roller_type: int, repetition: int, load_n: float) -> Key:
    return roller_type, repetition, float(f"{load_n:.6g}")


def points(rows: list[dict[str, Any]]) -> dict[Key, tuple[int, dict[str, Any]]]:
    """Each point of the judge's rows by its key: its load step in its repetition (the judge's order) and its
    row; the duplicated row counted once."""
    out: dict[Key, tuple[int, dict[str, Any]]] = {}
    count: dict[tuple[int, int], int] = {}
    previous = None
    for row in rows:
        if row != previous:
            t, rep = int(row["roller_type"]), int(row["repetition"])
            count[(t, rep)] = count.get((t, rep), 0) + 1
            out[_key(t, rep, row["load_n"])] = (count[(t, rep)] - 1, row)
        previous = row
    return out


def injected(at: dict[Key, tuple[int, dict[str, Any]]], outliers: dict[str, Any] | None) -> dict[Key, float]:
    """The judge's outlier points (``at``: ``points`` of its rows) and each one's size (|ln factor| over its
    stated σ)."""
    if not outliers:
        return {}
    out = {}
    for (t, rep, load), (step, row) in at.items():
        if t == outliers["roller_type"] and step == outliers["step"] and rep in outliers["repetitions"]:
            factor = outliers["factors"][outliers["repetitions"].index(rep)]
            out[(t, rep, load)] = abs(math.log(factor)) / (row["stiffness_std_n_per_m"] / row["stiffness_n_per_m"])
    return out


def set_aside(rows: list[dict[str, Any]]) -> set[Key]:
    """The points the workflow's screen sets aside as gross outliers."""
    data, _, screening = screened(csv_points(rows), baseline_spec("tripp"))
    return keys(data, screening.outliers)


def keys(data: Any, outliers: list[dict[str, Any]]) -> set[Key]:
    """The screen's outliers as the judge's points."""
    types = {c.label: c.case.roller.type_id for c in data.cases}
    return {_key(types[o["case"]], o["repetition"], o["load_n"]) for o in outliers}


def verdict_pair(rows: list[dict[str, Any]], bad: set[Key]) -> tuple[tuple[str, str], tuple[str, str]]:
    """The workflow's verdict and top explanation on the world as the judge wrote it, and without the injected
    points: what two bad points of one step must not change."""
    return outcome(rows), outcome(without(rows, bad))


def without(rows: list[dict[str, Any]], bad: set[Key]) -> list[dict[str, Any]]:
    """The world's rows less the injected points."""
    return [r for r in rows if _key(int(r["roller_type"]), int(r["repetition"]), r["load_n"]) not in bad]


def outcome(rows: list[dict[str, Any]]) -> tuple[str, str]:
    """The workflow's verdict and top explanation on these rows."""
    result = run_discrepancy(csv_points(rows))
    return result.verdict, result.scored[0].explanation.name


def worlds(judge: Any, seeds: Iterable[int], scenarios: Iterable[str] | None = None) -> Iterable[tuple[str, Any]]:
    """Each world of the judge with its name (scenario, seed, noise scale); ``scenarios``: only these."""
    for scenario in scenarios or judge.SCENARIOS:
        for seed in seeds:
            for scale in SCALES:
                yield f"{scenario} seed {seed} {scale:g}×", judge.generate(scenario, seed, scale)


def null_table(rows: list[tuple[float, int, str]]) -> None:
    """Null worlds with two injected outliers, by the smaller one's size: the acceptance "consistent, the outliers
    reported" (both injected points set aside and reported, one, or neither)."""
    print(f"\nnull worlds with two injected outliers: {len(rows)}; verdict consistent "
          f"{sum(v == 'consistent' for _, _, v in rows)}/{len(rows)}\n")
    print("| smaller injected size [stated σ] | worlds | consistent | both reported | one | neither |")
    print("|---|---|---|---|---|---|")
    for lo, hi in SIZE_BANDS:
        band = [(n, v) for size, n, v in rows if lo <= size < hi]
        if band:
            print(f"| {lo:g}–{hi:g} | {len(band)} | {sum(v == 'consistent' for _, v in band)} | "
                  f"{sum(n == 2 for n, _ in band)} | {sum(n == 1 for n, _ in band)} | {sum(n == 0 for n, _ in band)} |")
    for size, n, v in rows:
        if v != "consistent":
            print(f"- smaller outlier {size:.1f} σ, {n}/2 reported: {v}")


def third_judge_nulls(seeds: int) -> None:
    """The third judge's null worlds with two outliers (``bench/blind3``: ±8–15 % each, on the first two seatings of
    one step after the first of one roller case, whose seatings number 2–4): the acceptance "consistent, the
    outliers reported", per noise scale, and each world that is not consistent with where its outliers sit; and,
    in its other worlds, the clean points the screen sets aside, by the tails of the point noise."""
    judge = blind_worlds("blind3")
    table: dict[float, list[tuple[int, str]]] = {}
    for name, world in worlds(judge, range(seeds), ["null_outliers"]):
        rows = world.rows
        bad = {_key(int(rows[i]["roller_type"]), int(rows[i]["repetition"]), rows[i]["load_n"])
               for i in world.truth["outlier_rows"]}
        result = run_discrepancy(csv_points(rows))
        found = keys(result.data, result.screening.outliers)
        table.setdefault(world.truth["noise_scale"], []).append((len(found & bad), result.verdict))
        if result.verdict != "consistent":
            first = rows[world.truth["outlier_rows"][0]]
            seating = sorted(r["load_n"] for r in rows if (r["roller_type"], r["rail_ra_um"], r["repetition"]) ==
                             (first["roller_type"], first["rail_ra_um"], first["repetition"]))
            seatings = {r["repetition"] for r in rows if (r["roller_type"], r["rail_ra_um"]) ==
                        (first["roller_type"], first["rail_ra_um"])}
            print(f"- {name}: {result.verdict} ({result.scored[0].explanation.name}), {len(found & bad)}/2 reported, "
                  f"{len(found - bad)} clean set aside; step {seating.index(first['load_n']) + 1} of {len(seating)}, "
                  f"{len(seatings)} seatings")
    clean: dict[str, list[int]] = {"Gaussian": [], "Student-t": []}
    for _, world in worlds(judge, range(seeds), [s for s in judge.SCENARIOS if s != "null_outliers"]):
        tails = "Student-t" if world.truth["noise"]["student_t_nu"] else "Gaussian"
        clean[tails].append(len(set_aside(world.rows)))  # the screen alone; these worlds have no injected outlier
    print("\nthird judge, worlds without injected outliers: clean points the screen sets aside\n")
    print("| point noise | worlds | clean points set aside (mean per world) | worlds with any |\n|---|---|---|---|")
    for tails, found in clean.items():
        print(f"| {tails} | {len(found)} | {np.mean(found):.3f} | {np.mean(np.array(found) > 0):.3f} |")
    print(f"\nthird judge, null worlds with two injected outliers, seeds 0-{seeds - 1}\n")
    print("| noise | worlds | consistent | both reported | one | neither |\n|---|---|---|---|---|---|")
    for scale, got in table.items():
        print(f"| {scale:g}× | {len(got)} | {sum(v == 'consistent' for _, v in got)} | {sum(n == 2 for n, _ in got)} | "
              f"{sum(n == 1 for n, _ in got)} | {sum(n == 0 for n, _ in got)} |")


def own_probes() -> None:
    """Two outliers in one load step of null data from the project's own generator (2 % point noise at the
    preload, a third of it at the top): roller types 1, 3, 5, the lowest and the highest step, four pairs of
    factors on repetitions 1 and 2. Not a judge of the method (its generator is the method's); the case it found."""
    law = ContactLaw("tripp", 2e-3).stiffness_n_per_m
    null = synthesize(law, noise=NoiseModel(low=0.02, high=0.02 / 3), seating_rel=0.004, seed=11)
    loads: dict[tuple[int | None, int | None], list[float]] = {}
    for q in null:
        loads.setdefault((q.roller_type, q.repetition), []).append(q.load_n)
    loads = {k: sorted(v) for k, v in loads.items()}  # each seating's loads, once
    print("| roller type | step | factors | outliers reported | clean set aside | verdict |\n|---|---|---|---|---|---|")
    for roller_type, step, factors in itertools.product((1, 3, 5), (0, -1), FACTOR_PAIRS):
        points, bad = [], set()
        for p in null:
            if p.roller_type == roller_type and p.repetition in (1, 2) and \
                    p.load_n == loads[(p.roller_type, p.repetition)][step]:
                p = dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * factors[p.repetition - 1])
                bad.add((p.repetition, p.load_n))
            points.append(p)
        result = run_discrepancy(points)
        found = {(o["repetition"], o["load_n"]) for o in result.screening.outliers}
        print(f"| {roller_type} | {'lowest' if step == 0 else 'highest'} | {factors[0]:g}, {factors[1]:g} | "
              f"{len(found & bad)}/2 | {len(found - bad)} | {result.verdict} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8, help="seeds per scenario and noise scale")
    ap.add_argument("--calibration", action="store_true", help="the calibration seeds instead of the evaluation ones")
    ap.add_argument("--verdicts", action="store_true",
                    help="also run the whole workflow on each world with outliers, with and without them")
    ap.add_argument("--own", action="store_true", help="only the probes on the project's own generator")
    ap.add_argument("--scenarios", nargs="+", help="only these of the judge's scenarios (e.g. none)")
    ap.add_argument("--third", action="store_true", help="only the third judge's null worlds with outliers")
    args = ap.parse_args()
    if args.own:
        own_probes()
        return 0
    if args.third:
        third_judge_nulls(args.seeds)
        return 0
    first = CALIBRATION_SEEDS if args.calibration else 0
    sizes: list[tuple[float, bool]] = []
    far_at: dict[str, list[bool]] = {"at an end step": [], "elsewhere": []}
    false_with, false_without, clean_rep_instead = [], [], 0
    pairs: list[tuple[str, tuple[str, str], tuple[str, str]]] = []
    judge = blind_worlds("blind")
    null: list[tuple[float, int, str]] = []
    for name, world in worlds(judge, range(first, first + args.seeds), args.scenarios):
        outliers = world.truth["faults"]["outliers"]
        at = points(world.rows)
        bad = injected(at, outliers)
        found = set_aside(world.rows)
        sizes += [(size, key in found) for key, size in bad.items()]
        if bad:
            end = outliers["step"] in (0, judge.LOAD_STEPS - 1)
            far_at["at an end step" if end else "elsewhere"] += [key in found for key, size in bad.items() if size >= 8]
            if any(k[0] == outliers["roller_type"] and at[k][0] == outliers["step"] for k in found - set(bad)):
                clean_rep_instead += 1
        (false_with if bad else false_without).append(len(found - set(bad)))
        if bad and args.verdicts:
            pairs.append((name, *verdict_pair(world.rows, set(bad))))
        if bad and truth_name(world.truth) == "none":  # the workflow's own report of them
            result = run_discrepancy(csv_points(world.rows))
            verdict = result.verdict
            if verdict != "consistent":  # and without the injected points: is it the outliers or the world?
                verdict += f" ({outcome(without(world.rows, set(bad)))[0]} without them; {name})"
            null.append((min(bad.values()), len(keys(result.data, result.screening.outliers) & set(bad)), verdict))
    print(f"blind judge, {'calibration' if args.calibration else 'evaluation'} seeds {first}-{first + args.seeds - 1}, "
          f"noise {', '.join(f'{s:g}×' for s in SCALES)}: {len(false_with) + len(false_without)} worlds, "
          f"{len(false_with)} with two injected outliers\n")
    print("| injected size [stated σ] | points | set aside |")
    print("|---|---|---|")
    for lo, hi in SIZE_BANDS:
        band = [hit for size, hit in sizes if lo <= size < hi]
        share = f"{np.mean(band):.3f} ({sum(band)}/{len(band)})" if band else "-"
        print(f"| {lo:g}–{hi:g} | {len(band)} | {share} |")
    print("\n" + "beyond 8 σ: " + "; ".join(f"{k} {sum(v)}/{len(v)} set aside" for k, v in far_at.items()))
    print("\n| worlds | n | clean points set aside (mean per world) | worlds with any |")
    print("|---|---|---|---|")
    for name, false in (("with injected outliers", false_with), ("without", false_without)):
        if false:
            print(f"| {name} | {len(false)} | {np.mean(false):.3f} | {np.mean(np.array(false) > 0):.3f} |")
    print(f"\nworlds where a clean point of an injected step was set aside: {clean_rep_instead}")
    if null:
        null_table(null)
    if pairs:
        same = [a[0] == b[0] for _, a, b in pairs]
        top = [a[1] == b[1] for _, a, b in pairs]
        print(f"\nthe whole workflow on the {len(pairs)} worlds with injected outliers, against the same world without "
              f"them: verdict unchanged {sum(same)}/{len(pairs)}, top explanation unchanged {sum(top)}/{len(pairs)}")
        for name, a, b in pairs:
            if a != b:
                print(f"- {name}: {a[0]} ({a[1]}) with them, {b[0]} ({b[1]}) without")
    return 0


if __name__ == "__main__":
    sys.exit(main())
