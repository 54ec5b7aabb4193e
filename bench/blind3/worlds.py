"""Third blind judge: hidden-effect stiffness campaigns with varied structure and a rig-side noise model.

Run: PYTHONPATH=$PWD python bench/blind3/worlds.py --out DIR --seeds N --noise 0.5 1 2 [--summary]
"""

from __future__ import annotations

import argparse
import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench.blind3 import laws
from bench.blind3.contact import load_catalogue, static_rating_n
from bench.blind3.model import Effects, Unit, amplification, bounce_hz, rig_processing, roller_k, unit_law

PHYSICAL = ("surface_roughness", "end_effects", "material_hardness", "misalignment", "setup_compliance")
# scenario -> effect slots: a label, or "physical" / "measurement" for one drawn from that group
SCENARIO_SLOTS: dict[str, tuple[str, ...]] = {
    "roughness": ("surface_roughness",),
    "end": ("end_effects",),
    "hardness": ("material_hardness",),
    "misalignment": ("misalignment",),
    "setup": ("setup_compliance",),
    "outside": ("outside_library",),
    "calibration": ("measurement",),
    "pair_roughness_end": ("surface_roughness", "end_effects"),
    "pair_roughness_misalignment": ("surface_roughness", "misalignment"),
    "pair_physical_measurement": ("physical", "measurement"),
    "null": (),
    "null_outliers": (),
}
SCENARIOS: tuple[str, ...] = tuple(SCENARIO_SLOTS)
COLUMNS = ("diameter_mm", "contact_length_mm", "rail_ra_um", "load_n", "stiffness_n_per_m", "roller_type",
           "roller_length_mm", "material", "repetition", "rail_material", "stiffness_std_n_per_m")
ROLLERS, MATERIALS = load_catalogue()
RAIL = "1.3505"


@dataclass
class BlindDataset:
    """One world: the CSV rows (contract columns only) and the truth that made them."""

    rows: list[dict[str, Any]]
    truth: dict[str, Any] = field(default_factory=dict)


@dataclass
class Campaign:
    """The campaign's structure: units, their seatings and steps in the rig's order of work."""

    units: list[Unit]
    reps: list[int]
    unit: np.ndarray  # per point, in time order
    rep: np.ndarray
    load: np.ndarray  # true load per roller, N
    preload: np.ndarray  # that seating's preload, N
    in_seat: np.ndarray  # 0 at a seating's first step, 1 at its last
    tau: np.ndarray  # campaign time 0..1
    design: list[dict[str, Any]]


def _pick_units(rng: np.random.Generator, scenario: str) -> list[tuple[int, float]]:
    """Roller types and rail roughness: mostly steel on Ra 0.2, sometimes Ra 0.03 rails or an odd material."""
    n = int(rng.integers(3, 8))
    odd_p = 0.6 if scenario in ("hardness", "calibration") else 0.35
    smooth_p = 0.5 if scenario.startswith(("roughness", "pair_roughness")) else 0.25
    chosen: list[tuple[int, float]] = []
    if rng.random() < odd_p:
        chosen.append((int(rng.choice([8, 9])), 0.2))
    steel = [int(t) for t in rng.permutation(np.arange(1, 8))]
    if "misalignment" in scenario and rng.random() < 0.8:  # a long roller shows a tilt (gap ∝ length)
        long_t = int(rng.choice([3, 4, 6]))
        steel = [long_t] + [t for t in steel if t != long_t]
    if rng.random() < smooth_p:
        chosen.append((steel[0], 0.03))
        if n >= 5 and rng.random() < 0.5:
            chosen.append((steel[1], 0.03))
    for t in steel:
        if len(chosen) >= n:
            break
        chosen.append((t, 0.2))
    return [chosen[i] for i in rng.permutation(len(chosen))]


