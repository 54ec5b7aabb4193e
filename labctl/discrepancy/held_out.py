"""Each roller case predicted from the others: a candidate's leave-one-case-out log predictive density.

A law that fits every roller type only with its parameters set by that type's own points does not generalise; the
question "which effect?" weighs candidates by how well their fit to the other roller cases predicts each case
(pseudo-BMA+, Yao et al. 2018, with roller cases in place of points: ``labctl.discrepancy.questions``).

The refit without case c is the fit linearised about the full one: the whitened residuals z(x + δ) ≈ z + J·δ,
J the whitened Jacobian of the free parameters (``jacobian``), and each term's bend columns B (shared by every
case, prior N(0, BEND_SIGMA²)) beside them. Case c's residuals are N(Jδ + Bγ, Σ_c) with Σ_c = T·I + τ²·A_cA_c'
(the case's form discrepancy integrated out), so with the other cases' posterior of (δ, γ) the held-out case's
predictive density is Gaussian, exact for the linearised model: no case is refitted, and the whole costs a few
k × k solves per case. The fitted parameters get a vague proper prior, N(0, 1) in the fit's own units (the bounds
span 0–1; the depth is log10 metres), so a parameter only one case informs makes that case unpredictable rather
than infinitely so.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.model import Fit, residuals_at
from labctl.discrepancy.noise import NoiseFloor

STEP = 1e-4
"""Finite-difference step of the Jacobian, in the fit's own units (effect parameters scaled to 0–1 over bounds)."""
AT_BOUND = 1e-3
"""A parameter this close to a bound (0–1 units) is held there: the refit without a case does not move it."""
PARAM_PRIOR_SIGMA = 1.0
"""σ of the vague prior on every fitted parameter (0–1 units; log10 m for the depth)."""


def jacobian(data: Dataset, fit: Fit, noise: NoiseFloor, sigma: np.ndarray) -> np.ndarray:
    """Whitened d z / d x at the fit, central differences, one column per parameter not held at a bound."""
    lo, hi = fit.spec.bounds()
    measured = data.ln_stiffness
    cols = []
    for j in range(fit.x.size):
        if fit.x[j] - lo[j] < AT_BOUND * (hi[j] - lo[j]) or hi[j] - fit.x[j] < AT_BOUND * (hi[j] - lo[j]):
            continue
        up, down = fit.x.copy(), fit.x.copy()
        up[j] += STEP
        down[j] -= STEP
        col = (residuals_at(data, fit.spec, up, measured) - residuals_at(data, fit.spec, down, measured)) / (2 * STEP)
        if np.all(np.isfinite(col)):
            cols.append(col)
    if not cols:
        return np.zeros((data.n_points, 0))
    return noise.whiten(data, np.column_stack(cols), sigma)


def case_predictive(z: np.ndarray, design: np.ndarray, prior_sigma: np.ndarray,
                    cases: Sequence[tuple[slice, np.ndarray, np.ndarray]], inflation: float, tau: float
                    ) -> list[float]:
    """Each roller case's log predictive density given the others (constants common to every candidate dropped).

    ``z``: whitened residuals of the full fit; ``design``: the columns the linearised refit moves (Jacobian, bend
    columns, or an empirical basis), with ``prior_sigma`` their prior σ; ``cases``: per case its rows and the SVD
    (u, s²) of its block of the whitened form basis (``FormPrior.cases``); T and τ as in the evidence."""
    k = design.shape[1]
    per_case = []
    for sl, u, s2 in cases:
        g = tau**2 * s2 / inflation
        shrink = g / (1.0 + g)

        def inv(v: np.ndarray, u: np.ndarray = u, shrink: np.ndarray = shrink) -> np.ndarray:  # Σ_c⁻¹·v
            return (v - u @ (shrink[:, None] * (u.T @ v)) if v.ndim == 2 else v - u @ (shrink * (u.T @ v))) / inflation
        xc, zc = design[sl], z[sl]
        sx, sz = inv(xc), inv(zc)
        logdet = zc.size * np.log(inflation) + float(np.sum(np.log1p(g)))
        per_case.append((xc.T @ sx, xc.T @ sz, float(zc @ sz), logdet))
    prior = np.diag(1.0 / np.asarray(prior_sigma, dtype=float) ** 2) if k else np.zeros((0, 0))
    total = prior + sum((gc for gc, _, _, _ in per_case), np.zeros((k, k)))
    h_all = sum((hc for _, hc, _, _ in per_case), np.zeros(k))
    _, logdet_total = np.linalg.slogdet(total) if k else (1.0, 0.0)
    out = []
    for gc, hc, qc, logdet_c in per_case:
        p = total - gc
        theta = np.linalg.solve(p, h_all - hc) if k else np.zeros(0)
        w = hc - gc @ theta
        quad = qc - 2.0 * theta @ hc + theta @ gc @ theta - (w @ np.linalg.solve(total, w) if k else 0.0)
        logdet_p = np.linalg.slogdet(p)[1] if k else 0.0
        out.append(float(-0.5 * quad - 0.5 * (logdet_c + logdet_total - logdet_p)))
    return out
