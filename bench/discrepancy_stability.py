"""Do the discrepancy workflow's probabilities hang on the data's last digits?

Each blind world (the helper-written judges, ``bench/blind`` and ``bench/blind2``) is run through the CSV contract
twice: as written, and with every stiffness moved by a relative 10⁻⁹ (Gaussian, seeded by the world's seed) — a
thousand times below the last digit a stiffness table holds. A decision procedure that means its probabilities
gives the same verdict and the same probabilities to well within 10⁻³; a move larger than that is a decision
turning on where an optimiser happened to stop (a parameter started on its bound, a test at a tolerance), and is
listed with its world so it can be traced.

    python bench/discrepancy_stability.py [--judge blind] [--seeds 100000,100001] [--workers 2]

Run by hand (not a test); about four minutes for two seeds of one judge on two workers.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from discrepancy_blind import JUDGES, blind_worlds, csv_points  # noqa: E402

from labctl.discrepancy import run_discrepancy  # noqa: E402

RELATIVE_MOVE = 1e-9
MATERIAL = 1e-3
"""A probability moved by more than this is listed."""


@dataclasses.dataclass(frozen=True)
class World:
    judge: str
    scenario: str
    seed: int
    noise_scale: float


def both(world: World) -> dict[str, Any]:
    """The world run as written and moved; the largest change in any candidate's probability."""
    w = blind_worlds(world.judge).generate(world.scenario, world.seed, world.noise_scale)
    points = csv_points(w.rows)
    rng = np.random.default_rng(world.seed)
    moved = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * (1 + RELATIVE_MOVE * rng.standard_normal()))
             for p in points]
    runs = []
    for ps in (points, moved):
        result = run_discrepancy(ps)
        runs.append((result.verdict, {c.explanation.name: c.probability for c in result.scored}))
    (verdict, p), (verdict_moved, q) = runs
    worst = max(p, key=lambda k: abs(p[k] - q.get(k, 0.0)))
    return {"world": world, "verdicts": (verdict, verdict_moved), "candidate": worst,
            "probabilities": (p[worst], q.get(worst, 0.0)), "move": abs(p[worst] - q.get(worst, 0.0))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--judge", default="blind", choices=tuple(JUDGES))
    parser.add_argument("--seeds", default="100000,100001", help="comma-separated world seeds")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    worlds = [World(args.judge, s, seed, scale) for s in blind_worlds(args.judge).SCENARIOS for seed in seeds
              for scale in (0.5, 1.0, 2.0)]
    with Pool(args.workers) as pool:
        out = pool.map(both, worlds, chunksize=1)
    out.sort(key=lambda r: -r["move"])
    material = [r for r in out if r["move"] > MATERIAL]
    changed = [r for r in out if r["verdicts"][0] != r["verdicts"][1]]
    print(f"{args.judge}, seeds {args.seeds}: {len(out)} worlds, each as written and with every stiffness moved by "
          f"a relative {RELATIVE_MOVE:g}\n")
    print("| worlds | a probability moved > 0.001 | verdict changed | largest move |")
    print("|---|---|---|---|")
    print(f"| {len(out)} | {len(material)} | {len(changed)} | {out[0]['move']:.2g} |\n")
    if material:
        print("| world | candidate | probability as written → moved | verdict |")
        print("|---|---|---|---|")
        for r in material:
            w = r["world"]
            print(f"| {w.scenario} seed {w.seed} at {w.noise_scale:g}× | {r['candidate']} | "
                  f"{r['probabilities'][0]:.3f} → {r['probabilities'][1]:.3f} | {' → '.join(r['verdicts'])} |")


if __name__ == "__main__":
    main()
