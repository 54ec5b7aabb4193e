"""Load cell (or weighing terminal) speaking Mettler Toledo MT-SICS over a serial port.

Commands used: level 0 ``S`` (stable value), ``SI`` (value now, stable or dynamic), ``Z`` (zero), ``I4`` (serial
number), ``@`` (reset); level 1 ``T`` (tare) and ``TAC`` (clear tare), used only by ``tare``/``clear_tare`` (a
level-0-only device answers them ``ES``). The serial format (``8N1``, ``7E1``, …) and handshake (none, XON/XOFF,
RTS/CTS) must match the terminal's interface settings. A reply is ``<command> <status> [value unit]``,
the value right-justified, so fields are split on whitespace; status ``S`` stable, ``D`` dynamic, ``A`` done,
``I`` busy (retried, then :class:`DeviceBusy`), ``+``/``-`` above/below range. ``ES``/``ET``/``EL`` are the
syntax, transmission and logical errors. Values are converted to newtons; mass units use ``gravity_m_per_s2``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from drivers.errors import DeviceBusy, DeviceError
from drivers.hw.lifecycle import Lifecycle
from drivers.hw.serial_line import LineTransport
from drivers.interfaces import LoadReading

STANDARD_GRAVITY_M_PER_S2 = 9.80665
FORCE_UNITS_N = {"N": 1.0, "kN": 1e3, "mN": 1e-3, "daN": 10.0, "lbf": 4.4482216152605}
MASS_UNITS_KG = {"kg": 1.0, "g": 1e-3, "mg": 1e-6, "t": 1e3, "lb": 0.45359237, "oz": 0.028349523125}
REPLY_HEAD = {"S": "S", "SI": "S", "Z": "Z", "T": "T", "TAC": "TAC", "I4": "I4", "@": "I4"}
LEVEL_1 = ("T", "TAC")  # MT-SICS level 1: not every level-0 device has them
ERRORS = {
    "ES": "not understood (ES: syntax error)",
    "ET": "garbled on the way (ET: transmission error)",
    "EL": "refused now (EL: logical error)",
}


@dataclass(frozen=True)
class SicsReply:
    """One parsed reply line: the command echoed, its status letter and the remaining fields."""

    head: str
    status: str
    fields: tuple[str, ...]


def parse_reply(line: str) -> SicsReply | None:
    """Split a reply on whitespace; ``None`` for a line that is not MT-SICS (noise, a truncated line)."""
    parts = line.split()
    if not parts or not (line.isascii() and line.isprintable()):
        return None
    if parts[0] in ERRORS:
        return SicsReply(parts[0], "", ())
    if len(parts) < 2:
        return None
    return SicsReply(parts[0], parts[1], tuple(parts[2:]))


def to_newton(value: float, unit: str, gravity_m_per_s2: float = STANDARD_GRAVITY_M_PER_S2) -> float:
    """A displayed value in ``unit`` (force or mass) as a force in N."""
    if unit in FORCE_UNITS_N:
        return value * FORCE_UNITS_N[unit]
    if unit in MASS_UNITS_KG:
        return value * MASS_UNITS_KG[unit] * gravity_m_per_s2
    known = ", ".join([*FORCE_UNITS_N, *MASS_UNITS_KG])
    raise ValueError(f"unit {unit!r} is not a force or mass unit ({known})")


class MtSicsLoadCell(Lifecycle):
    """The rig's load cell: ``read()`` is the TOTAL force through the three rollers, in N."""

    def __init__(self, port: str, *, baudrate: int = 9600, timeout_s: float = 2.0, busy_retries: int = 3,
                 retry_delay_s: float = 0.2, stable_timeout_s: float = 10.0,
                 gravity_m_per_s2: float = STANDARD_GRAVITY_M_PER_S2, name: str | None = None,
                 serial_format: str = "8N1", handshake: str = "none") -> None:
        self.name = name or f"loadcell@{port}"
        self.port = port
        self.busy_retries, self.retry_delay_s = busy_retries, retry_delay_s
        self.stable_timeout_s, self.gravity_m_per_s2 = stable_timeout_s, gravity_m_per_s2
        self._line = LineTransport(self.name, port, baudrate=baudrate, timeout_s=timeout_s,
                                   serial_format=serial_format, handshake=handshake)

    def open(self) -> None:
        self._line.open()

    def close(self) -> None:
        self._line.close()


    def read(self) -> LoadReading:
        """The force now (``SI``), flagged stable or dynamic; the engine waits for stability itself."""
        return self._reading("SI", "read", None)

    def read_stable(self) -> LoadReading:
        """The next stable force (``S``): the load cell answers once its reading has settled."""
        return self._reading("S", "read stable", self.stable_timeout_s)

    def tare(self) -> None:
        """Tare (``T``, MT-SICS level 1): later readings are net of the present force."""
        self._command("T", "tare", ("S",), self.stable_timeout_s)

    def clear_tare(self) -> None:
        """Clear the tare (``TAC``, MT-SICS level 1)."""
        self._command("TAC", "clear tare", ("A",))

    def zero(self) -> None:
        """Zero (``Z``): the present force becomes the zero point (only within the cell's zero range)."""
        self._command("Z", "zero", ("A",), self.stable_timeout_s)

    def reset(self) -> str:
        """Reset (``@``): cancel pending commands; returns the serial number the cell announces."""
        return self._serial_number("@", "reset")

    def identify(self) -> str:
        """Serial number (``I4``)."""
        return self._serial_number("I4", "identify")

    def probe(self) -> str:
        """One line for ``labctl devices check``: who answers and what it reads now."""
        serial_number = self.identify()
        reading = self.read()
        state = "stable" if reading.stable else "dynamic"
        return f"MT-SICS serial {serial_number}, reads {reading.force_n:.2f} N ({state})"

    def _serial_number(self, command: str, action: str) -> str:
        reply = self._command(command, action, ("A",))
        return " ".join(reply.fields).strip('"') if reply.fields else ""

    def _reading(self, command: str, action: str, timeout_s: float | None) -> LoadReading:
        reply = self._command(command, action, ("S", "D"), timeout_s)
        if len(reply.fields) < 2:
            raise DeviceError(self.name, action, f"'{command}': reply without value and unit: {reply}")
        value_text, unit = reply.fields[0], reply.fields[1]
        try:
            force_n = to_newton(float(value_text), unit, self.gravity_m_per_s2)
        except ValueError as exc:
            raise DeviceError(self.name, action, f"'{command}': cannot read {value_text!r} {unit!r}: {exc}") from None
        return LoadReading(force_n=force_n, stable=reply.status == "S")

    def _command(self, command: str, action: str, ok: tuple[str, ...], timeout_s: float | None = None) -> SicsReply:
        """Send ``command``; retry while busy; any status outside ``ok`` becomes a typed error naming it."""
        head = REPLY_HEAD[command]
        for attempt in range(self.busy_retries + 1):
            reply = self._ask(command, head, action, timeout_s)
            if reply.head == "ET" and attempt == 0:
                continue  # a garbled command is worth sending once more
            if reply.head in ERRORS:
                level = " — an MT-SICS level 1 command; this device may offer level 0 only" \
                    if reply.head == "ES" and command in LEVEL_1 else ""
                raise DeviceError(self.name, action, f"command '{command}' {ERRORS[reply.head]}{level}")
            if reply.status in ok:
                return reply
            if reply.status == "I":
                if attempt < self.busy_retries:
                    time.sleep(self.retry_delay_s)
                    continue
                raise DeviceBusy(self.name, action, f"'{command}' answered busy (I) {attempt + 1} times")
            raise DeviceError(self.name, action, self._status_text(command, reply))
        raise DeviceError(self.name, action, f"command '{command}' garbled twice (ET: transmission error)")

    def _ask(self, command: str, head: str, action: str, timeout_s: float | None) -> SicsReply:
        def accept(line: str) -> bool:
            reply = parse_reply(line)
            return reply is not None and (reply.head == head or reply.head in ERRORS)

        reply = parse_reply(self._line.query(command, accept, action=action, timeout_s=timeout_s))
        assert reply is not None
        return reply

    @staticmethod
    def _status_text(command: str, reply: SicsReply) -> str:
        if reply.status == "+":
            return f"'{command}': overload ({reply.head} +): the force is above the load cell's range"
        if reply.status == "-":
            return f"'{command}': underload ({reply.head} -): the force is below the load cell's range"
        if reply.status == "L":
            return f"'{command}': refused ({reply.head} L): outside the zero range or not allowed now"
        return f"'{command}': unexpected status {reply.status!r} in {reply.head} {reply.status}"
