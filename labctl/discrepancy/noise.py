"""The noise floor of the measurement: scatter of ln k between repetitions of the same load step.

Points of one case are grouped into replicate sets (one per load step, one point per repetition); the
pooled within-set scatter is the pure error of regression's lack-of-fit test. Scatter falls with load (a few %
at the preload, < 1 % near C0), so it is pooled in bands of load per length and interpolated between them:
each point gets its own σ, which weights the fits. Without repetitions each point's distance from the line
through its two neighbours (in ln F) stands in, as one σ for all points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from labctl.discrepancy.data import CaseData, Dataset
from labctl.errors import InputError

SAME_STEP = 0.05
"""Loads of two repetitions' points within this relative distance count as the same step."""
CONSISTENT_P = 0.01
"""Lack-of-fit p-value above which the residuals count as noise."""
BAND_DOF = 12
"""Least degrees of freedom pooled in one load band."""
MAX_BANDS = 4


@dataclass(frozen=True)
class NoiseFloor:
    """Standard deviation of ln k of a single point (≈ relative scatter), with how it was found."""

    sigma: float
    """Pooled over all points: the overall noise floor, comparable with the gap."""
    dof: int
    method: str
    groups: tuple[np.ndarray, ...]
    """Replicate sets as index arrays into the dataset's concatenated points (singletons included)."""
    band_ln_p: tuple[float, ...] = ()
    """Centre of each load band as ln of load per length (N/m)."""
    band_sigma: tuple[float, ...] = ()

    def sigma_at(self, data: Dataset) -> np.ndarray:
        """σ of ln k for each point of any dataset, interpolated in ln(F/L_we) between the load bands."""
        x = np.concatenate([np.log(c.load_n / c.case.roller.contact_length_m) for c in data.cases])
        if len(self.band_sigma) < 2:
            return np.full(x.size, self.sigma)
        return np.exp(np.interp(x, self.band_ln_p, np.log(self.band_sigma)))

    def bands(self) -> list[dict[str, float]]:
        """The load bands at the user's edge: load per length in N/mm and σ."""
        return [{"load_per_length_n_per_mm": float(np.exp(x)) * 1e-3, "sigma": s}
                for x, s in zip(self.band_ln_p, self.band_sigma, strict=True)]

    def consistent(self, z: np.ndarray, n_params: int) -> bool:
        """Residuals z (in noise units) show no lack of fit, or a systematic part no larger than the noise."""
        p = self.lack_of_fit_p(z, n_params)
        return (p is not None and p >= CONSISTENT_P) or float(np.mean(z**2)) <= 2.0

    def lack_of_fit_p(self, residuals: np.ndarray, n_params: int) -> float | None:
        """p-value of the lack-of-fit F test (None without replicates): small means the model misses structure."""
        if self.method != "repetitions":
            return None
        n, m = residuals.size, len(self.groups)
        ss_pe = sum(float(np.sum((residuals[g] - residuals[g].mean()) ** 2)) for g in self.groups)
        ss_lof = float(np.sum(residuals**2)) - ss_pe
        df_lof, df_pe = m - n_params, n - m
        if df_lof <= 0 or df_pe <= 0 or ss_pe <= 0:
            return None
        return float(stats.f.sf((ss_lof / df_lof) / (ss_pe / df_pe), df_lof, df_pe))


def _case_groups(c: CaseData) -> list[np.ndarray]:
    """Replicate sets of one case: by step rank when every repetition has the same steps, else by load."""
    reps = np.unique(c.repetition)
    order = np.argsort(c.load_n, kind="stable")
    if reps.size > 1 and np.all(reps >= 0):
        per_rep = [order[c.repetition[order] == r] for r in reps]
        if len({p.size for p in per_rep}) == 1:
            ranks = np.stack(per_rep)
            loads = c.load_n[ranks]
            if np.all(loads.max(axis=0) <= loads.min(axis=0) * (1 + SAME_STEP)):
                return [ranks[:, j] for j in range(ranks.shape[1])]
    groups: list[list[int]] = []
    for i in order:
        last = groups[-1] if groups else None
        if (last is not None and c.load_n[i] <= c.load_n[last[0]] * (1 + SAME_STEP)
                and (c.repetition[i] < 0 or c.repetition[i] not in c.repetition[last])):
            last.append(int(i))
        else:
            groups.append([int(i)])
    return [np.array(g) for g in groups]


def _bands(x: np.ndarray, ss: np.ndarray, dof: np.ndarray) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Pool replicate sets into up to MAX_BANDS bands of load per length with at least BAND_DOF each."""
    keep = dof > 0
    x, ss, dof = x[keep], ss[keep], dof[keep]
    order = np.argsort(x)
    n_bands = int(min(MAX_BANDS, max(1, dof.sum() // BAND_DOF)))
    centre, sigma = [], []
    for part in np.array_split(order, n_bands):
        if ss[part].sum() <= 0:
            return (), ()
        centre.append(float(np.average(x[part], weights=dof[part])))
        sigma.append(math.sqrt(float(ss[part].sum() / dof[part].sum())))
    return tuple(centre), tuple(sigma)


def _pseudo_residual_scatter(data: Dataset) -> tuple[float, int]:
    """Gasser-Sargent-Sengupta: each point against the straight line through its neighbours in ln F.

    Removes any smooth trend (and all but the nearest points of a kink) without a model of the curve.
    """
    ss, n = 0.0, 0
    for c in data.cases:
        order = np.argsort(c.load_n, kind="stable")
        x, y = np.log(c.load_n[order]), c.ln_stiffness[order]
        if x.size < 3:
            continue
        span = x[2:] - x[:-2]
        ok = span > 0
        a = np.where(ok, (x[2:] - x[1:-1]) / np.where(ok, span, 1.0), 0.5)
        b = 1.0 - a
        eps = a * y[:-2] + b * y[2:] - y[1:-1]
        ss += float(np.sum(eps**2 / (a**2 + b**2 + 1.0)))
        n += eps.size
    return ss, n


def estimate_noise(data: Dataset) -> NoiseFloor:
    """Pooled scatter of replicate sets, or of a smooth per-case fit when the data have no repetitions."""
    groups: list[np.ndarray] = []
    for c, sl in zip(data.cases, data.case_slices(), strict=True):
        groups.extend(g + sl.start for g in _case_groups(c))
    y = data.ln_stiffness
    ss = np.array([float(np.sum((y[g] - y[g].mean()) ** 2)) for g in groups])
    dof = np.array([g.size - 1 for g in groups])
    if dof.sum() > 0 and ss.sum() > 0:
        x = np.concatenate([np.log(c.load_n / c.case.roller.contact_length_m) for c in data.cases])
        centre, sigma = _bands(np.array([x[g].mean() for g in groups]), ss, dof)
        return NoiseFloor(math.sqrt(ss.sum() / dof.sum()), int(dof.sum()), "repetitions", tuple(groups),
                          centre, sigma)
    ss, dof = _pseudo_residual_scatter(data)
    if dof <= 0 or ss <= 0:
        raise InputError("cannot estimate the measurement noise: give repetitions of the load steps or at least "
                         "three load steps per roller")
    return NoiseFloor(math.sqrt(ss / dof), dof, "neighbour-differences", tuple(groups))
