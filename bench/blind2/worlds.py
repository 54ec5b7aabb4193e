"""Second blind judge: stiffness tables with one known hidden cause, for labctl's discrepancy workflow.

`generate(scenario, seed, noise_scale)` returns a `BlindDataset` (CSV rows + truth); the CLI writes them:
`PYTHONPATH=$PWD python bench/blind2/worlds.py --out DIR --seeds N --noise 0.5 1 2 [--summary]`.
Physics draws use their own random stream, so a seed gives the same world at every noise scale.
"""

from __future__ import annotations

import argparse
import csv
import json
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.blind2.contact import RAIL, Line, load_catalogue, load_steps, rating_c0_n
from bench.blind2.families import Cfg, Ctx, Family, families_of
from bench.blind2.noise import NoiseModel, log_slope

LIBRARY = ["surface_roughness", "end_effects", "material_hardness", "misalignment", "setup_compliance"]
SCENARIOS: dict[str, list[str]] = {
    "roughness": ["surface_roughness"],
    "end_effects": ["end_effects"],
    "hardness": ["material_hardness"],
    "misalignment": ["misalignment"],
    "setup": ["setup_compliance"],
    "outside_library": ["outside_library"],
    "calibration": ["calibration"],
    "roughness+end_effects": ["surface_roughness", "end_effects"],
    "roughness+misalignment": ["surface_roughness", "misalignment"],
    "physical+calibration": ["physical", "calibration"],
    "null": [],
    "null_outliers": [],
}
REPS, STEPS = 3, 11
COLUMNS = ["roller_type", "diameter_mm", "contact_length_mm", "roller_length_mm", "material", "rail_material",
           "rail_ra_um", "repetition", "load_n", "stiffness_n_per_m", "stiffness_std_n_per_m"]


@dataclass
class BlindDataset:
    """CSV rows (dicts keyed by COLUMNS) and the hidden truth."""

    rows: list[dict]
    truth: dict


@dataclass
class Applied:
    """One physical effect as drawn: its family, shape parameters and strength."""

    fam: Family
    params: dict
    s: float


def _configs(effects: list[str], rng: np.random.Generator) -> list[tuple[int, float]]:
    """Seven (type, rail Ra µm): types 1-7 on Ra 0.2, with smooth-rail or Si3N4/stainless swaps."""
    cfgs = [(t, 0.2) for t in range(1, 8)]
    if "surface_roughness" in effects or rng.random() < 0.4:
        cfgs[int(rng.choice([1, 4]))] = (int(rng.choice([1, 3])), 0.03)  # type 2 or 5 slot → smooth rail
    if "material_hardness" in effects or rng.random() < 0.4:
        cfgs[6] = (9 if "material_hardness" in effects or rng.random() < 0.5 else 8, 0.2)
    return cfgs


def _context(cfg_list: list[tuple[int, float]], rng: np.random.Generator) -> Ctx:
    rollers, mats = load_catalogue()
    rail = mats[RAIL]
    cfgs = [Cfg(rollers[t], ra * 1e-6, Line(rollers[t].radius_m, rollers[t].material, rail)) for t, ra in cfg_list]
    preload = rng.uniform(36.0, 40.0)
    loads = np.empty((len(cfgs), REPS, STEPS))
    for i, c in enumerate(cfgs):
        nominal = load_steps(rating_c0_n(c.roller, rail), preload, rng)
        for r in range(REPS):
            jitter = np.r_[0.0, rng.normal(0.0, 0.01, STEPS - 1)]
            loads[i, r] = nominal * (1.0 + jitter)
    step = np.broadcast_to(np.arange(STEPS), loads.shape).copy()
    tau = np.arange(loads.size).reshape(loads.shape) / (loads.size - 1.0)
    return Ctx(cfgs, loads, step, tau)


def contact_k(ctx: Ctx, applied: list[Applied]) -> np.ndarray:
    """True stiffness at the true loads: one law (or Tripp), times factors, in series with compliances."""
    laws = [a for a in applied if a.fam.stage == "law"]
    k = laws[0].fam.fn(ctx, laws[0].params, laws[0].s) if laws else ctx.tripp()
    for a in applied:
        if a.fam.stage == "factor":
            k = k * np.exp(a.fam.fn(ctx, a.params, a.s))
    comp = 1.0 / k
    for a in applied:
        if a.fam.stage == "series":
            comp = comp + a.fam.fn(ctx, a.params, a.s)
    return 1.0 / comp


def _tripp_at(ctx: Ctx, load_n: np.ndarray) -> np.ndarray:
    return Ctx(ctx.cfgs, load_n, ctx.step, ctx.tau).tripp()


