"""An unnamed empirical term for what no library term explains: sparse regression over physical features.

When the model (with any named terms) still leaves structure beyond the noise, the residual
ln(k_measured/k_model) is regressed on a documented basis of features built from the contact's physical
quantities (``BASIS``): powers and logs of the load per length p = F/L_we, the contact length L_we, the
diameter D, the effective modulus E*, the composite roughness Ra and the peak pressure over the hardness. The
selection is forward stepwise on the whitened residuals (generalised least squares with the seating offsets),
with Tripp's depth re-adjusted alongside (its sensitivity column is always in the design); a feature enters only
when it improves the BIC by ``DECISIVE_BIC``, at most ``MAX_FEATURES`` of them. The result is a candidate effect
for the engineer to explain, labelled "unnamed", with its formula, coefficients, the gap it closes and a
held-out check (refitted with each roller geometry left out in turn).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from labctl.discrepancy.data import CaseData, Dataset
from labctl.discrepancy.model import Fit, depth_column
from labctl.discrepancy.search import DECISIVE_BIC, HELD_OUT_MARGIN, Search

MAX_FEATURES = 3
P_REF_N_PER_M = 1e4
"""Reference load per length (10 N/mm)."""
L_REF_M = 10e-3
D_REF_M = 5e-3
E_REF_PA = 114.6e9
RA_REF_M = 0.2e-6

Feature = Callable[[CaseData], np.ndarray]


def _p(c: CaseData) -> np.ndarray:
    return c.load_n / c.case.roller.contact_length_m / P_REF_N_PER_M


def _const(value: Callable[[CaseData], float]) -> Feature:
    return lambda c: np.full(c.load_n.size, value(c))


def _pressure_over_hardness(c: CaseData) -> np.ndarray:
    h = c.case.softer_hardness_pa
    return np.asarray(c.case.peak_pressure_pa(c.load_n)) / h


BASIS: dict[str, Feature] = {
    "ln(p/p0)": lambda c: np.log(_p(c)),
    "(p/p0)^-1": lambda c: 1.0 / _p(c),
    "(p/p0)^-0.5": lambda c: _p(c) ** -0.5,
    "(p/p0)^0.5": lambda c: _p(c) ** 0.5,
    "ln(L/L0)": _const(lambda c: math.log(c.case.roller.contact_length_m / L_REF_M)),
    "(L/L0)^-1": _const(lambda c: L_REF_M / c.case.roller.contact_length_m),
    "ln(D/D0)": _const(lambda c: math.log(c.case.roller.diameter_m / D_REF_M)),
    "ln(E*/E0)": _const(lambda c: math.log(c.case.effective_modulus_pa / E_REF_PA)),
    "Ra/Ra0": _const(lambda c: c.case.combined_ra_m / RA_REF_M),
    "(Ra/Ra0)·(p/p0)^-1": lambda c: c.case.combined_ra_m / RA_REF_M / _p(c),
    "(L/L0)^-1·(p/p0)^-0.5": lambda c: L_REF_M / c.case.roller.contact_length_m * _p(c) ** -0.5,
    "(L/L0)^-1·ln(p/p0)": lambda c: L_REF_M / c.case.roller.contact_length_m * np.log(_p(c)),
    "p_max/H": _pressure_over_hardness,
    "(p_max/H)^2": lambda c: _pressure_over_hardness(c) ** 2,
}
"""Feature name → values per point; p = F/L_we, p0 = 10 N/mm, L0 = 10 mm, D0 = 5 mm, E0 = 114.6 GPa (steel on
steel), Ra0 = 0.2 µm (composite Ra of roller and rail), H the softer body's hardness."""


def features(data: Dataset, names: list[str] | None = None) -> tuple[list[str], np.ndarray]:
    """The basis evaluated at every point; features constant over the data (no information) are dropped."""
    if names is not None:
        cols = [np.concatenate([BASIS[n](c) for c in data.cases]) for n in names]
        return names, np.stack(cols, axis=1) if cols else np.zeros((data.n_points, 0))
    every = list(BASIS)
    cols = [np.concatenate([BASIS[n](c) for c in data.cases]) for n in every]
    keep = [i for i, v in enumerate(cols) if np.ptp(v) > 1e-9 * max(1.0, float(np.max(np.abs(v))))]
    return [every[i] for i in keep], np.stack([cols[i] for i in keep], axis=1)


