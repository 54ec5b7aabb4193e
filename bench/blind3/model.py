"""A roller's true stiffness under the hidden effects, and what the rig's processing makes of it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench.blind3 import laws
from bench.blind3.contact import (
    K_SETUP,
    P_GRID,
    LengthLaw,
    Material,
    Roller,
    e_star,
    half_width,
    tripp_k,
    tripp_per_length,
)

Effects = dict[str, tuple[str, laws.Params]]


@dataclass(frozen=True)
class Unit:
    """One roller type on one pair of rails (a rail roughness) within a campaign."""

    index: int
    roller: Roller
    mroll: Material
    mrail: Material
    ra_um: float

    @property
    def ra_combined_um(self) -> float:
        """Composite roughness √(Ra_rail² + Ra_roller²) of the two surfaces in contact."""
        return float(np.hypot(self.ra_um, self.roller.ra_um))

    @property
    def h_soft(self) -> float:
        """Hardness of the softer body, Pa."""
        return min(self.mroll.hardness_pa, self.mrail.hardness_pa)

    def tripp(self, load_n: np.ndarray) -> np.ndarray:
        """The lab's Tripp baseline at the given loads."""
        return tripp_k(load_n, self.roller, self.mroll, self.mrail)


def unit_law(u: Unit, eff: Effects) -> LengthLaw:
    """The per-length law of one unit with the effects that act on the local contact (table over P)."""
    p = P_GRID
    r_m = u.roller.d_m / 2
    es0 = e_star(u.mroll, u.mrail)
    a = half_width(p, r_m, es0)
    esr: np.ndarray | float = 1.0
    esl = 1.0
    if "modulus_scale" in eff:
        fam, prm = eff["modulus_scale"]
        if fam == "rail_modulus":
            esl = 1.0 + prm["sign"] * prm["amp"]
        elif fam == "roller_material_modulus" and prm["material"] == u.mroll.name:
            esr = 1.0 + prm["sign"] * prm["amp"]
    if "outside_library" in eff and eff["outside_library"][0] == "austenite_layer":
        prm = eff["outside_library"][1]
        esr = 1.0 - prm["amp"] * np.exp(-a / prm["h_m"])
    delta, s = tripp_per_length(p, r_m, u.mroll, u.mrail, esr, esl)
    s_t0 = s[0]
    if "material_hardness" in eff:
        fam, prm = eff["material_hardness"]
        s = laws.hardness_stiffness(fam, prm, s, 2.0 * p / (np.pi * a), u.h_soft)
    extra = np.zeros_like(p)
    if "outside_library" in eff and eff["outside_library"][0] == "rail_depth":
        extra += 4.0 * u.mrail.compliance / np.pi * eff["outside_library"][1]["amp"]
    if "surface_roughness" in eff:
        fam, prm = eff["surface_roughness"]
        extra += laws.roughness_compliance(fam, prm, p, p / (2.0 * a), a, u.ra_combined_um, u.h_soft)
    s = 1.0 / (1.0 / s + extra)
    return LengthLaw(p, s, float(delta[0] + (1.0 / s[0] - 1.0 / s_t0) * p[0]))


def _slices(law: LengthLaw, gap: np.ndarray, w: np.ndarray, load: np.ndarray) -> np.ndarray:
    """Tangent stiffness of a roller cut in slices of width w with initial gaps (points × slices) at total load."""
    gap = np.broadcast_to(gap, (load.size, w.size))
    lo = np.zeros(load.size)
    hi = law.approach(load / w.sum()) + gap.max(axis=1)
    for _ in range(36):
        mid = 0.5 * (lo + hi)
        force = (law.load_at(mid[:, None] - gap) * w).sum(axis=1)
        big = force > load
        hi = np.where(big, mid, hi)
        lo = np.where(big, lo, mid)
    d = 0.5 * (lo + hi)[:, None] - gap
    p = law.load_at(d)
    return (np.where(d > 0, law.stiffness(p), 0.0) * w).sum(axis=1)


def roller_k(u: Unit, law: LengthLaw, eff: Effects, load: np.ndarray, rep: np.ndarray) -> np.ndarray:
    """Stiffness of one roller (N/m) at true loads, the length and alignment effects included."""
    lwe = u.roller.lwe_m
    if "end_effects" in eff and eff["end_effects"][0] == "plane_stress_ends":
        prm = eff["end_effects"][1]
        zone = min(prm["amp"] * u.roller.d_m / 2, lwe / 4)
        leff = lwe - 2.0 * zone * u.mroll.nu**2
        return leff * law.stiffness(load / leff)
    if "end_effects" in eff:
        fam, prm = eff["end_effects"]
        zone_ref = max((u.roller.lr_m - lwe) / 2, 4e-5)
        ell = prm["amp"] * zone_ref
        n_end = 12
        ue = (np.arange(n_end) + 0.5) / n_end * ell
        g_end = laws.end_profile(fam, prm, ue, zone_ref)
        g_end = np.where(np.isfinite(g_end), g_end, 1.0)
        w = np.concatenate([[lwe], np.full(2 * n_end, ell / n_end)])
        gap = np.concatenate([[0.0], g_end, g_end])
        return _slices(law, gap[None, :], w, load)
    if "misalignment" in eff:
        fam, prm = eff["misalignment"]
        nx = 32
        x = ((np.arange(nx) + 0.5) / nx - 0.5) * lwe
        gap = laws.misalignment_gap(fam, prm, x, lwe, u.index, rep, load)
        gap = gap - gap.min(axis=1, keepdims=True)
        return _slices(law, gap, np.full(nx, lwe / nx), load)
    return lwe * law.stiffness(load / lwe)


def rig_processing(k: np.ndarray, load: np.ndarray, eff: Effects) -> np.ndarray:
    """What the lab reports as k after series setup compliance, a parallel tube and a wrong disc mass."""
    if "setup_compliance" in eff:
        fam, prm = eff["setup_compliance"]
        k = 1.0 / (1.0 / k + laws.setup_compliance(fam, prm, load))
    k_total = 1.0 / (1.0 / (3.0 * k) + 1.0 / K_SETUP)
    if "outside_library" in eff and eff["outside_library"][0] == "isolation_tube":
        k_total = k_total + eff["outside_library"][1]["amp"]
    if "modulus_scale" in eff and eff["modulus_scale"][0] == "disc_mass":
        prm = eff["modulus_scale"][1]
        k_total = k_total * (1.0 + prm["sign"] * prm["amp"])
    return 1.0 / (3.0 * (1.0 / k_total - 1.0 / K_SETUP))


def amplification(k: np.ndarray) -> np.ndarray:
    """d ln k / d ln K_total through the K_setup correction: how a frequency error grows into k."""
    k_total = 1.0 / (1.0 / (3.0 * k) + 1.0 / K_SETUP)
    return K_SETUP / (K_SETUP - k_total)


def bounce_hz(k: np.ndarray, mass_kg: float) -> np.ndarray:
    """Bounce frequency f0 = √(2·K_total/m)/(2π) of the disc on three rollers in series with the rig."""
    k_total = 1.0 / (1.0 / (3.0 * k) + 1.0 / K_SETUP)
    return np.sqrt(2.0 * k_total / mass_kg) / (2.0 * np.pi)
