"""Static stiffness from the load–displacement curve (the paper's §2.5): the local slope, the rig removed.

At each load step the engine stores the mean of a few paired readings of the load cell and the displacement
sensor. The local slope dδ/dP at a step is that of the curve δ = δ0 + c·P^a through the step and its neighbours
(the nearest three at the ends: a contact's stiffness goes as a power of its load); 1/slope is a roller path's
stiffness, and ``labctl.physics`` removes the setup compliance (1/k = 1/k_path − 3/K_setup), as the rig model does
for the hammer. The slope is a difference quotient: its σ comes from the noise of the three steps' loads and
displacements (each step's read-to-read scatter pooled over the repetition, over √reads), the sensor's drift
over the time between them, and the local shape (how far a parabola through the same readings differs) —
which is why the static method scatters more than the hammer, whose error is tied to the absolute load.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from labctl.errors import ModelDomainError
from labctl.physics.rig import roller_stiffness_from_path

BUDGET = ("load", "displacement", "drift", "shape", "setup_stiffness")


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


def power_slope(x: np.ndarray, y: np.ndarray, at: float) -> float | None:
    """dδ/dP at ``at`` of δ = δ0 + c·P^a through the three points (a contact's local shape: its stiffness goes
    as a power of the load), or None when no exponent in 0.05..5 fits them (noise larger than the curvature)."""
    rise = (y[2] - y[1]) / (y[1] - y[0]) if y[1] != y[0] else math.nan
    if not (math.isfinite(rise) and rise > 0):
        return None

    def gap(a: float) -> float:
        return (x[2] ** a - x[1] ** a) / (x[1] ** a - x[0] ** a) - rise

    lo, hi = 0.05, 5.0
    if gap(lo) * gap(hi) > 0:
        return None
    a = brentq(gap, lo, hi, xtol=1e-12)
    c = (y[1] - y[0]) / (x[1] ** a - x[0] ** a)
    return float(c * a * at ** (a - 1.0))


def local_slope(x: np.ndarray, y: np.ndarray, i: int) -> tuple[float, float]:
    """The slope at node ``i`` of three readings and its shape uncertainty: the power-law slope (the parabola's
    when no power law fits), and how far the parabola through the same points differs from it."""
    quad = float(slope_weights(x, x[i]) @ y)
    power = power_slope(x, y, x[i])
    return (quad, 0.0) if power is None else (power, abs(power - quad))


def _gradient(x: np.ndarray, y: np.ndarray, i: int, slope: float) -> tuple[np.ndarray, np.ndarray]:
    """d slope / d P_j and d slope / d δ_j by central differences (the evaluation point moves with P_i)."""
    d_load, d_disp = np.zeros(3), np.zeros(3)
    for j in range(3):
        for arr, out, scale in ((x, d_load, max(abs(x[j]), 1.0) * 1e-5), (y, d_disp, abs(y[2] - y[0]) * 1e-4)):
            up, down = arr.copy(), arr.copy()
            up[j] += scale
            down[j] -= scale
            xu, yu = (up, y) if arr is x else (x, up)
            xd, yd = (down, y) if arr is x else (x, down)
            out[j] = (local_slope(xu, yu, i)[0] - local_slope(xd, yd, i)[0]) / (2 * scale)
    return d_load, d_disp


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
        slope, shape = local_slope(x, y, i - win.start)
        if not slope > 0:
            raise ModelDomainError(f"step {p.step}: the displacement does not rise with the load "
                                   f"(slope {slope:.3e} m/N); check the sensor's sign and mounting")
        d_load, d_disp = _gradient(x, y, i - win.start, slope)
        var_slope = {"load": float(np.sum((d_load * sem_load[win]) ** 2)),
                     "displacement": float(np.sum((d_disp * sem_disp[win]) ** 2)),
                     "drift": float((d_disp @ times[win]) ** 2 * drift_m_per_s**2),
                     "shape": shape**2}
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
