"""The planner as the engine's step advisor: which extra load steps, on the specimen that is mounted, teach most.

An adaptive campaign cannot change the specimen mid-campaign, so the candidates are the loads of the mounted
roller type on its rails: every whole number of the specimen's knob steps from the preload up to its load cap
(finer than the protocol's base steps when the protocol strides several knob steps). The discrepancy workflow
runs on everything measured so far in the file; the criterion of ``labctl.planning.plan`` picks the loads, a
load again when repeating it teaches most (the base steps already span the load range).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from labctl.discrepancy.workflow import run_discrepancy
from labctl.engine.plan import AddedStep, knob_angle_for, knob_steps_to_cap
from labctl.errors import InputError
from labctl.physics.rig_config import RigConfig
from labctl.planning.plan import models_in_play, score_specimen
from labctl.planning.specimens import Specimen
from labctl.protocol import SpecimenSpec
from labctl.stiffness_table import StiffnessPoint


def knob_loads(spec: SpecimenSpec, rig: RigConfig) -> np.ndarray:
    """Nominal loads per roller at every whole knob step from the preload up to the specimen's cap."""
    per_step = rig.load_per_knob_degree_n * spec.knob_step_deg
    return rig.preload_per_roller_n + per_step * np.arange(max(knob_steps_to_cap(spec, rig) + 1, 0))


@dataclass
class PlanAdvisor:
    """Satisfies ``labctl.engine.plan.StepAdvisor`` with the planner's criterion (D-optimal + discrimination)."""

    rig: RigConfig
    baseline: str = "tripp"
    candidates: Sequence[str] | None = None

    def extra_steps(self, points: Sequence[StiffnessPoint], spec: SpecimenSpec, budget_steps: int
                    ) -> list[AddedStep]:
        if spec.kind != "roller" or spec.roller_type is None:
            raise InputError(f"{spec.label}: the planner plans roller specimens only")
        if budget_steps < 1 or not points:
            return []
        loads = knob_loads(spec, self.rig)
        if loads.size == 0:
            return []
        result = run_discrepancy(points, self.baseline, setup_stiffness_n_per_m=self.rig.setup_stiffness_n_per_m)
        play, weights = models_in_play(result, self.candidates)
        case = spec.case()
        specimen = Specimen(case.roller, case.rail, spec.rail_ra_m, loads, spec.max_load_n)
        scored = score_specimen(result, play, weights, specimen, budget_steps, repeat=True)
        if scored is None:
            return []
        rec, total, _ = scored
        out = []
        for load in rec.loads_n:
            angle = knob_angle_for(load, spec, self.rig)
            if angle is not None:
                out.append(AddedStep(angle, float(load), rec.reason, float(f"{total:.4g}")))
        return out
