"""The hidden worlds of the discrepancy evaluation: effects in the library's forms and in independent ones,
calibration errors, crowned rollers and bad input (``bench/discrepancy_eval.py`` runs and scores them).

Everything here is written apart from the workflow's own terms: only the library forms of ``draw_effect`` (the
``twin`` suite) use ``labctl.physics``'s effect classes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from labctl.physics import (
    EFFECTS,
    ContactCase,
    EndEffects,
    MaterialHardness,
    Misalignment,
    SetupCompliance,
)
from labctl.physics import SurfaceRoughness as Roughness
from labctl.physics.materials import hardness_pa
from labctl.stiffness_table import StiffnessPoint

NONE = "none"
LABELS = (*EFFECTS, NONE)


def log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_effect(name: str, rng: np.random.Generator) -> Any:
    """One library effect with parameters drawn over a plausible range (None for null data)."""
    if name == "surface_roughness":
        return Roughness(asperity_scale=log_uniform(rng, 0.2, 3.0))
    if name == "end_effects":
        return EndEffects(edge_length_m=log_uniform(rng, 0.02e-3, 0.4e-3))
    if name == "material_hardness":
        return MaterialHardness(gain=log_uniform(rng, 0.1, 1.5), threshold=float(rng.uniform(0.15, 0.45)))
    if name == "misalignment":
        return Misalignment(tilt_rad=log_uniform(rng, 3e-5, 1.5e-3))
    if name == "setup_compliance":
        return SetupCompliance(stiffness_factor=log_uniform(rng, 0.5, 2.0))
    return None


Stiffness = Callable[[ContactCase, np.ndarray], np.ndarray]


def draw_independent(name: str, rng: np.random.Generator, inner: Stiffness, law: str = "") -> Stiffness:
    """The same physical effect in another functional form than the library's term, applied to ``inner``;
    ``law`` picks one of several forms where there are several (misalignment: ``""`` or ``"bed"``)."""
    if name == "surface_roughness":  # asperity layer with stiffness per length ∝ (F/L)^m, m < 1
        kappa, m = log_uniform(rng, 1e10, 1e11), float(rng.uniform(0.55, 0.85))

        def rough(case: ContactCase, f: np.ndarray) -> np.ndarray:
            length = case.roller.contact_length_m
            k_asp = kappa * length * (f / length / 1e4) ** m * (0.2e-6 / case.combined_ra_m)
            return 1.0 / (1.0 / inner(case, f) + 2.0 / k_asp)
        return rough
    if name == "end_effects":  # a constant spring at each roller end, in parallel
        k_edge = log_uniform(rng, 0.5e6, 6e6)
        return lambda case, f: inner(case, f) + 2.0 * k_edge
    if name == "material_hardness":  # stiffness gain ∝ (p_max/H)², no threshold
        gain = log_uniform(rng, 0.5, 4.0)

        def hard(case: ContactCase, f: np.ndarray) -> np.ndarray:
            h = hardness_pa(min(case.roller.material.hardness_hrc, case.rail.hardness_hrc))
            return inner(case, f) * (1.0 + gain * (case.peak_pressure_pa(f) / h) ** 2)
        return hard
    if name == "misalignment" and law == "bed":
        return tilt_on_stiffening_bed(log_uniform(rng, 5e-5, 1.5e-3), float(rng.uniform(0.55, 0.85)), inner)
    if name == "misalignment":  # contact length grows smoothly: L_c/L = (1 + x^-n)^(-1/n)
        tilt, n = log_uniform(rng, 5e-5, 1.5e-3), float(rng.choice([2.0, 4.0]))

        def tilted(case: ContactCase, f: np.ndarray) -> np.ndarray:
            k, length = inner(case, f), case.roller.contact_length_m
            x = np.sqrt(2.0 * f / (k / length * tilt)) / length
            return k * (1.0 + x**-n) ** (-1.0 / n)
        return tilted
    if name == "setup_compliance":  # an extra joint spring in series, stiffening with load
        k_joint, beta = log_uniform(rng, 2e8, 2e9), float(rng.uniform(0.0, 0.2))
        return lambda case, f: 1.0 / (1.0 / inner(case, f) + 1.0 / (k_joint * (f / 100.0) ** beta))
    return inner


def tilt_on_stiffening_bed(tilt_rad: float, a: float, inner: Stiffness) -> Stiffness:
    """A tilted roller on a bed whose local approach grows as δ = c·q^a with the load per length q (a < 1: the
    bed stiffens with load, as a rough or curved contact does); the measured stiffness is the tangent dF/dδ0.

    With the gap θ·x and u = δ0/δ_al, s = θ·L/δ_al (δ_al the aligned approach, c matched to ``inner``'s stiffness
    per length at each load: s = a·θ·k'·L²/F), the load balance is ∫₀¹ (u − sξ)₊^(1/a) dξ = 1 and the stiffness
    is ``inner`` × ∫₀¹ (u − sξ)₊^(1/a − 1) dξ. At a = 1 this is the library's kinked law; for a < 1 the
    partial-contact ratio to ``inner`` grows as (F/k')^(a/(1+a)) instead of (F/k')^½, and full contact is
    approached slowly without a kink (the load stays unevenly spread along a bed that stiffens) — no rounding of
    min(1, x) gives that."""
    b = 1.0 / a

    def integral(u: np.ndarray, s: np.ndarray, e: float) -> np.ndarray:  # ∫₀¹ (u − sξ)₊^e dξ
        return (u**(e + 1) - np.maximum(u - s, 0.0) ** (e + 1)) / (s * (e + 1))

    def k(case: ContactCase, f: np.ndarray) -> np.ndarray:
        stiff, length = inner(case, f), case.roller.contact_length_m
        s = a * tilt_rad * stiff * length / f
        lo, hi = np.zeros_like(s), 1.0 + s
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            short = integral(mid, s, b) < 1.0
            lo, hi = np.where(short, mid, lo), np.where(short, hi, mid)
        return stiff * integral(0.5 * (lo + hi), s, b - 1.0)
    return k


CALIBRATION = {"modulus_scale": 0.9, "load_gain": 1.08, "load_offset": 15.0}
"""Calibration errors: true moduli 0.9 × the catalogue's; recorded load 1.08 × the true one; recorded load the
true one + 15 N."""


def draw_calibration(name: str, inner: Stiffness) -> Stiffness:
    """The measured stiffness when the recorded load or the model's modulus is wrong (written here, not with
    the workflow's measurement terms)."""
    value = CALIBRATION[name]
    if name == "modulus_scale":
        def soft(case: ContactCase, f: np.ndarray) -> np.ndarray:
            r = case.roller
            mat = dataclasses.replace(r.material, youngs_modulus_pa=r.material.youngs_modulus_pa * value)
            rail = dataclasses.replace(case.rail, youngs_modulus_pa=case.rail.youngs_modulus_pa * value)
            return inner(dataclasses.replace(case, roller=dataclasses.replace(r, material=mat), rail=rail), f)
        return soft
    if name == "load_gain":
        return lambda case, f: inner(case, f / value)
    return lambda case, f: inner(case, f - value)


def crowned(rng: np.random.Generator, inner: Stiffness) -> Stiffness:
    """A crowned roller: a flat middle and parabolic end reliefs (relief fraction q of L_we per end, drop δc at
    the end) on an elastic bed of the line contact's stiffness per length; contact length grows with load."""
    q, drop = float(rng.uniform(0.1, 0.25)), log_uniform(rng, 2e-6, 8e-6)

    def k(case: ContactCase, f: np.ndarray) -> np.ndarray:
        length = case.roller.contact_length_m
        per_length = inner(case, f) / length
        flat, relief = length * (1 - 2 * q), length * q
        need = f / per_length  # ∫ max(0, δ − gap(x)) dx
        out = np.empty_like(f)
        for i, n in enumerate(need):
            def area(d: float) -> float:
                u = relief * math.sqrt(min(d / drop, 1.0))
                return d * flat + 2.0 * (d * u - drop * u**3 / (3.0 * relief**2))
            lo, hi = 0.0, n / flat
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if area(mid) < n else (lo, mid)
            d = 0.5 * (lo + hi)
            out[i] = per_length[i] * (flat + 2.0 * relief * math.sqrt(min(d / drop, 1.0)))
        return out
    return k


def bad_input(variant: str, points: list[StiffnessPoint], rng: np.random.Generator) -> list[StiffnessPoint]:
    """The same campaign with one kind of bad input: ``duplicate``, ``outliers`` or ``units``."""
    if variant == "duplicate":
        i = int(rng.integers(len(points)))
        bad = [*points, dataclasses.replace(points[i], stiffness_n_per_m=points[i].stiffness_n_per_m * 1.5)]
    elif variant == "outliers":
        bad = list(points)
        for i in rng.choice(len(points), size=max(1, round(0.03 * len(points))), replace=False):
            factor = math.exp(float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.2, 0.5)))
            bad[i] = dataclasses.replace(bad[i], stiffness_n_per_m=bad[i].stiffness_n_per_m * factor)
    else:  # stiffness in N/mm
        bad = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * 1e-3) for p in points]
    return bad
