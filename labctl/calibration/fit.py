"""Fit the rig's disc mass, K_setup, disc inertia and support stiffness to ball runs (Hertz contacts, no FEM).

Each identified ball step gives a bounce frequency (and the tilt pair's mean where identified) at a measured
load. The model is the rig's own eigen-analysis (``labctl.physics.rig.rig_modes``) with three equal Hertz ball
contacts at that load, so the fit and the processing share one formula. Parameters are fitted in log space
by generalised least squares. The covariance of the measured frequencies has three parts: the identification
std of each step, the load-cell noise carried through Hertz (k ∝ F^(1/3)), and the balls' reseating scatter
(one random stiffness factor per seating, shared by every step of that seating), whose size is estimated from
the data so that χ² equals its degrees of freedom. A parameter whose fitted relative std exceeds
``DETERMINED_REL`` is not determined by the data: it is held at its nominal value and reported as null.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.special import stdtrit  # Student t quantile: what scipy.stats.t.ppf computes

from labctl.calibration.data import BallStep
from labctl.errors import InputError
from labctl.physics.rig import ContactModeModel
from labctl.physics.rig_config import RigConfig

PARAMETERS = ("mass_kg", "setup_stiffness_n_per_m", "inertia_kg_m2", "support_stiffness_n_per_m")
DETERMINED_REL = 0.2  # a parameter the data fix to worse than 20 % (1σ) is reported as not determined
MAX_SCATTER_REL = 0.3  # cap on the estimated seating scatter (beyond it the fit is meaningless anyway)
SUPPORT_PRIOR_REL = 0.5  # the rubber tube's stiffness when the data do not determine it (the rig file gives none)
_EPS = 1e-6
TWO_SIGMA_COVERAGE = 0.97725  # one-sided: ±2σ of a normal distribution covers 95.45 %


def rig_values(rig: RigConfig) -> dict[str, float]:
    """The calibrated parameters' values in a rig (disc mass and inertia: the mean of the two discs)."""
    return {
        "mass_kg": 0.5 * (rig.upper.mass_kg + rig.lower.mass_kg),
        "setup_stiffness_n_per_m": rig.setup_stiffness_n_per_m,
        "inertia_kg_m2": 0.5 * (rig.upper.inertia_kg_m2 + rig.lower.inertia_kg_m2),
        "support_stiffness_n_per_m": rig.support_stiffness_n_per_m,
    }


def rig_with(rig: RigConfig, values: dict[str, float]) -> RigConfig:
    """The rig with the given parameters; mass and inertia apply to both discs (equal, as in Eq. 4)."""
    upper, lower = rig.upper, rig.lower
    if "mass_kg" in values:
        upper, lower = replace(upper, mass_kg=values["mass_kg"]), replace(lower, mass_kg=values["mass_kg"])
    if "inertia_kg_m2" in values:
        i = values["inertia_kg_m2"]
        upper, lower = replace(upper, inertia_kg_m2=i), replace(lower, inertia_kg_m2=i)
    out = replace(rig, upper=upper, lower=lower)
    if "setup_stiffness_n_per_m" in values:
        out = replace(out, setup_stiffness_n_per_m=values["setup_stiffness_n_per_m"])
    if "support_stiffness_n_per_m" in values:
        out = replace(out, support_stiffness_n_per_m=values["support_stiffness_n_per_m"])
    return out


@dataclass(frozen=True)
class Observations:
    """The fitted frequencies: one bounce per step, one tilt mean per step where identified."""

    steps: tuple[BallStep, ...]
    hz: np.ndarray
    std_hz: np.ndarray
    step_of: np.ndarray  # index into steps
    is_tilt: np.ndarray
    run_of: np.ndarray  # index of the seating
    stiffness_n_per_m: np.ndarray  # Hertz stiffness per step at its measured load

    @classmethod
    def of(cls, steps: Sequence[BallStep], use_tilt: bool = True) -> Observations:
        hz, std, step_of, tilt = [], [], [], []
        for i, s in enumerate(steps):
            hz.append(s.bounce_hz)
            std.append(s.bounce_std_hz)
            step_of.append(i)
            tilt.append(False)
            if use_tilt and s.tilt_hz is not None and s.tilt_std_hz is not None:
                hz.append(s.tilt_hz)
                std.append(s.tilt_std_hz)
                step_of.append(i)
                tilt.append(True)
        runs = sorted({s.run_key for s in steps})
        run_index = {r: i for i, r in enumerate(runs)}
        step_of_arr = np.asarray(step_of, dtype=int)
        k = np.array([float(s.contact.stiffness_n_per_m(s.load_n)) for s in steps])
        return cls(tuple(steps), np.asarray(hz, float), np.asarray(std, float), step_of_arr,
                   np.asarray(tilt, bool), np.array([run_index[steps[i].run_key] for i in step_of_arr]), k)

    @property
    def run_count(self) -> int:
        return int(self.run_of.max()) + 1 if self.run_of.size else 0


