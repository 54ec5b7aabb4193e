"""Fitting a contact law to measured points: the baseline's nuisance parameters plus any effect terms.

A :class:`ModelSpec` names the baseline and the effects; its parameter vector holds log10 of Tripp's
evaluation depth (a nuisance parameter, always fitted) and each effect's physical parameters scaled to
[0, 1] over the effect's BOUNDS. Every evaluation goes through :class:`labctl.physics.law.ContactLaw`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.lsq import bounded_least_squares
from labctl.discrepancy.measurement import MEASUREMENT, TRIPP_DEPTH_RANGE_M
from labctl.discrepancy.noise import NoiseFloor, whiten
from labctl.errors import ModelDomainError
from labctl.physics.effects import EFFECTS, Effect
from labctl.physics.law import ContactLaw
from labctl.physics.tripp import DEFAULT_DEPTH_M

DEPTH_BOUNDS_M = (0.1e-3, 100e-3)
"""The widest depths ever tried (to report what depth a free fit would want)."""
FIT_FTOL = 1e-4
"""Stop a fit when the cost (≈ n whitened squares) falls by less than this share: at 231 points that is ≤ 0.02 in
−2 ln L, far below every decision's scale (the candidates' probabilities agree to 4 decimals with 1e-7), at a
quarter less work per fit."""
BAD_RESIDUAL = 10.0
"""Stands in for ln-residuals where a trial parameter set makes the model non-physical."""

FIT_ONLY_BOUNDS: dict[str, dict[str, tuple[float, float]]] = {
    "misalignment": {"transition": (0.0, 0.6)},
    "material_hardness": {"roughness_exponent": (0.0, 1.0)},
    "end_effects": {"half_width_share": (-3.0, 3.0), "radius_share": (-0.3, 0.6)},
    "surface_roughness": {"load_exponent": (0.25, 1.0)},
}
"""Shape parameters beyond the effect's world ``BOUNDS``, fitted only when a spec frees them (``free_shape``): the
rounding of the tilt law's closing (``Misalignment.transition``; 0 is the independent-spring kink, 0.6 a closing
spread over about a decade of load); how the yield term follows the surface roughness
(``MaterialHardness.roughness_exponent``; 1 is asperity conformity, 0 a bulk yield blind to the surface); the
share of the contact half-width the ends add (``EndEffects.half_width_share``; 0 is a fixed edge length) and of the
roller radius (``EndEffects.radius_share``); and how
fast the asperities stiffen with load (``SurfaceRoughness.load_exponent``; 1 is the exponential height tail)."""
SHAPE_STARTS: dict[str, dict[str, float]] = {"misalignment": {"transition": 0.3},
                                             "material_hardness": {"roughness_exponent": 0.0},
                                             "end_effects": {"half_width_share": 1.0, "radius_share": 0.1},
                                             "surface_roughness": {"load_exponent": 0.5}}
"""Where a freed shape parameter is fitted from: the other end of the doubt from the law's own form."""


STARTS: dict[str, tuple[dict[str, float], ...]] = {
    "surface_roughness": ({"asperity_scale": 1.0},),
    "end_effects": ({"edge_length_m": 0.1e-3},),
    "material_hardness": ({"gain": 0.2, "threshold": 0.2}, {"gain": 0.2, "threshold": 0.5},
                          {"gain": -0.2, "threshold": 0.2}, {"gain": -0.2, "threshold": 0.5}),
    "misalignment": ({"tilt_rad": 2e-4, "transition": 0.0}, {"tilt_rad": 1e-3, **SHAPE_STARTS["misalignment"]}),
    "setup_compliance": ({"stiffness_factor": 0.8}, {"stiffness_factor": 1.3}),
    "load_gain": ({"gain": 1.0},),
    "load_offset": ({"offset_n": 0.0},),
    "modulus_scale": ({"scale": 1.0},),
}
"""Physically plausible starting points per effect; several where the term has a kink to cross (the hardness
term's on both sides of zero gain: from a stiffening start the fit does not reach a softening onset)."""


SIGNED_BOUNDS: dict[str, dict[str, tuple[float, float]]] = {
    "end_effects": {"edge_length_m": (-0.4e-3, 2e-3)},
    "material_hardness": {"gain": (-0.5, 2.0)},
}
"""Fitted ranges wider than the world ``BOUNDS`` where the physics goes both ways: a negative edge length is a
length lost at each end (edge relief, unloaded edges); a negative hardness gain is yield softening above the
onset instead of conformity stiffening. The twin's worlds use only the world ranges."""


