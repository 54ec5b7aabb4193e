"""The gross-outlier screen: each point judged against the local repetition spread, before the noise is pooled.

A point is compared with lines (in ln F) through two of its own seating's neighbouring steps — the nearest two,
and each with one of them replaced by the next point beyond — and is set aside when it is far off all of them
(in robust σ at its load per length), the worst of its neighbourhood, in a load step where another repetition
passes smoothly. The threshold is family-wise: ``OUTLIER_ALPHA`` spread over the dataset's points.

The robust σ is a median (MAD) per band of load per length, interpolated between the bands' centres in ln σ
against ln(F/L_we): the point noise falls with load all along, and a σ held constant over a band overstated it at
the band's top and understated it at its foot, where clean points then passed a threshold 4 σ out. Each band's
median stays local: a law fitted to every band at once (ln σ linear in ln(F/L_we)) was tilted by an effect's bend
at the lowest loads and judged the highest in a σ a third of theirs.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtri  # the normal quantile

from labctl.discrepancy.data import Dataset

OUTLIER_ALPHA = 0.01
"""Chance, on clean Gaussian data, that the screen sets any point of a dataset aside (Bonferroni over its points)."""
SMOOTH_Z = 2.5
"""A repetition within this many robust σ of its neighbours passes a load step smoothly."""
MAD_TO_SIGMA = 1.4826
"""σ over the median of |e| for Gaussian e."""


def outlier_z(n_points: int) -> float:
    """How many robust σ off every line through its neighbours a point must be to be set aside as a gross outlier:
    two-sided, ``OUTLIER_ALPHA`` shared among the dataset's points (4.1 for 231 points, 3.8 for 66)."""
    return float(ndtri(1.0 - OUTLIER_ALPHA / (2.0 * max(1, n_points))))


