"""Empirical forms scored as candidates: an effect outside the library, and a library term in a free form.

Both are the baseline plus up to ``MAX_FEATURES`` features of the empirical basis
(``labctl.discrepancy.empirical.BASIS``), chosen by forward selection on the evidence and charged −ln C(F, m) for
choosing m of the F features allowed. *Unlisted* may choose any feature. A library term in a *free form* may choose
only the features that carry its physical signature (``SIGNATURES``): how the term scales with the roller and the
surfaces, which is its physics, kept; its dependence on load, which is the part of its law the library only
approximates, left to the data. An end effect that loses or gains a length per roller end is ∝ 1/L in ln k whatever
its load law; a surface layer's compliance scales with the roughness; a yield term follows the peak pressure over the
hardness. The term's evidence averages its library law and the free form (``FREE_FORM_DOUBT``), so a name does not
hinge on the library's exponent, while an effect outside every signature is still left to *unlisted*.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.empirical import MAX_FEATURES, features
from labctl.discrepancy.form import FormPrior

SIGNATURES: dict[str, tuple[str, ...]] = {
    "end_effects": ("(L/L0)^-1", "(L/L0)^-1·(p/p0)^-0.5", "(L/L0)^-1·ln(p/p0)"),
    "surface_roughness": ("Ra/Ra0", "(Ra/Ra0)·(p/p0)^-1"),
    "material_hardness": ("p_max/H", "(p_max/H)^2"),
}
"""The basis features that carry each term's signature: per roller end (∝ 1/L), per unit roughness (∝ Ra), per unit
of the peak pressure over the hardness. A term without one (a tilt, the rig's compliance) keeps its library law."""
FREE_FORM_DOUBT = 1.0 / 3.0
"""Prior probability that a term with a signature follows a load law the library does not have: its library law
(with its own shape doubt) is taken as twice as likely as the free form."""


def signature(terms: tuple[str, ...]) -> tuple[str, ...] | None:
    """The features a free form of ``terms`` may choose (the union of their signatures), or None when a term has no
    signature (the explanation has no free form)."""
    if not terms or any(t not in SIGNATURES for t in terms):
        return None
    return tuple(dict.fromkeys(f for t in terms for f in SIGNATURES[t]))


@dataclass(frozen=True)
class Selected:
    """An empirical form chosen at each noise inflation T."""

    features: tuple[str, ...]
    """The features chosen at the decision's T."""
    log_fit_by_t: dict[float, float]
    log_evidence_by_t: dict[float, float]
    case_log_lik_by_t: dict[float, list[float]]
    tau: float
    residual: np.ndarray
    """The whitened residual left at the decision's T."""


def select(data: Dataset, form: FormPrior, y: np.ndarray, head: np.ndarray, whiten: Callable[[np.ndarray], np.ndarray],
           charged: Callable[[float, int, float], float], k0: int, temperatures: tuple[float, ...],
           allowed: tuple[str, ...] | None = None) -> Selected | None:
    """Forward selection of at least one and at most ``MAX_FEATURES`` features (of ``allowed``, or any) on the
    whitened residual ``y`` with the columns ``head`` (the depth's) always in, at each T; None if none is
    available. ``charged(log_fit, k, T)``: the evidence of a fit with ``k`` parameters."""
    names, x = features(data)
    keep = [i for i, n in enumerate(names) if allowed is None or n in allowed]
    if len(data.roller_keys()) < 3:  # a per-geometry feature cannot be told from the seating offsets
        keep = [i for i in keep if np.unique(x[:, i]).size > len(data.cases)]
    if not keep:
        return None
    names, xw = [names[i] for i in keep], whiten(x[:, keep])

    def evaluate(chosen: list[int], t: float) -> tuple[float, float, np.ndarray]:
        a = np.column_stack([head, xw[:, chosen]])
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        e = y - a @ coef
        log_m, tau = form.log_marginal(e, inflation=t)
        return log_m - math.log(math.comb(len(names), len(chosen))), tau, e

    def evidence(log_fit: float, m: int, t: float) -> float:
        return charged(log_fit, k0 + m, t) if m else -math.inf

    def best_at(t: float) -> tuple[list[int], tuple[float, float, np.ndarray]]:
        # at least one feature: with none, the form is the baseline itself — "none" under another name
        chosen: list[int] = []
        best = (-math.inf, 0.0, y)
        while len(chosen) < min(MAX_FEATURES, len(names)):
            trial = [(evaluate([*chosen, i], t), i) for i in range(len(names)) if i not in chosen]
            top = max(trial, key=lambda r: evidence(r[0][0], len(chosen) + 1, t))
            if evidence(top[0][0], len(chosen) + 1, t) <= evidence(best[0], len(chosen), t):
                break
            best, chosen = top[0], [*chosen, top[1]]
        return chosen, best

    chosen_by_t = {t: best_at(t) for t in temperatures}
    chosen, (_, tau, e) = chosen_by_t[temperatures[0]]
    return Selected(tuple(names[i] for i in chosen), {t: b[0] for t, (_, b) in chosen_by_t.items()},
                    {t: evidence(b[0], len(c), t) for t, (c, b) in chosen_by_t.items()},
                    {t: form.case_log_marginals(b[2], t, b[1]) for t, (_, b) in chosen_by_t.items()}, tau, e)


def averaged(law: dict[float, float], free: dict[float, float]) -> dict[float, float]:
    """The evidence averaged over the library law (1 − ``FREE_FORM_DOUBT``) and the free form."""
    return {t: float(np.logaddexp(math.log1p(-FREE_FORM_DOUBT) + v, math.log(FREE_FORM_DOUBT) + free[t]))
            for t, v in law.items()}