def _campaign(rng: np.random.Generator, scenario: str) -> Campaign:
    """Draw the structure: seatings per type, nut-turn load steps on a stiffening spring, the order of work."""
    picks = _pick_units(rng, scenario)
    base_reps = int(rng.integers(2, 5))
    cols: dict[str, list[Any]] = {k: [] for k in ("unit", "rep", "load", "preload", "in_seat")}
    units, reps, design = [], [], []
    for i, (t, ra) in enumerate(picks):
        r = ROLLERS[t]
        u = Unit(i, r, MATERIALS[r.material], MATERIALS[RAIL], ra)
        c0 = static_rating_n(r, u.mroll, u.mrail)
        top = c0 * rng.uniform(0.2, 0.35)
        pre = min(rng.uniform(25.0, 60.0), 0.45 * top)
        n_steps = int(rng.integers(6, 15))
        gamma = rng.uniform(0.1, 0.5)  # the spring's rate stiffens with compression
        n_rep = int(np.clip(base_reps + (rng.integers(-1, 2) if rng.random() < 0.3 else 0), 2, 4))
        for rep in range(1, n_rep + 1):
            turns = np.concatenate([[0.0], np.cumsum(1.0 + rng.normal(0.0, 0.04, n_steps - 1))]) / (n_steps - 1)
            f0 = pre + rng.normal(0.0, 1.0)
            cols["load"] += list(f0 + (top - pre) * (turns + gamma * turns**2) / (1.0 + gamma))
            cols["preload"] += [f0] * n_steps
            cols["in_seat"] += list(np.linspace(0.0, 1.0, n_steps))
            cols["unit"] += [i] * n_steps
            cols["rep"] += [rep] * n_steps
        units.append(u)
        reps.append(n_rep)
        design.append({"roller_type": t, "rail_ra_um": ra, "material": r.material, "repetitions": n_rep,
                       "steps": n_steps, "preload_n": round(pre, 2), "top_n": round(top, 1), "c0_n": round(c0, 1),
                       "spring_stiffening": round(gamma, 3)})
    n = len(cols["load"])
    return Campaign(units, reps, np.array(cols["unit"]), np.array(cols["rep"]), np.array(cols["load"]),
                    np.array(cols["preload"]), np.array(cols["in_seat"]), np.linspace(0.0, 1.0, n), design)


def _effects(rng: np.random.Generator, scenario: str, camp: Campaign) -> Effects:
    """Draw the scenario's effects and one family each, with physically ranged parameters."""
    eff: Effects = {}
    top = float(camp.load.max())
    for slot in SCENARIO_SLOTS[scenario]:
        label = slot
        if slot == "physical":
            label = str(rng.choice(PHYSICAL))
        elif slot == "measurement":
            label = str(rng.choice(laws.MEASUREMENT))
        fam = str(rng.choice(list(laws.FAMILIES[label])))
        prm = laws.draw_params(fam, rng, camp.reps, top)
        if fam == "roller_material_modulus":
            odd = [u.mroll.name for u in camp.units if u.mroll.name != RAIL]
            prm["material"] = odd[0] if odd else RAIL
        eff[label] = (fam, prm)
    return eff


@dataclass
class Noise:
    """The rig's noise: frequency resolution, seating, thermal drift, load cell, heavy tails (unit draws)."""

    sigma_f_hz: float
    seat_rel: float
    drift_rel: float
    load_rel: float
    nu: float  # Student-t degrees of freedom of the frequency error (0: Gaussian)
    mass_kg: float
    z_f: np.ndarray
    z_seat: np.ndarray
    z_load: np.ndarray
    drift: np.ndarray  # smooth shape along the campaign, max |.| = 1
    warm: np.ndarray  # rig temperature 0..1 along the campaign


def _noise(rng: np.random.Generator, camp: Campaign) -> Noise:
    """Draw the noise amplitudes and every standard draw once, so the world is the same at any noise scale."""
    n = camp.load.size
    nu = float(rng.integers(3, 9)) if rng.random() < 0.4 else 0.0
    z_f = rng.standard_t(nu, n) / np.sqrt(nu / (nu - 2.0)) if nu else rng.standard_normal(n)
    tau_t = rng.uniform(0.3, 1.5)
    warm = (1.0 - np.exp(-camp.tau / tau_t)) / (1.0 - np.exp(-1.0 / tau_t))
    shape = (2.0 * warm - 1.0) * rng.uniform(0.5, 1.0) + rng.uniform(0.0, 0.5) * np.sin(
        2 * np.pi * camp.tau + rng.uniform(0, 2 * np.pi))
    shape = shape * rng.choice([-1.0, 1.0]) / np.abs(shape).max()
    z_seat = rng.standard_normal((len(camp.units), 5))
    return Noise(rng.uniform(0.3, 2.0), rng.uniform(0.002, 0.01), rng.uniform(0.0005, 0.003),
                 rng.uniform(0.002, 0.01), nu, rng.uniform(10.5, 12.5), z_f, z_seat[camp.unit, camp.rep - 1],
                 rng.standard_normal(n), shape, warm)


