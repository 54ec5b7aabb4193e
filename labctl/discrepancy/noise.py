"""The statistical model of the measurement: how ln k scatters about the truth, as the data are taken.

Every roller case is measured in repetitions; each repetition seats the roller anew, so its points share a
**seating offset** (a random effect of σ_seat, the same for every load of that seating) on top of the
**point noise** σ(F), which falls with load. Both are estimated from the repetitions with a two-way layout per
case (load step × seating): the residuals of "step means + seating offsets" are pure point noise, pooled in up
to four bands of load per length (gross outliers screened out first with a robust MAD scale); the scatter of
the seating means beyond what the point noise explains is σ_seat². Without repetitions each point's distance
from the line through its two neighbours (in ln F) stands in for the point noise (no seating term).

Fits, BIC, the lack-of-fit test and held-out scores all use residuals whitened with this model: within one
seating, r_i − c·m (m the seating's σ-weighted mean residual, c = 1 − 1/sqrt(1 + σ_seat²·Σ1/σ_i²)), divided by
σ_i. "Consistent with the noise" is the lack-of-fit F test of generalised least squares at level
``CONSISTENT_P``: the model's whitened misfit beyond the saturated model (one mean per load step and case)
against the pure error, read against its null distribution simulated under the estimated noise model
(``labctl.discrepancy.lof_reference``: the estimate itself makes the plain F reference reject too often).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from scipy.special import fdtrc  # the F distribution's survival function (scipy.stats.f.sf)

from labctl.discrepancy.data import CaseData, Dataset
from labctl.discrepancy.lof_reference import Reference, simulate
from labctl.discrepancy.outliers import gross_outliers, off_line
from labctl.discrepancy.turns import dataset_turns, level_to_turns, seatings_in_load_order
from labctl.errors import InputError

SAME_STEP = 0.05
"""Loads of two repetitions' points within this relative distance count as the same step."""
CONSISTENT_P = 0.01
"""Level of the lack-of-fit test: residuals count as noise when its p-value is at least this."""
BAND_DOF = 12
"""Least degrees of freedom pooled in one load band."""
MAX_BANDS = 4


@dataclass(frozen=True)
class LackOfFit:
    """Lack-of-fit F test of a fitted model against the pure error (whitened residuals)."""

    f: float
    df_lack: int
    df_pure: int
    p: float
    pure_mean_square: float = 1.0
    """The whitened noise variance the misfit is divided by (the pure error's; 1 without repetitions)."""

    def to_dict(self) -> dict[str, float]:
        return {"f": self.f, "df_lack": self.df_lack, "df_pure": self.df_pure, "p": self.p}