def canonical(names: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """Effect names in the registry's order (contact terms first, the measurement chain's setup term last)."""
    unknown = [n for n in names if n not in EFFECTS]
    if unknown:
        raise ValueError(f"unknown effect {unknown[0]!r}; expected one of {', '.join(EFFECTS)}")
    return tuple(n for n in EFFECTS if n in names)


def term_class(name: str) -> type:
    """The class of a physical effect or a measurement-side term, by name."""
    return EFFECTS[name] if name in EFFECTS else MEASUREMENT[name]


@dataclass(frozen=True)
class ModelSpec:
    """Which baseline and effects a fit uses; effects the rig fixes (nominal K_setup) come in ``fixed``."""

    baseline: str = "tripp"
    effects: tuple[str, ...] = ()
    fixed: dict[str, dict[str, float]] = field(default_factory=dict, compare=False, hash=False)
    measurement: tuple[str, ...] = ()
    """Measurement-side terms (``labctl.discrepancy.measurement``): applied to the model's inputs."""
    depth_bounds_m: tuple[float, float] = TRIPP_DEPTH_RANGE_M
    """Tripp's evaluation depth is fitted within its physical range (a depth outside it is no contact physics)."""
    free_shape: tuple[tuple[str, str], ...] = ()
    """(term, shape parameter) pairs (``FIT_ONLY_BOUNDS``) fitted; the rest keep the effect's default form."""

    def depth_at_bound(self, depth_m: float | None) -> bool:
        """A fitted depth pinned at an end of its range: the baseline cannot absorb what the data show."""
        return depth_m is not None and any(abs(math.log(depth_m / b)) < 0.01 for b in self.depth_bounds_m)

    @property
    def fits_depth(self) -> bool:
        return self.baseline == "tripp"

    @property
    def terms(self) -> tuple[str, ...]:
        return self.effects + self.measurement

    def with_effects(self, *names: str) -> ModelSpec:
        physical = [n for n in names if n not in MEASUREMENT]
        chain = [*self.measurement, *(n for n in names if n in MEASUREMENT)]
        return ModelSpec(self.baseline, canonical([*self.effects, *physical]), self.fixed,
                         tuple(n for n in MEASUREMENT if n in chain), self.depth_bounds_m, self.free_shape)

    def with_free_shape(self, name: str, parameter: str) -> ModelSpec:
        """The same model with shape parameter ``parameter`` of term ``name`` fitted too."""
        return replace(self, free_shape=(*self.free_shape, (name, parameter)))

    def slots(self) -> list[tuple[str, str, float, float]]:
        """(term, parameter, lower, upper) per fitted term parameter, in vector order after the depth."""
        return list(self._slots)

    @cached_property
    def _slots(self) -> tuple[tuple[str, str, float, float], ...]:  # a fit decodes its vector thousands of times
        return tuple((n, k, lo, hi) for n in self.terms
                     for k, (lo, hi) in {**term_class(n).BOUNDS, **SIGNED_BOUNDS.get(n, {}), **self._shape(n)}.items())

    def _shape(self, name: str) -> dict[str, tuple[float, float]]:
        return {k: b for k, b in FIT_ONLY_BOUNDS.get(name, {}).items() if (name, k) in self.free_shape}

    def n_params(self) -> int:
        return int(self.fits_depth) + len(self.slots())

    def law(self, x: np.ndarray, values: dict[str, dict[str, float]] | None = None) -> ContactLaw:
        """The contact law for a parameter vector (``values``: its ``decode``, when the caller has it)."""
        depth = 10.0 ** x[0] if self.fits_depth else DEFAULT_DEPTH_M
        values = self.decode(x) if values is None else values
        effects: list[Effect] = [EFFECTS[n](**values[n], **self.fixed.get(n, {})) for n in self.effects]
        return ContactLaw(self.baseline, depth, tuple(effects))

    def chain(self, x: np.ndarray, values: dict[str, dict[str, float]] | None = None) -> tuple[Any, ...]:
        """The measurement-side terms for a parameter vector (``values``: its ``decode``, when the caller has it)."""
        values = self.decode(x) if values is None else values
        return tuple(MEASUREMENT[n](**values[n]) for n in self.measurement)

    def decode(self, x: np.ndarray) -> dict[str, dict[str, float]]:
        """Term parameters (SI) from the vector."""
        out: dict[str, dict[str, float]] = {n: {} for n in self.terms}
        for u, (n, k, lo, hi) in zip(x[int(self.fits_depth):].tolist(), self._slots, strict=True):
            out[n][k] = lo + u * (hi - lo)
        return out

    def encode(self, depth_m: float, values: dict[str, dict[str, float]]) -> np.ndarray:
        head = [math.log10(depth_m)] if self.fits_depth else []
        tail = [(values[n].get(k, getattr(term_class(n), k)) - lo) / (hi - lo) for n, k, lo, hi in self.slots()]
        return np.array(head + tail, dtype=float)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [math.log10(self.depth_bounds_m[0])] if self.fits_depth else []
        hi = [math.log10(self.depth_bounds_m[1])] if self.fits_depth else []
        n = len(self.slots())
        return np.array(lo + [0.0] * n), np.array(hi + [1.0] * n)


def predict_ln(data: Dataset, law: ContactLaw, chain: tuple[Any, ...] = (),
               baselines: dict[tuple[str, float], np.ndarray] | None = None) -> np.ndarray:
    """ln of the modelled stiffness at every measured point (cases concatenated), evaluated at the true load
    and moduli the measurement-side terms ``chain`` infer from the recorded ones.

    ``baselines``: a fit's memo of the baseline's stiffness at the recorded points per (baseline, depth); used
    without a chain (which moves the points): a Jacobian column of an effect parameter keeps the depth."""
    case, load = data.stacked_case, data.load_n  # every case in one evaluation (the same numbers)
    for term in chain:
        case, load = term.transform(case, load)
    load = np.asarray(load)
    if (load > 0).all():  # the usual case: nothing to mask
        if baselines is None or chain:
            return np.log(law.stiffness_n_per_m(case, load))
        key = (law.baseline, law.depth_m)
        if key not in baselines:
            baselines[key] = ContactLaw(law.baseline, law.depth_m).stiffness_n_per_m(case, load)
        return np.log(law.stiffness_n_per_m(case, load, baselines[key]))
    bad = ~(load > 0)  # a load offset larger than the recorded load: no such model
    value = np.log(law.stiffness_n_per_m(case, np.where(bad, 1.0, load)))
    return np.where(bad, np.nan, value)


@dataclass(frozen=True)
class Fit:
    """A fitted model: its law, parameters and residuals r = ln(k_model/k_measured), each with its noise σ."""

    spec: ModelSpec
    x: np.ndarray
    law: ContactLaw
    residuals: np.ndarray
    sigma: np.ndarray
    white: np.ndarray | None = None
    """Residuals whitened with the noise model (seating offsets and point noise); None: residuals/σ."""

    @property
    def z(self) -> np.ndarray:
        """Residuals in units of their noise, whitened for shared seating offsets."""
        return self.residuals / self.sigma if self.white is None else self.white

    @property
    def score(self) -> float:
        """rms of z: about 1 when the model explains all but the noise."""
        return math.sqrt(float(np.mean(self.z**2)))

    @property
    def chain(self) -> tuple[Any, ...]:
        return self.spec.chain(self.x)

    def predict(self, data: Dataset) -> np.ndarray:
        """ln of this model's stiffness at the points of ``data``."""
        return predict_ln(data, self.law, self.chain)

    def lack_of_fit_p(self, data: Dataset, noise: NoiseFloor) -> float | None:
        """The lack-of-fit test's p-value for this fit on ``data`` (None: no test, without repetitions)."""
        return noise.lack_of_fit_p(data, self.residuals, self.sigma, self.spec.n_params())

    @property
    def n_points(self) -> int:
        return int(self.residuals.size)

    @property
    def rss(self) -> float:
        return float(np.sum(self.residuals**2))

    @property
    def gap(self) -> float:
        """The gap: rms over all points of ln(k_model/k_measured)."""
        return math.sqrt(self.rss / self.n_points)

    @property
    def bic(self) -> float:
        """Bayesian information criterion of the noise-weighted fit, the noise scale profiled out."""
        n = self.n_points
        return n * math.log(max(self.score, 1e-150) ** 2) + self.spec.n_params() * math.log(n)

    @property
    def depth_m(self) -> float | None:
        return 10.0 ** float(self.x[0]) if self.spec.fits_depth else None

    def effect_parameters(self) -> dict[str, dict[str, float]]:
        """Physical effects' parameters (SI)."""
        values = self.spec.decode(self.x)
        return {n: values[n] for n in self.spec.effects}

    def measurement_parameters(self) -> dict[str, dict[str, float]]:
        values = self.spec.decode(self.x)
        return {n: values[n] for n in self.spec.measurement}

    def baseline_parameters(self) -> dict[str, Any]:
        return {"depth_m": self.depth_m} if self.spec.fits_depth else {}


def depth_column(fit: Fit, data: Dataset) -> np.ndarray | None:
    """d ln k / d ln depth at the fit's parameters (None without a fitted depth)."""
    if fit.depth_m is None:
        return None
    step = 0.01
    law = replace(fit.law, depth_m=fit.law.depth_m * math.exp(step))
    return (predict_ln(data, law, fit.chain) - fit.predict(data)) / step


def residuals_at(data: Dataset, spec: ModelSpec, x: np.ndarray, measured: np.ndarray,
                 baselines: dict[tuple[str, float], np.ndarray] | None = None) -> np.ndarray:
    """ln k_model − ``measured`` at parameter vector ``x``; ``BAD_RESIDUAL`` where the model is not physical, and
    everywhere when a trial load offset takes the loads out of an empirical baseline's domain."""
    with np.errstate(all="ignore"):
        values = spec.decode(x)
        try:
            r = predict_ln(data, spec.law(x, values), spec.chain(x, values), baselines) - measured
        except ModelDomainError:
            return np.full(measured.shape, BAD_RESIDUAL)
    return np.where(np.isfinite(r), r, BAD_RESIDUAL)


def _starts(spec: ModelSpec, warm: Fit | None, guess: dict[str, dict[str, float]]) -> list[np.ndarray]:
    depth = warm.depth_m if warm is not None and warm.depth_m else DEFAULT_DEPTH_M
    known = {**(warm.spec.decode(warm.x) if warm is not None else {}), **guess}
    out = []
    fresh = [n for n in spec.terms if n not in known]
    for combo in itertools.product(*(STARTS[n] for n in fresh)):
        values = {**known, **dict(zip(fresh, combo, strict=True))}
        out.append(np.clip(spec.encode(depth, values), *spec.bounds()))
    return out


def fit_model(data: Dataset, spec: ModelSpec, warm: Fit | None = None, sigma: np.ndarray | None = None,
              guess: dict[str, dict[str, float]] | None = None, seating_sigma: float = 0.0,
              post: Callable[[np.ndarray], np.ndarray] | None = None) -> Fit:
    """Noise-weighted least squares on ln k, started from the warm fit's values, any guessed effect
    parameters, and each remaining effect's start grid.

    ``sigma`` is each point's noise (σ of ln k); without it all points weigh the same. ``seating_sigma`` is the
    σ of the offset shared by one seating's points: residuals are whitened for it (generalised least squares).
    ``post`` maps whitened residuals before the squares are summed (a form discrepancy integrated out); the fit
    returned keeps the plain whitened residuals.
    """
    measured = data.ln_stiffness
    sig = np.ones(measured.size) if sigma is None else np.asarray(sigma, dtype=float)
    runs = data.run_ids()

    def white(r: np.ndarray) -> np.ndarray:
        return whiten(runs, r, sig, seating_sigma)

    objective = post or (lambda e: e)
    lo, hi = spec.bounds()
    baselines: dict[tuple[str, float], np.ndarray] = {}
    best: tuple[float, np.ndarray] | None = None
    for x0 in _starts(spec, warm, guess or {}):
        if x0.size == 0:
            best = (0.0, x0)
            break
        sol = bounded_least_squares(lambda x: objective(white(residuals_at(data, spec, x, measured, baselines))),
                                    x0, lo, hi, ftol=FIT_FTOL)
        cost = float(np.sum(sol.fun**2))
        if best is None or cost < best[0]:
            best = (cost, sol.x)
    assert best is not None
    x = best[1]
    r = residuals_at(data, spec, x, measured)
    return Fit(spec, x, spec.law(x), r, sig, white(r))
