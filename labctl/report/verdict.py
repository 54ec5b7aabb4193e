"""Pass/fail of each load step against a model band, and the rig and model parameters behind the numbers.

Rule (stated on the report page): a step's mean stiffness over its repetitions is compared with the
reference model at the step's mean load — Eq. 5 or Eq. 6 for rollers (the fit made for the rails'
roughness), Hertz for balls. Its uncertainty u combines the standard error of the mean over the
repetitions with the rig's systematic uncertainty (disc mass, K_setup, rig model; from the rig file's
``[uncertainty]``). With the interval k ± 2u (about 95 %): **pass** when the whole interval lies within
the band, **fail** when it lies wholly outside, otherwise **cannot tell**. Eqs. 5/6 were fitted to steel
rollers; a roller whose contact modulus differs from bearing steel's by more than 5 % gets no verdict.
A step whose load drifted during the step (in any repetition) is never a pass or a fail: the stiffness
belongs to a load that did not hold, so it is **cannot tell** with the drift in its note.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from labctl.physics import FITS, RigConfig, effective_modulus, material
from labctl.physics.materials import BEARING_STEEL
from labctl.physics.references import fit_for_rail, model_curve
from labctl.physics.tripp import DEFAULT_DEPTH_M
from labctl.report.data import SeriesData

ROLLER_BAND = 0.10  # most of the paper's points lie within ±10 % of Eqs. 5/6
BALL_BAND = 0.05  # the ball verification's agreement with Hertz (§2.6)
COVERAGE = 2.0  # k ± 2u: about 95 %
STEEL_MODULUS_TOLERANCE = 0.05
PASS, FAIL, UNDECIDED, NO_MODEL = "pass", "fail", "cannot tell", "no verdict"


@dataclass(frozen=True)
class StepVerdict:
    """One load step of one specimen series against its reference model."""

    series: int
    label: str
    step: int
    load_n: float
    stiffness_n_per_m: float
    std_n_per_m: float  # u: standard error of the mean and the rig's systematic part
    repetitions: int
    model: str  # "Eq. 5", "Eq. 6", "Hertz" or "" (none applies)
    model_n_per_m: float
    band: float
    verdict: str
    note: str = ""

    @property
    def deviation(self) -> float:
        return self.stiffness_n_per_m / self.model_n_per_m - 1.0 if self.model_n_per_m > 0 else math.nan


def steel_fit_applies(series: SeriesData) -> tuple[bool, float]:
    """Whether Eqs. 5/6 (fitted to steel rollers) apply, and the relative difference of E* from steel's."""
    steel = effective_modulus(material(BEARING_STEEL), series.case.rail)
    mine = effective_modulus(series.case.roller.material, series.case.rail)
    diff = mine / steel - 1.0
    return abs(diff) <= STEEL_MODULUS_TOLERANCE, diff


def rig_relative_std(rig: RigConfig, stiffness_n_per_m: float) -> float:
    """Relative 1-σ of a stiffness from the rig's parameters (disc mass, K_setup, their correlation, the rig
    model): the stiffness budget's rig terms (``labctl.processing.stiffness.stiffness_budget``), the bounce
    frequency that gives ``stiffness_n_per_m`` held fixed."""
    if not stiffness_n_per_m > 0:
        return math.nan
    from labctl.processing.stiffness import stiffness_budget

    return stiffness_budget(rig, stiffness_n_per_m, 0.0).total_std_n_per_m / stiffness_n_per_m


def _verdict(k: float, std: float, k_model: float, band: float) -> str:
    if not (k_model > 0 and math.isfinite(k)):
        return NO_MODEL
    lo, hi = (k - COVERAGE * std) / k_model - 1, (k + COVERAGE * std) / k_model - 1
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return UNDECIDED
    if -band <= lo and hi <= band:
        return PASS
    if hi < -band or lo > band:
        return FAIL
    return UNDECIDED


