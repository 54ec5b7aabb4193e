"""Blind hidden-effect stiffness worlds: stiffness tables with a known cause of departure from Tripp.

Written without reading labctl's discrepancy workflow (see discrepancy_brief.md here). Each world: roller types
1-7 x 3 repetitions x 11 load steps from 38 N to 0.31 C0, a hidden physical effect (several load laws each,
drawn per seed), a calibration error or none, rig-like noise and optional faults. `truth` says what is in it.

    python bench/blind/discrepancy_worlds.py --out DIR --seeds N [--noise 0.5 1 2] [--summary]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from blind_contact import PRELOAD_N, RAIL_MATERIAL, load_materials, load_rollers, static_rating_n  # noqa: E402
from blind_families import OUTSIDE, PHYSICAL, Family, RollerLoads  # noqa: E402

ROLLER_TYPES = (1, 2, 3, 4, 5, 6, 7)
REPETITIONS = 3
LOAD_STEPS = 11
MAX_LOAD_SHARE = 0.31
RA_ROUGH_UM, RA_SMOOTH_UM = 0.2, 0.03
CALIBRATION = ("load_gain", "load_offset", "modulus_scale")
PAIRS = {
    "surface_roughness+end_effects": ("surface_roughness", "end_effects"),
    "surface_roughness+misalignment": ("surface_roughness", "misalignment"),
}
SCENARIOS: tuple[str, ...] = (
    "none", *PHYSICAL, *(f"outside_{name}" for name in OUTSIDE), *CALIBRATION, *PAIRS, "physical+calibration",
)
COLUMNS = ("roller_type", "diameter_mm", "contact_length_mm", "roller_length_mm", "material", "rail_material",
           "rail_ra_um", "repetition", "load_n", "stiffness_n_per_m", "stiffness_std_n_per_m")
SMALL_SHARE = 0.25  # share of effects drawn below 3 σ (at noise scale 1)


@dataclass
class BlindDataset:
    """Rows of a stiffness-table CSV and the truth behind them."""

    rows: list[dict[str, Any]]
    truth: dict[str, Any] = field(default_factory=dict)


def _rng(scenario: str, seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(scenario.encode()), stream]))


def _sigma_rel(load_n: np.ndarray, noise: dict[str, float]) -> np.ndarray:
    """Point noise σ_rel(F) = a + b (F_pre/F)^c at noise scale 1."""
    return noise["a"] + noise["b"] * (noise["preload_n"] / load_n) ** noise["c"]


def _ln_ratio_max(family: Family, rollers: list[RollerLoads], params: dict[str, float], amp: float) -> float:
    return max(float(np.max(np.abs(np.log(family.apply(r, params, amp) / r.tripp())))) for r in rollers)


def _amp_for_size(family: Family, rollers: list[RollerLoads], params: dict[str, float], target_ln: float) -> float:
    """Amplitude whose largest |ln(k/k_tripp)| is `target_ln` (bisection in log amp, clipped to the range)."""
    lo, hi = np.log(family.amp_range[0]), np.log(family.amp_range[1])
    if _ln_ratio_max(family, rollers, params, float(np.exp(hi))) <= target_ln:
        return float(np.exp(hi))
    if _ln_ratio_max(family, rollers, params, float(np.exp(lo))) >= target_ln:
        return float(np.exp(lo))
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if _ln_ratio_max(family, rollers, params, float(np.exp(mid))) < target_ln:
            lo = mid
        else:
            hi = mid
    return float(np.exp(0.5 * (lo + hi)))


def _components(scenario: str, rng: np.random.Generator) -> tuple[list[str], list[str]]:
    """(hidden physical effects, calibration errors) of a scenario."""
    if scenario == "none":
        return [], []
    if scenario in PHYSICAL or scenario.startswith("outside_"):
        return [scenario], []
    if scenario in CALIBRATION:
        return [], [scenario]
    if scenario in PAIRS:
        return list(PAIRS[scenario]), []
    if scenario == "physical+calibration":
        return [str(rng.choice(list(PHYSICAL)))], [str(rng.choice(CALIBRATION))]
    raise ValueError(f"scenario {scenario!r} unknown; expected one of {', '.join(SCENARIOS)}")


def _families_of(effect: str) -> list[Family]:
    return [OUTSIDE[effect.removeprefix("outside_")]] if effect.startswith("outside_") else PHYSICAL[effect]


def _calibration(name: str, rng: np.random.Generator) -> dict[str, float]:
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if name == "load_gain":
        return {"gain": float(rng.uniform(1.02, 1.10) if sign > 0 else rng.uniform(0.92, 0.98))}
    if name == "load_offset":
        return {"offset_n": sign * float(rng.uniform(5.0, 25.0))}
    return {"scale": 1.0 + sign * float(rng.uniform(0.05, 0.15))}


def _world_loads(rng: np.random.Generator, specs: dict, rail, preload_n: float) -> dict[int, np.ndarray]:
    """True loads (repetition x step) per type: evenly spaced knob steps with a little scatter per repetition."""
    loads = {}
    for t in ROLLER_TYPES:
        f_max = MAX_LOAD_SHARE * static_rating_n(specs[t], rail)
        base = np.linspace(preload_n, f_max, LOAD_STEPS)
        jitter = rng.uniform(-0.03, 0.03, size=(REPETITIONS, LOAD_STEPS)) * (base[1] - base[0])
        jitter[:, 0] = 0.0
        loads[t] = base[None, :] + jitter
    return loads


def generate(scenario: str, seed: int, noise_scale: float, families: dict[str, str] | None = None) -> BlindDataset:
    """One world: the rows of its stiffness table and its truth. `families` pins an effect's family by name."""
    world, noise_rng = _rng(scenario, seed, 0), _rng(scenario, seed, 1)
    specs, mats = load_rollers(), load_materials()
    rail = mats[RAIL_MATERIAL]
    noise = {"a": float(world.uniform(0.008, 0.02)), "b": float(world.uniform(0.005, 0.03)),
             "c": float(world.uniform(0.5, 1.5)), "seat_sigma": float(world.uniform(0.003, 0.01)),
             "preload_n": PRELOAD_N * float(world.uniform(0.97, 1.03))}
    smooth = [int(t) for t in world.choice(ROLLER_TYPES, size=2, replace=False)] if world.random() < 0.35 else []
    ra = {t: RA_SMOOTH_UM if t in smooth else RA_ROUGH_UM for t in ROLLER_TYPES}
    loads = _world_loads(world, specs, rail, noise["preload_n"])
    rollers = [RollerLoads(specs[t], rail, ra[t], loads[t].ravel()) for t in ROLLER_TYPES]
    sigma_med1 = float(np.median(np.concatenate([_sigma_rel(r.load_n, noise) for r in rollers])))

    effects, calib = _components(scenario, world)
    ln_ratio = [np.zeros_like(r.load_n) for r in rollers]
    family_of, params_of, target_of, size_of = {}, {}, {}, {}
    for effect in effects:
        options = _families_of(effect)
        pinned = (families or {}).get(effect)
        fam = next(f for f in options if f.name == pinned) if pinned else options[int(world.integers(len(options)))]
        params = fam.draw(world, rollers)
        small = world.random() < SMALL_SHARE
        z = float(np.exp(world.uniform(np.log(0.5), np.log(3.0)) if small else world.uniform(np.log(3), np.log(15))))
        if fam.natural_range is not None and world.random() < 0.5:
            amp = float(np.exp(world.uniform(*np.log(fam.natural_range))))
        else:
            amp = _amp_for_size(fam, rollers, params, z * sigma_med1)
        for i, r in enumerate(rollers):
            ln_ratio[i] += np.log(fam.apply(r, params, amp) / r.tripp())
        name = "outside_library" if effect.startswith("outside_") else effect
        family_of[name], params_of[name], target_of[name] = fam.name, {**params, "amp": amp}, z
        size_of[name] = _ln_ratio_max(fam, rollers, params, amp) / (sigma_med1 * noise_scale)

    cal = {name: _calibration(name, world) for name in calib}
    k_scale = cal.get("modulus_scale", {}).get("scale", 1.0)
    gain = cal.get("load_gain", {}).get("gain", 1.0)
    offset = cal.get("load_offset", {}).get("offset_n", 0.0)
    faults = _draw_faults(world)

    for name in calib:  # a calibration error alone: the true Tripp read at the reported load (and scale)
        one = {"load_gain": (1.0, gain, 0.0), "load_offset": (1.0, 1.0, offset),
               "modulus_scale": (k_scale, 1.0, 0.0)}[name]
        size_of[name] = max(float(np.max(np.abs(np.log(one[0] * r.tripp() / r.tripp(
            load_n=one[1] * r.load_n + one[2]))))) for r in rollers) / (sigma_med1 * noise_scale)
    rows, all_ln, sigma_pts = [], [], []
    for i, (t, r) in enumerate(zip(ROLLER_TYPES, rollers, strict=True)):
        k_clean = r.tripp() * np.exp(ln_ratio[i]) * k_scale
        f_rep = gain * r.load_n + offset
        all_ln.append(np.log(k_clean / r.tripp(load_n=f_rep)))
        s_pt = _sigma_rel(r.load_n, noise) * noise_scale
        sigma_pts.append(s_pt)
        seat = noise_rng.normal(0.0, noise["seat_sigma"] * noise_scale, REPETITIONS)
        k_obs = k_clean * np.exp(np.repeat(seat, LOAD_STEPS) + s_pt * noise_rng.normal(size=s_pt.size))
        s_tot = np.hypot(s_pt, noise["seat_sigma"] * noise_scale)
        for j in range(r.load_n.size):
            rep, step = divmod(j, LOAD_STEPS)
            k = float(k_obs[j])
            if faults["outliers"] and t == faults["outliers"]["roller_type"] and step == faults["outliers"]["step"]:
                k *= faults["outliers"]["factors"][faults["outliers"]["repetitions"].index(rep + 1)] \
                    if rep + 1 in faults["outliers"]["repetitions"] else 1.0
            rows.append(_row(r, t, rep + 1, float(f_rep[j]), k, float(s_tot[j]) * k))
    if faults["duplicate_row"] is not None:
        rows.insert(faults["duplicate_row"] + 1, dict(rows[faults["duplicate_row"]]))

    c_median = float(np.median(np.concatenate(sigma_pts)))
    truth = {
        "scenario": scenario, "seed": seed, "noise_scale": noise_scale,
        "effects": ["outside_library" if e.startswith("outside_") else e for e in effects],
        "measurement_effects": list(calib),
        "outside_library": any(e.startswith("outside_") for e in effects),
        "outside_effect": next((e.removeprefix("outside_") for e in effects if e.startswith("outside_")), None),
        "family": family_of, "params": {**params_of, **cal}, "target_size_sigma_at_scale_1": target_of,
        "size_sigma": float(np.max(np.abs(np.concatenate(all_ln)))) / c_median,
        "size_sigma_by_effect": size_of,
        "median_sigma_rel": c_median,
        "noise": {**noise, "scale": noise_scale},
        "rail_ra_um_by_type": {str(t): ra[t] for t in ROLLER_TYPES},
        "max_load_n_by_type": {str(t): float(loads[t].max()) for t in ROLLER_TYPES},
        "faults": faults, "rail_material": RAIL_MATERIAL,
        "combination": "effects multiply k (their ln k/k_tripp add); modulus_scale multiplies k; "
                       "load_gain/load_offset change the reported load only",
    }
    return BlindDataset(rows, truth)


