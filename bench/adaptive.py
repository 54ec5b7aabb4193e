"""Same impacts, smaller uncertainty? The adaptive campaign against the fixed protocol on the simulated rig.

World: ``--world`` (default ``surface_roughness``: Tripp 1.5 mm + asperity scale 3, a hidden effect that bends
the stiffness-load curve most at low load). Specimen: roller type ``--type`` on Ra 0.2 µm rails, load cap
``--cap`` N, knob step 90°, 2 impacts per step of 8192 samples, ``--reps`` repetitions. Two campaigns per seed,
run end to end through ``run_campaign`` (simulated records, the one step pipeline, stored step results):

- ``fixed``: the protocol with ``base + budget`` load steps spread evenly from the preload to the cap;
- ``adaptive``: the protocol with ``base`` load steps, run with ``--adaptive --budget-steps budget``: after each
  repetition's base steps the planner adds the ``budget`` loads it ranks highest for the mounted roller.

Both spend the same number of steps and so of impacts (counted from the files and printed). Each campaign's
stiffness points are fitted with the discrepancy workflow's model fit using the true model's terms (Tripp + the
hidden effect, noise model re-estimated from the data); the table gives, per seed, the standard error of the
hidden effect's parameter (Laplace, in its fitted coordinate scaled by the bound span) and the ratio.

    python bench/adaptive.py [--seeds 4] [--base 3] [--budget 3] [--reps 2]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np

from labctl.campaign import run_campaign
from labctl.discrepancy.data import build_dataset
from labctl.discrepancy.model import ModelSpec, fit_model
from labctl.discrepancy.noise import NoiseFloor, estimate_noise
from labctl.physics.world import load_world
from labctl.planning.rivals import from_fit
from labctl.stiffness_table import StiffnessPoint
from labctl.storage.table import campaign_stiffness_points

PROTOCOL = """
[protocol]
name = "{name}"
[specimen]
roller_type = {type_id}
rail_ra_um = 0.2
max_load_n = {cap}
knob_step_deg = 90.0
[acquisition]
samples = 8192
impacts_per_step = 2
timeout_s = 5.0
[loading]
settle_poll_s = 0.0
settle_timeout_s = 5.0
max_steps = {steps}
[repetitions]
count = {reps}
"""


def effect_se(points: list[StiffnessPoint], effect: str, baseline: str, noise: NoiseFloor | None = None
              ) -> tuple[float, float, int]:
    """The hidden effect's fitted parameter, its standard error and the number of points of a campaign (the
    noise model estimated from its own points, or the one given)."""
    data = build_dataset(points)
    noise = noise or estimate_noise(data)
    sigma = noise.sigma_at(data)
    spec = ModelSpec(baseline, (effect,), {"setup_compliance": {"nominal_setup_n_per_m": 1.45e9}})
    fit = fit_model(data, spec, sigma=sigma, seating_sigma=noise.seating_sigma)
    rival = from_fit(fit).with_covariance(data, lambda a: noise.whiten(data, a, sigma))
    slots = spec.slots()
    i = [n for n, *_ in slots].index(effect)
    k = int(spec.fits_depth) + i
    lo, hi = slots[i][2:]
    assert rival.covariance is not None
    value = next(iter(fit.effect_parameters()[effect].values()))
    return value, float(np.sqrt(rival.covariance[k, k])) * (hi - lo), len(points)


def accepted_impacts(path: Path) -> int:
    n = 0
    with h5py.File(path, "r") as f:
        def visit(name: str, obj: object) -> None:
            nonlocal n
            if isinstance(obj, h5py.Group) and name.rsplit("/", 1)[-1].startswith("impact_"):
                n += int(bool(obj.attrs.get("accepted", False)))
        f.visititems(visit)
    return n


def added_loads(path: Path) -> list[list[float]]:
    """The loads the planner added to each repetition (from the stored plan)."""
    with h5py.File(path, "r") as f:
        sg = f["series_01"]
        return [[round(a["target_load_n"]) for a in json.loads(sg[r].attrs.get("added_steps", "[]"))]
                for r in sorted(sg) if r.startswith("run_")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--base", type=int, default=3)
    ap.add_argument("--budget", type=int, default=3)
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--type", type=int, default=1)
    ap.add_argument("--cap", type=float, default=400.0)
    ap.add_argument("--world", default="surface_roughness")
    ap.add_argument("--verbose", action="store_true", help="print the loads the planner added")
    args = ap.parse_args()
    world = load_world(args.world)
    effects = list(world.law.effects)
    effect = str(effects[0].name)
    baseline = world.law.baseline
    print(f"world {args.world}: hidden effect {effect}; type {args.type}, cap {args.cap:g} N, {args.reps} reps, "
          f"fixed {args.base + args.budget} steps vs adaptive {args.base} + {args.budget} planned")
    print(f"{'seed':>4} {'impacts F/A':>12} {'value F':>10} {'SE fixed':>10} {'value A':>10} {'SE adapt':>10} "
          f"{'ratio':>6} {'SE F pool':>10} {'SE A pool':>10} {'ratio':>6} {'time s':>7}")
    ratios: list[float] = []
    shared: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for seed in range(1, args.seeds + 1):
            t0 = time.perf_counter()
            res: dict[str, tuple[float, float, int, int]] = {}
            points: dict[str, list[StiffnessPoint]] = {}
            for mode, steps in (("fixed", args.base + args.budget), ("adaptive", args.base)):
                proto = d / f"{mode}.toml"
                proto.write_text(PROTOCOL.format(name=mode, type_id=args.type, cap=args.cap, steps=steps,
                                                 reps=args.reps))
                out = d / f"{mode}_{seed}.h5"
                o = run_campaign(proto, out=out, seed=seed, world=args.world, adaptive=mode == "adaptive",
                                 budget_steps=args.budget)
                assert o.status == "complete", o.message
                points[mode] = campaign_stiffness_points(out)
                res[mode] = (*effect_se(points[mode], effect, baseline), accepted_impacts(out))
                if mode == "adaptive" and args.verbose:
                    print(f"     added loads per repetition (N): {added_loads(out)}")
            (vf, sf, _, nf), (va, sa, _, na) = res["fixed"], res["adaptive"]
            # the same rig's noise for both: one noise model from both campaigns' points (seatings kept apart)
            pooled = points["fixed"] + [replace(p, repetition=p.repetition + args.reps) for p in points["adaptive"]]
            noise = estimate_noise(build_dataset(pooled))
            sf2 = effect_se(points["fixed"], effect, baseline, noise)[1]
            sa2 = effect_se(points["adaptive"], effect, baseline, noise)[1]
            ratios.append(sa / sf)
            shared.append(sa2 / sf2)
            print(f"{seed:>4} {nf:>5}/{na:<6} {vf:>10.4g} {sf:>10.3g} {va:>10.4g} {sa:>10.3g} {sa / sf:>6.2f} "
                  f"{sf2:>10.3g} {sa2:>10.3g} {sa2 / sf2:>6.2f} {time.perf_counter() - t0:>7.1f}")
    for label, values in (("own noise model", ratios), ("shared noise model", shared)):
        r = np.array(values)
        print(f"SE ratio adaptive/fixed ({label}): median {np.median(r):.2f}, max {r.max():.2f}, "
              f"{int(np.sum(r <= 0.7))}/{r.size} seeds ≤ 0.7")


if __name__ == "__main__":
    main()
