"""What the lab can measure next: catalogue roller types on the rails it has, at loads the knobs reach.

A candidate specimen is a roller type of the catalogue (``labctl.physics.catalogue``) on bearing rails of one
of the lab's two roughnesses. Its loads are the ones the engine would step through: the preload, then one
knob step (``labctl.engine.plan.plan_steps``: a multiple of the protocol's knob angle) at a time, up to the
protocol's C0 cap for that roller (``labctl.protocol.model.c0_cap_n``, ``labctl.physics.rating``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from labctl.data.units import UM
from labctl.engine.plan import plan_steps
from labctl.physics.catalogue import Roller, rollers
from labctl.physics.effects import ContactCase
from labctl.physics.materials import Material
from labctl.physics.rig_config import RigConfig
from labctl.protocol import Protocol, SpecimenSpec
from labctl.protocol.model import c0_cap_n

RAIL_RA_UM: tuple[float, ...] = (0.2, 0.03)
"""The rail roughnesses the lab has (the paper's two rail sets)."""


@dataclass(frozen=True)
class Specimen:
    """A catalogue roller on rails of one roughness, with every load the rig reaches below its cap."""

    roller: Roller
    rail: Material
    rail_ra_m: float
    loads_n: np.ndarray
    cap_n: float

    @property
    def case(self) -> ContactCase:
        return ContactCase(self.roller, self.rail, self.rail_ra_m)

    @property
    def type_id(self) -> int:
        assert self.roller.type_id is not None
        return self.roller.type_id


def reachable_loads(protocol: Protocol, roller_type: int, rail: Material, rail_ra_m: float, rig: RigConfig
                    ) -> tuple[np.ndarray, float]:
    """Loads per roller the engine steps through (preload first) up to the protocol's C0 cap, and the cap."""
    cap = c0_cap_n("roller", roller_type, rail.name, protocol.loading)
    assert cap is not None
    spec = SpecimenSpec(kind="roller", label=f"type {roller_type}", roller_type=roller_type, ball_diameter_m=None,
                        ball_material="", rail_material=rail.name, rail_ra_m=rail_ra_m, max_load_n=cap,
                        knob_step_deg=protocol.loading.knob_step_deg)
    step = plan_steps(protocol, spec, rig)
    per_step = rig.load_per_knob_degree_n * step.step_angle_deg
    loads = rig.preload_per_roller_n + per_step * np.arange(step.steps_estimate)
    return loads[loads <= cap * (1 + 1e-9)], cap


def candidate_specimens(protocol: Protocol, rig: RigConfig, rail: Material,
                        rail_ra_um: tuple[float, ...] = RAIL_RA_UM) -> list[Specimen]:
    """Every catalogue roller type on every rail roughness the lab has (types whose cap is below the preload,
    which the rig cannot load at all, are left out)."""
    out = []
    for type_id, r in sorted(rollers().items()):
        for ra_um in rail_ra_um:
            loads, cap = reachable_loads(protocol, type_id, rail, ra_um * UM, rig)
            if loads.size:
                out.append(Specimen(r, rail, ra_um * UM, loads, cap))
    return out
