"""One load step out of line: the outliers the point screen cannot see, judged by a model's lack of fit.

Two bad repetitions of one load step agree with each other and outvote the clean one, and at a seating's end
their lines only extrapolate to them; the point screen (``labctl.discrepancy.outliers``) keeps them. What marks
them is the model: every other step of every roller case follows the baseline and that one step does not. So
each step (a replicate set of one case) is given a free mean in turn — the mean-shift outlier test, F(1,
pure-error dof), Bonferroni over the steps at ``OUTLIER_ALPHA``, made whether or not the lack-of-fit test, pooled
over every step, rejects — and the most significant one is set aside only if, with it free, the lack of fit passes
at ``CONSISTENT_P``: the misfit is that step's alone, not an effect's, which shows at many steps and roller cases.
Of that step only the repetitions far off the baseline (beyond ``SMOOTH_Z``, on the side of the shift) go, and
only when one repetition stays close to it and they differ from it beyond the noise (their contrast at
``OUTLIER_ALPHA``, shared among the ways to part the step in two): a clean repetition is never set aside. When
every repetition is that far off the same way, the step goes whole if it lies inside its case's load range:
a contact's stiffness is smooth in load, so one step off while the steps below and above it follow the fit is
that step's fault (a load set or read wrong, a mode crossing at that load); a campaign with two seatings holds
two bad points of one step so. At a seating's first or last step such a shift stays the contact's (a tilt
bedding in, a yield setting in).

Two bad repetitions in opposite directions leave the step's mean where it was and swell the pure error instead,
which can hide an effect's lack of fit; they show as the step's spread (``step_too_spread``, Cochran's test).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.special import betaincc, fdtrc, ndtri  # Beta and F survival functions, the normal quantile

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.noise import NoiseFloor, lack_of_fit_rejects
from labctl.discrepancy.outliers import OUTLIER_ALPHA, SMOOTH_Z


class StepFinding(NamedTuple):
    """What the mean-shift test found: the repetitions to set aside, and a seating's first or last step that every
    repetition leaves the same way while the rest follows the fit (kept as the contact's, but said), with which end
    of its case's load range it is ("first" or "last"; "" without one)."""

    set_aside: list[int]
    end_step: list[int]
    end: str = ""


def step_out_of_line(data: Dataset, noise: NoiseFloor, residuals: np.ndarray, sigma: np.ndarray,
                     n_params: int) -> StepFinding:
    """The repetitions of the one load step whose mean is out of line with this fit (``residuals`` =
    ln(k_model/k_measured), σ, ``n_params``) and without which the fit passes the lack-of-fit test (see the module
    doc); none when there is none, or when the misfit is not one step's."""
    none = StepFinding([], [])
    test = noise.lack_of_fit(data, residuals, sigma, n_params)
    if noise.method != "repetitions" or test is None or test.df_lack < 2:
        return none  # without repetitions there are no steps to judge
    e = noise.whiten(data, residuals, sigma)
    lx = noise.cells(data, sigma)
    along = lx.T @ e
    gain = along**2 / np.maximum(np.einsum("ij,ij->j", lx, lx), 1e-300)
    sizes = np.array([g.size for g in noise.groups])
    gain[sizes < 2] = 0.0
    j = int(np.argmax(gain))
    pure = test.pure_mean_square
    if len(noise.groups) * fdtrc(1, test.df_pure, gain[j] / pure) >= OUTLIER_ALPHA:
        return none
    rest = max(0.0, float(e @ e) - gain[j] - pure * test.df_pure) / (test.df_lack - 1) / pure
    if lack_of_fit_rejects(noise.p_value(data, rest, test.df_lack - 1, test.df_pure)):
        return none
    step = noise.groups[j]
    z = e[step] * np.sign(along[j])
    bad, kept = z > SMOOTH_Z, np.abs(z) <= SMOOTH_Z
    if np.all(bad):  # every repetition off the same way: inside the load range the step's fault, at an end unclear
        every, end = [int(i) for i in step], _end_of_range(data, step)
        return StepFinding([], every, end) if end else StepFinding(every, [])
    if not np.any(kept) or not np.any(bad):
        return none
    contrast = (z[bad].mean() - z[kept].mean()) / np.sqrt(pure * (1 / bad.sum() + 1 / kept.sum()))
    splits = 2 ** (step.size - 1) - 1  # the ways to part the step's repetitions in two
    if contrast <= ndtri(1.0 - OUTLIER_ALPHA / (2.0 * splits)):
        return none
    return StepFinding([int(i) for i in step[bad]], [])


def _end_of_range(data: Dataset, step: np.ndarray) -> str:
    """Which end of its roller case's load range the step is: "first" with no load of the case below it (where a
    tilt beds in), "last" with none above it (where a yield sets in), "" inside the range."""
    sl = data.case_slices()[data.case_of(int(step[0]))]
    others = data.load_n[np.setdiff1d(np.arange(sl.start, sl.stop), step)]
    if not np.any(others < data.load_n[step].min()):
        return "first"
    return "" if np.any(others > data.load_n[step].max()) else "last"


def step_too_spread(data: Dataset, noise: NoiseFloor, residuals: np.ndarray, sigma: np.ndarray) -> list[int]:
    """Indices of the repetitions of the one load step whose spread is out of line with every other step's
    (Cochran's test: its share of the pure error against Beta(ν_j/2, (ν − ν_j)/2), Bonferroni over the steps at
    ``OUTLIER_ALPHA``; not made when the noise model has one load band, whose σ cannot follow the noise's rise at
    low loads), beyond ``SMOOTH_Z`` of this fit on either side, where the step's median repetition stays within it:
    two bad points in opposite directions, which leave the step's mean and swell the pure error. A fit that misses
    the step shows as its median off it, and then nothing is set aside — unless every repetition is off, some above
    and some below the fit (two seatings with one bad point each way): the fit misses none of them, and none is
    clean to keep."""
    if noise.method != "repetitions" or len(noise.band_ln_p) < 2:
        return []  # one load band: a step's spread cannot be told from the noise's own rise at low loads
    pure = noise.pure_residuals(data, residuals, sigma)
    ss = np.array([float(pure[g] @ pure[g]) for g in noise.groups])
    dof = np.maximum(np.array([g.size for g in noise.groups]) - 1, 0)
    total = float(ss.sum())
    if total <= 0 or dof.sum() <= 2:
        return []
    p = np.where(dof > 0, betaincc(np.maximum(dof, 1) / 2, (dof.sum() - dof) / 2, ss / total), 1.0)
    j = int(np.argmin(p))
    if len(noise.groups) * p[j] >= OUTLIER_ALPHA:
        return []
    step = noise.groups[j]
    z = noise.whiten(data, residuals, sigma)[step]
    bad = np.abs(z) > SMOOTH_Z
    if np.all(bad) and z.min() < 0 < z.max():
        return [int(i) for i in step]  # every repetition off, some above and some below: none to keep
    middle = np.argsort(z)[(z.size - 1) // 2 : z.size // 2 + 1]  # the step's median repetition(s)
    if not np.any(bad) or np.any(bad[middle]):
        return []
    return [int(i) for i in step[bad]]