def series_verdicts(series: SeriesData, rig: RigConfig, band: float | None = None) -> list[StepVerdict]:
    """Every step of a series against its reference model (band: ±10 % rollers, ±5 % balls by default)."""
    ball = series.kind == "ball"
    band = band if band is not None else (BALL_BAND if ball else ROLLER_BAND)
    applies, diff = (True, 0.0) if ball else steel_fit_applies(series)
    reference = "hertz" if ball else fit_for_rail(series.case.rail_ra_m)
    name = "Hertz" if ball else FITS[reference].equation
    stats = series.step_stats()
    loads = np.array([s.load_n for s in stats])
    k_model = model_curve(reference, series.case, loads) if applies else np.full(len(stats), np.nan)
    out = []
    for st, km in zip(stats, k_model, strict=True):
        per_run = [float(r.stiffness_n_per_m[list(r.steps).index(st.step)]) for r in series.runs
                   if st.step in list(r.steps)]
        se = float(np.std(per_run, ddof=1) / math.sqrt(len(per_run))) if len(per_run) > 1 else math.nan
        sys_std = rig_relative_std(rig, st.stiffness_n_per_m) * st.stiffness_n_per_m
        std = math.hypot(se, sys_std)
        note = ""
        if not applies:
            note = f"{name} was fitted to steel rollers; this roller's E* differs by {diff:+.0%}"
        elif not math.isfinite(km):
            note = f"{name} is not defined at this load"
        elif len(per_run) < 2:
            note = "one repetition: no scatter estimate"
        verdict = _verdict(st.stiffness_n_per_m, std, float(km), band) if applies else NO_MODEL
        drifted = series.drifted(st.step)
        if drifted and verdict in (PASS, FAIL):  # the stiffness belongs to a load that did not hold
            verdict = UNDECIDED
        if drifted:
            note = "; ".join([*(f"run {e.run}: load drifted {e.load_before_n:.1f} → {e.load_after_n:.1f} N "
                                f"during the step" for e in drifted), *([note] if note else [])])
        out.append(StepVerdict(series.index, series.name, st.step, st.load_n, st.stiffness_n_per_m, std,
                               st.repetitions, name if applies else "", float(km), band, verdict, note))
    return out


@dataclass(frozen=True)
class Parameter:
    name: str
    value: str
    std: str
    source: str


def rig_parameters(rig: RigConfig) -> list[Parameter]:
    """The rig and model parameters every reported stiffness depends on, with their 1-σ where known."""
    u = rig.uncertainty
    source = rig.source or "the shipped paper rig"
    calibrated = f"calibration {rig.calibration.get('source', '')}".strip() if rig.calibration else "nominal"

    def rel(std: float, value: float, scale: float = 1.0, unit: str = "") -> str:
        return f"± {std * scale:.3g}{unit} ({std / value:.1%})" if std > 0 else "not given"

    mass, setup = rig.upper.mass_kg, rig.setup_stiffness_n_per_m
    return [
        Parameter("disc mass m (each disc)", f"{mass:.4g} kg", rel(u.mass_std_kg, mass, unit=" kg"),
                  f"{source} ({calibrated})"),
        Parameter("K_setup (in series with the rollers)", f"{setup * 1e-6:.4g} N/µm",
                  rel(u.setup_stiffness_std_n_per_m, setup, 1e-6, " N/µm"), source),
        Parameter("correlation of m and K_setup", f"{u.mass_setup_correlation:.2f}", "", source),
        Parameter("rig model idealisation", "rigid discs, point contacts", f"± {u.model_rel:.1%} on k"
                  if u.model_rel > 0 else "not given", source),
        Parameter("contact radius", f"{rig.contact_radius_m * 1e3:.4g} mm", "", source),
        Parameter("Tripp evaluation depth t", f"{DEFAULT_DEPTH_M * 1e3:g} mm", "a model choice, not measured",
                  "labctl.physics.tripp"),
        *(Parameter(f"{c.equation} (rails Ra {c.rail_ra_m * 1e6:g} µm)",
                    f"C = {c.c_n_per_m2:.4g} N/m², p₀ = {c.p0_n_per_m * 1e-3:.4g} N/mm", "", "paper")
          for c in FITS.values()),
    ]
