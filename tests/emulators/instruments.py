"""Behavioural serial instruments for the pty emulator: an MT-SICS load cell and an automatic hammer.

They answer like the real devices (not a fixed script) so a whole run can talk to them; tests that assert an
exact exchange use ``ExpectedProtocol`` instead.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class MtSicsDevice:
    """An MT-SICS level 0 load cell showing ``force()`` newtons in ``unit`` (``N`` or ``kg``).

    ``busy_replies`` answers that many weighing commands with ``S I`` first; ``capacity_n`` gives ``S +``
    above it.
    """

    force: Callable[[], float]
    serial_number: str = "B947123456"
    unit: str = "N"
    stable: bool = True
    busy_replies: int = 0
    capacity_n: float = 5000.0
    tare_n: float = 0.0
    zero_n: float = 0.0
    log: list[str] = field(default_factory=list)

    def __call__(self, command: str) -> str:
        self.log.append(command)
        net = self.force() - self.zero_n - self.tare_n
        if command in ("S", "SI"):
            if self.busy_replies > 0:
                self.busy_replies -= 1
                return "S I"
            if net > self.capacity_n:
                return "S +"
            if net < -self.capacity_n:
                return "S -"
            status = "S" if self.stable or command == "S" else "D"
            return f"S {status} {self._shown(net):>10} {self.unit}"
        if command == "T":
            self.tare_n = self.force() - self.zero_n
            return f"T S {self._shown(self.tare_n):>10} {self.unit}"
        if command == "TAC":
            self.tare_n = 0.0
            return "TAC A"
        if command == "Z":
            self.zero_n, self.tare_n = self.force(), 0.0
            return "Z A"
        if command in ("I4", "@"):
            return f'I4 A "{self.serial_number}"'
        return "ES"

    def _shown(self, force_n: float) -> str:
        value = force_n / 9.80665 if self.unit == "kg" else force_n
        return f"{value:.3f}" if self.unit == "kg" else f"{value:.2f}"


@dataclass
class HammerDevice:
    """An Arduino-style automatic hammer: ``FIRE <level>`` calls ``on_fire(level)`` and answers ``OK``."""

    on_fire: Callable[[int], None] = lambda level: None
    identity: str = "AUTOHAMMER 1.2"
    error: str | None = None  # answer ``ERR <error>`` instead of firing
    fired: list[int] = field(default_factory=list)

    def __call__(self, command: str) -> str:
        if command == "ID?":
            return f"ID {self.identity}"
        word, _, arg = command.partition(" ")
        if word != "FIRE":
            return "ERR UNKNOWN"
        if not arg.isdigit() or not 1 <= int(arg) <= 255:
            return "ERR LEVEL"
        if self.error:
            return f"ERR {self.error}"
        self.fired.append(int(arg))
        self.on_fire(int(arg))
        return "OK"
