"""Is the structure a named term leaves its own form's, or another effect's?

A real effect whose law differs from the library's term (an asperity layer with another load exponent, a joint
spring that stiffens with load, a constant spring at the roller ends) is named by its closest term and leaves
structured residuals; any flexible further term then absorbs part of them, in sample. The alternative to "a
second effect" is therefore "the first term's form is not quite right": the current model with each term's
contribution d_t (ln k with the term minus ln k without it, same parameters) bent with load,
ln k + Σ_t d_t·(a_t + b_t·ln(p/p̄)) with p the load per length, p̄ its geometric mean, plus Tripp's depth
re-adjusted (linearised, generalised least squares). One parameter b_t per term; the a_t and the depth re-adjust
parameters already fitted. A further term is named only when it beats this bent model decisively; a term that
leaves structure the bend does not explain (``own_form_share`` < ½) must predict left-out roller types too.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import Fit, depth_column, predict_ln
from labctl.discrepancy.noise import NoiseFloor


def contribution(fit: Fit, data: Dataset, name: str) -> np.ndarray:
    """ln k of the fitted model minus ln k with term ``name`` left out (the other parameters unchanged)."""
    if name in MEASUREMENT:
        chain = tuple(t for t, n in zip(fit.chain, fit.spec.measurement, strict=True) if n != name)
        law = fit.law
    else:
        chain = fit.chain
        law = replace(fit.law, effects=tuple(e for e in fit.law.effects if e.name != name))
    with np.errstate(all="ignore"):
        d = fit.predict(data) - predict_ln(data, law, chain)
    return np.nan_to_num(d, nan=0.0, posinf=0.0, neginf=0.0)


def bent_ss(fit: Fit, data: Dataset, noise: NoiseFloor) -> float:
    """Whitened sum of squares of ``fit`` with each term's contribution bent with load (see the module doc)."""
    if not fit.spec.terms:
        return float(fit.z @ fit.z)
    ln_p = np.log(data.load_per_length_n_per_m)
    ln_p = ln_p - ln_p.mean()
    cols = []
    for name in fit.spec.terms:
        d = contribution(fit, data, name)
        cols += [d, d * ln_p]
    j = depth_column(fit, data)
    if j is not None:
        cols.append(np.nan_to_num(j))
    a = noise.whiten(data, np.column_stack(cols), fit.sigma)
    coef, *_ = np.linalg.lstsq(a, fit.z, rcond=None)
    e = fit.z - a @ coef
    return max(float(e @ e), 1e-300)


def bent_bic(fit: Fit, data: Dataset, noise: NoiseFloor) -> float:
    """BIC of ``fit`` with its terms' load dependence bent (one parameter per term); its own BIC without terms."""
    if not fit.spec.terms:
        return fit.bic
    n = fit.n_points
    return n * math.log(bent_ss(fit, data, noise) / n) + (fit.spec.n_params() + len(fit.spec.terms)) * math.log(n)


def own_form_share(fit: Fit, data: Dataset, noise: NoiseFloor) -> float:
    """Share of the structure ``fit`` leaves (its whitened misfit above the noise's expectation) that bending its
    terms' load dependence explains: near 1 when the leftover is the terms' own law, near 0 when it is not."""
    left = float(fit.z @ fit.z) - (fit.n_points - fit.spec.n_params())
    if left <= 0:
        return 1.0
    return max(0.0, min(1.0, (float(fit.z @ fit.z) - bent_ss(fit, data, noise)) / left))