def _draw_faults(rng: np.random.Generator) -> dict[str, Any]:
    """Optional faults: two gross outliers at one step of one type; one duplicated row (index before insertion)."""
    outliers = None
    if rng.random() < 0.3:
        reps = sorted(int(x) for x in rng.choice(np.arange(1, REPETITIONS + 1), size=2, replace=False))
        outliers = {"roller_type": int(rng.choice(ROLLER_TYPES)), "step": int(rng.integers(LOAD_STEPS)),
                    "repetitions": reps,
                    "factors": [float(1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.08, 0.15)) for _ in reps]}
    n = len(ROLLER_TYPES) * REPETITIONS * LOAD_STEPS
    duplicate = int(rng.integers(n)) if rng.random() < 0.2 else None
    return {"outliers": outliers, "duplicate_row": duplicate}


def _row(r: RollerLoads, t: int, rep: int, load_n: float, k: float, k_std: float) -> dict[str, Any]:
    return {"roller_type": t, "diameter_mm": round(r.spec.diameter_m * 1e3, 6),
            "contact_length_mm": round(r.spec.contact_length_m * 1e3, 6),
            "roller_length_mm": round(r.spec.total_length_m * 1e3, 6), "material": r.spec.material.name,
            "rail_material": r.rail.name, "rail_ra_um": r.rail_ra_um, "repetition": rep,
            "load_n": float(f"{load_n:.6g}"), "stiffness_n_per_m": float(f"{k:.7g}"),
            "stiffness_std_n_per_m": float(f"{k_std:.4g}")}


