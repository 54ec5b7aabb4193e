"""Does the lack-of-fit test hold its level? The share of null campaigns (no effect at all) it rejects.

Null campaigns from three sources: the project's own generator (``labctl.discrepancy.synthetic``: 7 roller types,
3 repetitions, 11 steps, 2 % → 0.67 % point noise, a 0.6 % seating offset) and the two judges written blind to the
workflow (``bench/blind``, ``bench/blind2``: their null scenario at noise 1×, the seeds with injected outliers left
out). Each is screened and its baseline fitted as the workflow does (``labctl.discrepancy.set_aside.screened``), and
its lack-of-fit p-value taken against the plain F(df_lack, df_pure) reference and against the reference simulated
under the estimated noise model (``labctl.discrepancy.lof_reference``). A test that holds its level rejects about
1 %, 5 % and 10 % of them at those levels (the ± is the binomial standard error at the nominal rate). A second table
splits the simulated reference's rejections by the noise the workflow estimated on each campaign — how steeply σ(F)
rises to low loads (its lowest load band's σ over its highest's) and how large the seating offset is beside the point
noise (σ_seat over the pooled σ), each in thirds over all campaigns: where the noise model falls short, the
rejections gather. ``--oracle`` runs the first judge's nulls alone, the reference drawn also from the judge's own
noise (its truth file's σ_rel(F) = a + b·(F_pre/F)^c and σ_seat: what no workflow knows), to tell what a better
noise estimate could gain.

    python bench/lof_level.py --seeds 200 --workers 2 [--oracle] [--sources own,blind,blind2,blind3]
    python bench/lof_level.py --seeds 300 --workers 2 --sources blind3 --quiet drift,load,tails
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from discrepancy_blind import blind_worlds, csv_points

from labctl.discrepancy.lof_reference import simulate
from labctl.discrepancy.noise import null_statistic
from labctl.discrepancy.search import Search
from labctl.discrepancy.set_aside import screened
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.discrepancy.workflow import baseline_spec
from labctl.physics import ContactLaw

LEVELS = (0.01, 0.05, 0.10)
SOURCES = ("own", "blind", "blind2")
"""The sources run by default; ``--sources`` may add the third judge (``blind3``: 2–4 seatings, uneven steps, a load
cell's reading noise, drift, Student-t tails), whose nulls were never part of the level's record above."""
ALL_SOURCES = (*SOURCES, "blind3")


QUIET_PARTS = ("drift", "load", "tails")
"""Parts of the third judge's own noise ``--quiet`` may switch off: its thermal drift, its load cell's reading noise,
its Student-t tails (Gaussian draws instead)."""


def quiet_third_judge(parts: tuple[str, ...]) -> None:
    """Switch ``parts`` of the third judge's noise off in its draws: a diagnostic of which of them the workflow's
    noise model misses (it patches the judge's private noise draw; no method may use it)."""
    if not parts:
        return
    judge = blind_worlds("blind3")
    draw = judge._noise

    def quieter(rng: Any, camp: Any) -> Any:
        noise = draw(rng, camp)
        change: dict[str, Any] = {}
        if "drift" in parts:
            change["drift_rel"] = 0.0
        if "load" in parts:
            change["load_rel"] = 0.0
        if "tails" in parts and noise.nu:
            seed = np.frombuffer(noise.z_f.tobytes()[:16], dtype=np.uint32)
            change.update(nu=0.0, z_f=np.random.default_rng(seed).standard_normal(noise.z_f.size))
        return dataclasses.replace(noise, **change)

    judge._noise = quieter


def null_world(source: str, seed: int) -> Any:
    """A judge's null world at noise 1× (its rows and truth), or None for a seed with injected outliers."""
    world = blind_worlds(source).generate("none" if source == "blind" else "null", seed, 1.0)
    faults = world.truth.get("faults") or {}
    return None if ("outliers" in faults if isinstance(faults, list) else faults.get("outliers")) else world


def points(source: str, seed: int) -> list[Any] | None:
    """One null campaign's points, or None (a blind seed with injected outliers)."""
    if source == "own":
        return synthesize(ContactLaw("tripp", 2e-3).stiffness_n_per_m, noise=NoiseModel(0.02, 0.02 / 3),
                          seed=seed, seating_rel=0.006)
    world = null_world(source, seed)
    return None if world is None else csv_points(world.rows)


def baseline_tests(pts: list[Any]) -> tuple[Any, Any, Any, Any]:
    """Screen a campaign and fit its baseline as the workflow does: (data, noise model, the baseline's lack-of-fit
    test against the plain F reference and against the simulated one; None where untestable)."""
    spec = baseline_spec("tripp")
    data, noise, _ = screened(pts, spec)
    fit = Search(data, noise).fit(spec)
    plain = noise.lack_of_fit(data, fit.residuals, fit.sigma, spec.n_params(), simulated=False)
    return data, noise, plain, noise.lack_of_fit(data, fit.residuals, fit.sigma, spec.n_params())


def p_values(job: tuple[str, int]) -> tuple[str, float, float, float, float] | None:
    """The baseline's lack-of-fit p-value, plain and simulated, on one null campaign, and its estimated noise's
    steepness (σ of the lowest load band / the highest's) and seating share (σ_seat / pooled σ)."""
    source, seed = job
    pts = points(source, seed)
    if pts is None:
        return None
    _, noise, plain, test = baseline_tests(pts)
    if plain is None or test is None:
        return None
    steep = noise.band_sigma[0] / noise.band_sigma[-1] if len(noise.band_sigma) > 1 else 1.0
    return source, plain.p, test.p, steep, noise.seating_sigma / noise.sigma


def shares(p: np.ndarray, spread: bool = False) -> str:
    """The share and count of p-values below each level (``spread``: and the binomial standard error there)."""
    return " | ".join(f"{np.mean(p < a):.3f} ({int(np.sum(p < a))}"
                      + (f"; ± {math.sqrt(a * (1 - a) / p.size):.3f})" if spread else ")") for a in LEVELS)


def by_noise(results: list[tuple[str, float, float, float, float]]) -> str:
    """The simulated reference's rejections per source, in thirds of the estimated noise's steepness and seating
    share (tercile edges over all campaigns)."""
    rows = [f"| source | estimated noise | n | {' | '.join(f'rejected at {a:g}' for a in LEVELS)} |",
            "|---|---|---|" + "---|" * len(LEVELS)]
    for column, name in ((3, "σ low / high load"), (4, "σ_seat / σ")):
        values = np.array([r[column] for r in results])
        edges = np.quantile(values, [1 / 3, 2 / 3])
        for source in dict.fromkeys(r[0] for r in results):
            mine = [r for r in results if r[0] == source]
            x, p = np.array([r[column] for r in mine]), np.array([r[2] for r in mine])
            third = np.searchsorted(edges, x)
            for k, label in enumerate((f"{name} < {edges[0]:.2f}", f"{name} {edges[0]:.2f}–{edges[1]:.2f}",
                                       f"{name} ≥ {edges[1]:.2f}")):
                q = p[third == k]
                rows.append(f"| {source} | {label} | {q.size} | {shares(q)} |")
    return "\n".join(rows)


def oracle_p(seed: int) -> tuple[float, float] | None:
    """A first-judge null campaign's lack-of-fit p-value against the estimated-noise reference and against one
    simulated under the judge's own noise (None: a seed with injected outliers)."""
    world = null_world("blind", seed)
    if world is None:
        return None
    data, _, _, test = baseline_tests(csv_points(world.rows))
    noise = world.truth["noise"]
    sigma = blind_worlds("blind")._sigma_rel(data.load_n, noise)  # the judge's own σ_rel(F)
    reference = simulate(data, sigma, noise["seat_sigma"], null_statistic)
    if test is None or reference is None:
        return None
    return test.p, reference.p(test.f, test.df_lack)


def print_oracle(seeds: int, workers: int) -> None:
    with ProcessPoolExecutor(workers) as pool:
        pairs = np.array([r for r in pool.map(oracle_p, range(seeds), chunksize=4) if r is not None])
    print(f"| first judge's nulls: reference drawn from | n | {' | '.join(f'rejected at {a:g}' for a in LEVELS)} |")
    print("|---|---|" + "---|" * len(LEVELS))
    for name, column in (("the estimated noise (the workflow's)", 0), ("the judge's own noise (oracle)", 1)):
        print(f"| {name} | {len(pairs)} | {shares(pairs[:, column])} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=200, help="null campaigns per source (default 200)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--oracle", action="store_true", help="the first judge's nulls against its own noise too")
    parser.add_argument("--sources", default=",".join(SOURCES),
                        help=f"comma-separated sources among {', '.join(ALL_SOURCES)} (default the first three)")
    parser.add_argument("--quiet", default="", help="comma-separated parts of the third judge's noise to switch off: "
                        "drift, load, tails (a diagnostic)")
    args = parser.parse_args()
    if args.oracle:
        print_oracle(args.seeds, args.workers)
        return
    sources = [s.strip() for s in args.sources.split(",") if s.strip()]
    unknown = [s for s in sources if s not in ALL_SOURCES]
    if unknown:
        parser.error(f"--sources: unknown source {unknown[0]!r}; expected among {', '.join(ALL_SOURCES)}")
    quiet = tuple(q.strip() for q in args.quiet.split(",") if q.strip())
    if any(q not in QUIET_PARTS for q in quiet):
        parser.error(f"--quiet: expected parts among {', '.join(QUIET_PARTS)}, got {args.quiet!r}")
    if quiet:
        print(f"the third judge's noise without its {', '.join(quiet)}\n")
    jobs = [(source, seed) for source in sources for seed in range(args.seeds)]
    with ProcessPoolExecutor(args.workers, initializer=quiet_third_judge, initargs=(quiet,)) as pool:
        results = [r for r in pool.map(p_values, jobs, chunksize=4) if r is not None]
    head = " | ".join(f"rejected at {a:g} (count; ± at {a:g})" for a in LEVELS)
    print(f"| source | reference | n | {head} |")
    print("|---|---|---|" + "---|" * len(LEVELS))
    for source in sources:
        rows = [r for r in results if r[0] == source]
        for name, column in (("plain F", 1), ("simulated", 2)):
            p = np.array([r[column] for r in rows])
            print(f"| {source} | {name} | {p.size} | {shares(p, spread=True)} |")
    print("\nThe simulated reference's rejections by the noise estimated on each campaign\n")
    print(by_noise(results))


if __name__ == "__main__":
    main()
