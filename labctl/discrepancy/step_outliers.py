"""One load step out of line: the outliers the point screen cannot see, judged by the baseline's lack of fit.

Two bad repetitions of one load step agree with each other and outvote the clean one, and at a seating's end
their lines only extrapolate to them; the point screen (``labctl.discrepancy.outliers``) keeps them. What marks
them is the model: every other step of every roller case follows the baseline and that one step does not. So,
when the baseline fails the lack-of-fit test, each step (a replicate set of one case) is given a free mean in turn
— the mean-shift outlier test, F(1, pure-error dof), Bonferroni over the steps at ``OUTLIER_ALPHA`` — and the most
significant one is set aside only if, with it free, the lack of fit passes at ``CONSISTENT_P``: the misfit is that
step's alone, not an effect's, which shows at many steps and roller cases. Of that step only the repetitions far
off the baseline (beyond ``SMOOTH_Z``, on the side of the shift) go, and only when one repetition stays close to
it: a shift every repetition shares is the contact's, and a clean repetition is never the one set aside.
"""

from __future__ import annotations

import numpy as np
from scipy.special import fdtrc, ndtri  # the F survival function (scipy.stats.f.sf), the normal quantile

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.noise import NoiseFloor, lack_of_fit_rejects
from labctl.discrepancy.outliers import OUTLIER_ALPHA, SMOOTH_Z


def step_out_of_line(data: Dataset, noise: NoiseFloor, residuals: np.ndarray, sigma: np.ndarray,
                     n_params: int) -> list[int]:
    """Indices of the repetitions of the one load step whose mean alone makes this fit (``residuals`` =
    ln(k_model/k_measured), σ, ``n_params``) fail the lack-of-fit test (see the module doc); [] when there is
    none, or when the misfit is not one step's."""
    test = noise.lack_of_fit(data, residuals, sigma, n_params)
    if test is None or not lack_of_fit_rejects(test.p) or test.df_lack < 2:
        return []
    e = noise.whiten(data, residuals, sigma)
    lx = noise.cells(data, sigma)
    s_pure = noise.pure_error(data, residuals, sigma)
    along = lx.T @ e
    gain = along**2 / np.maximum(np.einsum("ij,ij->j", lx, lx), 1e-300)
    sizes = np.array([g.size for g in noise.groups])
    gain[sizes < 2] = 0.0
    j = int(np.argmax(gain))
    pure = s_pure / test.df_pure
    if len(noise.groups) * fdtrc(1, test.df_pure, gain[j] / pure) >= OUTLIER_ALPHA:
        return []
    rest = max(0.0, float(e @ e) - gain[j] - s_pure) / (test.df_lack - 1) / pure
    if lack_of_fit_rejects(float(fdtrc(test.df_lack - 1, test.df_pure, rest))):
        return []
    step = noise.groups[j]
    z = e[step] * np.sign(along[j])
    bad, kept = z > SMOOTH_Z, np.abs(z) <= SMOOTH_Z
    if not np.any(kept) or not np.any(bad):
        return []
    contrast = (z[bad].mean() - z[kept].mean()) / np.sqrt(pure * (1 / bad.sum() + 1 / kept.sum()))
    splits = 2 ** (step.size - 1) - 1  # the ways to part the step's repetitions in two
    if contrast <= ndtri(1.0 - OUTLIER_ALPHA / (2.0 * splits)):
        return []
    return [int(i) for i in step[bad]]
