"""The protocol engine: sequencing, run control, guarded hardware calls and load-step planning."""

from __future__ import annotations

from labctl.engine.calls import GuardedCaller, HardwareFailure
from labctl.engine.conditions import Condition, LoadDrift, LoadInterlock, SafePoint, Trip
from labctl.engine.control import RunControl, StopRequested
from labctl.engine.sequencer import Engine, Outcome, RigFactory
from labctl.engine.steps import Interlock

__all__ = ["Condition", "Engine", "GuardedCaller", "HardwareFailure", "Interlock", "LoadDrift", "LoadInterlock",
           "Outcome", "RigFactory", "RunControl", "SafePoint", "StopRequested", "Trip"]
