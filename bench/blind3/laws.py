"""The hidden-effect families of the third blind judge: one physics line each, parameter draws and the laws."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import erfc, ndtr

Params = dict[str, Any]

# effect -> family -> the physics in one line (the README's families table is printed from this)
FAMILIES: dict[str, dict[str, str]] = {
    "surface_roughness": {
        "asperity_flattening": "plastic asperity flattening: compliance ∝ Ra^q·exp(−p_mean/(β·H_soft)), in series",
        "abbott_closure": "bearing-area (Abbott) closure: Gaussian heights, carrying share tp = Φ(α√p_mean − z0), "
                          "layer compliance ∝ (1 − tp)/tp in series",
        "two_scale": "waviness + roughness: roughness ∝ Ra^q/(1 + p_mean/p_r) plus waviness bridged as "
                     "exp(−(a/λ_w)²), in series",
    },
    "end_effects": {
        "log_crown": "Lundberg log crown in the end zone beyond L_we: drop −h·ln(1 − (u/ℓ)²), slices engage "
                     "where the approach exceeds the drop (edges stiffen with load)",
        "dub_off": "dub-off of fixed radius R_d in the end zone: drop u²/(2R_d), slices engage with the approach",
        "plane_stress_ends": "free ends in plane stress: end zones of width η·R carry E instead of E/(1 − ν²), "
                             "L_eff = L_we − 2ηRν²",
    },
    "material_hardness": {
        "tabor_cube_root": "Tabor onset p0 > θ·H/3 of the softer body, conformity stiffening ∝ excess^(1/3)",
        "ludwik_layer": "work-hardening (Ludwik) layer above the onset: extra series compliance ∝ excess^(1/n)",
        "cavity_power": "Johnson cavity model above the onset: k ∝ (p0/p_on)^γ",
    },
    "misalignment": {
        "seating_wedge": "parallelism error between the two rails: a wedge re-drawn at each seating, slices",
        "twist_skew": "rail twist met by a cage skew: symmetric gap κ·x² per seating (longer rollers ∝ L²), slices",
        "spring_seat": "elastic rail seat tilting back with load: θ(F) = θ0·(1 − 3F/F_c), slices",
    },
    "setup_compliance": {
        "slip_lock_joint": "rail-disc friction joint that slips then locks: compliance falls by erfc in ln F",
        "hertz_seat_pair": "disc-rail bolt: two preloaded Hertz seats in series, compliance ∝ (F_b + 3F)^(−1/3)",
        "stress_stiffened_disc": "disc flexure with stress stiffening: compliance c0/(1 + 3F/F_ss)",
    },
    "outside_library": {
        "austenite_layer": "retained-austenite soft layer of depth h on the roller: E·(1 − d·exp(−a/h))",
        "isolation_tube": "the rubber isolation tube as a parallel spring on the bounce mode",
        "rail_depth": "rail supported deeper than the 3 mm evaluation depth: series 4(1−ν²)/(πE)·ln(t'/t)/L_we",
    },
    "load_gain": {
        "hysteresis_up": "load cell hysteresis: up-steps read high by h·FS·4u(1 − u)",
        "spring_increment": "load from the spring increment with a wrong rate: F0 + (F − F0)(1 + g)",
        "auto_range": "amplifier auto-range with a gain error on the upper range only",
    },
    "load_offset": {
        "retare_drift": "zero drifting within each seating, re-tared at the next: sawtooth offset",
        "missing_tare": "the top rails and cage not tared: reads low by their weight per roller",
        "thermal_zero": "zero shift following the rig temperature along the campaign",
    },
    "modulus_scale": {
        "rail_modulus": "the rails' real modulus differs from the catalogue's (rail material only)",
        "disc_mass": "the disc mass used in processing is off: K_total scaled, k through the K_setup correction",
        "roller_material_modulus": "one roller material's real modulus differs from the catalogue's",
    },
}
MEASUREMENT = ("load_gain", "load_offset", "modulus_scale")

# |amp| bounds: the physical range an amplitude may be tuned in
AMP_RANGE: dict[str, tuple[float, float]] = {
    "asperity_flattening": (2e-13, 8e-11), "abbott_closure": (1e-13, 4e-11), "two_scale": (2e-13, 8e-11),
    "log_crown": (0.03, 1.6), "dub_off": (0.03, 1.6), "plane_stress_ends": (0.02, 1.5),
    "tabor_cube_root": (0.001, 0.25), "ludwik_layer": (0.002, 3.0), "cavity_power": (0.002, 0.4),
    "seating_wedge": (5e-6, 4e-4), "twist_skew": (0.003, 0.8), "spring_seat": (5e-6, 4e-4),
    "slip_lock_joint": (3e-11, 2e-9), "hertz_seat_pair": (3e-11, 2e-9), "stress_stiffened_disc": (3e-11, 2e-9),
    "austenite_layer": (0.01, 0.3), "isolation_tube": (5e4, 2e7), "rail_depth": (0.03, 1.2),
    "hysteresis_up": (0.001, 0.04), "spring_increment": (0.005, 0.12), "auto_range": (0.005, 0.12),
    "retare_drift": (0.3, 25.0), "missing_tare": (0.3, 20.0), "thermal_zero": (0.3, 20.0),
    "rail_modulus": (0.005, 0.15), "disc_mass": (0.005, 0.1), "roller_material_modulus": (0.005, 0.15),
}


def draw_params(family: str, rng: np.random.Generator, seats: list[int], top_n: float) -> Params:
    """Draw one family's parameters (the amplitude 'amp' inside its physical range; per-seating draws by unit)."""
    lo, hi = AMP_RANGE[family]
    amp = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    sign = float(rng.choice([-1.0, 1.0]))
    per_seat = [[float(x) for x in rng.uniform(0.5, 1.5, n)] for n in seats]
    u = rng.uniform
    table: dict[str, Params] = {
        "asperity_flattening": {"beta": u(0.04, 0.12), "q": u(0.8, 1.3)},
        "abbott_closure": {"alpha": u(2.5, 4.0), "z0": u(1.5, 2.5), "q": u(0.6, 1.2)},
        "two_scale": {"q": u(0.8, 1.3), "p_r_pa": u(0.2e9, 0.6e9), "lam_m": u(15e-6, 40e-6), "w": u(0.3, 1.0)},
        "log_crown": {"h_m": u(0.5e-6, 4e-6)},
        "dub_off": {"r_d_m": u(0.1e-3, 1.5e-3)},
        "plane_stress_ends": {},
        "tabor_cube_root": {"theta": u(0.5, 0.8)},
        "ludwik_layer": {"theta": u(0.5, 0.8), "n": u(0.3, 0.6)},
        "cavity_power": {"theta": u(0.5, 0.8)},
        "seating_wedge": {"seat": per_seat},
        "twist_skew": {"seat": per_seat},
        "spring_seat": {"f_c_n": 3.0 * top_n * u(1.3, 2.5)},
        "slip_lock_joint": {"f_l_n": u(80.0, 600.0), "r_lock": u(0.2, 0.5), "w": u(0.3, 0.8)},
        "hertz_seat_pair": {"f_b_n": [u(2e3, 1e4), u(2e3, 1e4)], "share": u(0.3, 0.7)},
        "stress_stiffened_disc": {"f_ss_n": u(500.0, 5000.0)},
        "austenite_layer": {"h_m": u(5e-6, 25e-6)},
        "isolation_tube": {},
        "rail_depth": {},
        "hysteresis_up": {},
        "spring_increment": {"sign": sign},
        "auto_range": {"sign": sign, "switch": u(0.2, 0.5)},
        "retare_drift": {"sign": sign},
        "missing_tare": {},
        "thermal_zero": {"sign": sign},
        "rail_modulus": {"sign": sign},
        "disc_mass": {"sign": sign},
        "roller_material_modulus": {"sign": sign},
    }
    return {"amp": amp, **{k: v if isinstance(v, list) else float(v) for k, v in table[family].items()}}


