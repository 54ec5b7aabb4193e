"""Automatic impact hammer (an Arduino-style solenoid or pendulum release) over a serial line.

Line protocol, ASCII, one command per line, CR LF (the device may also accept a bare LF):

====================  ===========================  =============================================
host sends            device answers               meaning
====================  ===========================  =============================================
``ID?``               ``ID <text>``                identification (firmware name and version)
``FIRE <level>``      ``OK``                       blow delivered; ``level`` 1-255 sets the energy
``FIRE <level>``      ``ERR <reason>``             not fired: ``ERR BUSY`` (recharging), ``ERR LEVEL``,
                                                   ``ERR INTERLOCK`` or any other text
====================  ===========================  =============================================

The DAQ is armed before ``strike`` and its force trigger catches the blow, exactly as for a manual hammer.
Many Arduino boards reset when the port opens: ``boot_delay_s`` waits that out before the first command.
"""

from __future__ import annotations

import time

from drivers.errors import DeviceBusy, DeviceError
from drivers.hw.lifecycle import Lifecycle
from drivers.hw.serial_line import LineTransport

LEVEL_RANGE = (1, 255)


def _is_reply(line: str, heads: tuple[str, ...]) -> bool:
    return line.isascii() and line.strip().split(" ", 1)[0] in heads


class SerialHammer(Lifecycle):
    """``strike()`` sends ``FIRE <level>`` and returns once the device answers ``OK``."""

    def __init__(self, port: str, *, level: int = 128, baudrate: int = 115200, timeout_s: float = 2.0,
                 boot_delay_s: float = 0.0, name: str | None = None) -> None:
        low, high = LEVEL_RANGE
        if not (isinstance(level, int) and low <= level <= high):
            raise ValueError(f"hammer level = {level!r}: expected an integer {low}-{high}")
        self.name = name or f"hammer@{port}"
        self.port, self.level, self.boot_delay_s = port, level, boot_delay_s
        self._line = LineTransport(self.name, port, baudrate=baudrate, timeout_s=timeout_s)

    def open(self) -> None:
        if self._line.is_open:
            return
        self._line.open()
        if self.boot_delay_s > 0:
            time.sleep(self.boot_delay_s)

    def close(self) -> None:
        self._line.close()


    def identify(self) -> str:
        self.open()
        line = self._line.query("ID?", lambda s: _is_reply(s, ("ID",)), action="identify")
        return line.strip()[2:].strip()

    def strike(self) -> None:
        """Deliver one blow at the configured level."""
        self.open()
        command = f"FIRE {self.level}"
        line = self._line.query(command, lambda s: _is_reply(s, ("OK", "ERR")), action="strike").strip()
        if line == "OK":
            return
        reason = line[3:].strip() or "no reason given"
        if reason.upper().startswith("BUSY"):
            raise DeviceBusy(self.name, "strike", f"'{command}' answered {line!r}")
        raise DeviceError(self.name, "strike", f"'{command}' answered {line!r}")

    def probe(self) -> str:
        return f"hammer '{self.identify()}' answers on {self.port} (level {self.level}; not fired)"
