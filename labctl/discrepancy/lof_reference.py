"""The lack-of-fit test's null distribution, simulated under the noise model that was estimated.

The test divides the model's whitened misfit beyond the saturated model by the pure error; but the whitening uses
a point noise σ(F) and a seating σ estimated from the same repetitions (four load bands, a moment estimate), so the
statistic is not F(df_lack, df_pure) distributed: on null campaigns the plain F reference rejected at level 0.01 in
2–3 % of them, at 0.05 in about 9 % (``bench/lof_level.py``). Here the whole estimate is repeated on ``DRAWS``
campaigns simulated from the estimated model (Gaussian point noise of σ(F) at every point, a Gaussian offset of
σ_seat per seating, the same design; the cell means do not enter the statistic), each statistic taken against the
true mean, and a scaled F, c·F(df, d), is fitted to the draws by maximum likelihood (``scipy.stats.f.fit``, df fixed
to the saturated model's number of cells): the reference every lack-of-fit test on these data is read against, with
the model's own df_lack. Fixed draws: the same data always give the same p-value. The draws share the campaign's
design (``Dataset.with_ln_stiffness``): what the loads and seatings alone decide in the noise estimate is worked out
once (``Dataset.design_memo``; ``python bench/lof_reference_speed.py``: about 2.5 times faster than anew per draw).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.special import fdtrc  # the F distribution's survival function (scipy.stats.f.sf)

from labctl.discrepancy.data import Dataset

DRAWS = 100
"""Simulated campaigns per reference fit."""


@dataclass(frozen=True)
class Reference:
    """The test statistic's null distribution: ``scale``·F(df_lack, ``dfd``)."""

    dfd: float
    scale: float

    def p(self, f: float, df_lack: int) -> float:
        """The p-value of statistic ``f`` with ``df_lack`` degrees of freedom of misfit."""
        return float(fdtrc(df_lack, self.dfd, f / self.scale))


def simulate(data: Dataset, sigma: np.ndarray, seating_sigma: float,
             statistic: Callable[[Dataset], tuple[float, int] | None]) -> Reference | None:
    """Fit the reference to ``DRAWS`` null campaigns like ``data`` (point σ ``sigma``, seating σ
    ``seating_sigma``); ``statistic(campaign)``: the lack-of-fit statistic of the true mean (zero) and its
    df_lack on a simulated campaign, its noise estimated anew (None: no test). None when the
    draws give no test."""
    rng = np.random.default_rng(0)
    runs = data.run_ids()
    draws, df = [], 0
    for _ in range(DRAWS):
        y = sigma * rng.standard_normal(sigma.size) + seating_sigma * rng.standard_normal(int(runs.max()) + 1)[runs]
        test = statistic(data.with_ln_stiffness(y))
        if test is not None and np.isfinite(test[0]):
            draws.append(test[0])
            df = max(df, test[1])
    if len(draws) < DRAWS // 2 or np.ptp(draws) <= 0:
        return None
    from scipy import stats  # only here: importing it costs every command's start-up about 0.3 s

    with warnings.catch_warnings():  # the optimiser's overflow warnings on far trial values
        warnings.simplefilter("ignore")
        _, dfd, _, scale = stats.f.fit(np.asarray(draws), fdfn=df, floc=0)
    return Reference(float(dfd), float(scale))
