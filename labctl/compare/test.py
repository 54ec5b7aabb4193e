"""The two-group test: at each common load, Welch's t on ln k over the repetition curves, Holm's step-down
adjustment over the loads (family-wise error at the stated level under any correlation between loads), and
Bonferroni-simultaneous intervals for the difference.

Replicates are repetition curves (re-seated rollers); the rig's shared uncertainties (disc mass, K_setup)
scale every curve of one rig alike and cancel in a difference measured on one rig, so they are not added.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import stdtr, stdtrit  # Student t: what scipy.stats.t.sf / .ppf compute

from labctl.compare.groups import Curve, overlap
from labctl.errors import InputError

DEFAULT_LEVEL = 0.05
MIN_CURVES = 2
UNITS = ("auto", "repetition", "campaign")
END_STRETCH = 0.02


@dataclass(frozen=True)
class LoadDifference:
    """The groups' difference at one load."""

    load_n: float
    difference: float
    """Relative difference of the geometric means, k_A / k_B − 1."""
    low: float
    high: float
    """Its simultaneous interval at the comparison's level (all loads covered together), relative."""
    p_value: float
    """Welch's two-sided p at this load, before adjustment."""
    p_adjusted: float
    """Holm-adjusted p over all loads of the comparison."""
    significant: bool
    """p_adjusted below the level."""


@dataclass(frozen=True)
class Comparison:
    """Groups A and B compared load by load at a stated family-wise level."""

    level: float
    unit: str
    """The replicate: ``repetition`` (each seating) or ``campaign`` (each campaign's mean curve)."""
    replicates_a: int
    replicates_b: int
    loads: list[LoadDifference]

    @property
    def significant(self) -> bool:
        return any(d.significant for d in self.loads)

    @property
    def significant_loads_n(self) -> list[float]:
        return [d.load_n for d in self.loads if d.significant]


def _grid(curves: Sequence[Curve]) -> np.ndarray:
    """The loads compared: the most finely stepped curve's loads inside the range every curve covers, each
    curve's ends stretched by a fraction ``END_STRETCH`` (steps of one protocol land a few tenths of a newton
    apart from run to run)."""
    lo, hi = overlap(curves)
    lo, hi = lo / (1.0 + END_STRETCH), hi * (1.0 + END_STRETCH)
    if not lo < hi:
        raise InputError(f"the groups share no load range (every curve covers only {lo:.1f} N to {hi:.1f} N in "
                         "common); compare groups measured over overlapping loads")
    inside = [c.load_n[(c.load_n >= lo) & (c.load_n <= hi)] for c in curves]
    grid = max(inside, key=len)
    return grid if grid.size else np.array([lo, hi])


def _log_values(curves: Sequence[Curve], grid: np.ndarray) -> np.ndarray:
    """ln k of every curve at the grid loads: linear in ln F between its steps, its end segments extended over
    the small stretch ``_grid`` allows."""
    x = np.log(grid)
    out = []
    for c in curves:
        xc, yc = np.log(c.load_n), np.log(c.stiffness_n_per_m)
        y = np.interp(x, xc, yc)
        low, high = x < xc[0], x > xc[-1]
        y[low] = yc[0] + (x[low] - xc[0]) * (yc[1] - yc[0]) / (xc[1] - xc[0])
        y[high] = yc[-1] + (x[high] - xc[-1]) * (yc[-1] - yc[-2]) / (xc[-1] - xc[-2])
        out.append(y)
    return np.array(out)


def _holm(p: np.ndarray) -> np.ndarray:
    order = np.argsort(p)
    m = p.size
    adjusted = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adjusted[i] = running
    return adjusted


def _replicates(curves: Sequence[Curve], grid: np.ndarray, unit: str) -> np.ndarray:
    y = _log_values(curves, grid)
    if unit == "repetition":
        return y
    keys = sorted({c.campaign for c in curves})
    return np.array([y[[c.campaign == key for c in curves]].mean(axis=0) for key in keys])


def compare_groups(a: Sequence[Curve], b: Sequence[Curve], *, level: float = DEFAULT_LEVEL,
                   unit: str = "auto") -> Comparison:
    """Is ln k of group A different from group B's beyond the replicates' scatter, and at which loads?

    ``unit="auto"`` takes each campaign's mean curve as the replicate when both groups hold two or more campaigns
    (campaigns may differ by day or specimen, which repetitions within one campaign do not show), else each
    repetition."""
    if not 0.0 < level < 0.5:
        raise InputError(f"--level {level!r}: expected a test level between 0 and 0.5 (e.g. 0.05)")
    if unit not in UNITS:
        raise InputError(f"--unit {unit!r}: expected one of {', '.join(UNITS)}")
    if unit == "auto":
        several = all(len({c.campaign for c in g}) >= MIN_CURVES for g in (a, b))
        unit = "campaign" if several else "repetition"
    grid = _grid([*a, *b])
    ya, yb = _replicates(a, grid, unit), _replicates(b, grid, unit)
    for name, y in (("A", ya), ("B", yb)):
        if len(y) < MIN_CURVES:
            raise InputError(f"group {name} has {len(y)} {unit}(s): the scatter needs at least {MIN_CURVES} "
                             f"({'run more repetitions' if unit == 'repetition' else 'add campaigns'} to the group)")
    na, nb = len(ya), len(yb)
    va, vb = ya.var(axis=0, ddof=1) / na, yb.var(axis=0, ddof=1) / nb
    se = np.sqrt(va + vb)
    diff = ya.mean(axis=0) - yb.mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        df = (va + vb) ** 2 / (va**2 / (na - 1) + vb**2 / (nb - 1))
        t = diff / se
    df = np.where(np.isfinite(df), df, float(min(na, nb) - 1))
    p = np.where(se > 0, 2.0 * stdtr(df, -np.abs(np.nan_to_num(t))), np.where(diff == 0, 1.0, 0.0))
    adjusted = _holm(p)
    half = stdtrit(df, 1.0 - level / (2.0 * grid.size)) * se
    loads = [LoadDifference(load_n=float(f), difference=float(np.expm1(d)), low=float(np.expm1(d - h)),
                            high=float(np.expm1(d + h)), p_value=float(pv), p_adjusted=float(pa),
                            significant=bool(pa < level))
             for f, d, h, pv, pa in zip(grid, diff, half, p, adjusted, strict=True)]
    return Comparison(level=level, unit=unit, replicates_a=na, replicates_b=nb, loads=loads)