def write(dataset: BlindDataset, out: Path, stem: str) -> None:
    """`stem`.csv (the table) and `stem`.json (the truth) under `out`."""
    with (out / f"{stem}.csv").open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(dataset.rows)
    (out / f"{stem}.json").write_text(json.dumps(dataset.truth, indent=1) + "\n", encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="directory for <scenario>_<seed>_<noise>.csv/.json")
    ap.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 per scenario")
    ap.add_argument("--noise", type=float, nargs="+", default=[0.5, 1.0, 2.0], help="noise scale factors")
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    ap.add_argument("--summary", action="store_true", help="print the share of effects >= 3 sigma per scenario")
    args = ap.parse_args(argv)
    if args.seeds < 1 or any(not n > 0 for n in args.noise):
        print("discrepancy_worlds: --seeds must be >= 1 and --noise factors > 0", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for scenario in args.scenarios:
        sizes = []
        for seed in range(args.seeds):
            for noise in args.noise:
                ds = generate(scenario, seed, noise)
                write(ds, args.out, f"{scenario}_{seed}_{noise:g}")
                sizes.append(ds.truth["size_sigma"])
        if args.summary:
            big = np.mean(np.array(sizes) >= 3.0)
            print(f"{scenario:32s} n={len(sizes):3d}  size_sigma median {np.median(sizes):6.2f}  >=3σ {big:5.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