def _clean(camp: Campaign, eff: Effects, noise: Noise) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free reported stiffness and reported load of every point under the given effects."""
    k = np.empty(camp.load.size)
    for u in camp.units:
        m = camp.unit == u.index
        k[m] = roller_k(u, unit_law(u, eff), eff, camp.load[m], camp.rep[m])
    k = rig_processing(k, camp.load, eff)
    rep_load = camp.load
    for label in ("load_gain", "load_offset"):
        if label in eff:
            fam, prm = eff[label]
            rep_load = laws.reported_load(fam, prm, camp.load, 1.25 * float(camp.load.max()), camp.preload,
                                          camp.in_seat, noise.warm)
    return k, np.maximum(rep_load, 1.0)


def _tripp(camp: Campaign, load: np.ndarray) -> np.ndarray:
    """The lab's Tripp baseline at each point's load."""
    out = np.empty(load.size)
    for u in camp.units:
        m = camp.unit == u.index
        out[m] = u.tripp(load[m])
    return out


def _sigma_rel(camp: Campaign, noise: Noise, k: np.ndarray) -> np.ndarray:
    """Each point's relative σ of ln k at noise 1, all sources (frequency, seating, drift, load via the slope)."""
    f = bounce_hz(k, noise.mass_kg)
    fit = 2.0 * noise.sigma_f_hz / f * amplification(k)
    slope = np.log(_tripp(camp, camp.load * 1.01) / _tripp(camp, camp.load)) / np.log(1.01)
    drift_rms = noise.drift_rel * float(np.sqrt(np.mean(noise.drift**2)))
    return np.sqrt(fit**2 + noise.seat_rel**2 + drift_rms**2 + (noise.load_rel * slope) ** 2)


def _size(camp: Campaign, eff: Effects, noise: Noise, med_sigma: float) -> float:
    """Largest |ln(k / Tripp at the reported load)| of the effects, noise-free, in median point σ."""
    k, rep = _clean(camp, eff, noise)
    return float(np.max(np.abs(np.log(k / _tripp(camp, rep))))) / med_sigma


def _tune(camp: Campaign, eff: Effects, noise: Noise, label: str, target: float, med: float) -> None:
    """Scale one effect's amplitude (within its physical range) toward a target size in σ: bracketed secant in logs."""
    fam, prm = eff[label]
    lo, hi = np.log(laws.AMP_RANGE[fam])

    def miss(x: float) -> float:
        prm["amp"] = float(np.exp(x))
        size = _size(camp, {label: (fam, prm)}, noise, med)
        return float(np.log(max(size, 1e-9) / target))

    x = float(np.log(prm["amp"]))
    y = miss(x)
    below: tuple[float, float] | None = (x, y) if y < 0 else None
    above: tuple[float, float] | None = (x, y) if y >= 0 else None
    best = (abs(y), x)
    for _ in range(7):
        if abs(y) < 0.05:
            break
        if below and above:
            (x1, y1), (x2, y2) = below, above
            xn = x1 - y1 * (x2 - x1) / (y2 - y1) if y2 != y1 else 0.5 * (x1 + x2)
            xn = float(np.clip(xn, x1 + 0.1 * (x2 - x1), x2 - 0.1 * (x2 - x1)))
        else:
            xn = float(np.clip(x - float(np.clip(y, -2.5, 2.5)), lo, hi))
            if abs(xn - x) < 1e-9:
                break
        x, y = xn, miss(xn)
        best = min(best, (abs(y), x))
        if y < 0:
            below = (x, y)
        else:
            above = (x, y)
    prm["amp"] = float(np.exp(best[1]))


