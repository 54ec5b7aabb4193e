"""Does the planner's next mounting determine the hidden effect better than the protocol's next run?

World: Tripp (1.5 mm) with surface roughness (asperity scale 1.5) and end effects (edge length 0.1 mm).
Data so far: roller type 1 on Ra 0.2 µm rails, 3 repetitions × 11 load steps (33 points, noise 2 % at the
preload falling to 0.7 % at the top, seating offsets of ``--seating``). One more mounting of ``--budget``
points is then simulated in three ways:

- ``fixed``: the protocol's next run, another repetition of type 1 at ``--budget`` of its reachable loads
  spread evenly from the preload to the cap;
- ``random``: a catalogue roller and rail drawn at random, its loads spread the same way;
- ``planned``: the top recommendation of ``labctl plan`` (``plan_measurements``) at its chosen loads.

Each combined dataset is fitted with the true model's terms (Tripp + surface_roughness + end_effects, the
noise model re-estimated); the table gives, over ``--seeds`` seeds, the median standard error of the end-effect
length (Laplace, whitened with the noise model) and the rms error of the fitted length against the truth.

    python bench/planning.py [--seeds 8] [--budget 5] [--seating 0.0]

``--suite verdicts`` instead checks the two verdicts of the plan over seeds: the paper's programme (types 1-7
on both rails, 2 repetitions × 8 steps) on worlds with one or two library effects must give ``enough``; one
short roller type (1, 2, 7 or 9) with roughness and end effects must not, and its top recommendation must be a
roller of at least twice or at most half its contact length.

    python bench/planning.py --suite verdicts [--seeds 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from labctl.discrepancy.data import build_dataset
from labctl.discrepancy.model import ModelSpec, fit_model
from labctl.discrepancy.noise import estimate_noise
from labctl.discrepancy.synthetic import NoiseModel, case_for, synthesize
from labctl.physics import ContactLaw, EndEffects, SurfaceRoughness, load_rig, material
from labctl.planning import plan_measurements
from labctl.planning.rivals import from_fit
from labctl.planning.specimens import RAIL_RA_UM, reachable_loads
from labctl.protocol import load_protocol
from labctl.stiffness_table import StiffnessPoint

EDGE_M = 0.1e-3
LAW = ContactLaw("tripp", 1.5e-3, (SurfaceRoughness(1.5), EndEffects(EDGE_M)))
NOISE = NoiseModel(0.02, 0.007)
SPEC_TERMS = ("surface_roughness", "end_effects")


def mounting(type_id: int, rail_ra_m: float, loads: np.ndarray, rng: np.random.Generator, seating: float,
             rep: int) -> list[StiffnessPoint]:
    """One simulated mounting at the given loads (same noise model as the data so far)."""
    case = case_for(type_id, rail_ra_m)
    top = float(loads.max())
    actual = loads * np.exp(NOISE.load_rel * rng.standard_normal(loads.size))
    k = LAW.stiffness_n_per_m(case, actual) * np.exp(NOISE.sigma(actual, top) * rng.standard_normal(loads.size))
    k = k * np.exp(seating * rng.standard_normal())
    r = case.roller
    return [StiffnessPoint(r.diameter_m, r.contact_length_m, rail_ra_m, float(f), float(kk), roller_type=type_id,
                           roller_length_m=r.total_length_m, material=r.material.name, repetition=rep)
            for f, kk in zip(actual, k, strict=True)]


def spread(loads: np.ndarray, n: int) -> np.ndarray:
    return loads[np.unique(np.round(np.linspace(0, loads.size - 1, min(n, loads.size))).astype(int))]


def edge_estimate(points: list[StiffnessPoint]) -> tuple[float, float]:
    """Fitted end-effect length and its standard error (m) with the true model's terms."""
    data = build_dataset(points)
    noise = estimate_noise(data)
    sigma = noise.sigma_at(data)
    spec = ModelSpec("tripp", SPEC_TERMS, {"setup_compliance": {"nominal_setup_n_per_m": 1.45e9}})
    fit = fit_model(data, spec, sigma=sigma, seating_sigma=noise.seating_sigma)
    rival = from_fit(fit).with_covariance(data, lambda a: noise.whiten(data, a, sigma))
    k = 1 + [n for n, *_ in spec.slots()].index("end_effects")
    lo, hi = spec.slots()[k - 1][2:]
    assert rival.covariance is not None
    return fit.effect_parameters()["end_effects"]["edge_length_m"], float(np.sqrt(rival.covariance[k, k])) * (hi - lo)