def roughness_compliance(fam: str, prm: Params, p: np.ndarray, p_mean: np.ndarray, a: np.ndarray,
                         ra_um: float, h_soft: float) -> np.ndarray:
    """Series compliance per length (m²/N) of the rough layer at line load P (mean pressure p_mean, half-width a)."""
    rel = ra_um / 0.2
    amp = prm["amp"]
    if fam == "asperity_flattening":
        return amp * rel ** prm["q"] * np.exp(-p_mean / (prm["beta"] * h_soft))
    if fam == "abbott_closure":
        tp = ndtr(prm["alpha"] * np.sqrt(p_mean / 1e9) - prm["z0"] * rel**0.3)
        return amp * rel ** prm["q"] * (1.0 - tp) / np.maximum(tp, 0.02)
    if fam == "two_scale":
        rough = rel ** prm["q"] / (1.0 + p_mean / prm["p_r_pa"])
        wavy = prm["w"] * rel**0.5 * np.exp(-((a / prm["lam_m"]) ** 2))
        return amp * (rough + wavy)
    raise KeyError(fam)


def hardness_stiffness(fam: str, prm: Params, s: np.ndarray, p0: np.ndarray, h_soft: float) -> np.ndarray:
    """Per-length stiffness after the hardness departure above the onset p_on = θ·H_soft/3 (Tabor's Y)."""
    p_on = prm["theta"] * h_soft / 3.0
    excess = np.clip(p0 / p_on - 1.0, 0.0, None)
    if fam == "tabor_cube_root":
        return s * (1.0 + prm["amp"] * np.cbrt(excess))
    if fam == "ludwik_layer":
        return s / (1.0 + prm["amp"] * excess ** (1.0 / prm["n"]))
    if fam == "cavity_power":
        return s * (1.0 + excess) ** prm["amp"]
    raise KeyError(fam)


