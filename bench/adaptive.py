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
hidden effect's parameter (Laplace, in its fitted coordinate scaled by the bound span) and the ratio, once with
each campaign's own noise model and once with one noise model estimated from both campaigns' points. A further
line gives both SEs with the shared noise model at the world's true parameters instead of at each fit.

For a kinked effect (``KINK``: the hardness threshold) the SE is never linearised across the kink: it is the SD
of the effect's parameter over the planner's kink grid (``kink_posteriors``: the threshold held at each grid
value, the rest refitted, each slice weighted by exp(−χ²/2) and carrying its Laplace SE). "At the true
parameters" it is that SD for noise-free data from the world's law at the campaign's points, and one more line
gives it with the shared noise model scaled by the best slice's misfit (σ × s, s² = max(1, χ²/(n − p))).

``--rig-noise N`` adds a third SE per campaign and ratio, with the rig's noise measured apart from both designs:
one campaign (seed 0, independent of the compared seeds) at every knob step with N repetitions, whose noise
model has load bands (the point noise of this rig is largest at the preload).

``--bound`` adds, per seed, the best ratio any choice of loads could reach in this design space, from the same
Laplace covariance (the Fisher information of the shared noise model at the fixed campaign's fit): the base
loads plus the best ``budget`` loads of the knob grid (the same in every repetition), distinct or with repeats,
and every load free (``base + budget`` per repetition, with repeats, on every other knob step plus the top).

    python bench/adaptive.py [--seeds 4] [--first-seed 1] [--base 3] [--budget 3] [--reps 2] [--rig-noise 6] [--bound]
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's labctl and tests/

from labctl.campaign import run_campaign
from labctl.discrepancy.data import Dataset, build_dataset
from labctl.discrepancy.model import ModelSpec, fit_model
from labctl.discrepancy.noise import NoiseFloor, estimate_noise
from labctl.physics.effects import EFFECTS
from labctl.physics.law import ContactLaw
from labctl.physics.rig_config import load_rig
from labctl.physics.world import World, load_world
from labctl.planning.adaptive import knob_loads
from labctl.planning.rivals import Rival, from_fit, kink_posteriors
from labctl.protocol import load_protocol
from labctl.stiffness_table import StiffnessPoint
from labctl.storage.table import campaign_stiffness_points
from tests.engine_util import stepped_protocol_text


@dataclass(frozen=True)
class EffectFit:
    """The true model fitted to a campaign: the hidden effect's parameter, its SE and what they came from."""

    value: float
    se: float
    rival: Rival
    noise: NoiseFloor
    row: int
    """Index of the effect's parameter in the fitted vector."""
    span: float
    """Bounded range of the parameter (the fitted coordinate is scaled by it)."""
    parameters: tuple[tuple[str, float], ...] = ()
    """Every fitted parameter of the effect (SI)."""
    posterior: tuple[float, float] | None = None
    """For a kinked effect: the parameter's and the kink parameter's means over the kink grid (SI)."""
    se_scaled: float | None = None
    """For a kinked effect: the SE over the kink grid with the noise scaled by the misfit (``kink_posteriors``)."""


def fit_effect(points: list[StiffnessPoint], effect: str, baseline: str, noise: NoiseFloor | None = None
               ) -> EffectFit:
    """The hidden effect's fitted parameter and its standard error (the noise model estimated from the
    campaign's own points, or the one given)."""
    data = build_dataset(points)
    noise = noise or estimate_noise(data)
    sigma = noise.sigma_at(data)
    spec = ModelSpec(baseline, (effect,), {"setup_compliance": {"nominal_setup_n_per_m": 1.45e9}})
    # the workflow's start grid, and the effect's own defaults: a kinked term (the hardness threshold) can leave
    # the grid's starts in a local minimum when its onset lies between them
    fits = [fit_model(data, spec, sigma=sigma, seating_sigma=noise.seating_sigma, guess=guess)
            for guess in (None, {effect: EFFECTS[effect]().parameters()})]
    fit = min(fits, key=lambda f: float(np.sum(f.z**2)))
    slots = spec.slots()
    i = [n for n, *_ in slots].index(effect)
    lo, hi = slots[i][2:]
    params = tuple((k, float(v)) for k, v in fit.effect_parameters()[effect].items())
    out = EffectFit(params[0][1], 0.0, from_fit(fit), noise, int(spec.fits_depth) + i, hi - lo, params)
    return effect_se(out, points)


def design_se(fit: EffectFit, points: Sequence[StiffnessPoint]) -> float:
    """SE of the effect's parameter (Laplace, the fit's noise model) for points at these loads and seatings."""
    data = build_dataset(list(points))
    sigma = fit.noise.sigma_at(data)
    rival = fit.rival.with_covariance(data, lambda a: fit.noise.whiten(data, a, sigma))
    assert rival.covariance is not None
    return float(np.sqrt(rival.covariance[fit.row, fit.row])) * fit.span


def at_truth(fit: EffectFit, world: World) -> EffectFit | None:
    """The fit linearised at the world's true parameters instead of its own (None for a world law without them):
    a design's SE there does not depend on where a fit of a kinked term happened to land."""
    law = world.law
    if not isinstance(law, ContactLaw) or len(law.effects) != 1:
        return None
    effect = law.effects[0]
    spec = ModelSpec(law.baseline, (effect.name,))
    theta = spec.encode(law.depth_m, {effect.name: effect.parameters()})
    return replace(fit, rival=replace(fit.rival, theta=theta))


def kinked_se(fit: EffectFit, data: Dataset, misfit_scaled: Sequence[bool] = (False,)) -> list[tuple[float, float,
                                                                                                       float]]:
    """For a kinked effect, per setting of ``misfit_scaled``: the effect's parameter's mean and SD over the kink
    grid (``kink_posteriors``: slices weighted by exp(−χ²/2), each with its Laplace SE; scaled: the noise scaled
    by the misfit) and the kink parameter's mean, all SI."""
    sigma = fit.noise.sigma_at(data)
    posts = kink_posteriors(fit.rival, fit.row, data, lambda a: fit.noise.whiten(data, a, sigma), misfit_scaled)
    term = EFFECTS[fit.rival.terms[0]]
    (g0, g1), (t0, t1) = term.BOUNDS[fit.parameters[0][0]], term.BOUNDS[term.KINK]
    return [(g0 + p.mean * (g1 - g0), p.sd * (g1 - g0), t0 + p.kink_mean * (t1 - t0)) for p in posts]


def effect_se(fit: EffectFit, points: Sequence[StiffnessPoint]) -> EffectFit:
    """The fit with the SE of the effect's parameter for its points: Laplace at the fit, or for a kinked effect
    over the kink grid (never linearised across the kink)."""
    if fit.rival.kink is None:
        return replace(fit, se=design_se(fit, points))
    (mean, se, kink), (_, se_scaled, _) = kinked_se(fit, build_dataset(list(points)), (False, True))
    return replace(fit, se=se, posterior=(mean, kink), se_scaled=se_scaled)


def truth_se(fit: EffectFit, world: World, points: Sequence[StiffnessPoint]) -> float | None:
    """SE of the effect's parameter at the world's true parameters (None for a world law without them): Laplace
    linearised there, or for a kinked effect the kink-grid SD for noise-free data from the true law at these
    points (a design's SE that does not depend on where a fit of a kinked term happened to land)."""
    true = at_truth(fit, world)
    if true is None:
        return None
    if fit.rival.kink is None:
        return design_se(true, points)
    data = build_dataset(list(points))
    mu = true.rival.predict(data, true.rival.theta)
    return kinked_se(true, data.with_ln_stiffness(mu))[0][1]


def design_points(template: StiffnessPoint, loads_per_rep: Sequence[Sequence[float]]) -> list[StiffnessPoint]:
    return [replace(template, load_n=float(f), repetition=r) for r, loads in enumerate(loads_per_rep, 1)
            for f in loads]


Design = tuple[float, tuple[int, ...]]
"""A design's SE ratio to the fixed campaign's and its loads per repetition (N, rounded)."""


def best_ratios(fit: EffectFit, points: list[StiffnessPoint], base: list[list[float]], grid: np.ndarray,
                budget: int) -> tuple[Design, Design, Design]:
    """Best SE ratio to the fixed campaign's over designs, and the loads that reach it: base + ``budget``
    distinct grid loads, base + any ``budget`` grid loads (repeats allowed), all loads free (repeats allowed,
    coarse grid); the same added loads in every repetition."""
    fixed = design_se(fit, points)

    def best(choices: itertools.combinations | itertools.combinations_with_replacement,  # type: ignore[type-arg]
             with_base: bool) -> Design:
        se, loads = min((design_se(fit, design_points(points[0], [(b if with_base else []) + list(c)
                                                                  for b in base])), c) for c in choices)
        return se / fixed, tuple(round(float(f)) for f in loads)

    coarse = np.unique(np.append(grid[::2], grid[-1]))
    free_n = len(base[0]) + budget
    return (best(itertools.combinations(grid, budget), True),
            best(itertools.combinations_with_replacement(grid, budget), True),
            best(itertools.combinations_with_replacement(coarse, free_n), False))


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


def rig_noise(d: Path, args: argparse.Namespace) -> NoiseFloor:
    """The rig's noise model from a campaign of its own (seed 0) at every knob step, ``--rig-noise`` repetitions."""
    proto = d / "noise.toml"
    proto.write_text(stepped_protocol_text("noise", args.type, args.cap, max_steps=1, reps=1))
    steps = knob_loads(load_protocol(proto).specimens[0], load_rig()).size
    proto.write_text(stepped_protocol_text("noise", args.type, args.cap, max_steps=steps, reps=args.rig_noise))
    o = run_campaign(proto, out=d / "noise.h5", seed=0, world=args.world)
    assert o.status == "complete", o.message
    noise = estimate_noise(build_dataset(campaign_stiffness_points(d / "noise.h5")))
    bands = ", ".join(f"{b['sigma']:.4f} at {b['load_per_length_n_per_mm']:.0f} N/mm" for b in noise.bands())
    print(f"rig noise ({steps} steps × {args.rig_noise} repetitions, seed 0): point σ {bands}; "
          f"seating σ {noise.seating_sigma:.4f}")
    return noise


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--base", type=int, default=3)
    ap.add_argument("--budget", type=int, default=3)
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--type", type=int, default=1)
    ap.add_argument("--cap", type=float, default=400.0)
    ap.add_argument("--world", default="surface_roughness")
    ap.add_argument("--verbose", action="store_true", help="print the loads the planner added")
    ap.add_argument("--bound", action="store_true", help="print the best ratio any loads could reach (see above)")
    ap.add_argument("--rig-noise", type=int, default=0, help="repetitions of a rig-noise campaign (see above)")
    args = ap.parse_args()
    world = load_world(args.world)
    effects = list(world.law.effects)
    effect = str(effects[0].name)
    baseline = world.law.baseline
    print(f"world {args.world}: hidden effect {effect}; type {args.type}, cap {args.cap:g} N, {args.reps} reps, "
          f"fixed {args.base + args.budget} steps vs adaptive {args.base} + {args.budget} planned")
    ratios: list[float] = []
    shared: list[float] = []
    rig: list[float] = []
    truth: list[float] = []
    scaled: list[float] = []
    bounds: list[tuple[float, ...]] = []
    rig_bounds: list[tuple[float, ...]] = []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        measured = rig_noise(d, args) if args.rig_noise else None
        print(f"{'seed':>4} {'impacts F/A':>12} {'value F':>10} {'SE fixed':>10} {'value A':>10} {'SE adapt':>10} "
              f"{'ratio':>6} {'SE F pool':>10} {'SE A pool':>10} {'ratio':>6} {'time s':>7}")
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            t0 = time.perf_counter()
            res: dict[str, tuple[EffectFit, int]] = {}
            points: dict[str, list[StiffnessPoint]] = {}
            for mode, steps in (("fixed", args.base + args.budget), ("adaptive", args.base)):
                proto = d / f"{mode}.toml"
                proto.write_text(stepped_protocol_text(mode, args.type, args.cap, max_steps=steps, reps=args.reps))
                out = d / f"{mode}_{seed}.h5"
                o = run_campaign(proto, out=out, seed=seed, world=args.world, adaptive=mode == "adaptive",
                                 budget_steps=args.budget)
                assert o.status == "complete", o.message
                points[mode] = campaign_stiffness_points(out)
                res[mode] = (fit_effect(points[mode], effect, baseline), accepted_impacts(out))
                if mode == "adaptive" and args.verbose:
                    print(f"     added loads per repetition (N): {added_loads(out)}")
            (ff, nf), (fa, na) = res["fixed"], res["adaptive"]
            # the same rig's noise for both: one noise model from both campaigns' points (seatings kept apart)
            pooled = points["fixed"] + [replace(p, repetition=p.repetition + args.reps) for p in points["adaptive"]]
            noise = estimate_noise(build_dataset(pooled))
            shared_fixed = fit_effect(points["fixed"], effect, baseline, noise)
            shared_adaptive = fit_effect(points["adaptive"], effect, baseline, noise)
            sf2, sa2 = shared_fixed.se, shared_adaptive.se
            ratios.append(fa.se / ff.se)
            shared.append(sa2 / sf2)
            print(f"{seed:>4} {nf:>5}/{na:<6} {ff.value:>10.4g} {ff.se:>10.3g} {fa.value:>10.4g} {fa.se:>10.3g} "
                  f"{fa.se / ff.se:>6.2f} {sf2:>10.3g} {sa2:>10.3g} {sa2 / sf2:>6.2f} {time.perf_counter() - t0:>7.1f}")
            st_f = truth_se(shared_fixed, world, points["fixed"])
            st_a = truth_se(shared_adaptive, world, points["adaptive"])
            if st_f is not None and st_a is not None:
                truth.append(st_a / st_f)
                print(f"     at the true parameters (shared noise): SE fixed {st_f:.3g}, SE adaptive {st_a:.3g}, "
                      f"ratio {st_a / st_f:.2f}")
            if shared_fixed.se_scaled is not None and shared_adaptive.se_scaled is not None:
                sf4, sa4 = shared_fixed.se_scaled, shared_adaptive.se_scaled
                scaled.append(sa4 / sf4)
                print(f"     shared noise scaled by the misfit: SE fixed {sf4:.3g}, SE adaptive {sa4:.3g}, "
                      f"ratio {sa4 / sf4:.2f}")
            if args.verbose:
                words = [", ".join(f"{k} {v:.4g}" for k, v in f.parameters) for f in (shared_fixed, shared_adaptive)]
                print(f"     shared noise model fits: fixed {words[0]}; adaptive {words[1]}")
                if shared_fixed.posterior is not None and shared_adaptive.posterior is not None:
                    words = [f"{f.posterior[0]:.4g} ({f.posterior[1]:.4g})" for f in (shared_fixed, shared_adaptive)]
                    name = f"{shared_fixed.parameters[0][0]} ({EFFECTS[effect].KINK})"
                    print(f"     means over the kink grid, {name}: fixed {words[0]}; adaptive {words[1]}")
            if measured is not None:
                sf3, sa3 = (fit_effect(points[m], effect, baseline, measured).se for m in ("fixed", "adaptive"))
                rig.append(sa3 / sf3)
                print(f"     rig noise: SE fixed {sf3:.3g}, SE adaptive {sa3:.3g}, ratio {sa3 / sf3:.2f}")
            if args.bound:
                reps = sorted({p.repetition for p in points["adaptive"]})
                base = [[p.load_n for p in points["adaptive"] if p.repetition == r][: args.base] for r in reps]
                spec = load_protocol(d / "adaptive.toml").specimens[0]
                grid = knob_loads(spec, load_rig())
                fits = [("shared noise model", shared_fixed, bounds)]
                if measured is not None:
                    fits.append(("rig noise", fit_effect(points["fixed"], effect, baseline, measured), rig_bounds))
                for label, fit, found in fits:
                    designs = best_ratios(fit, points["fixed"], base, grid, args.budget)
                    found.append(tuple(r for r, _ in designs))
                    words = ", ".join(f"{name} {r:.2f}" + (f" {list(loads)}" if args.verbose else "")
                                      for name, (r, loads) in zip(("base + distinct", "base + repeats",
                                                                   "all loads free"), designs, strict=True))
                    print(f"     best ratio possible ({label}): {words}")
    for label, values in (("own noise model", ratios), ("shared noise model", shared), ("rig noise", rig),
                          ("shared noise model scaled by the misfit", scaled),
                          ("shared noise model, at the true parameters", truth)):
        if not values:
            continue
        r = np.array(values)
        print(f"SE ratio adaptive/fixed ({label}): median {np.median(r):.2f}, max {r.max():.2f}, "
              f"{int(np.sum(r <= 0.7))}/{r.size} seeds ≤ 0.7")
    for label, found in (("shared noise model", bounds), ("rig noise", rig_bounds)):
        if found:
            b = np.median(np.array(found), axis=0)
            print(f"best ratio possible ({label}), median: base + distinct {b[0]:.2f}, base + repeats {b[1]:.2f}, "
                  f"all loads free {b[2]:.2f}")


if __name__ == "__main__":
    main()
