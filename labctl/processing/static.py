"""Static stiffness from the load–displacement curve (the paper's §2.5): the local slope, the rig removed.

At each load step the engine stores the mean of a few paired readings of the load cell and the displacement
sensor. The local slope dδ/dP at a step is the derivative of the parabola through that step and its neighbours
(the nearest three at the ends); 1/slope is a roller path's stiffness, and ``labctl.physics`` removes the setup
compliance (1/k = 1/k_path − 3/K_setup), exactly as the rig model does for the hammer. The slope is a difference
quotient: its uncertainty comes from the noise of the loads and displacements of the three steps (each step's
read-to-read scatter, pooled over the repetition) the sensor's drift over the time between them, and the parabola's truncation error (from the
third divided difference with the next step outward) — which is
why the static method scatters more than the hammer, whose error is tied to the absolute load.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from labctl.errors import ModelDomainError
from labctl.physics.rig import roller_stiffness_from_path

BUDGET = ("load", "displacement", "drift", "truncation", "setup_stiffness")


@dataclass(frozen=True)
class StaticPoint:
    """One step's static reading: mean load per roller and displacement with their read-to-read sample standard
    deviations, the number of paired reads, and the rig-clock time of the reading (s)."""

    step: int
    load_n: float
    load_sd_n: float
    displacement_m: float
    displacement_sd_m: float
    reads: int
    time_s: float


@dataclass(frozen=True)
class StaticStiffness:
    """The static stiffness at one step: the roller's (setup removed) and the path's, with its 1-σ budget."""

    step: int
    load_n: float
    path_stiffness_n_per_m: float
    stiffness_n_per_m: float
    std_n_per_m: float
    budget_n_per_m: dict[str, float] = field(default_factory=dict)

    @property
    def std_independent_n_per_m(self) -> float:
        """The σ without the K_setup share, which the hammer's result carries too (for comparing the methods)."""
        return math.sqrt(sum(v * v for k, v in self.budget_n_per_m.items() if k != "setup_stiffness"))


def slope_weights(x: np.ndarray, at: float) -> np.ndarray:
    """Weights w with Σ w_j y_j = the derivative at ``at`` of the parabola through the three points (x_j, y_j)."""
    a, b, c = x
    return np.array([(2 * at - b - c) / ((a - b) * (a - c)), (2 * at - a - c) / ((b - a) * (b - c)),
                     (2 * at - a - b) / ((c - a) * (c - b))])


def _window(i: int, n: int) -> slice:
    start = min(max(i - 1, 0), n - 3)
    return slice(start, start + 3)


def truncation_m_per_n(x: np.ndarray, y: np.ndarray, i: int, x4: float, y4: float) -> float:
    """The parabola's slope error at node x[i]: f'''/6 times the product over j != i of (x_i - x_j), with
    f'''/6 the third divided difference of the three points and a fourth (the next step outward)."""
    xs, ys = np.append(x, x4), np.append(y, y4)
    third = sum(ys[j] / np.prod([xs[j] - xs[m] for m in range(4) if m != j]) for j in range(4))
    return float(third * np.prod([x[i] - x[j] for j in range(3) if j != i]))


def _pooled_sd(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return math.sqrt(float(np.mean(np.square(finite)))) if finite else 0.0


def static_stiffness(points: Sequence[StaticPoint], setup_stiffness_n_per_m: float,
                     setup_std_n_per_m: float = 0.0, drift_m_per_s: float = 0.0) -> list[StaticStiffness]:
    """Each step's static stiffness (needs three steps of rising load); the slope's σ from each step's load and
    displacement σ (the pooled read-to-read scatter over √reads), the drift rate's σ over the steps' times, and
    K_setup's σ."""
    pts = sorted(points, key=lambda p: p.step)
    if len(pts) < 3:
        raise ModelDomainError(f"static stiffness needs at least 3 load steps, got {len(pts)}")
    load = np.array([p.load_n for p in pts])
    disp = np.array([p.displacement_m for p in pts])
    times = np.array([p.time_s for p in pts])
    reads = np.array([max(p.reads, 1) for p in pts], dtype=float)
    sem_load = _pooled_sd([p.load_sd_n for p in pts]) / np.sqrt(reads)
    sem_disp = _pooled_sd([p.displacement_sd_m for p in pts]) / np.sqrt(reads)
    out = []
    for i, p in enumerate(pts):
        win = _window(i, len(pts))
        x, y = load[win], disp[win]
        if len(set(x.tolist())) < 3:
            raise ModelDomainError(f"step {p.step}: the loads of steps {pts[win.start].step}..{pts[win.stop - 1].step}"
                                   " are not distinct; no slope")
        w = slope_weights(x, load[i])
        slope = float(w @ y)
        if not slope > 0:
            raise ModelDomainError(f"step {p.step}: the displacement does not rise with the load "
                                   f"(slope {slope:.3e} m/N); check the sensor's sign and mounting")
        # d slope / d P_j by central differences of the closed form (the evaluation point moves with P_i)
        d_load = np.zeros(3)
        for j in range(3):
            h = 1e-4 * max(abs(x[j]), 1.0)
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            at_p = xp[i - win.start] if i - win.start == j else load[i]
            at_m = xm[i - win.start] if i - win.start == j else load[i]
            d_load[j] = (slope_weights(xp, at_p) @ y - slope_weights(xm, at_m) @ y) / (2 * h)
        outer = win.stop if win.stop < len(pts) else win.start - 1
        trunc = truncation_m_per_n(x, y, i - win.start, load[outer], disp[outer]) if 0 <= outer < len(pts) else 0.0
        var_slope = {"load": float(np.sum((d_load * sem_load[win]) ** 2)),
                     "displacement": float(np.sum((w * sem_disp[win]) ** 2)),
                     "drift": float((w @ times[win]) ** 2 * drift_m_per_s**2),
                     "truncation": trunc**2}
        k_path = 1.0 / slope
        k = float(roller_stiffness_from_path(k_path, setup_stiffness_n_per_m))
        if not math.isfinite(k):
            raise ModelDomainError(f"step {p.step}: the path stiffness {k_path:.3e} N/m is stiffer than the setup "
                                   f"share K_setup/3 = {setup_stiffness_n_per_m / 3:.3e} N/m; no roller is left")
        gain = (k / k_path) ** 2 * k_path**2  # dk/dslope = (k/k_path)² · k_path²
        budget = {name: gain * math.sqrt(v) for name, v in var_slope.items()}
        budget["setup_stiffness"] = 3.0 * k * k / setup_stiffness_n_per_m**2 * setup_std_n_per_m
        total = math.sqrt(sum(v * v for v in budget.values()))
        out.append(StaticStiffness(p.step, p.load_n, k_path, k, total, budget))
    return out
