"""Plot-ready data for the terminal: a few hundred points per trace that keep every peak of the full records.

A terminal plot is at most a few hundred cells wide; drawing 65 536 samples would be slow and show nothing
more. Traces are reduced to min/max envelopes (a spike is never lost), FRFs to the peak of each bin.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from labctl.physics.effects import ContactCase
from labctl.physics.references import reference_curves

MODEL_LABELS = {"tripp": "Tripp", "fit-ra0.2": "Eq. 5 (Ra 0.2 µm)", "fit-ra0.03": "Eq. 6 (Ra 0.03 µm)",
                "hertz": "Hertz"}
N_PER_UM = 1e6  # stiffness is drawn in N/µm (4.65e7 N/m = 46.5 N/µm)
FRF_SPAN_HZ = 2000.0  # the FRF is always shown over the same span: the paper's range of interest
NICE_STEPS = (1.0, 2.0, 5.0, 10.0)


def nice_ticks(lo: float, hi: float, count: int = 5) -> tuple[list[float], list[str]]:
    """Tick positions on a 1-2-5 grid covering [lo, hi] with about ``count`` intervals, and their labels
    (as many decimals as the step needs, no more)."""
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return [], []
    raw = (hi - lo) / max(count, 1)
    magnitude = 10.0 ** np.floor(np.log10(raw))
    step = next(m * magnitude for m in NICE_STEPS if m * magnitude >= raw * (1 - 1e-9))
    first, last = int(np.ceil(lo / step - 1e-9)), int(np.floor(hi / step + 1e-9))
    ticks = [float(k * step) for k in range(first, last + 1)]
    decimals = max(0, -int(np.floor(np.log10(step) + 1e-9)))
    return ticks, [f"{t:.{decimals}f}" for t in ticks]


def nice_range(lo: float, hi: float, count: int = 5) -> tuple[float, float]:
    """[lo, hi] widened to the 1-2-5 ticks around it (a flat trace gets a range of its own)."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return 0.0, 1.0
    if hi <= lo:
        pad = abs(lo) * 0.1 or 1.0
        lo, hi = lo - pad, hi + pad
    raw = (hi - lo) / max(count, 1)
    magnitude = 10.0 ** np.floor(np.log10(raw))
    step = next(m * magnitude for m in NICE_STEPS if m * magnitude >= raw * (1 - 1e-9))
    return float(np.floor(lo / step + 1e-9) * step), float(np.ceil(hi / step - 1e-9) * step)


PLOT_DOTS = 200
"""The widest plot's resolution: a 100-column terminal drawn in braille, two dots per column. A trace reduced to
this many points (an envelope: half as many bins, each its minimum and maximum) looks the same as the full one,
and plotext's drawing time grows with the points it is given."""


def _bins(y: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples as one row per bin (bins of np.linspace edges, rows padded past a bin's end), which cells of a
    row are the bin's own, and each bin's first sample."""
    edges = np.linspace(0, y.size, bins + 1).astype(int)
    start, width = edges[:-1], np.diff(edges)
    cols = np.arange(int(width.max()))
    inside = cols[None, :] < width[:, None]
    return y[np.minimum(start[:, None] + cols[None, :], y.size - 1)], inside, start


def envelope(x: ArrayLike, y: ArrayLike, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Min/max per bin, interleaved, so the reduced trace spans the same extremes as the full one."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if y.size <= 2 * bins:
        return x, y
    rows, inside, start = _bins(y, bins)
    i = start + np.argmin(np.where(inside, rows, np.inf), axis=1)
    j = start + np.argmax(np.where(inside, rows, -np.inf), axis=1)
    order = np.column_stack([np.minimum(i, j), np.maximum(i, j)]).ravel()
    return x[order], y[order]


def bin_peaks(x: ArrayLike, y: ArrayLike, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """The largest value of each bin at its own abscissa (resonance peaks of an FRF stay at their frequency)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if y.size <= bins:
        return x, y
    rows, inside, start = _bins(y, bins)
    rows = np.where(inside & ~np.isnan(rows), rows, -np.inf)  # NaN ignored, as np.nanargmax does
    idx = np.where(np.isfinite(rows).any(axis=1), start + np.argmax(rows, axis=1), start)
    return x[idx], y[idx]


def pulse_window(force_n: ArrayLike, sample_rate_hz: float, before_s: float = 1e-3,
                 after_s: float = 3e-3) -> tuple[np.ndarray, np.ndarray]:
    """The force record around its peak: time in ms relative to the peak, force in N."""
    f = np.asarray(force_n, dtype=float)
    if f.size == 0:
        return np.empty(0), np.empty(0)
    peak = int(np.argmax(np.abs(f)))
    a = max(peak - int(round(before_s * sample_rate_hz)), 0)
    b = min(peak + int(round(after_s * sample_rate_hz)) + 1, f.size)
    t_ms = (np.arange(a, b) - peak) / sample_rate_hz * 1e3
    return t_ms, f[a:b]


def response_window(accel: ArrayLike, sample_rate_hz: float, duration_s: float = 0.1,
                    bins: int = PLOT_DOTS // 2) -> tuple[np.ndarray, np.ndarray]:
    """The first ``duration_s`` of one acceleration trace as an envelope: time in ms, m/s²."""
    a = np.asarray(accel, dtype=float)
    n = min(a.size, max(int(round(duration_s * sample_rate_hz)), 1))
    t_ms = np.arange(n) / sample_rate_hz * 1e3
    return envelope(t_ms, a[:n], bins)


def vertical_channels(channels: Sequence[str]) -> list[int]:
    """Indices of the vertical (Z) accelerometers, which carry the bounce; all channels if none is vertical."""
    idx = [i for i, c in enumerate(channels) if c.upper().endswith("Z")]
    return idx or list(range(len(channels)))


def frf_band(frequencies_hz: ArrayLike, values: ArrayLike, f_max_hz: float,
             bins: int = PLOT_DOTS) -> tuple[np.ndarray, np.ndarray]:
    """One FRF (or coherence) curve from 0 to ``f_max_hz``, reduced to the peak of each bin."""
    f, v = np.asarray(frequencies_hz, dtype=float), np.asarray(values, dtype=float)
    keep = (f > 0) & (f <= f_max_hz)
    return bin_peaks(f[keep], v[keep], bins)


def frf_limit_hz(bounce_hz: float, floor_hz: float = 1000.0) -> float:
    """Upper frequency shown: well above the bounce mode, below the discs' flexible modes."""
    return max(floor_hz, 1.6 * bounce_hz) if np.isfinite(bounce_hz) else floor_hz


def finite_pairs(x: ArrayLike, y: ArrayLike) -> tuple[list[float], list[float]]:
    """Only the points where both coordinates are finite (plotext cannot draw NaN)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    return x[ok].tolist(), y[ok].tolist()


def model_curves(case: ContactCase, kind: str, load_min_n: float, load_max_n: float,
                 points: int = 60) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Reference models (Tripp and Eq. 5/6, or Hertz) on a load grid, as (load N, stiffness N/m) per label."""
    lo, hi = max(load_min_n, 1e-3), max(load_max_n, load_min_n * 1.01, 1e-2)
    grid = np.geomspace(lo, hi, points)
    return {MODEL_LABELS.get(name, name): (grid, k) for name, k in reference_curves(case, kind, grid).items()}
