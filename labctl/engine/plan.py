"""Load-step planning: how far to turn the knobs per step, and when the next step would pass the cap."""

from __future__ import annotations

import math
from dataclasses import dataclass

from labctl.physics.rig_config import RigConfig
from labctl.protocol import Protocol, SpecimenSpec


@dataclass(frozen=True)
class StepPlan:
    step_angle_deg: float
    steps_estimate: int
    cap_n: float


def plan_steps(protocol: Protocol, spec: SpecimenSpec, rig: RigConfig) -> StepPlan:
    """Knob angle per step (a multiple of the protocol's step, so at most ``max_steps`` steps reach the cap)."""
    per_step = rig.load_per_knob_degree_n * spec.knob_step_deg
    span = max(spec.max_load_n - rig.preload_per_roller_n, 0.0)
    needed = int(math.floor(span / per_step + 1e-9)) + 1
    multiple = max(1, math.ceil(needed / protocol.loading.max_steps))
    angle = spec.knob_step_deg * multiple
    return StepPlan(angle, int(math.floor(span / (per_step * multiple) + 1e-9)) + 1, spec.max_load_n)


def next_load_n(loads: list[float], step_angle_deg: float, rig: RigConfig) -> float:
    """Expected load after one more step: the last measured increment, or the rig's calibration at first."""
    if len(loads) >= 2 and loads[-1] > loads[-2]:
        return loads[-1] + (loads[-1] - loads[-2])
    return loads[-1] + rig.load_per_knob_degree_n * step_angle_deg
