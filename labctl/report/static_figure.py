"""The paper's Fig. 8 comparison of the two methods: static and hammer stiffness vs load with their spreads.

Reads a combined campaign (``[static]`` in its protocol): per step, the hammer's stiffness of each repetition
(its stored curve) and the static stiffness of each repetition (the run's stored static curve). ``compare``
gives the numbers the figure shows and the acceptance checks use: the methods' agreement per repetition and
step (their difference over the quadrature of the two independent σ), and the spread over the repetitions.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from labctl.engine.static import stored_static_curve
from labctl.storage.reader import CampaignReader

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
        """Per step: the repetitions' sample standard deviation."""
        return np.nanstd(values, axis=1, ddof=1)

    def upper_half_ratio(self) -> float:
        """Static over hammer spread over the upper half of the loads (root mean square of the steps' spreads)."""
        upper = self.load_n.mean(axis=1) >= np.median(self.load_n.mean(axis=1))
        s, h = self.spread(self.static_n_per_m)[upper], self.spread(self.hammer_n_per_m)[upper]
        return float(np.sqrt(np.nanmean(s**2)) / np.sqrt(np.nanmean(h**2)))


def compare(path: str | Path) -> list[MethodComparison]:
    """The series of a campaign that have static curves, with the hammer's results at the same steps."""
    out = []
    with CampaignReader(path) as reader:
        for series in reader.series_indices():
            rows: dict[int, dict[int, tuple[float, ...]]] = {}
            reps = []
            for curve in reader.curves():
                if curve.series != series:
                    continue
                static = {s.step: s for s in stored_static_curve(reader.run_attrs(series, curve.run))}
                if not static:
                    continue
                reps.append(curve.run)
                for i, step in enumerate(curve.step.tolist()):
                    st = static.get(step)
                    if st is not None:
                        rows.setdefault(step, {})[curve.run] = (
                            float(curve.load_n[i]), float(curve.stiffness_n_per_m[i]),
                            float(curve.stiffness_std_n_per_m[i]), st.stiffness_n_per_m, st.std_independent_n_per_m)
            if not rows:
                continue
            steps = sorted(rows)
            table = np.full((len(steps), len(reps), 5), np.nan)
            for a, step in enumerate(steps):
                for b, run in enumerate(reps):
                    if run in rows[step]:
                        table[a, b] = rows[step][run]
            out.append(MethodComparison(series, reader.specimen(series).label, np.array(steps), *np.moveaxis(table,
                                                                                                              2, 0)))
    return out


def static_figure(comparisons: list[MethodComparison], simulated: bool) -> Figure:
    """Left: stiffness vs load, both methods' means with their repetitions' min–max; right: the spreads."""
    fig = Figure(figsize=(10.0, 3.8 * len(comparisons) + 0.4), layout="constrained")
    axes = fig.subplots(len(comparisons), 2, squeeze=False)
    for (left, right), c in zip(axes, comparisons, strict=True):
        load = np.nanmean(c.load_n, axis=1)
        for values, name, marker, shift in ((c.hammer_n_per_m, "hammer impact", "o", -0.6),
                                            (c.static_n_per_m, "static displacement", "s", 0.6)):
            mean = np.nanmean(values, axis=1)
            err = np.array([mean - np.nanmin(values, axis=1), np.nanmax(values, axis=1) - mean]).clip(min=0)
            left.errorbar(load + shift, mean * N_PER_UM, yerr=err * N_PER_UM, fmt=marker, ms=4, capsize=3,
                          label=f"{name} (mean, min–max of {values.shape[1]})")
            right.plot(load, c.spread(values) * N_PER_UM, marker=marker, label=name)
        left.set(xlabel="load per roller (N)", ylabel="stiffness (N/µm)", title=c.label)
        right.set(xlabel="load per roller (N)", ylabel="spread over repetitions, σ (N/µm)",
                  title=f"static / hammer spread, upper half: {c.upper_half_ratio():.1f}×")
        left.legend(fontsize="small")
        right.legend(fontsize="small")
        left.grid(alpha=0.3)
        right.grid(alpha=0.3)
    fig.suptitle(("SIMULATED — " if simulated else "") + "Static vs hammer stiffness (cf. Fig. 8, §2.5)")
    return fig
