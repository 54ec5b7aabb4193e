"""The protocol engine: sequencing, run control, guarded hardware calls and load-step planning."""

from __future__ import annotations

from labctl.engine.calls import GuardedCaller, HardwareFailure
from labctl.engine.control import RunControl, StopRequested
from labctl.engine.sequencer import Engine, Interlock, Outcome, RigFactory

__all__ = ["Engine", "GuardedCaller", "HardwareFailure", "Interlock", "Outcome", "RigFactory", "RunControl",
           "StopRequested"]