@dataclass(frozen=True)
class NoiseFloor:
    """Point noise σ(F) of ln k and the seating offset σ_seat, with how they were found."""

    sigma: float
    """Point noise pooled over all points: the overall noise floor, comparable with the gap."""
    dof: int
    method: str
    groups: tuple[np.ndarray, ...]
    """Replicate sets (load steps of a case) as index arrays into the dataset's points (singletons included)."""
    band_ln_p: tuple[float, ...] = ()
    """Centre of each load band as ln of load per length (N/m)."""
    band_sigma: tuple[float, ...] = ()
    seating_sigma: float = 0.0
    """σ of ln k shared by all points of one seating (repetition of a roller case)."""
    seating_dof: int = 0
    outliers: tuple[int, ...] = field(default=())
    """Indices (into the dataset it was estimated on) of gross outliers: excluded from every fit."""
    _references: dict[tuple[int, bytes], Reference | None] = field(default_factory=dict, init=False, repr=False,
                                                                     compare=False)
    """The lack-of-fit test's simulated null distribution, by the campaign it was simulated for."""

    def reference(self, data: Dataset) -> Reference | None:
        """The lack-of-fit statistic's null distribution on ``data`` under this noise model, simulated once
        (``labctl.discrepancy.lof_reference``); None without repetitions (the plain F reference is kept)."""
        if self.method != "repetitions":
            return None
        key = (data.n_points, data.load_n.tobytes())
        if key not in self._references:
            self._references[key] = simulate(data, self.sigma_at(data), self.seating_sigma, null_statistic)
        return self._references[key]

    def p_value(self, data: Dataset, f: float, df_lack: int, df_pure: int) -> float:
        """The lack-of-fit p-value of statistic ``f`` on ``data``: against the simulated reference, or F(df_lack,
        df_pure) without one."""
        ref = self.reference(data)
        return float(fdtrc(df_lack, df_pure, f)) if ref is None else ref.p(f, df_lack)

    def sigma_at(self, data: Dataset) -> np.ndarray:
        """σ of ln k for each point of any dataset, interpolated in ln(F/L_we) between the load bands."""
        x = np.log(data.load_per_length_n_per_m)
        if len(self.band_sigma) < 2:
            return np.full(x.size, self.sigma)
        return np.exp(np.interp(x, self.band_ln_p, np.log(self.band_sigma)))

    def whiten(self, data: Dataset, residuals: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        """Residuals (n or n×k) made independent with unit variance under the model (see the module doc)."""
        return whiten(data.run_ids(), residuals, sigma, self.seating_sigma)

    def bands(self) -> list[dict[str, float]]:
        """The load bands at the user's edge: load per length in N/mm and σ."""
        return [{"load_per_length_n_per_mm": float(np.exp(x)) * 1e-3, "sigma": s}
                for x, s in zip(self.band_ln_p, self.band_sigma, strict=True)]

    def lack_of_fit(self, data: Dataset, residuals: np.ndarray, sigma: np.ndarray, n_params: int,
                    simulated: bool = True) -> LackOfFit | None:
        """F test of the model's misfit beyond the saturated model against the pure error, read against the
        simulated reference (``simulated``; else the plain F distribution); None if untestable."""
        e = self.whiten(data, residuals, sigma)
        s_model = float(e @ e)
        n = e.size
        if self.method != "repetitions":
            df = n - n_params
            if df <= 0 or self.dof <= 0:
                return None
            f = s_model / df
            return LackOfFit(f, df, self.dof, float(fdtrc(df, self.dof, f)))
        m = len(self.groups)
        s_pure = float(np.sum(self.pure_residuals(data, residuals, sigma) ** 2))
        df_lack, df_pure = m - n_params, n - m
        if df_lack <= 0 or df_pure <= 0 or s_pure <= 0:
            return None
        f = max(0.0, s_model - s_pure) / df_lack / (s_pure / df_pure)
        p = self.p_value(data, f, df_lack, df_pure) if simulated else float(fdtrc(df_lack, df_pure, f))
        return LackOfFit(f, df_lack, df_pure, p, s_pure / df_pure)

    def cells(self, data: Dataset, sigma: np.ndarray) -> np.ndarray:
        """The saturated model's columns (one per replicate set: a load step of a case), whitened (n × m)."""
        cells = np.zeros((data.n_points, len(self.groups)))
        for j, g in enumerate(self.groups):
            cells[g, j] = 1.0
        return self.whiten(data, cells, sigma)

    def pure_residuals(self, data: Dataset, residuals: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        """The saturated model's whitened residuals (one mean per load step and case): pure point noise."""
        lx = self.cells(data, sigma)
        ly = self.whiten(data, -residuals, sigma)  # model - measured: the saturated model fits the same offsets
        coef, *_ = np.linalg.lstsq(lx, ly, rcond=None)
        return ly - lx @ coef

    def lack_of_fit_p(self, data: Dataset, residuals: np.ndarray, sigma: np.ndarray, n_params: int
                      ) -> float | None:
        test = self.lack_of_fit(data, residuals, sigma, n_params)
        return None if test is None else test.p


def null_statistic(campaign: Dataset) -> tuple[float, int] | None:
    """The lack-of-fit statistic and its df_lack of the true mean (ln k = 0) on a simulated null campaign, its
    noise estimated anew as on the data (None: no test)."""
    floor = estimate_noise(campaign)
    test = floor.lack_of_fit(campaign, -campaign.ln_stiffness, floor.sigma_at(campaign), 0, simulated=False)
    return None if test is None else (test.f, test.df_lack)


def lack_of_fit_rejects(p: float | None) -> bool:
    """The lack-of-fit test (p-value ``p``; None: no test) rejects the model at level ``CONSISTENT_P``."""
    return p is not None and p < CONSISTENT_P


def whiten(run_ids: np.ndarray, residuals: np.ndarray, sigma: np.ndarray, seating_sigma: float) -> np.ndarray:
    """Whitened residuals for points with seating ``run_ids``, point σ and seating σ (exact for that model)."""
    r = np.asarray(residuals, dtype=float)
    w = 1.0 / sigma**2
    if seating_sigma <= 0:
        return r / (sigma if r.ndim == 1 else sigma[:, None])
    n_runs = int(run_ids.max()) + 1
    wsum = np.bincount(run_ids, w, minlength=n_runs)
    c = 1.0 - 1.0 / np.sqrt(1.0 + seating_sigma**2 * wsum)
    if r.ndim == 1:
        mean = np.bincount(run_ids, w * r, minlength=n_runs) / wsum
        return (r - (c * mean)[run_ids]) / sigma
    sums = np.zeros((n_runs, r.shape[1]))
    np.add.at(sums, run_ids, w[:, None] * r)
    mean = sums / wsum[:, None]
    return (r - (c[:, None] * mean)[run_ids]) / sigma[:, None]


def _replicate_sets(data: Dataset) -> tuple[list[list[np.ndarray]], list[np.ndarray]]:
    """Each case's replicate sets (indices into the case) and all of them as indices into the dataset."""
    case_groups = [_case_groups(c) for c in data.cases]
    groups = [g + sl.start for cg, sl in zip(case_groups, data.case_slices(), strict=True) for g in cg]
    return case_groups, groups


def _case_groups(c: CaseData) -> list[np.ndarray]:
    """Replicate sets of one case: by step rank when every repetition has the same steps, else by load."""
    seatings = seatings_in_load_order(c)
    if seatings is not None and len({s.size for s in seatings}) == 1:
        ranks = np.stack(seatings)
        loads = c.load_n[ranks]
        if np.all(loads.max(axis=0) <= loads.min(axis=0) * (1 + SAME_STEP)):
            return [ranks[:, j] for j in range(ranks.shape[1])]
    order = np.argsort(c.load_n, kind="stable")
    groups: list[list[int]] = []
    for i in order:
        last = groups[-1] if groups else None
        if (last is not None and c.load_n[i] <= c.load_n[last[0]] * (1 + SAME_STEP)
                and (c.repetition[i] < 0 or c.repetition[i] not in c.repetition[last])):
            last.append(int(i))
        else:
            groups.append([int(i)])
    return [np.array(g) for g in groups]


@dataclass(frozen=True)
class _TwoWay:
    """The two-way (load step + seating) least squares of one case with some points left out: its design alone."""

    design: np.ndarray
    """The kept points' columns (step means, seating offsets)."""
    pinv: np.ndarray
    keep: np.ndarray
    leverage: np.ndarray

    def residual(self, y: np.ndarray) -> np.ndarray:
        """y less its fit (NaN at the points left out)."""
        residual = np.full(y.size, np.nan)
        residual[self.keep] = y[self.keep] - self.design @ (self.pinv @ y[self.keep])
        return residual


def _step_residuals(data: Dataset, case_groups: list[list[np.ndarray]], y: np.ndarray, keep: np.ndarray,
                    key: str) -> tuple[np.ndarray, np.ndarray]:
    """Each point's residual from its step's mean plus its seating's offset (``case_groups``: each case's steps;
    NaN at the points left out) and the degrees of freedom it spares the fit (1 − leverage; 0 where left out)."""
    runs = data.run_ids()
    resid, dof = np.full(y.size, np.nan), np.zeros(y.size)
    for i, (cg, sl) in enumerate(zip(case_groups, data.case_slices(), strict=True)):
        tw = data.design_memo((key, i, keep[sl].tobytes()), partial(_two_way, cg, runs[sl], keep[sl]))
        resid[sl], dof[sl] = tw.residual(y[sl]), np.where(keep[sl], 1.0 - tw.leverage, 0.0)
    return resid, dof


def _across_turns(data: Dataset, case_groups: list[list[np.ndarray]], keep: np.ndarray
                  ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Each kept point's residual from its nut turn's mean plus its seating's offset, standardised for its leverage
    (NaN where it has none to spare), and the turns as indices into the dataset: the outlier screen's view across
    repetitions. Each ln k is first brought to its turn's mean load, so a turn whose seatings' loads differ by
    several per cent is still compared within itself."""
    per_case, turns = data.design_memo("turns", lambda: dataset_turns(data, case_groups))
    y, x = data.ln_stiffness, np.log(data.load_n)
    level = y.copy()
    for tc, sl in zip(per_case, data.case_slices(), strict=True):
        k = keep[sl]
        level[sl] = level_to_turns(x[sl], y[sl], [g[k[g]] for g in tc])
    resid, dof = _step_residuals(data, per_case, level, keep, "two-way turns")
    ok = dof > 1e-6
    return np.where(ok, resid / np.sqrt(np.where(ok, dof, 1.0)), np.nan), turns


def _two_way(groups: list[np.ndarray], runs: np.ndarray, keep: np.ndarray) -> _TwoWay:
    """Least squares on step means plus seating offsets (points not in ``keep`` left out)."""
    n = runs.size
    run_values = np.unique(runs)
    x = np.zeros((n, len(groups) + run_values.size))
    for j, g in enumerate(groups):
        x[g, j] = 1.0
    for j, r in enumerate(run_values):
        x[runs == r, len(groups) + j] = 1.0
    xk = x[keep]
    pinv = np.linalg.pinv(xk)
    leverage = np.ones(n)
    leverage[keep] = np.einsum("ij,ji->i", xk, pinv)
    return _TwoWay(xk, pinv, keep.copy(), np.clip(leverage, 0.0, 1.0))


def _bands(x: np.ndarray, ss: np.ndarray, dof: np.ndarray) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Pool per-point squared residuals into up to MAX_BANDS bands of load per length, ≥ BAND_DOF dof each."""
    keep = dof > 1e-6
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
        i = np.arange(1, x.size - 1)
        ss += float(np.sum(off_line(x, y, i, i - 1, i + 1) ** 2))
        n += i.size
    return ss, n


def estimate_noise(data: Dataset) -> NoiseFloor:
    """Point noise per load band, seating σ and gross outliers from the repetitions (else neighbour scatter)."""
    case_groups, groups = data.design_memo("replicate sets", lambda: _replicate_sets(data))
    y, x = data.ln_stiffness, np.log(data.load_per_length_n_per_m)
    keep = np.ones(y.size, dtype=bool)
    for _ in range(4):
        across, turns = _across_turns(data, case_groups, keep)
        new = gross_outliers(data, keep, turns, BAND_DOF, MAX_BANDS, across)
        if not new:
            break
        keep[new] = False
    resid, dof_pt = _step_residuals(data, case_groups, y, keep, "two-way")  # the floor, once the screen is done
    informative = dof_pt > 1e-6
    dof_total = float(dof_pt.sum())
    if dof_total >= 1.0 and float(np.nansum(resid[informative] ** 2)) > 0:
        ss = np.where(informative, np.nan_to_num(resid) ** 2, 0.0)
        centre, sigma = _bands(x, ss, dof_pt)
        pooled = math.sqrt(float(ss.sum()) / dof_total)
        floor = NoiseFloor(pooled, int(round(dof_total)), "repetitions", tuple(groups), centre, sigma,
                           outliers=tuple(int(i) for i in np.flatnonzero(~keep)))
        seatings = data.design_memo(("seatings", keep.tobytes()), partial(_seatings, data, case_groups, keep))
        tau, tau_dof = _seating_sigma(data, floor, seatings)
        return replace(floor, seating_sigma=tau, seating_dof=tau_dof)
    ss_p, dof = _pseudo_residual_scatter(data)
    if dof <= 0 or ss_p <= 0:
        raise InputError("cannot estimate the measurement noise: give repetitions of the load steps or at least "
                         "three load steps per roller")
    return NoiseFloor(math.sqrt(ss_p / dof), dof, "neighbour-differences", tuple(groups))


@dataclass(frozen=True)
class _Seatings:
    """The points σ_seat is estimated from — kept, in a load step with another kept point, of a case with two
    seatings or more among them — by step, and of those with a repetition number (``seated``, positions in
    ``points``) their seating and each seating's case, numbered from 0: the design alone."""

    points: np.ndarray
    step: np.ndarray
    seated: np.ndarray
    seat: np.ndarray
    case_of_seat: np.ndarray


def _seatings(data: Dataset, case_groups: list[list[np.ndarray]], keep: np.ndarray) -> _Seatings:
    """Which points σ_seat is estimated from when only ``keep`` are kept (``_Seatings``)."""
    runs = data.run_ids()
    repetition = np.concatenate([c.repetition for c in data.cases])
    steps: list[np.ndarray] = []
    case_of_run: dict[int, int] = {}
    n_cases = 0
    for c, cg, sl in zip(data.cases, case_groups, data.case_slices(), strict=True):
        reps = np.unique(c.repetition[keep[sl]])
        case_steps = [g for g in (g[keep[sl][g]] + sl.start for g in cg) if g.size > 1]
        if reps[reps >= 0].size < 2 or not case_steps:
            continue
        pts = np.concatenate(case_steps)
        seats = np.unique(runs[pts[repetition[pts] >= 0]])
        if seats.size < 2:
            continue
        case_of_run.update((int(r), n_cases) for r in seats)
        n_cases += 1
        steps.extend(case_steps)
    if not steps:
        empty = np.zeros(0, dtype=int)
        return _Seatings(empty, empty, empty, empty, empty)
    points = np.concatenate(steps)
    seated = np.flatnonzero(repetition[points] >= 0)
    run_list = np.array(sorted(case_of_run))
    return _Seatings(points, np.repeat(np.arange(len(steps)), [g.size for g in steps]), seated,
                     np.searchsorted(run_list, runs[points[seated]]),
                     np.array([case_of_run[int(r)] for r in run_list]))


def _seating_sigma(data: Dataset, floor: NoiseFloor, seatings: _Seatings) -> tuple[float, int]:
    """σ_seat by moments: the spread of each seating's weighted mean residual about its load steps' means,
    less what the point noise alone gives it."""
    if seatings.points.size == 0:
        return 0.0, 0
    y = data.ln_stiffness[seatings.points]
    step = seatings.step
    e1 = y - (np.bincount(step, y) / np.bincount(step))[step]
    w = 1.0 / floor.sigma_at(data)[seatings.points[seatings.seated]] ** 2
    w_sum = np.bincount(seatings.seat, w)
    mu = np.bincount(seatings.seat, w * e1[seatings.seated]) / w_sum
    case = seatings.case_of_seat
    count = np.bincount(case)
    centre = np.bincount(case, mu) / count
    num = float(np.sum((mu - centre[case]) ** 2) - np.sum((count - 1) * np.bincount(case, 1.0 / w_sum) / count))
    den = int(np.sum(count - 1))
    return math.sqrt(max(0.0, num / den)), den