def predict_hz(rig: RigConfig, obs: Observations, stiffness_scale: float = 1.0) -> np.ndarray:
    """Model frequencies of the observations: the rig's eigen-analysis (``ContactModeModel``, the model of
    ``rig_modes``) with three equal Hertz contacts at each step's load, every step in one batched call."""
    if obs.hz.size == 0:
        return np.empty(0)
    k = stiffness_scale * np.asarray(obs.stiffness_n_per_m, dtype=float)
    freqs, _ = ContactModeModel.of(rig).many(np.repeat(k[:, None], 3, axis=1))  # (bounce, tilt, tilt) per step
    per_step = freqs[obs.step_of]
    return np.where(obs.is_tilt, per_step[:, 1:].mean(axis=1), per_step[:, 0])


@dataclass
class FitResult:
    """The fitted parameters (SI), their covariance and what the data could not determine."""

    values: dict[str, float]  # every parameter: fitted, or the nominal value it was held at
    std: dict[str, float | None]  # 1σ of the determined parameters; None: not determined (held at nominal)
    total_std: dict[str, float]  # 1σ of every parameter: held ones at their nominal uncertainty
    correlation: dict[str, dict[str, float]]  # of the estimates' errors, held parameters included
    free: tuple[str, ...]  # the determined parameters (written to the calibrated rig)
    held: dict[str, str]  # parameter -> why it is not determined (the rig keeps its nominal value)
    chi2: float
    dof: int
    seating_scatter_rel: float  # σ of the balls' stiffness factor per seating (estimated)
    frequency_scatter_rel: float  # σ per measured frequency beyond its identification and load noise (estimated)
    error_scale: float  # factor applied to every uncertainty where χ² still exceeded its degrees of freedom
    load_noise_n: float  # σ of one load reading per ball (estimated from repeat readings)
    ball_sizes_mm: list[float]
    residuals: list[dict] = field(default_factory=list)  # per observation: source, kind, measured, model, z
    unseparated_fit: dict[str, tuple[float, float]] = field(default_factory=dict)  # fitted but not used: value, σ
    coverage_factors: dict[str, float] = field(default_factory=dict)  # small-sample widening applied per parameter


def _load_noise_n(steps: Sequence[BallStep]) -> float:
    """Pooled σ of one load reading from the before/after readings of each step (0 if none repeat)."""
    d = [s.load_n - s.load_repeat_n for s in steps if s.load_repeat_n is not None]
    return math.sqrt(float(np.mean(np.square(d))) / 2.0) if d else 0.0


