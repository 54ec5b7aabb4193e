"""The simulated rig: a digital twin whose instruments share one state and the rig's physics.

``drivers.sim`` imports nothing from ``labctl``: the backend factory (``labctl.backends.make_rig``) passes the
rig description, the hidden world's roller model and the modes function in as objects.
"""

from __future__ import annotations

from drivers.interfaces import Operator, Rig
from drivers.operators import ScriptedOperator
from drivers.sim.faults import FaultSettings
from drivers.sim.instruments import SimActuator, SimClock, SimDaq, SimHammer, SimLoadCell
from drivers.sim.model import ModesFunction, RigLike, SimSettings, Specimen
from drivers.sim.operator import TwinOperator
from drivers.sim.twin import RigTwin


def build_sim_rig(twin: RigTwin, operator: Operator | None = None, description: dict[str, str] | None = None) -> Rig:
    """The instruments of a twin as a ``Rig``; the operator (a confirming script by default) is observed."""
    return Rig(
        daq=SimDaq(twin),
        hammer=SimHammer(twin),
        load_cell=SimLoadCell(twin),
        actuator=SimActuator(twin),
        operator=TwinOperator(operator if operator is not None else ScriptedOperator(), twin),
        backend="sim",
        description={"seed": str(twin.seed), **(description or {})},
        clock=SimClock(twin),
    )


def twin_of(rig: Rig) -> RigTwin:
    """The twin behind a simulated rig, for its test hooks and its truth."""
    twin = getattr(rig.daq, "twin", None)
    if not isinstance(twin, RigTwin):
        raise TypeError(f"rig backend {rig.backend!r} is not a simulated rig")
    return twin


__all__ = [
    "FaultSettings", "ModesFunction", "RigLike", "RigTwin", "SimActuator", "SimClock", "SimDaq", "SimHammer",
    "SimLoadCell", "SimSettings", "Specimen", "TwinOperator", "build_sim_rig", "twin_of",
]
