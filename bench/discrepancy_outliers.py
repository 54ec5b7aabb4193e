"""What the discrepancy workflow's outlier screen sets aside on worlds written blind to it, against what was put in.

The blind judge (``bench/blind/``) puts two gross outliers (a factor 1 ± 8–15 %) into one load step of one roller
type in 30 % of its worlds, in two of the three repetitions. Each world goes through the CSV contract and the
workflow's own screen (``screen_points``, then ``set_aside_outliers``: the noise model's neighbour test) without
any model fit. An injected point's size is |ln factor| over the point σ the judge states for it (its
``stiffness_std_n_per_m``, seating included): how far it sits outside the noise it came with.

Printed: per size band, the injected points set aside (and beyond 8 σ, at an end load step or elsewhere); per
world, clean points set aside (false alarms), with and without injected outliers; and worlds where a clean
repetition of an injected step was set aside in place of a bad one.

    python bench/discrepancy_outliers.py [--seeds 8] [--calibration]

Run by hand (not a test); about 15 s for the default 384 worlds.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from discrepancy_blind import CALIBRATION_SEEDS, blind_worlds, csv_points  # noqa: E402

from labctl.discrepancy.data import build_dataset  # noqa: E402
from labctl.discrepancy.screen import screen_points  # noqa: E402
from labctl.discrepancy.workflow import set_aside_outliers  # noqa: E402

SCALES = (0.5, 1.0, 2.0)
SIZE_BANDS = ((0.0, 3.0), (3.0, 5.0), (5.0, 8.0), (8.0, math.inf))
"""Injected outliers by size, in the point σ the judge states for them."""

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
    kept, screening = screen_points(csv_points(rows))
    data = build_dataset(kept)
    types = {c.label: c.case.roller.type_id for c in data.cases}
    set_aside_outliers(data, screening)
    return {_key(types[o["case"]], o["repetition"], o["load_n"]) for o in screening.outliers}


def worlds(judge: Any, seeds: Iterable[int]) -> Iterable[Any]:
    for scenario in judge.SCENARIOS:
        for seed in seeds:
            for scale in SCALES:
                yield judge.generate(scenario, seed, scale)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8, help="seeds per scenario and noise scale")
    ap.add_argument("--calibration", action="store_true", help="the calibration seeds instead of the evaluation ones")
    args = ap.parse_args()
    first = CALIBRATION_SEEDS if args.calibration else 0
    sizes: list[tuple[float, bool]] = []
    far_at: dict[str, list[bool]] = {"at an end step": [], "elsewhere": []}
    false_with, false_without, clean_rep_instead = [], [], 0
    judge = blind_worlds("blind")
    for world in worlds(judge, range(first, first + args.seeds)):
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