class _Problem:
    """Whitened residuals of the fit for a given seating scatter; parameters in log space."""

    def __init__(self, rig: RigConfig, obs: Observations, free: Sequence[str], load_noise_n: float) -> None:
        self.rig, self.obs, self.free = rig, obs, tuple(free)
        self.nominal = rig_values(rig)
        base = predict_hz(rig, obs)
        # sensitivities to a common scale of the ball stiffness (seating) and to the load (Hertz: dlnk/dlnF = 1/3)
        self.g = (predict_hz(rig, obs, 1.0 + 1e-4) - base) / 1e-4
        loads = np.array([obs.steps[i].load_n for i in obs.step_of])
        self.load_hz = self.g * load_noise_n / (3.0 * loads)  # one load error moves a step's bounce and tilt alike
        self.load_var = self.load_hz**2
        self.set_scatter(0.0)

    @property
    def noise_var(self) -> np.ndarray:
        """Variance of each frequency from its identification and the load reading."""
        return np.maximum(self.obs.std_hz, 1e-9 * self.obs.hz) ** 2 + self.load_var

    def set_scatter(self, seating_rel: float, step_rel: float = 0.0) -> None:
        """Covariance: noise, plus a stiffness factor per seating (shared by its steps), plus per-frequency σ."""
        obs = self.obs
        cov = np.diag(np.maximum(obs.std_hz, 1e-9 * obs.hz) ** 2 + (step_rel * obs.hz) ** 2)
        same_step = obs.step_of[:, None] == obs.step_of[None, :]
        same_run = obs.run_of[:, None] == obs.run_of[None, :]
        cov = cov + np.outer(self.load_hz, self.load_hz) * same_step
        cov = cov + seating_rel**2 * np.outer(self.g, self.g) * same_run
        self.chol = np.linalg.cholesky(cov)

    def scatter_moments(self, raw: np.ndarray, step_rel: float) -> tuple[float, float]:
        """Seating and per-frequency scatter from residuals (Hz): each seating's common offset along the
        stiffness-scale direction, and what remains once those offsets are removed."""
        obs, g = self.obs, self.g
        runs = obs.run_count
        offsets, offset_noise = np.zeros(runs), np.zeros(runs)
        rest = raw.copy()
        for r in range(runs):
            m = obs.run_of == r
            a = float(g[m] @ raw[m] / (g[m] @ g[m]))
            offsets[r] = a
            rest[m] -= a * g[m]
            var = self.noise_var[m] + (step_rel * obs.hz[m]) ** 2
            offset_noise[r] = float(g[m] ** 2 @ var) / float(g[m] @ g[m]) ** 2
        dof = max(obs.hz.size - runs - len(self.free), 1)
        excess_step = (float(np.sum(rest**2 / obs.hz**2)) - float(np.sum(self.noise_var / obs.hz**2))) / dof
        seating = float(np.mean(offsets**2 - offset_noise)) * runs / max(runs - 1, 1)
        return math.sqrt(max(seating, 0.0)), math.sqrt(max(excess_step, 0.0))

    def config(self, x: np.ndarray) -> RigConfig:
        return rig_with(self.rig, {p: float(math.exp(v)) for p, v in zip(self.free, x, strict=True)})

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return np.linalg.solve(self.chol, self.obs.hz - predict_hz(self.config(x), self.obs))

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Whitened residuals' derivatives with respect to the free log-parameters."""
        r0 = self.residuals(x)
        return np.column_stack([(self.residuals(x + h) - r0) / 1e-6 for h in 1e-6 * np.eye(len(x))])

    def held_jacobian(self, x: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """Whitened residuals' derivatives at ``x`` with respect to held (not fitted) log-parameters."""
        base = self.config(x)
        values = rig_values(base)
        r0 = self.residuals(x)
        cols = []
        for p in names:
            shifted = rig_with(base, {p: values[p] * math.exp(1e-6)})
            cols.append((np.linalg.solve(self.chol, self.obs.hz - predict_hz(shifted, self.obs)) - r0) / 1e-6)
        return np.column_stack(cols)

    def solve(self, x0: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
        nominal = np.log([self.nominal[p] for p in self.free])
        sol = least_squares(self.residuals, np.clip(x0, nominal - 2.0, nominal + 2.0), method="dogbox",
                            bounds=(nominal - 2.3, nominal + 2.3), diff_step=_EPS, xtol=1e-10, ftol=1e-10,
                            max_nfev=40)
        j = sol.jac
        try:
            cov = np.linalg.inv(j.T @ j)
        except np.linalg.LinAlgError:
            cov = np.full((len(x0), len(x0)), np.inf)
        return sol.x, float(np.sum(sol.fun**2)), cov


def expected_rel_std(rig: RigConfig, steps: Sequence[BallStep], *, seating_rel: float, load_noise_n: float,
                     use_tilt: bool = True) -> dict[str, float]:
    """Relative 1σ a fit of all parameters would reach on such steps (Fisher information at ``rig``): for
    planning a calibration protocol without simulating it. The steps' measured frequencies are not used."""
    obs = Observations.of(steps, use_tilt)
    has_tilt = bool(obs.is_tilt.any())
    free = [p for p in PARAMETERS if has_tilt or p != "inertia_kg_m2"]
    problem = _Problem(rig, obs, free, load_noise_n)
    problem.set_scatter(seating_rel)
    x = np.log([problem.nominal[p] for p in free])
    j = problem.jacobian(x)
    return dict(zip(free, np.sqrt(np.diag(np.linalg.inv(j.T @ j))).tolist(), strict=True))


def _priors(rig: RigConfig) -> dict[str, float]:
    """Relative 1-σ of a parameter held at its nominal value (carried into the fitted ones): the rig file's."""
    u, v = rig.uncertainty, rig_values(rig)
    return {"mass_kg": u.mass_std_kg / v["mass_kg"],
            "setup_stiffness_n_per_m": u.setup_stiffness_std_n_per_m / v["setup_stiffness_n_per_m"],
            "inertia_kg_m2": 0.0, "support_stiffness_n_per_m": SUPPORT_PRIOR_REL}


def fit_rig(rig: RigConfig, steps: Sequence[BallStep], *, use_tilt: bool = True) -> FitResult:
    """Fit the rig parameters the ball steps determine; hold the rest at nominal and say why.

    A parameter the data fix only through an assumption they cannot check (K_setup from one ball size) is
    fitted alongside, so the others' uncertainty allows for it, but not reported or written: the rig keeps
    its nominal value and nominal uncertainty.
    """
    if not steps:
        raise InputError("no identified ball steps to calibrate from")
    obs = Observations.of(steps, use_tilt)
    held: dict[str, str] = {}
    unseparated: dict[str, str] = {}
    if not obs.is_tilt.any():
        held["inertia_kg_m2"] = "no tilt frequencies identified, and the bounce mode does not depend on the inertia"
    sizes = sorted({round(s.ball_diameter_m * 1e3, 6) for s in steps})
    if len(sizes) < 2:
        unseparated["setup_stiffness_n_per_m"] = (
            f"one ball size ({sizes[0]:g} mm) cannot separate K_setup from the ball contacts: K_setup then shows "
            "only in how the frequencies bend with load, which is Hertz's load exponent (k ∝ F^1/3) assumed "
            "exact, so any departure of the contacts from it (roughness, films) would be taken for K_setup; a "
            "second ball size, whose contacts differ by (D1/D2)^1/3 at equal load, gives the independent lever")
    free = [p for p in PARAMETERS if p not in held]
    load_noise = _load_noise_n(steps)
    start = {p: math.log(v) for p, v in rig_values(rig).items()}
    while True:
        if obs.hz.size <= len(free):
            raise InputError(f"{obs.hz.size} measured frequencies cannot determine {len(free)} rig parameters; "
                             "measure more load steps")
        problem = _Problem(rig, obs, free, load_noise)
        x, chi2, cov, sigma, step_rel, scale = _fit_with_scatter(problem, obs, np.array([start[p] for p in free]))
        start.update(zip(free, x, strict=True))
        rel = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        worst = int(np.argmax(rel))
        if not np.all(np.isfinite(rel)) or rel[worst] > DETERMINED_REL:
            name = free[worst]
            held[name] = (f"the data fix it only to ±{_pct(rel[worst])} (1σ), worse than the "
                          f"{DETERMINED_REL:.0%} needed to call it determined")
            unseparated.pop(name, None)
            free.remove(name)
            if not free:
                raise InputError("the ball steps determine none of the rig parameters")
            continue
        break
    coverage = _coverage_factors(problem, x, cov, sigma, step_rel, scale)
    cov = cov * np.outer(coverage, coverage)
    fitted = dict(rig_values(rig))
    for i, p in enumerate(free):
        fitted[p] = float(math.exp(x[i]))
    # held parameters carry their nominal uncertainty into the fitted ones (linearised); the written rig keeps
    # held and unseparated parameters at nominal, whose errors are then independent of the fit's
    held_names = [p for p in PARAMETERS if p in held]
    prior = _priors(rig)
    s_h = np.diag([prior[p] ** 2 for p in held_names])
    n = len(free)
    joint = np.zeros((n + len(held_names), n + len(held_names)))
    joint[:n, :n] = cov
    if held_names:
        a = cov @ problem.jacobian(x).T @ problem.held_jacobian(x, held_names)
        joint[:n, :n] += a @ s_h @ a.T
        joint[:n, n:] = -a @ s_h
        joint[n:, :n] = (-a @ s_h).T
        joint[n:, n:] = s_h
    names = free + held_names
    unused = {p: (fitted[p], fitted[p] * math.sqrt(joint[free.index(p), free.index(p)])) for p in unseparated}
    for i, p in enumerate(free):
        if p in unseparated:
            joint[i, :] = joint[:, i] = 0.0
            joint[i, i] = prior[p] ** 2
    reported = [p for p in free if p not in unseparated]
    values = {p: fitted[p] if p in reported else v for p, v in rig_values(rig).items()}
    sd = np.sqrt(np.clip(np.diag(joint), 0.0, None))
    std: dict[str, float | None] = {p: None for p in PARAMETERS}
    total: dict[str, float] = {}
    for i, p in enumerate(names):
        total[p] = values[p] * float(sd[i])  # log-space σ → absolute (first order)
        if p in reported:
            std[p] = total[p]
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = joint / np.outer(sd, sd)
    correlation = {p: {q: float(corr[i, j]) for j, q in enumerate(names) if q != p and sd[i] > 0 and sd[j] > 0}
                   for i, p in enumerate(names)}
    model = predict_hz(problem.config(x), obs)
    z = problem.residuals(x)
    residuals = [{"source": obs.steps[i].source, "mode": "tilt" if t else "bounce",
                  "load_n": obs.steps[i].load_n, "ball_diameter_m": obs.steps[i].ball_diameter_m,
                  "measured_hz": float(m), "model_hz": float(f), "whitened": float(r)}
                 for i, t, m, f, r in zip(obs.step_of, obs.is_tilt, obs.hz, model, z, strict=True)]
    return FitResult(values, std, total, correlation, tuple(reported), {**unseparated, **held}, chi2,
                     int(obs.hz.size - len(free)), sigma, step_rel, scale, load_noise, sizes, residuals, unused,
                     dict(zip(free, coverage.tolist(), strict=True)))


def _coverage_factors(problem: _Problem, x: np.ndarray, cov: np.ndarray, seating: float, step: float,
                      scale: float) -> np.ndarray:
    """Widening of each parameter's σ so that ±2σ covers 95.4 % although the seating scatter is estimated from
    few seatings: Student's t with Welch–Satterthwaite degrees of freedom, (seatings − 1) / w², where w is the
    share of the parameter's variance that comes from the seating scatter."""
    runs = problem.obs.run_count
    if seating <= 0.0 or runs < 2:
        return np.ones(len(x))
    problem.set_scatter(0.0, step)
    j0 = problem.jacobian(x)
    problem.set_scatter(seating, step)
    try:
        without = np.diag(np.linalg.inv(j0.T @ j0)) * scale**2
    except np.linalg.LinAlgError:
        return np.ones(len(x))
    share = np.clip(1.0 - without / np.diag(cov), 1e-6, 1.0)
    nu = (runs - 1) / share**2
    return np.maximum(stdtrit(nu, TWO_SIGMA_COVERAGE) / 2.0, 1.0)


def _fit_with_scatter(problem: _Problem, obs: Observations, x0: np.ndarray
                      ) -> tuple[np.ndarray, float, np.ndarray, float, float, float]:
    """Fit with the scatter the data show: per seating and per frequency, estimated from the residuals.

    The two scatter terms are estimated by moments and the fit repeated (three rounds); if χ² still exceeds
    its degrees of freedom, every uncertainty is scaled up by sqrt(χ²/dof) (never down).
    Returns parameters, χ², covariance, seating σ, per-frequency σ, the error scale applied.
    """
    dof = obs.hz.size - len(problem.free)
    seating = step = 0.0
    problem.set_scatter(seating, step)
    x, chi2, cov = problem.solve(x0)
    for _ in range(4 if chi2 > dof else 0):
        seating, step = problem.scatter_moments(obs.hz - predict_hz(problem.config(x), obs), step)
        seating = min(seating, MAX_SCATTER_REL)
        problem.set_scatter(seating, step)
        x, chi2, cov = problem.solve(x)
    scale = math.sqrt(chi2 / dof) if chi2 > dof else 1.0
    return x, chi2, cov * scale**2, seating, step, scale


def _pct(rel: float) -> str:
    return "∞" if not math.isfinite(rel) else f"{100 * rel:.3g} %"