def off_line(x: np.ndarray, y: np.ndarray, i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Points ``i`` against the straight lines through points ``j`` and ``k`` (y against x = ln F), standardised
    for the line's own noise (equal point noise): (y_i − line)/√(1 + w_j² + w_k²); coincident j, k: their mean."""
    return _Lines(i, j, k, x).off(y)


class _Lines:
    """Points ``i`` and the lines through points ``j`` and ``k`` in x = ln F: the weights, which x alone sets."""

    def __init__(self, i: np.ndarray, j: np.ndarray, k: np.ndarray, x: np.ndarray) -> None:
        span = x[k] - x[j]
        self.i, self.j, self.k = i, j, k
        self.t = np.divide(x[i] - x[j], span, out=np.full(np.shape(span), 0.5), where=span != 0)
        self.s = 1 - self.t
        self.norm = np.sqrt(1 + self.s**2 + self.t**2)

    def off(self, y: np.ndarray) -> np.ndarray:
        """Each point's distance from its line, in the line's own noise (``off_line``)."""
        return (y[self.i] - self.s * y[self.j] - self.t * y[self.k]) / self.norm


def _reference_pairs(p: int, n: int) -> list[tuple[int, int]]:
    """Positions (in load order, of ``n``) of the neighbour pairs a point at position ``p`` is judged against: first
    its two nearest neighbours (at an end: the two nearest on its one side), then, for each of them, a pair
    without it — the other with the next point beyond the one left out (next to an end, where there is none
    beyond the end point: two points on the other side, one apart, which extrapolate with less noise than two
    adjacent ones)."""
    left, right = list(range(p - 1, -1, -1)), list(range(p + 1, n))  # nearest first
    if left and right:
        pairs = [(left[0], right[0])] + ([(left[1], right[0])] if len(left) > 1 else []) + \
            ([(left[0], right[1])] if len(right) > 1 else [])
        if len(left) == 1 and len(right) > 1:  # next to an end: the end point may be the bad one
            pairs.append((right[0], right[min(2, len(right) - 1)]))
        if len(right) == 1 and len(left) > 1:
            pairs.append((left[0], left[min(2, len(left) - 1)]))
        return pairs
    side = right or left
    return [(side[0], side[1])] + ([(side[1], side[min(3, len(side) - 1)])] if len(side) > 2 else [])


class _Neighbourhoods(_Lines):
    """Every kept point's ``_reference_pairs`` over the dataset, one row each in ``slots`` (−1 beyond its last)."""

    def __init__(self, data: Dataset, keep: np.ndarray) -> None:
        x, runs = np.log(data.load_n), data.run_ids()
        rows: list[tuple[int, int, int]] = []
        for run in np.unique(runs):
            idx = np.flatnonzero((runs == run) & keep)
            if idx.size < 3:
                continue
            idx = idx[np.argsort(x[idx], kind="stable")]
            rows.extend((idx[p], idx[a], idx[b]) for p in range(idx.size) for a, b in _reference_pairs(p, idx.size))
        i, j, k = np.array(rows, dtype=int).reshape(-1, 3).T
        super().__init__(i, j, k, x)
        start = np.flatnonzero(np.r_[True, i[1:] != i[:-1]]) if i.size else np.zeros(0, dtype=int)
        self.points = i[start]
        count = np.diff(np.r_[start, i.size])
        slot = np.arange(int(count.max()) if count.size else 0)
        self.slots = np.where(slot < count[:, None], start[:, None] + slot, -1)  # a point's nearest pair first


def _neighbour_residuals(data: Dataset, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each kept point against the lines (in ln F) through two of its own seating's neighbouring steps
    (``off_line``): against its two nearest neighbours, and the smallest (in size) over the ``_reference_pairs`` —
    which a single bad neighbour cannot inflate, as it moves its lines, not all of them. NaN where a seating has
    fewer than three kept points."""
    y = data.ln_stiffness
    hoods = data.design_memo(("neighbourhoods", keep.tobytes()), lambda: _Neighbourhoods(data, keep))
    nearest, least = np.full(y.size, np.nan), np.full(y.size, np.nan)
    if hoods.points.size == 0:
        return nearest, least
    e = hoods.off(y)
    nearest[hoods.points] = e[hoods.slots[:, 0]]
    size = np.where(hoods.slots >= 0, np.abs(e)[hoods.slots], np.inf)
    least[hoods.points] = e[hoods.slots[np.arange(hoods.points.size), np.argmin(size, axis=1)]]
    return nearest, least


def gross_outliers(data: Dataset, keep: np.ndarray, groups: list[np.ndarray], band_dof: int, max_bands: int,
                   across: np.ndarray) -> list[int]:
    """Gross outliers judged against the local repetition spread: a point more than ``outlier_z`` robust σ (at its
    load per length, ``_band_scale`` of the residuals against the nearest neighbours) off every line through its own
    seating's neighbours that ``_reference_pairs`` names, the worst of its neighbourhood so judged, in a load step where
    another repetition passes smoothly and which is off those repetitions by more than ``SMOOTH_Z`` (``across``,
    below: where its lines miss the curve, across a gap in the loads, its fellow repetitions agree with it). A
    deviation every repetition shares is the contact's (a kink), not an outlier; two bad points of one step never
    outvote the clean repetition; a bad point's neighbours, off the lines through it but not off the others, are
    not taken for it (at the end of a seating above all, where the end point extrapolated from two neighbours moves
    with its neighbour's error as much as the neighbour does).
    So a seating's end point, which its lines only extrapolate to (with √6 times the noise), is also set aside
    when it is off its lines by more than ``SMOOTH_Z`` and far off its step's other repetitions (``across``: its
    residual from step means plus seating offsets, standardised for its leverage; ``outlier_z`` with the level
    shared by the two tests), the worst of its step so judged. A clean repetition that two bad ones outvote at its
    step is smooth on its own lines, and is kept. Its steps (``groups``) are the nut turns its seatings share, each
    point brought to its turn's load (``labctl.discrepancy.turns``), where the seatings reach one turn at loads
    too far apart to be one replicate set of the noise floor."""
    eps, least = _neighbour_residuals(data, keep)
    ok = np.flatnonzero(np.isfinite(eps))
    if ok.size < 2 * band_dof:
        return []
    bands, end = data.design_memo(("screen", keep.tobytes(), band_dof, max_bands),
                                  lambda: _bands_and_ends(data, keep, ok, band_dof, max_bands))
    x = np.log(data.load_per_length_n_per_m)
    scale = _band_scale(x, eps, bands)
    ratio, firm = _ratio(eps, scale), _ratio(least, scale)
    off = _ratio(across, _band_scale(x, across, bands))
    runs, ln_f = data.run_ids(), np.log(data.load_n)
    z, z_end = outlier_z(int(ok.size)), outlier_z(2 * int(ok.size))
    suspect = keep & ((firm > z) | (end & (off > z_end) & (firm > SMOOTH_Z)))
    if not np.any(suspect):
        return []
    out = []
    for g in groups:
        g = g[keep[g]]
        smooth = g[ratio[g] <= SMOOTH_Z]
        for i in g[suspect[g]]:
            if g.size > 1 and smooth.size == 0:
                continue  # every repetition shares it: the contact's own shape
            if g.size > 1 and off[i] <= SMOOTH_Z:
                continue  # its step's other repetitions agree with it: its lines miss the curve, not the point
            same = np.flatnonzero((runs == runs[i]) & keep)
            near = same[np.argsort(np.abs(ln_f[same] - ln_f[i]))[:3]]
            if (firm[i] >= firm[near].max()) if firm[i] > z else (off[i] >= off[g].max()):
                out.append(int(i))
    return out


def _bands_and_ends(data: Dataset, keep: np.ndarray, ok: np.ndarray, band_dof: int, max_bands: int
                    ) -> tuple[list[np.ndarray], np.ndarray]:
    """The load bands of the points judged (``ok``), and which kept points end their seating: the design alone."""
    x = np.log(data.load_per_length_n_per_m)
    bands = np.array_split(ok[np.argsort(x[ok])], max(1, min(max_bands, ok.size // band_dof)))
    runs, ln_f = data.run_ids(), np.log(data.load_n)
    end = np.zeros(keep.size, dtype=bool)
    for run in np.unique(runs[keep]):
        idx = np.flatnonzero((runs == run) & keep)
        end[idx[[np.argmin(ln_f[idx]), np.argmax(ln_f[idx])]]] = True
    return bands, end


def _band_scale(x: np.ndarray, e: np.ndarray, bands: list[np.ndarray]) -> np.ndarray:
    """Each point's robust σ of e at its x = ln(F/L_we): 1.4826 × MAD of each load band's e, at the band's median
    x, interpolated between the bands in ln σ (held flat beyond the outer ones); inf where no band has any."""
    centre, log_scale = [], []
    for part in bands:
        finite = part[np.isfinite(e[part])]
        s = MAD_TO_SIGMA * float(np.median(np.abs(e[finite]))) if finite.size else 0.0
        if s > 0:
            centre.append(float(np.median(x[finite])))
            log_scale.append(math.log(s))
    if not centre:
        return np.full(e.size, np.inf)
    order = np.argsort(centre)
    return np.exp(np.interp(x, np.array(centre)[order], np.array(log_scale)[order]))


def _ratio(e: np.ndarray, scale: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(e), np.abs(np.nan_to_num(e)) / scale, 0.0)
