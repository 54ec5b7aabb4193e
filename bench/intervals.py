"""Confidence intervals and table cells for the benchmarks: bootstrap over seeds, Wilson for shares."""

from __future__ import annotations

import math

import numpy as np

RNG = np.random.default_rng(12345)
RELIABILITY_BINS = ((0.0, 0.5), (0.5, 0.7), (0.7, 0.9), (0.9, 0.97), (0.97, 0.995), (0.995, 1.0001))
"""Stated-probability bins of the reliability tables (the discrepancy evaluation's and the oracle's)."""


def boot(stat, *arrays, n: int = 1000) -> tuple[float, float]:
    """95 % percentile bootstrap interval of ``stat`` over seeds (arrays resampled together)."""
    arrays = [np.asarray(a, float) for a in arrays]
    m = len(arrays[0])
    vals = []
    for _ in range(n):
        idx = RNG.integers(0, m, m)
        vals.append(stat(*(a[idx] for a in arrays)))
    lo, hi = np.nanpercentile(vals, [2.5, 97.5])
    return float(lo), float(hi)


def wilson(k: int, n: int) -> tuple[float, float, float]:
    """Share k/n with its 95 % Wilson interval."""
    z = 1.96
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return p, max(c - h, 0.0), min(c + h, 1.0)  # the bounds are 0 and 1 at k = 0 and n; no round-off past them


def rms(v) -> float:
    v = np.asarray(v, float)
    return float(np.sqrt(np.nanmean(v**2))) if np.any(np.isfinite(v)) else math.nan


def fmt(v: float, spec: str) -> str:
    return "—" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def ci(pair: tuple[float, float], spec: str) -> str:
    return f"[{format(pair[0], spec)}, {format(pair[1], spec)}]"


def share(w: tuple[float, float, float] | None) -> str:
    return "—" if w is None else f"{100 * w[0]:.0f} % [{100 * w[1]:.0f}, {100 * w[2]:.0f}]"