def _measure(ctx: Ctx, k: np.ndarray, cal: dict | None) -> tuple[np.ndarray, np.ndarray]:
    """(reported load, stiffness) once a calibration error acts; modulus_scale: the true moduli differ."""
    f = ctx.load_n
    if cal is None:
        return f, k
    fam, v = cal["family"], cal["value"]
    if fam == "linear_gain":
        return v * f, k
    if fam == "quadratic_load_cell":
        return f * (1.0 + v * f / cal["full_scale_n"]), k
    if fam == "offset":
        return f + v, k
    scaled = Ctx([Cfg(c.roller, c.rail_ra_m, Line(c.line.radius_m, c.line.roller, c.line.rail, v)) for c in ctx.cfgs],
                 f, ctx.step, ctx.tau)
    return f, k * scaled.tripp() / ctx.tripp()


def _draw_calibration(rng: np.random.Generator, ctx: Ctx) -> dict:
    # gains are weighted down: k_Tripp depends on load only logarithmically, so a gain world is ~1 σ by nature
    kind = str(rng.choice(["linear_gain", "quadratic_load_cell", "offset", "modulus"], p=[0.2, 0.15, 0.35, 0.3]))
    sign = rng.choice([-1.0, 1.0])
    if kind == "linear_gain":
        v = float(rng.uniform(0.92, 0.98) if sign < 0 else rng.uniform(1.03, 1.10))
        return {"label": "load_gain", "family": kind, "value": v}
    if kind == "quadratic_load_cell":
        return {"label": "load_gain", "family": kind, "value": float(sign * rng.uniform(0.04, 0.10)),
                "full_scale_n": float(ctx.load_n.max())}
    if kind == "offset":
        return {"label": "load_offset", "family": kind, "value": float(sign * rng.uniform(5.0, 25.0))}
    return {"label": "modulus_scale", "family": kind, "value": float(1.0 + sign * rng.uniform(0.05, 0.15))}


def _amplitude(ctx: Ctx, applied: list[Applied], k0: np.ndarray) -> float:
    return float(np.max(np.abs(np.log(contact_k(ctx, applied) / k0))))


def _calibrate(ctx: Ctx, fam: Family, params: dict, target: float, k0: np.ndarray) -> float:
    """Strength s (bisection in ln s within the family's range) whose largest |ln k/k_Tripp| is the target."""
    lo, hi = np.log(fam.s_range[0]), np.log(fam.s_range[1])
    if _amplitude(ctx, [Applied(fam, params, float(np.exp(hi)))], k0) <= target:
        return float(np.exp(hi))
    for _ in range(28):
        mid = 0.5 * (lo + hi)
        if _amplitude(ctx, [Applied(fam, params, float(np.exp(mid)))], k0) > target:
            hi = mid
        else:
            lo = mid
    return float(np.exp(0.5 * (lo + hi)))


def _faults(scenario: str, rng: np.random.Generator) -> dict:
    heavy = scenario == "null_outliers"
    out: dict = {}
    if heavy or rng.random() < 0.1:
        out["outliers"] = {"cfg": int(rng.integers(7)), "step": int(rng.integers(STEPS)),
                           "reps": sorted(int(r) for r in rng.choice(REPS, 2, replace=False)),
                           "factors": [float(1 + rng.choice([-1, 1]) * rng.uniform(0.08, 0.15)) for _ in range(2)]}
    if heavy or rng.random() < 0.1:
        out["duplicate_row"] = int(rng.integers(7 * REPS * STEPS))
    return out


