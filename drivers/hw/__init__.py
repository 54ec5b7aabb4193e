"""Backends for the real rig: MT-SICS load cell and automatic hammer over serial, the MCC USB-1608FS-Plus over
pyusb, NI-DAQmx (imported only when used), and the instruments the technician works by hand.

Nothing here imports labctl; ``labctl.hardware`` builds these from a devices file.
"""

from __future__ import annotations

from drivers.hw.acquisition import InputWiring
from drivers.hw.hammer_serial import SerialHammer
from drivers.hw.manual import ManualActuator, ManualHammer
from drivers.hw.mcc_usb import MccUsbDaq
from drivers.hw.mtsics import MtSicsLoadCell
from drivers.hw.nidaq import NiDaq

__all__ = ["InputWiring", "ManualActuator", "ManualHammer", "MccUsbDaq", "MtSicsLoadCell", "NiDaq", "SerialHammer"]
