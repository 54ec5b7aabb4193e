"""Hidden effects of the blind worlds: each a few physically different load laws with one amplitude knob.

A family maps the true loads of one roller (and its rail) to the true stiffness. Its shape parameters are
drawn per seed by `draw`; its amplitude `amp` (within `amp_range`, monotone in the effect's size) is chosen by
the world generator to reach a drawn size in units of the dataset's noise.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from blind_contact import (
    DEPTH_M,
    Mat,
    RollerSpec,
    compliance_per_length,
    effective_modulus_pa,
    half_width_m,
    hardness_pa,
    peak_pressure_pa,
    tripp_stiffness,
)

C_REF = 5e-11  # m²/N: Tripp's compliance per length at light load, the scale of series compliances
P_REF = 5e4  # N/m: reference line load of the power laws


@dataclass(frozen=True)
class RollerLoads:
    """True loads of one roller type on its rails, with what the effects need about it."""

    spec: RollerSpec
    rail: Mat
    rail_ra_um: float
    load_n: np.ndarray

    @property
    def line_load(self) -> np.ndarray:
        return self.load_n / self.spec.contact_length_m

    @property
    def e_star(self) -> float:
        return effective_modulus_pa(self.spec.material, self.rail)

    def tripp(self, load_n: np.ndarray | None = None, length_m: float | np.ndarray | None = None) -> np.ndarray:
        f = self.load_n if load_n is None else load_n
        length = self.spec.contact_length_m if length_m is None else length_m
        return tripp_stiffness(f, length, self.spec.radius_m, self.spec.material, self.rail)

    def compliance(self, p: np.ndarray) -> np.ndarray:
        return compliance_per_length(p, self.spec.radius_m, self.spec.material, self.rail)

    def peak_pressure(self) -> np.ndarray:
        return peak_pressure_pa(self.line_load, self.spec.radius_m, self.e_star)


@dataclass(frozen=True)
class Family:
    """One functional form of a hidden effect."""

    name: str
    amp_range: tuple[float, float]
    draw: Callable[[np.random.Generator, list[RollerLoads]], dict[str, float]]
    apply: Callable[[RollerLoads, dict[str, float], float], np.ndarray]
    natural_range: tuple[float, float] | None = None  # if set, half the worlds draw amp here (log-uniform)


def _series(r: RollerLoads, compliance_per_roller: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 / r.tripp() + compliance_per_roller)


def _ra_factor(r: RollerLoads, q: float) -> float:
    return (r.rail_ra_um / 0.2) ** q


def _p_span(rs: list[RollerLoads]) -> tuple[float, float]:
    p = np.concatenate([r.line_load for r in rs])
    return float(p.min()), float(p.max())


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _logu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


# ---- 1. surface roughness: a series compliance, large at light load, larger on rough rails -------------------

def _rough_log(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    # the paper's Eq. 5/6 form, k = C ln(P/p0) L_we, as the asperity layer in series with the bulk
    k_rough = 1e10 / amp * np.log(r.line_load / q["p0_n_per_m"]) * r.spec.contact_length_m
    return 1.0 / (1.0 / r.tripp() + _ra_factor(r, q["ra_exponent"]) / k_rough)


def _rough_exp(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    c = amp * C_REF * _ra_factor(r, q["ra_exponent"]) * np.exp(-r.line_load / q["closure_n_per_m"])
    return _series(r, c / r.spec.contact_length_m)


def _rough_power(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    c = amp * C_REF * _ra_factor(r, q["ra_exponent"]) * (r.line_load / P_REF) ** (-q["m"])
    return _series(r, c / r.spec.contact_length_m)


def _rough_ra_layer(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    # an asperity layer of height ~Ra squeezed across the contact width 2a: compliance ~ Ra/(E* a)
    a = half_width_m(r.line_load, r.spec.radius_m, r.e_star)
    c = amp * r.rail_ra_um * 1e-6 / (r.e_star * a) * (1.0 + a / (q["closure_width_m"]))**-2
    return _series(r, c / r.spec.contact_length_m)


ROUGHNESS = [
    Family("paper_log", (1e-3, 30.0), lambda g, rs: {
        "p0_n_per_m": _u(g, 0.05, 0.5) * _p_span(rs)[0], "ra_exponent": _u(g, 0.6, 1.2)}, _rough_log),
    Family("gw_exponential", (1e-3, 50.0), lambda g, rs: {
        "closure_n_per_m": _logu(g, 1.5e4, 1.5e5), "ra_exponent": _u(g, 0.6, 1.2)}, _rough_exp),
    Family("power_law", (1e-3, 30.0), lambda g, rs: {
        "m": _u(g, 0.3, 0.8), "ra_exponent": _u(g, 0.6, 1.2)}, _rough_power),
    Family("ra_layer", (1e-2, 1e4), lambda g, rs: {
        "closure_width_m": _logu(g, 2e-5, 1e-4)}, _rough_ra_layer),
]


# ---- 2. end effects: the ends change the effective length, short rollers most ------------------------------

def _end_lost(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    return r.tripp(length_m=r.spec.contact_length_m - 2.0 * amp)


def _end_loaded(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    # edge zones unloaded at light load, loading up (and the profiled ends joining in) as the line load grows
    s = np.exp(-r.line_load / q["edge_load_n_per_m"])
    spare = r.spec.total_length_m - r.spec.contact_length_m
    change = -2.0 * q["lost_per_end_m"] * s + q["profile_share"] * spare * (1.0 - s)
    return r.tripp(length_m=r.spec.contact_length_m + amp * change)


def _end_stiff(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    return r.tripp() * (1.0 + amp * r.spec.diameter_m / r.spec.contact_length_m)


END_EFFECTS = [
    Family("lost_length", (1e-7, 0.3e-3), lambda g, rs: {}, _end_lost),
    Family("loaded_edges", (1e-4, 1.0), lambda g, rs: {
        "edge_load_n_per_m": _logu(g, 3e4, 3e5), "lost_per_end_m": _u(g, 0.05e-3, 0.3e-3),
        "profile_share": _u(g, 0.0, 0.6)}, _end_loaded),
    Family("edge_stiffening", (1e-4, 0.6), lambda g, rs: {}, _end_stiff),
]


# ---- 3. material hardness: departure from elastic above an onset peak pressure set by the hardness ---------

def _draw_onset(g: np.random.Generator, rs: list[RollerLoads]) -> dict[str, float]:
    p0 = np.concatenate([r.peak_pressure() for r in rs])
    lo, hi = float(np.percentile(p0, 10)), float(np.percentile(p0, 95))
    onset = lo + _u(g, 0.25, 0.7) * (hi - lo)
    hard = hardness_pa(min(rs[0].spec.material.hardness_hrc, rs[0].rail.hardness_hrc))
    return {"onset_over_hardness": onset / hard, "width": _u(g, 0.05, 0.25)}


def _excess(r: RollerLoads, q: dict[str, float]) -> np.ndarray:
    onset = q["onset_over_hardness"] * hardness_pa(min(r.spec.material.hardness_hrc, r.rail.hardness_hrc))
    return r.peak_pressure() / onset - 1.0


def _hard_kink(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    return r.tripp() * np.exp(-amp * np.maximum(_excess(r, q), 0.0))


def _hard_smooth(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    w = q["width"]
    return r.tripp() * np.exp(-amp * w * np.logaddexp(0.0, _excess(r, q) / w))


def _hard_conform(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    soft = 60.0 / r.spec.material.hardness_hrc
    gain = amp * soft * _ra_factor(r, 0.5) * (1.0 - np.exp(-np.maximum(_excess(r, q), 0.0) / (2.0 * q["width"])))
    return r.tripp() * (1.0 + gain)


HARDNESS = [
    Family("kink", (1e-3, 3.0), _draw_onset, _hard_kink),
    Family("smooth_yield", (1e-3, 3.0), _draw_onset, _hard_smooth),
    Family("plastic_conformity", (1e-3, 1.0), _draw_onset, _hard_conform),
]


# ---- 4. misalignment: a tilt γ (amp, rad) leaves the contact partial until the load closes the wedge -------
# A tilt of 0.5-3 mrad is always large (on the 8.3 mm roller 0.5 mrad is a 4 µm gap against ~0.3 µm of elastic
# approach at 38 N), so small effects need a smaller tilt: half the worlds draw γ in 0.5-3 mrad, the other half
# size it to the drawn size down to 5 µrad.
TILT_RANGE = (5e-6, 3e-3)
TILT_NATURAL = (0.5e-3, 3e-3)

def _contact_length(r: RollerLoads, gamma: float, law: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    length = np.full_like(r.load_n, r.spec.contact_length_m)
    for _ in range(8):  # Winkler wedge: F = γ c²/(2 c_P) with c_P the compliance per length at F/c
        f_full = gamma * r.spec.contact_length_m**2 / (2.0 * r.compliance(r.load_n / length))
        length = r.spec.contact_length_m * law(r.load_n, f_full)
    return length


def _tilt_wedge(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    c = _contact_length(r, amp, lambda f, ff: np.minimum(1.0, np.sqrt(f / ff)))
    return c / r.compliance(r.load_n / c)


def _tilt_smooth(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    n = q["sharpness"]
    c = _contact_length(r, amp, lambda f, ff: (1.0 + (ff / f) ** (n / 2.0)) ** (-1.0 / n))
    return c / r.compliance(r.load_n / c)


def _tilt_bed(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    # the rail rocks on a compliant bed; the tilt gap γL/2 closes along a saturating curve
    f_full = amp * r.spec.contact_length_m**2 / (2.0 * r.compliance(r.line_load))
    f_sat = q["bed_scale"] * f_full
    extra = amp * r.spec.contact_length_m / 2.0 * f_sat / (r.load_n + f_sat) ** 2
    return _series(r, extra)


MISALIGNMENT = [
    Family("wedge", TILT_RANGE, lambda g, rs: {}, _tilt_wedge, TILT_NATURAL),
    Family("smooth_gap", TILT_RANGE, lambda g, rs: {"sharpness": _u(g, 2.0, 6.0)}, _tilt_smooth, TILT_NATURAL),
    Family("compliant_bed", TILT_RANGE, lambda g, rs: {"bed_scale": _logu(g, 0.5, 5.0)}, _tilt_bed, TILT_NATURAL),
]


# ---- 5. setup compliance: a rig compliance in series (m/N, the same for every roller) ----------------------

SETUP = [
    Family("constant", (1e-13, 1e-8), lambda g, rs: {}, lambda r, q, amp: _series(r, np.full_like(r.load_n, amp))),
    Family("bolted_joint", (1e-13, 1e-8), lambda g, rs: {"q": _u(g, 0.3, 1.0)},
           lambda r, q, amp: _series(r, amp * (r.load_n / 100.0) ** (-q["q"]))),
    Family("joint_closing", (1e-13, 1e-8), lambda g, rs: {"closing_load_n": _logu(g, 50.0, 1000.0)},
           lambda r, q, amp: _series(r, amp * (0.3 + 0.7 * np.exp(-r.load_n / q["closing_load_n"])))),
]


# ---- 6. outside the library -------------------------------------------------------------------------------

def _porous(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    dense = np.clip(1.0 - r.line_load / q["dense_n_per_m"], 0.0, None) ** 2
    c = amp * (r.line_load * r.spec.radius_m) ** -0.5 * dense
    return _series(r, c / r.spec.contact_length_m)


def _draw_porous(g: np.random.Generator, rs: list[RollerLoads]) -> dict[str, float]:
    lo, hi = _p_span(rs)
    return {"dense_n_per_m": float(np.exp(np.log(lo) + _u(g, 0.35, 0.8) * np.log(hi / lo)))}


def _coating(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    # the rail's modulus seen by the contact moves from the coating's (a << h) to the substrate's (a >> h)
    c_rail = np.full_like(r.load_n, r.rail.compliance)
    for _ in range(4):
        e_star = 1.0 / (r.spec.material.compliance + c_rail)
        a = half_width_m(r.line_load, r.spec.radius_m, e_star)
        c_rail = r.rail.compliance / (1.0 + amp * np.exp(-a / q["thickness_m"]))
    return r.spec.contact_length_m / compliance_per_length(
        r.line_load, r.spec.radius_m, r.spec.material, r.rail, rail_compliance=c_rail)


def _interlayer(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    # a bonded shim under each rail: the load spreads through the rail over (L_we + 2t)
    return _series(r, np.full_like(r.load_n, amp / (r.spec.contact_length_m + 2.0 * DEPTH_M)))


def _rate(r: RollerLoads, q: dict[str, float], amp: float) -> np.ndarray:
    # a rate-dependent (viscoelastic) contact: the bounce frequency rises with k, and so does the modulus seen
    k = r.tripp()
    return k * (k / 1e8) ** amp


OUTSIDE = {
    "porous_layer": Family("porous_layer", (1e-14, 1e-8), _draw_porous, _porous),
    "hard_coating": Family("hard_coating", (1e-3, 3.0), lambda g, rs: {"thickness_m": _logu(g, 5e-6, 4e-5)},
                           _coating),
    "compliant_interlayer": Family("compliant_interlayer", (1e-17, 1e-10), lambda g, rs: {}, _interlayer),
    "rate_dependence": Family("rate_dependence", (1e-4, 0.2), lambda g, rs: {}, _rate),
}

PHYSICAL: dict[str, list[Family]] = {
    "surface_roughness": ROUGHNESS,
    "end_effects": END_EFFECTS,
    "material_hardness": HARDNESS,
    "misalignment": MISALIGNMENT,
    "setup_compliance": SETUP,
}