def generate(scenario: str, seed: int, noise_scale: float) -> BlindDataset:
    """One world: the same campaign and effects at every noise scale, only the noise amplitude changes."""
    rng = np.random.default_rng([seed, SCENARIOS.index(scenario), 3])
    camp = _campaign(rng, scenario)
    eff = _effects(rng, scenario, camp)
    noise = _noise(rng, camp)
    targets = {lab: float(rng.uniform(1.2, 2.8) if rng.random() < 0.2 else np.exp(rng.uniform(1.25, 2.7)))
               for lab in eff}
    with_std = bool(rng.random() < 0.5)
    n = camp.load.size
    keep = np.ones(n, bool)
    if rng.random() < 0.5:
        keep[rng.choice(np.arange(1, n), int(rng.integers(1, 3)), replace=False)] = False
    faults: list[str] = []
    out_unit, out_step, out_sign = int(rng.integers(len(camp.units))), rng.uniform(0.08, 0.15, 2), rng.choice(
        [-1.0, 1.0], 2)
    dup = int(rng.integers(n))
    if scenario == "null_outliers":
        faults.append("outliers")
    if rng.random() < (0.5 if scenario == "null_outliers" else 0.1):
        faults.append("duplicate_row")
    med0 = float(np.median(_sigma_rel(camp, noise, _tripp(camp, camp.load))))
    for lab in eff:
        _tune(camp, eff, noise, lab, targets[lab], med0)
    k, rep_load = _clean(camp, eff, noise)
    sig = _sigma_rel(camp, noise, k)
    med = float(np.median(sig))
    by_effect = {lab: round(_size(camp, {lab: eff[lab]}, noise, med) / noise_scale, 3) for lab in eff}
    size = float(np.max(np.abs(np.log(k / _tripp(camp, rep_load))))) / med / noise_scale if eff else 0.0
    s = noise_scale
    fit = 2.0 * noise.sigma_f_hz / bounce_hz(k, noise.mass_kg) * amplification(k)
    k_meas = k * np.exp(s * (fit * noise.z_f + noise.seat_rel * noise.z_seat + noise.drift_rel * noise.drift))
    load_meas = rep_load * (1.0 + s * noise.load_rel * noise.z_load)
    outlier_idx: list[int] = []
    if "outliers" in faults:
        u_steps = camp.design[out_unit]["steps"]
        step = int(rng.integers(1, u_steps))
        idx = np.flatnonzero((camp.unit == out_unit) & (np.round(camp.in_seat * (u_steps - 1)) == step))[:2]
        k_meas[idx] *= 1.0 + out_sign[: idx.size] * out_step[: idx.size]
        keep[idx] = True
        outlier_idx = [int(i) for i in idx]
    rows = []
    for i in np.flatnonzero(keep):
        u = camp.units[camp.unit[i]]
        row = {"diameter_mm": round(u.roller.d_m * 1e3, 4), "contact_length_mm": round(u.roller.lwe_m * 1e3, 4),
               "rail_ra_um": u.ra_um, "load_n": round(float(load_meas[i]), 3),
               "stiffness_n_per_m": round(float(k_meas[i]), 1), "roller_type": u.roller.type,
               "roller_length_mm": round(u.roller.lr_m * 1e3, 4), "material": u.mroll.name,
               "repetition": int(camp.rep[i]), "rail_material": u.mrail.name}
        if with_std:
            row["stiffness_std_n_per_m"] = round(float(k_meas[i] * s * fit[i]), 1)
        rows.append(row)
    row_of = {int(i): n for n, i in enumerate(np.flatnonzero(keep))}
    outlier_rows = [row_of[i] for i in outlier_idx]
    if "duplicate_row" in faults:
        j = min(dup, len(rows) - 1)
        rows.insert(j + 1, dict(rows[j]))
        outlier_rows = [r + 1 if r > j else r for r in outlier_rows]
    truth = {
        "scenario": scenario, "seed": seed, "noise_scale": noise_scale,
        "effects": [lab for lab in eff if lab not in laws.MEASUREMENT],
        "measurement_effects": [lab for lab in eff if lab in laws.MEASUREMENT],
        "outside_library": "outside_library" in eff,
        "family": {lab: fam for lab, (fam, _) in eff.items()},
        "params": {lab: prm for lab, (_, prm) in eff.items()},
        "size_sigma": round(size, 3), "size_sigma_by_effect": by_effect,
        "target_size_sigma_at_noise_1": {lab: round(t, 3) for lab, t in targets.items()},
        "faults": faults, "outlier_rows": outlier_rows,
        "design": {"units": camp.design, "points": int(keep.sum()), "missing": [int(i) for i in np.flatnonzero(~keep)],
                   "order": "units one after another, seatings in turn, loads ascending"},
        "noise": {"sigma_f_hz": noise.sigma_f_hz * s, "seating_rel": noise.seat_rel * s,
                  "drift_rel_max": noise.drift_rel * s, "load_rel": noise.load_rel * s,
                  "student_t_nu": noise.nu or None, "disc_mass_kg": noise.mass_kg,
                  "median_sigma_rel": med * s, "std_column": with_std},
    }
    return BlindDataset(rows, truth)


def write(ds: BlindDataset, stem: Path) -> None:
    """Write one world as SCENARIO_sSEED_nNOISE.csv and .truth.json."""
    cols = [c for c in COLUMNS if c in ds.rows[0]]
    with open(stem.with_suffix(".csv"), "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, cols, lineterminator="\n")
        w.writeheader()
        w.writerows(ds.rows)
    stem.with_suffix(".truth.json").write_text(json.dumps(ds.truth, indent=1, sort_keys=True) + "\n")


def main(argv: list[str] | None = None) -> None:
    """CLI: write every scenario × seed × noise world, optionally print the size summary."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--noise", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    ap.add_argument("--summary", action="store_true")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    sizes: dict[tuple[str, float], list[float]] = {}
    for sc in SCENARIOS:
        for seed in range(args.seeds):
            for ns in args.noise:
                ds = generate(sc, seed, ns)
                write(ds, args.out / f"{sc}_s{seed}_n{ns:g}")
                sizes.setdefault((sc, ns), []).append(ds.truth["size_sigma"])
    if args.summary:
        print(f"{'scenario':30s} {'noise':>5s} {'median size/σ':>14s} {'share ≥3σ':>10s}")
        for (sc, ns), v in sizes.items():
            arr = np.array(v)
            print(f"{sc:30s} {ns:5g} {np.median(arr):14.2f} {np.mean(arr >= 3.0):10.2f}")


if __name__ == "__main__":
    main()