def verdicts(seeds: int) -> None:
    """``enough`` on the full programme, a clearly different length recommended after one short roller."""
    from labctl.physics import SetupCompliance, rollers

    worlds = {"surface_roughness": (SurfaceRoughness(1.5),), "end_effects": (EndEffects(EDGE_M),),
              "surface_roughness + end_effects": (SurfaceRoughness(1.5), EndEffects(EDGE_M)),
              "setup_compliance": (SetupCompliance(1.25),)}
    print("| data | world | datasets | right verdict named | enough | top: L_we ratio >= 2 or <= 0.5 |")
    print("|---|---|---|---|---|---|")
    for name, effects in worlds.items():
        law = ContactLaw("tripp", 1.5e-3, effects)
        named = enough = 0
        for s in range(seeds):
            points: list[StiffnessPoint] = []
            for k, ra in enumerate((0.2e-6, 0.03e-6)):
                points += synthesize(law.stiffness_n_per_m, types=range(1, 8), rail_ra_m=ra, noise=NOISE,
                                     seed=10 * s + k, repetitions=2, steps=8)
            plan = plan_measurements(points)
            named += " + ".join(st.name for st in plan.result.steps) == name
            enough += plan.enough
        print(f"| types 1-7, both rails | {name} | {seeds} | {named} | {enough} | - |")
    for t in (1, 2, 7, 9):
        enough = clear = 0
        for s in range(seeds):
            plan = plan_measurements(synthesize(LAW.stiffness_n_per_m, types=[t], noise=NOISE, seed=s))
            top = plan.recommendations[0]
            ratio = rollers()[top.roller_type].contact_length_m / rollers()[t].contact_length_m
            enough += plan.enough
            clear += ratio >= 2 or ratio <= 0.5
        print(f"| type {t} only, Ra 0.2 | surface_roughness + end_effects | {seeds} | - | {enough} | {clear} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", choices=("se", "verdicts"), default="se")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--budget", type=int, default=5)
    ap.add_argument("--seating", type=float, default=0.0)
    args = ap.parse_args()
    if args.suite == "verdicts":
        verdicts(args.seeds)
        return
    protocol, rig, steel = load_protocol("roller_stiffness"), load_rig(), material("1.3505")
    from labctl.physics import rollers

    types = sorted(rollers())
    rows: dict[str, list[tuple[float, float]]] = {"before": [], "fixed": [], "random": [], "planned": []}
    picks = []
    t0 = time.time()
    for seed in range(args.seeds):
        rng = np.random.default_rng(1000 + seed)
        start = synthesize(LAW.stiffness_n_per_m, types=[1], noise=NOISE, seed=seed, seating_rel=args.seating)
        rows["before"].append(edge_estimate(start))
        own, _ = reachable_loads(protocol, 1, steel, 0.2e-6, rig)
        rows["fixed"].append(edge_estimate(start + mounting(1, 0.2e-6, spread(own, args.budget), rng,
                                                            args.seating, 4)))
        t, ra = int(rng.choice(types)), float(rng.choice(RAIL_RA_UM)) * 1e-6
        loads, _ = reachable_loads(protocol, t, steel, ra, rig)
        rows["random"].append(edge_estimate(start + mounting(t, ra, spread(loads, args.budget), rng,
                                                             args.seating, 1)))
        top = plan_measurements(start, budget_steps=args.budget).recommendations[0]
        picks.append(f"type {top.roller_type} / Ra {top.rail_ra_um:g}")
        planned = mounting(top.roller_type, top.rail_ra_um * 1e-6, np.array(top.loads_n), rng, args.seating, 1)
        rows["planned"].append(edge_estimate(start + planned))
    print(f"{args.seeds} seeds, budget {args.budget} points, seating σ {args.seating:g}, "
          f"{time.time() - t0:.0f} s; planner picked: {', '.join(picks)}")
    print("| data | points | median SE of edge length (µm) | rms error of edge length (µm) |")
    print("|---|---|---|---|")
    for name, values in rows.items():
        est = np.array([v[0] for v in values])
        se = np.array([v[1] for v in values])
        n = 33 + (0 if name == "before" else args.budget)
        rms = float(np.sqrt(np.mean((est - EDGE_M) ** 2)))
        print(f"| {name} | {n} | {np.median(se) * 1e6:.3g} | {rms * 1e6:.3g} |")


if __name__ == "__main__":
    main()
