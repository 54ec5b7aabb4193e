"""Does the lack-of-fit test hold its level? The share of null campaigns (no effect at all) it rejects.

Null campaigns from three sources: the project's own generator (``labctl.discrepancy.synthetic``: 7 roller types,
3 repetitions, 11 steps, 2 % → 0.67 % point noise, a 0.6 % seating offset) and the two judges written blind to the
workflow (``bench/blind``, ``bench/blind2``: their null scenario at noise 1×, the seeds with injected outliers left
out). Each is screened and its baseline fitted as the workflow does (``labctl.discrepancy.set_aside.screened``), and
its lack-of-fit p-value taken against the plain F(df_lack, df_pure) reference and against the reference simulated
under the estimated noise model (``labctl.discrepancy.lof_reference``). A test that holds its level rejects about
1 %, 5 % and 10 % of them at those levels (the ± is the binomial standard error at the nominal rate).

    python bench/lof_level.py --seeds 200 --workers 2
"""

from __future__ import annotations

import argparse
import math
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from discrepancy_blind import blind_worlds, csv_points

from labctl.discrepancy.search import Search
from labctl.discrepancy.set_aside import screened
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.discrepancy.workflow import baseline_spec
from labctl.physics import ContactLaw

LEVELS = (0.01, 0.05, 0.10)
SOURCES = ("own", "blind", "blind2")


def points(source: str, seed: int) -> list[Any] | None:
    """One null campaign's points, or None (a blind seed with injected outliers)."""
    if source == "own":
        return synthesize(ContactLaw("tripp", 2e-3).stiffness_n_per_m, noise=NoiseModel(0.02, 0.02 / 3),
                          seed=seed, seating_rel=0.006)
    world = blind_worlds(source).generate("none" if source == "blind" else "null", seed, 1.0)
    if (world.truth.get("faults") or {}).get("outliers"):
        return None
    return csv_points(world.rows)


def p_values(job: tuple[str, int]) -> tuple[str, float, float] | None:
    """The baseline's lack-of-fit p-value, plain and simulated, on one null campaign."""
    source, seed = job
    pts = points(source, seed)
    if pts is None:
        return None
    spec = baseline_spec("tripp")
    data, noise, _ = screened(pts, spec)
    fit = Search(data, noise).fit(spec)
    plain = noise.lack_of_fit(data, fit.residuals, fit.sigma, spec.n_params(), simulated=False)
    test = noise.lack_of_fit(data, fit.residuals, fit.sigma, spec.n_params())
    if plain is None or test is None:
        return None
    return source, plain.p, test.p


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=200, help="null campaigns per source (default 200)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    jobs = [(source, seed) for source in SOURCES for seed in range(args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        results = [r for r in pool.map(p_values, jobs, chunksize=4) if r is not None]
    head = " | ".join(f"rejected at {a:g} (count; ± at {a:g})" for a in LEVELS)
    print(f"| source | reference | n | {head} |")
    print("|---|---|---|" + "---|" * len(LEVELS))
    for source in SOURCES:
        rows = [r for r in results if r[0] == source]
        for name, column in (("plain F", 1), ("simulated", 2)):
            p = np.array([r[column] for r in rows])
            shares = " | ".join(f"{np.mean(p < a):.3f} ({int(np.sum(p < a))}; ± {math.sqrt(a * (1 - a) / p.size):.3f})"
                                for a in LEVELS)
            print(f"| {source} | {name} | {p.size} | {shares} |")


if __name__ == "__main__":
    main()