def end_profile(fam: str, prm: Params, u: np.ndarray, zone_m: float) -> np.ndarray:
    """Drop (m) of the end profile at distance u beyond L_we/2 (zone length ℓ = amp·zone_m)."""
    ell = prm["amp"] * zone_m
    if fam == "log_crown":
        frac = np.clip(u / ell, 0.0, 0.999)
        return np.where(u < ell, -prm["h_m"] * np.log(1.0 - frac**2), np.inf)
    if fam == "dub_off":
        return np.where(u < ell, u**2 / (2.0 * prm["r_d_m"]), np.inf)
    raise KeyError(fam)


def misalignment_gap(fam: str, prm: Params, x: np.ndarray, length_m: float, unit: int, rep: np.ndarray,
                     load_n: np.ndarray) -> np.ndarray:
    """Gap (m) per point and slice across the flat length x ∈ [−L/2, L/2] before the roller seats."""
    if fam == "seating_wedge":
        theta = prm["amp"] * np.asarray(prm["seat"][unit])[rep - 1]
        return theta[:, None] * (x[None, :] + length_m / 2)
    if fam == "twist_skew":
        kappa = prm["amp"] * np.asarray(prm["seat"][unit])[rep - 1]
        return kappa[:, None] * x[None, :] ** 2
    if fam == "spring_seat":
        theta = prm["amp"] * np.clip(1.0 - 3.0 * load_n / prm["f_c_n"], 0.05, None)
        return theta[:, None] * (x[None, :] + length_m / 2)
    raise KeyError(fam)


def setup_compliance(fam: str, prm: Params, load_n: np.ndarray) -> np.ndarray:
    """Extra compliance (m/N) per roller in series, the same function of load for every roller."""
    amp = prm["amp"]
    if fam == "slip_lock_joint":
        slip = 0.5 * erfc(np.log(load_n / prm["f_l_n"]) / prm["w"])
        return amp * (prm["r_lock"] + (1.0 - prm["r_lock"]) * slip)
    if fam == "hertz_seat_pair":
        f1, f2 = prm["f_b_n"]
        sh = prm["share"]
        return amp * (sh * (1.0 + 3.0 * load_n / f1) ** (-1 / 3) + (1 - sh) * (1.0 + 3.0 * load_n / f2) ** (-1 / 3))
    if fam == "stress_stiffened_disc":
        return amp / (1.0 + 3.0 * load_n / prm["f_ss_n"])
    raise KeyError(fam)


def reported_load(fam: str, prm: Params, f: np.ndarray, full_scale: float, preload: np.ndarray,
                  in_seat: np.ndarray, warm: np.ndarray) -> np.ndarray:
    """The load the lab reads for true load f under a load-side error (before the load cell's noise)."""
    amp = prm["amp"]
    if fam == "hysteresis_up":
        uu = f / full_scale
        return f + amp * full_scale * 4.0 * uu * (1.0 - uu)
    if fam == "spring_increment":
        return preload + (f - preload) * (1.0 + prm["sign"] * amp)
    if fam == "auto_range":
        sw = prm["switch"] * full_scale
        return np.where(f < sw, f, sw + (f - sw) * (1.0 + prm["sign"] * amp))
    if fam == "retare_drift":
        return f + prm["sign"] * amp * in_seat
    if fam == "missing_tare":
        return f - amp
    if fam == "thermal_zero":
        return f + prm["sign"] * amp * warm
    raise KeyError(fam)
