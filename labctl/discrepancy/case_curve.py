"""Each case's own bend of ln k with ln F, fitted robustly: what the outlier screen draws its lines about.

Over coarse load steps ln k bends away from the straight line through a point's neighbours by several point σ, in
every seating alike; the screen's lines (``labctl.discrepancy.outliers``) would take that bend for the point's own
departure. The bend is taken from the data, not from one law (the effect under test bends it too): a cubic in
ln F beside an offset per seating, per case, fitted by iteratively reweighted least squares — Huber weights from
the least-squares start, then Tukey's bisquare, which gives a gross point no weight, so the point being judged
does not pull the curve it is judged against. Only the cubic's bend matters: a line through two neighbours of
the same seating is unchanged by any offset or slope.

The fit is a handful of small weighted least-squares solves per case; it runs on every noise estimate (the
lack-of-fit reference repeats that estimate on its simulated draws), so it is written on ``numpy.linalg``
directly rather than through a general robust-regression package the project does not otherwise need.
"""

from __future__ import annotations

import numpy as np

from labctl.discrepancy.data import Dataset

DEGREE = 3
"""The curve's degree in ln F: enough for the bend between coarse steps, too little to follow one point."""
MIN_POINTS_PER_PARAMETER = 3
"""A case's curve is fitted only with this many judged points per coefficient; else it is left flat."""
HUBER_K = 1.345
BISQUARE_C = 4.685
"""The usual tuning constants (95 % efficiency on Gaussian noise) of the Huber and bisquare weights."""
ITERATIONS = 12
TOLERANCE = 0.01
"""The weights are settled once the curve moves by less than this share of the point scale in a round."""
MAD_TO_SIGMA = 1.4826


class _Cases:
    """Cases of one shape (as many judged points, as many seatings): their judged points (seatings with three kept
    points or more, ``idx``: cases × points) and the columns fitted to them — an offset per seating, then the
    powers of centred ln F — stacked so that one batch of small solves fits them all: the design alone."""

    def __init__(self, idx: np.ndarray, columns: np.ndarray, n_powers: int) -> None:
        self.idx, self.a, self.n_powers = idx, columns, n_powers

    def bend(self, y: np.ndarray) -> np.ndarray:
        """The robustly fitted curves' bends (their powers above the first) at the judged points (cases × points)."""
        coef = self._solve(np.ones(y.shape), y)
        scale = np.zeros(y.shape[0])
        for huber in (True, False):  # Huber, rescaled each round, from the least-squares start; then the bisquare
            for _ in range(ITERATIONS):
                r = y - np.einsum("cnp,cp->cn", self.a, coef)
                if huber:
                    scale = MAD_TO_SIGMA * np.median(np.abs(r), axis=1)
                u = np.abs(r) / np.where(scale > 0, scale, np.inf)[:, None]
                w = np.minimum(1.0, HUBER_K / np.maximum(u, 1e-12)) if huber else \
                    np.clip(1.0 - (u / BISQUARE_C) ** 2, 0.0, None) ** 2
                new = self._solve(w, y)
                moved = np.abs(np.einsum("cnp,cp->cn", self.a, new - coef)).max(axis=1)
                done = bool(np.all(moved <= TOLERANCE * scale))
                coef = new
                if done:
                    break
        return np.einsum("cnp,cp->cn", self.a[:, :, -self.n_powers:], coef[:, -self.n_powers:])

    def _solve(self, w: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Weighted least squares per case, by its normal equations (a few columns, well scaled)."""
        aw = self.a * w[:, :, None]
        lhs = np.einsum("cnp,cnq->cpq", aw, self.a)
        lhs += 1e-12 * np.eye(lhs.shape[1]) * np.trace(lhs, axis1=1, axis2=2)[:, None, None]
        return np.linalg.solve(lhs, np.einsum("cnp,cn->cp", aw, y)[:, :, None])[:, :, 0]


def _design(idx: np.ndarray, runs: np.ndarray, ln_f: np.ndarray) -> np.ndarray:
    """One case's columns: an offset per seating, ln F centred and scaled to unit span, and its powers."""
    u = ln_f - ln_f.mean()
    u = u / (float(np.ptp(u)) or 1.0)
    seatings = (runs[:, None] == np.unique(runs)[None, :]).astype(float)
    return np.hstack([seatings] + [u[:, None] ** d for d in range(1, DEGREE + 1)])


def _designs(data: Dataset, keep: np.ndarray) -> list[_Cases]:
    runs, ln_f = data.run_ids(), np.log(data.load_n)
    shapes: dict[tuple[int, int], list[tuple[np.ndarray, np.ndarray]]] = {}
    for sl in data.case_slices():
        idx = np.arange(sl.start, sl.stop)[keep[sl]]
        seat, count = np.unique(runs[idx], return_counts=True)
        idx = idx[np.isin(runs[idx], seat[count >= 3])]
        n_seat = int(np.unique(runs[idx]).size)
        if n_seat and idx.size >= MIN_POINTS_PER_PARAMETER * (n_seat + DEGREE) and \
                np.unique(ln_f[idx]).size > DEGREE + 2:
            shapes.setdefault((idx.size, n_seat), []).append((idx, _design(idx, runs[idx], ln_f[idx])))
    return [_Cases(np.stack([i for i, _ in group]), np.stack([a for _, a in group]), DEGREE - 1)
            for group in shapes.values()]


def case_bend(data: Dataset, keep: np.ndarray) -> np.ndarray:
    """Each kept point's case curve less its offset and slope (0 where a case has too few points for one)."""
    designs = data.design_memo(("case curves", keep.tobytes()), lambda: _designs(data, keep))
    y, out = data.ln_stiffness, np.zeros(data.n_points)
    for d in designs:
        out[d.idx] = d.bend(y[d.idx])
    return out
