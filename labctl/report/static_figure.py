"""The paper's Fig. 8 comparison of the two methods: static and hammer stiffness vs load with their spreads.

Reads a combined campaign (``[static]`` in its protocol): per step, the hammer's stiffness of each repetition
(its stored curve) and the static stiffness of each repetition (the run's stored static curve). ``compare``
gives the numbers the figure shows and the acceptance checks use: the methods' agreement per repetition and
step (their difference over the quadrature of the two independent σ), and the spread over the repetitions.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from labctl.engine.static import stored_static_curve
from labctl.storage.reader import CampaignReader, RunInfo

N_PER_UM = 1e-6
AGREE_Z = 2.0
"""Agreement level: the methods differ by less than 2 σ of their difference (about 95 % for normal errors)."""


@dataclass(frozen=True)
class MethodComparison:
    """One series: steps × repetitions arrays of load, hammer and static stiffness and their σ (N, N/m)."""

    series: int
    label: str
    step: np.ndarray
    load_n: np.ndarray
    hammer_n_per_m: np.ndarray
    hammer_std_n_per_m: np.ndarray
    static_n_per_m: np.ndarray
    static_std_n_per_m: np.ndarray  # its σ without the K_setup share, which the hammer's result carries too

    @property
    def z(self) -> np.ndarray:
        """(static − hammer) / σ of the difference, per step and repetition."""
        return (self.static_n_per_m - self.hammer_n_per_m) / np.hypot(self.static_std_n_per_m,
                                                                        self.hammer_std_n_per_m)

    def spread(self, values: np.ndarray) -> np.ndarray:
        """Per step: the repetitions' sample standard deviation (NaN with fewer than two values)."""
        finite = np.isfinite(values)
        count = finite.sum(axis=1)
        mean = np.where(finite, values, 0.0).sum(axis=1, keepdims=True) / np.maximum(count, 1)[:, None]
        squares = np.where(finite, (values - mean) ** 2, 0.0).sum(axis=1)
        return np.where(count >= 2, np.sqrt(squares / np.maximum(count - 1, 1)), np.nan)

    def upper_half_ratio(self) -> float:
        """Static over hammer spread over the upper half of the loads (root mean square of the steps' spreads)."""
        upper = self.load_n.mean(axis=1) >= np.median(self.load_n.mean(axis=1))
        s, h = self.spread(self.static_n_per_m)[upper], self.spread(self.hammer_n_per_m)[upper]
        s, h = s[np.isfinite(s)], h[np.isfinite(h)]
        if not (s.size and h.size):
            return float("nan")
        return float(np.sqrt(np.mean(s**2)) / np.sqrt(np.mean(h**2)))


def compare(path: str | Path) -> list[MethodComparison]:
    """The series of a campaign that have static curves, with the hammer's results at the same steps (NaN where
    a step has none, as in a static-only campaign)."""
    with CampaignReader(path) as reader:
        return compare_methods(reader)


def compare_methods(reader: CampaignReader, runs: Mapping[int, list[RunInfo]] | None = None
                    ) -> list[MethodComparison]:
    """``compare`` on an open campaign; ``runs`` (series → its repetitions) when the caller has read them already."""
    nan5 = (np.nan,) * 5
    out = []
    for series in reader.series_indices():
        rows: dict[int, dict[int, tuple[float, ...]]] = {}
        reps = []
        for info in runs[series] if runs is not None else reader.runs(series):
            static = stored_static_curve(reader.run_attrs(series, info.run))
            if not static:
                continue
            reps.append(info.run)
            curve = reader.curve(series, info.run)
            hammer = {} if curve is None else {
                int(n): (float(k), float(sd)) for n, k, sd in
                zip(curve.step, curve.stiffness_n_per_m, curve.stiffness_std_n_per_m, strict=True)}
            for st in static:
                k, sd = hammer.get(st.step, (np.nan, np.nan))
                rows.setdefault(st.step, {})[info.run] = (st.load_n, k, sd, st.stiffness_n_per_m,
                                                          st.std_independent_n_per_m)
        if not rows:
            continue
        steps = sorted(rows)
        table = np.array([[rows[step].get(run, nan5) for run in reps] for step in steps], dtype=float)
        out.append(MethodComparison(series, reader.specimen(series).label, np.array(steps),
                                    *np.moveaxis(table, 2, 0)))
    return out


def static_figure(comparisons: list[MethodComparison], simulated: bool) -> Figure:
    """Left: stiffness vs load, both methods' means with their repetitions' min–max; right: the spreads."""
    fig = Figure(figsize=(10.0, 3.8 * len(comparisons) + 0.4), layout="constrained")
    axes = fig.subplots(len(comparisons), 2, squeeze=False)
    for (left, right), c in zip(axes, comparisons, strict=True):
        _panels(left, right, c)
    fig.suptitle(("SIMULATED — " if simulated else "") + "Static vs hammer stiffness (cf. Fig. 8, §2.5)")
    return fig


def _panels(left: Axes, right: Axes, c: MethodComparison) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a step no repetition identified is left blank
        load = np.nanmean(c.load_n, axis=1)
        methods = [(c.hammer_n_per_m, "hammer impact", "o", -0.6), (c.static_n_per_m, "static displacement", "s", 0.6)]
        for values, name, marker, shift in [m for m in methods if np.isfinite(m[0]).any()]:
            mean = np.nanmean(values, axis=1)
            err = np.array([mean - np.nanmin(values, axis=1), np.nanmax(values, axis=1) - mean]).clip(min=0)
            left.errorbar(load + shift, mean * N_PER_UM, yerr=err * N_PER_UM, fmt=marker, ms=4, capsize=3,
                          label=f"{name} (mean, min–max of {values.shape[1]})")
            right.plot(load, c.spread(values) * N_PER_UM, marker=marker, label=name)
        left.set(xlabel="load per roller (N)", ylabel="stiffness (N/µm)", title=c.label)
        ratio = c.upper_half_ratio()
        right.set(xlabel="load per roller (N)", ylabel="spread over repetitions, σ (N/µm)",
                  title=f"static / hammer spread, upper half: {ratio:.1f}×" if np.isfinite(ratio) else "static spread")
        left.legend(fontsize="small")
        right.legend(fontsize="small")
        left.grid(alpha=0.3)
        right.grid(alpha=0.3)
