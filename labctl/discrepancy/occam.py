"""The Occam factor of parameters a candidate adds to the baseline: Zellner's g prior with the hyper-g mixture.

With the residuals whitened (the noise scale known), k added parameters whose fit gains Δχ² over the baseline,
β ~ N(0, g·(J'J)⁻¹) and g ~ π(g) = (a − 2)/2·(1 + g)^(−a/2), the Bayes factor against the baseline is

    BF = (a − 2)/2 ∫ (1 + g)^(−(a+k)/2) exp(g/(1 + g)·Δχ²/2) dg = (a − 2)/(a + k − 2) · ₁F₁(1; (a + k)/2; Δχ²/2)

(the hyper-g prior of Liang, Paulo, Molina, Clyde & Berger, 2008, with σ known). Its penalty follows the fit's
gain: a gain within the noise costs about ln((a + k − 2)/(a − 2)) (an effect too small to see is not ruled out,
where BIC's ½·k·ln n all but rules it out), a large one about ½·k·ln Δχ². a = 3 is the authors' default.
"""

from __future__ import annotations

import math

from scipy.special import gammainc, gammaln, hyp1f1

HYPER_A = 3.0
"""The hyper-g prior's a, in (2, 4]: π(g) = (a − 2)/2·(1 + g)^(−a/2)."""
_SERIES_UP_TO = 50.0
"""Beyond this half-gain ₁F₁ is taken from the incomplete gamma function (it overflows near 700)."""


def log_bayes_factor(chi2_gain: float, k: int, a: float = HYPER_A) -> float:
    """log BF of ``k`` added parameters whose fit gains ``chi2_gain`` (whitened Δχ², may be negative) over the
    baseline; no parameter added: the likelihood ratio itself."""
    x = 0.5 * chi2_gain
    if k <= 0:
        return x
    b = 0.5 * (a + k)
    lead = math.log((a - 2.0) / (a + k - 2.0))
    if x <= _SERIES_UP_TO:
        return lead + math.log(float(hyp1f1(1.0, b, x)))
    # ₁F₁(1; b; x) = (b − 1)·eˣ·x^(1−b)·γ(b − 1, x), γ the lower incomplete gamma function
    return (lead + math.log(b - 1.0) + x + (1.0 - b) * math.log(x) + float(gammaln(b - 1.0))
            + math.log(float(gammainc(b - 1.0, x))))