@dataclass(frozen=True)
class EmpiricalTerm:
    """ln(k_measured/k_model) ≈ Σ coefficient·feature (+ a depth re-adjustment): an unnamed candidate effect."""

    features: tuple[str, ...]
    coefficients: tuple[float, ...]
    depth_factor: float
    gap_before: float
    gap_after: float
    lack_of_fit_p: float | None
    held_out: dict[str, Any] | None

    @property
    def formula(self) -> str:
        terms = " ".join(f"{c:+.4g}·{n}" for c, n in zip(self.coefficients, self.features, strict=True))
        return f"ln(k_measured/k_model) = {terms}"

    @property
    def generalises(self) -> bool:
        return bool(self.held_out and self.held_out["passed"])

    def to_dict(self) -> dict[str, Any]:
        return {"label": "unnamed", "formula": self.formula,
                "parameters": dict(zip(self.features, self.coefficients, strict=True)),
                "depth_factor": self.depth_factor, "gap_before": self.gap_before, "gap_after": self.gap_after,
                "lack_of_fit_p": self.lack_of_fit_p, "held_out": self.held_out, "generalises": self.generalises,
                "basis": "p = F/L_we, p0 = 10 N/mm, L0 = 10 mm, D0 = 5 mm, E0 = 114.6 GPa, Ra0 = 0.2 µm, "
                         "H = hardness of the softer body"}


def _design(fit: Fit, data: Dataset, names: list[str]) -> np.ndarray:
    _, x = features(data, names)
    j = depth_column(fit, data)
    return x if j is None else np.column_stack([j, x])


def _rss(a: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    if a.shape[1] == 0:
        return float(y @ y), np.zeros(0)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    r = y - a @ coef
    return float(r @ r), coef


def propose(search: Search, current: Fit) -> EmpiricalTerm | None:
    """Sparse regression of the current model's residual over the feature basis; None if nothing earns a place."""
    data, noise = search.data, search.noise
    y = -current.residuals
    names, x = features(data)
    if len(data.roller_keys()) < 3:  # a per-geometry feature cannot be told from the seating offsets
        keep = [i for i, n in enumerate(names) if np.unique(x[:, i]).size > len(data.cases)]
        names, x = [names[i] for i in keep], x[:, keep]
    j = depth_column(current, data)
    base = np.zeros((data.n_points, 0)) if j is None else j[:, None]
    white = lambda a: noise.whiten(data, a, search.sigma)  # noqa: E731
    yw, bw, xw = white(y), white(base) if base.shape[1] else base, white(x)
    n = y.size
    chosen: list[int] = []
    rss, _ = _rss(bw, yw)
    while len(chosen) < MAX_FEATURES:
        best: tuple[float, int] | None = None
        for i in range(len(names)):
            if i in chosen:
                continue
            r, _ = _rss(np.column_stack([bw, xw[:, [*chosen, i]]]), yw)
            if best is None or r < best[0]:
                best = (r, i)
        if best is None or best[0] <= 0 or n * math.log(rss / best[0]) - math.log(n) < DECISIVE_BIC:
            break
        rss = best[0]
        chosen.append(best[1])
    if not chosen:
        return None
    sel = [names[i] for i in chosen]
    _, coef = _rss(np.column_stack([bw, xw[:, chosen]]), yw)
    design = np.column_stack([base, x[:, chosen]])
    after = current.residuals + design @ coef
    lof = noise.lack_of_fit(data, after, search.sigma, current.spec.n_params() + len(chosen))
    depth_factor = float(math.exp(coef[0])) if j is not None else 1.0
    return EmpiricalTerm(tuple(sel), tuple(float(c) for c in coef[base.shape[1]:]), depth_factor,
                         current.gap, math.sqrt(float(np.mean(after**2))), None if lof is None else lof.p,
                         _held_out(search, current, sel))


def _held_out(search: Search, current: Fit, names: list[str]) -> dict[str, Any] | None:
    """Leave each roller geometry out: fit the current model and the empirical term on the rest, predict it."""
    by, weak, folds = search.folds
    if not folds:
        return None
    noise = search.noise
    ss0 = ss1 = sq0 = sq1 = 0.0
    n = 0
    for (train, test), (train_fit, r_test) in zip(folds, search.fold_fits(current.spec), strict=True):
        a_train = _design(train_fit, train, names)
        white = noise.whiten(train, a_train, noise.sigma_at(train))
        coef, *_ = np.linalg.lstsq(white, noise.whiten(train, -train_fit.residuals, noise.sigma_at(train)),
                                   rcond=None)
        r_new = r_test + _design(train_fit, test, names) @ coef
        s = noise.sigma_at(test)
        e0, e1 = noise.whiten(test, r_test, s), noise.whiten(test, r_new, s)
        ss0, ss1 = ss0 + float(e0 @ e0), ss1 + float(e1 @ e1)
        sq0, sq1 = sq0 + float(r_test @ r_test), sq1 + float(r_new @ r_new)
        n += r_test.size
    gain = ss0 - ss1
    return {"by": by, "folds": len(folds), "weak": weak, "gap_without": math.sqrt(sq0 / n),
            "gap_with": math.sqrt(sq1 / n), "score_without": math.sqrt(ss0 / n), "score_with": math.sqrt(ss1 / n),
            "passed": bool(gain >= HELD_OUT_MARGIN * ss0 and gain >= DECISIVE_BIC)}
