"""Load-step planning: how far to turn the knobs per step, and when the next step would pass the cap."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from labctl.physics.rig_config import RigConfig
from labctl.protocol import Protocol as LabProtocol
from labctl.protocol import SpecimenSpec
from labctl.stiffness_table import StiffnessPoint

FLOOR_SLACK = 1e-9
"""Added before rounding a step count down, so a cap reached exactly (up to rounding) counts as reached."""


@dataclass(frozen=True)
class StepPlan:
    step_angle_deg: float
    steps_estimate: int
    cap_n: float


def knob_steps_within_cap(spec: SpecimenSpec, rig: RigConfig) -> tuple[float, int]:
    """(nominal load per roller of one knob step, the number of whole knob steps above the preload whose load stays
    within the specimen's cap: negative when the preload alone passes it)."""
    per_step = rig.load_per_knob_degree_n * spec.knob_step_deg
    return per_step, int(math.floor((spec.max_load_n - rig.preload_per_roller_n) / per_step + FLOOR_SLACK))


def plan_steps(protocol: LabProtocol, spec: SpecimenSpec, rig: RigConfig) -> StepPlan:
    """Knob angle per step (a multiple of the protocol's step, so at most ``max_steps`` steps reach the cap)."""
    per_step, n_cap = knob_steps_within_cap(spec, rig)
    span = max(spec.max_load_n - rig.preload_per_roller_n, 0.0)
    needed = max(n_cap, 0) + 1
    multiple = max(1, math.ceil(needed / protocol.loading.max_steps))
    angle = spec.knob_step_deg * multiple
    return StepPlan(angle, int(math.floor(span / (per_step * multiple) + FLOOR_SLACK)) + 1, spec.max_load_n)


def next_load_n(loads: list[float], step_angle_deg: float, rig: RigConfig) -> float:
    """Expected load after one more step: the last measured increment, or the rig's calibration at first."""
    if len(loads) >= 2 and loads[-1] > loads[-2]:
        return loads[-1] + (loads[-1] - loads[-2])
    return loads[-1] + rig.load_per_knob_degree_n * step_angle_deg


EXTRA_STEPS = 5
"""Base steps a repetition may run past the plan's estimate while the measured loads stay clearly under the cap."""


def continue_after(loads: list[float], plan: StepPlan, rig: RigConfig, margin: float) -> bool:
    """Whether a repetition runs another base step after the steps whose loads are ``loads``.

    The plan's estimate (from the rig's load per knob degree) decides, unless the measured loads say clearly,
    by more than ``margin`` of the cap, that the next step would pass the cap (stop early) or stay under it
    (go on, at most ``EXTRA_STEPS`` more). Load noise within the margin never changes the plan, so a
    repetition resumed after a crash runs the steps an uninterrupted one would have run."""
    k = len(loads)
    if k >= plan.steps_estimate + EXTRA_STEPS:
        return False
    expected = next_load_n(loads, plan.step_angle_deg, rig)
    if k < plan.steps_estimate:
        return expected <= plan.cap_n * (1 + margin)
    return expected <= plan.cap_n * (1 - margin)


@dataclass(frozen=True)
class AddedStep:
    """A load step an adaptive campaign adds after a repetition's base steps, and why."""

    angle_deg: float
    """Knob angle from the preload: a multiple of the specimen's knob step, within its load cap."""
    target_load_n: float
    reason: str
    score: float


class StepAdvisor(Protocol):
    """Chooses the extra load steps for the mounted specimen from the points measured so far (the planner)."""

    def extra_steps(self, points: Sequence[StiffnessPoint], spec: SpecimenSpec, budget_steps: int
                    ) -> list[AddedStep]: ...


def knob_angle_for(load_n: float, spec: SpecimenSpec, rig: RigConfig) -> float | None:
    """The knob angle (a whole number of knob steps) nearest ``load_n`` whose nominal load is within the cap."""
    per_step, n_cap = knob_steps_within_cap(spec, rig)
    if n_cap < 0:
        return None
    n = min(max(round((load_n - rig.preload_per_roller_n) / per_step), 0), n_cap)
    return n * spec.knob_step_deg
