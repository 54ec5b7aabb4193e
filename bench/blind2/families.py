"""Hidden-effect families of the second blind judge: each a physical law with one strength knob `s`.

Stages say how an effect combines: `law` replaces the contact's F(δ) (length or tilt changes act through the
law), `factor` multiplies the contact stiffness (ln k shift), `series` adds a rig/film compliance (1/k adds),
`load` changes the load the lab *reports* (calibration), `modulus` scales the elastic constants (calibration).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bench.blind2.contact import Line, Roller


@dataclass
class Cfg:
    """One roller configuration of a dataset: catalogue type on a rail of given Ra."""

    roller: Roller
    rail_ra_m: float
    line: Line

    @property
    def rq_m(self) -> float:
        """Combined rms roughness of roller and rail (Rq ≈ 1.25 Ra)."""
        return 1.25 * float(np.hypot(self.rail_ra_m, 0.03e-6))


@dataclass
class Ctx:
    """All points of a dataset: true loads (n_cfg, reps, steps), step index and campaign time in [0, 1]."""

    cfgs: list[Cfg]
    load_n: np.ndarray
    step: np.ndarray
    tau: np.ndarray

    def per_cfg(self, fn: Callable[[Cfg], float]) -> np.ndarray:
        return np.array([fn(c) for c in self.cfgs], dtype=float)[:, None, None]

    @property
    def p(self) -> np.ndarray:
        return self.load_n / self.per_cfg(lambda c: c.roller.contact_length_m)

    def half_width(self) -> np.ndarray:
        return np.stack([c.line.half_width(self.p[i]) for i, c in enumerate(self.cfgs)])

    def p0(self) -> np.ndarray:
        return np.stack([c.line.p_max(self.p[i]) for i, c in enumerate(self.cfgs)])

    def tripp(self) -> np.ndarray:
        return np.stack([c.line.stiffness(self.load_n[i], c.roller.contact_length_m) for i, c in enumerate(self.cfgs)])


@dataclass
class Family:
    """One functional form of one effect: label, stage, why, strength range, shape-parameter draw, law."""

    effect: str
    name: str
    stage: str
    why: str
    s_range: tuple[float, float]
    draw: Callable[[np.random.Generator, Ctx], dict] = field(repr=False)
    fn: Callable[[Ctx, dict, float], np.ndarray] = field(repr=False)


# ---------- laws with a load-dependent loaded length or a tilt (numerical F(δ), tangent k = dF/dδ) ----------

def _length_law(ctx: Ctx, length_of: Callable[[Cfg, np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """k(F) for a contact whose loaded length depends on (P, δ): F = P·L(P, δ(P)), k = (dF/dP)/(dδ/dP)."""
    out = np.empty_like(ctx.load_n)
    for i, c in enumerate(ctx.cfgs):
        p = np.geomspace(1e2, 3e6, 600)
        d = c.line.approach(p)
        f = p * np.maximum(length_of(c, p, d), 1e-7)
        k = np.gradient(f, p) / c.line.compliance_per_length(p)
        out[i] = np.exp(np.interp(np.log(ctx.load_n[i]), np.log(f), np.log(k)))
    return out


def _tilt_k(line: Line, length_m: float, theta: np.ndarray, load_n: np.ndarray, n: int = 96) -> np.ndarray:
    """Slice integration of a rigid tilt: gap g(x) = θ·x along the length, local P from the inverse line law;
    δ found by bisection so that ∫P dx = F; the hammer sees k = ∫ dx / (dδ/dP)(P(x)) over the loaded slices."""
    x = (np.arange(n) + 0.5) / n * length_m
    dx = length_m / n
    theta = np.broadcast_to(theta, load_n.shape).ravel()
    f = load_n.ravel()
    lo = np.zeros_like(f)
    hi = line.approach(f / length_m) + theta * length_m + 1e-9
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        pl = line.load_per_length(mid[:, None] - theta[:, None] * x[None, :])
        too_much = pl.sum(axis=1) * dx > f
        hi = np.where(too_much, mid, hi)
        lo = np.where(too_much, lo, mid)
    pl = line.load_per_length(0.5 * (lo + hi)[:, None] - theta[:, None] * x[None, :])
    k = np.where(pl > 0, dx / line.compliance_per_length(np.maximum(pl, 1.0)), 0.0).sum(axis=1)
    return k.reshape(load_n.shape)


def _tilt_law(ctx: Ctx, theta_of: Callable[[Cfg, np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    return np.stack([
        _tilt_k(c.line, c.roller.contact_length_m, theta_of(c, ctx.load_n[i], ctx.step[i]), ctx.load_n[i])
        for i, c in enumerate(ctx.cfgs)
    ])


def _no_draw(rng: np.random.Generator, ctx: Ctx) -> dict:
    return {}


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _onset(rng: np.random.Generator, ctx: Ctx) -> dict:
    """Onset coefficient c (p_on = c·H of the softer body) placed so steel yields at 45-80 % of its top p0."""
    steel = [i for i, c in enumerate(ctx.cfgs) if c.roller.material.name == "1.3505"]
    p0max = float(ctx.p0()[steel].max())
    h_steel = ctx.cfgs[steel[0]].roller.material.hardness_pa
    return {"onset_over_hardness": float(rng.uniform(0.45, 0.80) * p0max / h_steel)}


def _h_soft(ctx: Ctx) -> np.ndarray:
    return ctx.per_cfg(lambda c: min(c.roller.material.hardness_pa, c.line.rail.hardness_pa))


FAMILIES: list[Family] = [
    # ---- surface_roughness ----
    Family("surface_roughness", "persson_linear", "series",
           "Persson: asperity stiffness rises ∝ load, k_r = F/(s·Rq), in series; joins the elastic line at high load",
           (1e-3, 1e3), _no_draw,
           lambda ctx, q, s: s * ctx.per_cfg(lambda c: c.rq_m) / ctx.load_n),
    Family("surface_roughness", "fractal_power", "series",
           "fractal (Weierstrass-type) asperities: k_r = E*·L·(P/(E*·Rq))^m / s, m = 2 − D_f, D_f ∈ [1.3, 1.6]",
           (1e-3, 1e4), lambda rng, ctx: {"fractal_dimension": float(rng.uniform(1.3, 1.6))},
           lambda ctx, q, s: s / (ctx.per_cfg(lambda c: c.line.estar * c.roller.contact_length_m)
                                  * (ctx.p / ctx.per_cfg(lambda c: c.line.estar * c.rq_m))
                                  ** (2.0 - q["fractal_dimension"]))),
    Family("surface_roughness", "logistic_closure", "factor",
           "roughness gap closes as a logistic in ln P centred at P_c = β·E*·Rq; depth ∝ Ra (s per 0.2 µm)",
           (1e-4, 3.0), lambda rng, ctx: {"beta": float(rng.uniform(0.3, 3.0)), "width": float(rng.uniform(0.5, 1.2))},
           lambda ctx, q, s: -s * ctx.per_cfg(lambda c: c.rail_ra_m / 0.2e-6) * _sigmoid(
               -(np.log(ctx.p) - np.log(q["beta"] * ctx.per_cfg(lambda c: c.line.estar * c.rq_m))) / q["width"])),
    # ---- end_effects ----
    Family("end_effects", "log_end_profile", "law",
           "logarithmic end relief over s (m) per end: loaded length L − 2s + 2s·√(1 − exp(−δ/h)) from the approach",
           (1e-6, 2e-4), lambda rng, ctx: {"relief_depth_m": float(rng.uniform(2e-6, 8e-6))},
           lambda ctx, q, s: _length_law(ctx, lambda c, p, d: c.roller.contact_length_m - 2 * s
                                         + 2 * s * np.sqrt(1 - np.exp(-d / q["relief_depth_m"])))),
    Family("end_effects", "boussinesq_edge", "law",
           "Boussinesq edge correction: each end carries an extra strip κ·a, loaded length L + 2κa (κ = s)",
           (1e-3, 6.0), _no_draw,
           lambda ctx, q, s: _length_law(ctx, lambda c, p, d: c.roller.contact_length_m
                                         + 2 * s * c.line.half_width(p))),
    Family("end_effects", "chamfer_engagement", "law",
           "the corner radii (L_r − L_we) come into contact with the approach: L + s·(L_r − L_we)·(1 − e^(−δ/δc))",
           (1e-3, 1.0), lambda rng, ctx: {"delta_c_m": float(rng.uniform(1e-6, 6e-6))},
           lambda ctx, q, s: _length_law(ctx, lambda c, p, d: c.roller.contact_length_m + s * (
               c.roller.total_length_m - c.roller.contact_length_m) * (1 - np.exp(-d / q["delta_c_m"])))),
    # ---- material_hardness ----
    Family("material_hardness", "shakedown", "factor",
           "Johnson shakedown: above p_on the groove conforms, ln k += s·(1 − p_on/p0)₊ (p_on = c·H of softer body)",
           (1e-4, 5.0), _onset,
           lambda ctx, q, s: s * np.clip(1 - q["onset_over_hardness"] * _h_soft(ctx) / ctx.p0(), 0, None)),
    Family("material_hardness", "bilinear_hardening", "factor",
           "bilinear hardening: ln k rises linearly from p_on over 0.3·p_on then plateaus at s",
           (1e-4, 2.0), _onset,
           lambda ctx, q, s: s * np.clip((ctx.p0() / (q["onset_over_hardness"] * _h_soft(ctx)) - 1) / 0.3, 0, 1)),
    Family("material_hardness", "hv_onset_quadratic", "factor",
           "onset from HV: ln k += s·((p0/p_on)² − 1)₊·(HV_ref/HV) — plastic conformity, softer materials more",
           (1e-4, 5.0), _onset,
           lambda ctx, q, s: s * np.clip((ctx.p0() / (q["onset_over_hardness"] * _h_soft(ctx))) ** 2 - 1, 0, None)
           * (6.8e9 / _h_soft(ctx))),
    # ---- misalignment ----
    Family("misalignment", "rigid_tilt_slices", "law",
           "rigid tilt θ = s rad, Tripp slices integrated along the length (partial contact until θL is closed)",
           (5e-6, 3e-3), _no_draw,
           lambda ctx, q, s: _tilt_law(ctx, lambda c, f, st: np.full_like(f, s))),
    Family("misalignment", "relaxing_tilt", "law",
           "the seat rotates under load: θ = s/(1 + F/F_r), F_r ∈ [50, 200] N, slices as above",
           (5e-6, 3e-3), lambda rng, ctx: {"f_relax_n": float(rng.uniform(50, 200))},
           lambda ctx, q, s: _tilt_law(ctx, lambda c, f, st: s / (1 + f / q["f_relax_n"]))),
    Family("misalignment", "bedding_in", "law",
           "tilt s at the first step of each repetition, bedded in to a fraction r ∈ [0.05, 0.3] from step 2 on",
           (5e-6, 3e-3), lambda rng, ctx: {"bedded_fraction": float(rng.uniform(0.05, 0.3))},
           lambda ctx, q, s: _tilt_law(ctx, lambda c, f, st: np.where(st == 0, s, s * q["bedded_fraction"]))),
    # ---- setup_compliance (common to all rollers) ----
    Family("setup_compliance", "hertz_ball_joint", "series",
           "a ball seat in the load path: Hertz k_s ∝ F^(1/3), compliance s (m/N) at 100 N per roller",
           (1e-12, 1e-7), _no_draw,
           lambda ctx, q, s: s * (ctx.load_n / 100.0) ** (-1.0 / 3.0)),
    Family("setup_compliance", "bolt_two_slope", "series",
           "preloaded bolt: compliance 0.3·s until the joint decompresses at F_d, then s (smooth over 0.15·F_d)",
           (1e-12, 1e-7), lambda rng, ctx: {"f_decompress_n": float(rng.uniform(80, 300))},
           lambda ctx, q, s: s * (0.3 + 0.7 * _sigmoid((ctx.load_n - q["f_decompress_n"])
                                                       / (0.15 * q["f_decompress_n"])))),
    Family("setup_compliance", "thermal_drift", "series",
           "rig compliance drifting linearly over the campaign: s·(1 + β·τ), β ∈ [0.5, 2], τ the campaign time",
           (1e-12, 1e-7), lambda rng, ctx: {"beta": float(rng.uniform(0.5, 2.0))},
           lambda ctx, q, s: s * (1 + q["beta"] * ctx.tau)),
    # ---- outside_library ----
    Family("outside_library", "squeeze_film", "series",
           "oxide/lubricant film on both faces: c = 2h/(E_f·2a·L), h = h0·exp(−p_m/p_h) squeezed out; s = h0/E_f",
           (1e-22, 1e-14), lambda rng, ctx: {"p_h_pa": float(rng.uniform(0.3e9, 1.0e9))},
           lambda ctx, q, s: 2 * s * np.exp(-(ctx.p / (2 * ctx.half_width())) / q["p_h_pa"])
           / (2 * ctx.half_width() * ctx.per_cfg(lambda c: c.roller.contact_length_m))),
    Family("outside_library", "residual_stress", "factor",
           "compressive residual layer of depth z_r stiffens while the max-shear depth 0.78a is inside it",
           (1e-4, 1.0), lambda rng, ctx: {"z_r_m": float(rng.uniform(5e-6, 30e-6))},
           lambda ctx, q, s: s * np.exp(-0.78 * ctx.half_width() / q["z_r_m"])),
    Family("outside_library", "graded_soft_layer", "factor",
           "a ground-in tempered layer: modulus deficit s·exp(−a/z0) sampled at depth a, z0 ∈ [20, 60] µm",
           (1e-4, 1.0), lambda rng, ctx: {"z0_m": float(rng.uniform(20e-6, 60e-6))},
           lambda ctx, q, s: np.log1p(-np.minimum(s, 0.9) * np.exp(-ctx.half_width() / q["z0_m"]))),
]


def families_of(effect: str) -> list[Family]:
    return [f for f in FAMILIES if f.effect == effect]