def generate(scenario: str, seed: int, noise_scale: float) -> BlindDataset:
    """One dataset of a scenario; physics and noise draws depend only on (scenario, seed)."""
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; expected one of {', '.join(SCENARIOS)}")
    if not noise_scale >= 0:
        raise ValueError(f"noise scale {noise_scale!r} must be ≥ 0")
    ss = np.random.SeedSequence([int(seed), zlib.crc32(scenario.encode())])
    rng, nrng = (np.random.default_rng(s) for s in ss.spawn(2))
    slots = list(SCENARIOS[scenario])
    if "physical" in slots:
        slots[slots.index("physical")] = str(rng.choice(LIBRARY))
    ctx = _context(_configs(slots, rng), rng)
    noise = NoiseModel.draw(rng)
    k0 = ctx.tripp()
    sig_med = float(np.median(noise.total_sigma(k0, ctx.load_n, log_slope(k0, ctx.load_n))))
    applied: list[Applied] = []
    cal = None
    for eff in slots:
        if eff == "calibration":
            cal = _draw_calibration(rng, ctx)
            continue
        fams = families_of(eff)
        fam = fams[int(rng.integers(len(fams)))]
        params = fam.draw(rng, ctx)
        z = rng.uniform(1.0, 2.8) if rng.random() < 0.25 else rng.uniform(3.5, 12.0)
        applied.append(Applied(fam, params, _calibrate(ctx, fam, params, z * sig_med, k0)))
    faults = _faults(scenario, rng)

    k_true = contact_k(ctx, applied)
    f_rep, k_meas = _measure(ctx, k_true, cal)
    slope = log_slope(k_meas, f_rep)
    sigma = noise.total_sigma(k_meas, f_rep, slope) * noise_scale
    k_obs = k_meas * noise.sample(nrng, k_meas, f_rep, slope, noise_scale)
    med = float(np.median(sigma)) if noise_scale > 0 else sig_med  # noiseless worlds: sizes at scale 1
    k_base = _tripp_at(ctx, f_rep)
    by_effect = {a.fam.effect: _amplitude(ctx, [a], k0) / med for a in applied}
    if cal is not None:
        f_c, k_c = _measure(ctx, k0, cal)
        by_effect[cal["label"]] = float(np.max(np.abs(np.log(k_c / _tripp_at(ctx, f_c))))) / med
    if "outliers" in faults:
        o = faults["outliers"]
        for r, fac in zip(o["reps"], o["factors"], strict=True):
            k_obs[o["cfg"], r, o["step"]] *= fac
    rows = _rows(ctx, f_rep, k_obs, sigma * k_obs)
    if "duplicate_row" in faults:
        rows.insert(faults["duplicate_row"] + 1, dict(rows[faults["duplicate_row"]]))
    truth = {
        "scenario": scenario, "seed": int(seed), "noise_scale": float(noise_scale),
        "effects": [a.fam.effect for a in applied],
        "measurement_effects": [cal["label"]] if cal else [],
        "outside_library": any(a.fam.effect == "outside_library" for a in applied),
        "family": {**{a.fam.effect: a.fam.name for a in applied}, **({cal["label"]: cal["family"]} if cal else {})},
        "why": {a.fam.effect: a.fam.why for a in applied},
        "params": {**{a.fam.effect: {"strength": a.s, **a.params} for a in applied},
                   **({cal["label"]: {k: v for k, v in cal.items() if k not in ("label", "family")}} if cal else {})},
        "size_sigma": float(np.max(np.abs(np.log(k_meas / k_base)))) / med,
        "size_sigma_by_effect": by_effect,
        "median_sigma_rel": med,
        "noise": noise.__dict__,
        "faults": faults,
        "configs": [{"roller_type": c.roller.type, "rail_ra_um": c.rail_ra_m * 1e6} for c in ctx.cfgs],
    }
    return BlindDataset(rows, truth)


def _rows(ctx: Ctx, f_rep: np.ndarray, k: np.ndarray, k_std: np.ndarray) -> list[dict]:
    rows = []
    for i, c in enumerate(ctx.cfgs):
        ro = c.roller
        for r in range(REPS):
            for j in range(STEPS):
                rows.append({
                    "roller_type": ro.type, "diameter_mm": round(ro.diameter_m * 1e3, 4),
                    "contact_length_mm": round(ro.contact_length_m * 1e3, 4),
                    "roller_length_mm": round(ro.total_length_m * 1e3, 4), "material": ro.material.name,
                    "rail_material": RAIL, "rail_ra_um": round(c.rail_ra_m * 1e6, 4), "repetition": r + 1,
                    "load_n": round(float(f_rep[i, r, j]), 4), "stiffness_n_per_m": float(f"{k[i, r, j]:.6g}"),
                    "stiffness_std_n_per_m": float(f"{k_std[i, r, j]:.4g}"),
                })
    return rows


def write_csv(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--noise", type=float, nargs="+", default=[1.0])
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=list(SCENARIOS))
    ap.add_argument("--summary", action="store_true", help="print size (in σ) per scenario and noise scale")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    sizes: dict[tuple[str, float], list[float]] = {}
    for sc in a.scenarios:
        for seed in range(a.seeds):
            for ns in a.noise:
                ds = generate(sc, seed, ns)
                stem = f"{sc}_s{seed}_n{ns:g}"
                write_csv(a.out / f"{stem}.csv", ds.rows)
                (a.out / f"{stem}.truth.json").write_text(json.dumps(ds.truth, indent=1))
                sizes.setdefault((sc, ns), []).append(ds.truth["size_sigma"])
    if a.summary:
        print(f"{'scenario':24s} {'noise':>5s} {'median size/σ':>14s} {'share ≥ 3σ':>10s}")
        for (sc, ns), v in sizes.items():
            print(f"{sc:24s} {ns:5g} {np.median(v):14.2f} {np.mean(np.array(v) >= 3):10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
