"""CR LF framed request/reply over a serial port, shared by the MT-SICS load cell and the hammer actuator.

Opening maps the operating system's refusals to typed errors (missing port, permission, busy); a reply is
reassembled from however many chunks it arrives in, within one deadline; a port that goes away mid-exchange
is reopened once before the device is declared disconnected.
"""

from __future__ import annotations

import contextlib
import errno
import re
import time
from collections.abc import Callable

import serial

try:
    from termios import error as _TermiosError
except ImportError:  # not a POSIX system
    _TermiosError = OSError

from drivers.errors import DeviceBusy, DeviceDisconnected, DeviceError, DeviceTimeout

_POLL_S = 0.02  # granularity of the reply deadline
SERIAL_FORMAT = re.compile(r"^([5-8])([NEOMS])(1|1\.5|2)$")  # data bits, parity, stop bits: "8N1", "7E1"
HANDSHAKES = ("none", "xonxoff", "rtscts")


def parse_serial_format(text: str) -> tuple[int, str, float]:
    """``"7E1"`` → (7, "E", 1.0): data bits, parity letter (pyserial's), stop bits; ValueError naming the text."""
    match = SERIAL_FORMAT.match(text)
    if not match:
        raise ValueError(f"serial format {text!r}: expected data bits 5-8, parity N/E/O/M/S and stop bits 1/1.5/2, "
                         "e.g. '8N1' or '7E1'")
    stop = float(match.group(3))
    return int(match.group(1)), match.group(2), stop
PORT_ERRORS = (serial.SerialException, OSError, _TermiosError)  # how a vanished port shows up


def open_error(device: str, port: str, exc: Exception) -> DeviceError:
    """Turn pyserial's refusal to open ``port`` into the typed error a user can act on."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code in (errno.ENOENT, errno.ENODEV, errno.ENXIO) or "No such file" in text:
        return DeviceDisconnected(device, "open", f"no such port {port} (is the instrument plugged in?)")
    if code == errno.EACCES or "Permission denied" in text:
        return DeviceError(device, "open", f"permission denied on {port} (add the user to the 'dialout' group)")
    if code in (errno.EBUSY, errno.EAGAIN) or "exclusively lock" in text:
        return DeviceBusy(device, "open", f"{port} is in use by another program")
    return DeviceError(device, "open", f"{port}: {text}")


def _why(exc: BaseException) -> str:
    """A port failure in words (termios errors carry only an (errno, text) tuple)."""
    args = exc.args
    if len(args) == 2 and isinstance(args[0], int) and isinstance(args[1], str):
        return f"{args[1]} (errno {args[0]})"
    return str(exc) or type(exc).__name__


class LineTransport:
    """One serial port speaking in CR LF terminated ASCII lines; every failure names ``device``."""

    def __init__(self, device: str, port: str, *, baudrate: int = 9600, timeout_s: float = 2.0,
                 eol: bytes = b"\r\n", serial_format: str = "8N1", handshake: str = "none") -> None:
        if not timeout_s > 0:
            raise ValueError(f"{device}: timeout_s = {timeout_s!r}: expected a positive number of seconds")
        if handshake not in HANDSHAKES:
            raise ValueError(f"{device}: handshake {handshake!r}: expected one of {', '.join(HANDSHAKES)}")
        self.bytesize, self.parity, self.stopbits = parse_serial_format(serial_format)
        self.serial_format, self.handshake = serial_format, handshake
        self.device, self.port, self.baudrate, self.timeout_s, self.eol = device, port, baudrate, timeout_s, eol
        self._serial: serial.SerialBase | None = None
        self._pending = bytearray()

    @property
    def is_open(self) -> bool:
        return self._serial is not None and self._serial.is_open

    def open(self) -> None:
        """Open the port exclusively (a second program on the same port would corrupt the exchange)."""
        if self.is_open:
            return
        try:
            self._serial = serial.serial_for_url(
                self.port, baudrate=self.baudrate, bytesize=self.bytesize, parity=self.parity,
                stopbits=int(self.stopbits) if self.stopbits.is_integer() else self.stopbits,
                xonxoff=self.handshake == "xonxoff", rtscts=self.handshake == "rtscts", timeout=_POLL_S,
                write_timeout=self.timeout_s, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            self._serial = None
            raise open_error(self.device, self.port, exc) from exc
        self._pending.clear()

    def close(self) -> None:
        if self._serial is not None:
            with contextlib.suppress(*PORT_ERRORS):
                self._serial.close()
        self._serial = None
        self._pending.clear()

    def query(self, command: str, accept: Callable[[str], bool], *, action: str,
              timeout_s: float | None = None) -> str:
        """Send ``command`` and return the first reply line that ``accept`` recognises.

        Stale input is discarded before sending; lines ``accept`` rejects (garbage, late replies to an earlier
        command) are skipped. A port that fails mid-exchange is reopened and the command sent once more.
        """
        try:
            return self._exchange(command, accept, action, timeout_s)
        except PORT_ERRORS as first:
            self.close()
            try:
                self.open()
            except DeviceError as exc:
                raise DeviceDisconnected(self.device, action, f"{self.port} went away ({_why(first)}); "
                                         f"reopening failed: {exc.detail}") from first
            try:
                return self._exchange(command, accept, action, timeout_s)
            except PORT_ERRORS as second:
                raise DeviceDisconnected(self.device, action, f"{self.port}: {_why(second)}") from second

    def _exchange(self, command: str, accept: Callable[[str], bool], action: str, timeout_s: float | None) -> str:
        port = self._port(action)
        port.reset_input_buffer()
        self._pending.clear()
        try:
            port.write(command.encode("ascii") + self.eol)
            port.flush()
        except serial.SerialTimeoutException as exc:
            detail = f"'{command}': could not send within {self.timeout_s:g} s"
            raise DeviceTimeout(self.device, action, detail) from exc
        limit = self.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + limit
        skipped: list[str] = []
        while True:
            line = self._read_line(port, deadline)
            if line is None:
                partial = bytes(self._pending)
                if partial:
                    detail = f"'{command}': partial reply {partial!r} within {limit:g} s"
                elif skipped:
                    detail = f"'{command}': no valid reply within {limit:g} s (got {', '.join(skipped[:3])})"
                else:
                    detail = f"'{command}': no reply within {limit:g} s"
                raise DeviceTimeout(self.device, action, detail)
            if accept(line):
                return line
            skipped.append(repr(line))

    def _read_line(self, port: serial.SerialBase, deadline: float) -> str | None:
        while True:
            cut = self._pending.find(self.eol)
            if cut >= 0:
                raw = bytes(self._pending[:cut])
                del self._pending[: cut + len(self.eol)]
                return raw.decode("ascii", errors="replace")
            if time.monotonic() >= deadline:
                return None
            chunk = port.read(max(1, port.in_waiting))
            self._pending.extend(chunk)

    def _port(self, action: str) -> serial.SerialBase:
        if not self.is_open:
            self.open()
        assert self._serial is not None
        return self._serial
