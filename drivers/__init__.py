"""Instrument drivers: interfaces, the simulated rig (``drivers.sim``) and real backends.

Backends never import labctl's engine, UI or CLI: the simulated rig receives its physics as objects.
"""

from __future__ import annotations

from drivers.errors import DeviceBusy, DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.interfaces import (
    Channel,
    Daq,
    Hammer,
    LoadActuator,
    LoadCell,
    LoadReading,
    Operator,
    OperatorAction,
    Record,
    Rig,
    TriggerSpec,
)

__all__ = [
    "Channel", "Daq", "DeviceBusy", "DeviceDisconnected", "DeviceError", "DeviceTimeout", "Hammer",
    "LoadActuator", "LoadCell", "LoadReading", "Operator", "OperatorAction", "Record", "Rig", "TriggerSpec",
]
