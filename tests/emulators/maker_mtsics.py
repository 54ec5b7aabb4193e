"""A Mettler Toledo MT-SICS balance on a pseudo-terminal (facts: tests/emulators/MAKER_FACTS.md).

The driver opens ``balance.port`` with its own termios settings. The balance has its own serial format
(data bits, parity, stop bits, XON/XOFF); every character crosses a bit-level model of the line, so a host set to
8N1 talking to a 7E1 balance gets what a real one gets: ``ET`` for characters that fail the balance's parity
check and mangled replies. Commands follow the MT-SICS levels: a level-0 balance answers ``ES`` to level-1
commands. The test sets the load (``load_g``) and whether it has settled (``stable``).
"""

from __future__ import annotations

import os
import select
import termios
import threading
import time
import tty
from dataclasses import dataclass

import serial

XON, XOFF = 0x11, 0x13

LEVEL0 = ("@", "I0", "I1", "I2", "I3", "I4", "I5", "S", "SI", "SIR", "Z", "ZI")
LEVEL1 = ("D", "DW", "K", "SR", "T", "TA", "TAC", "TI")


@dataclass(frozen=True)
class SerialFormat:
    """A UART frame: ``data_bits`` 7 or 8, ``parity`` 'N', 'E' or 'O', ``stop_bits``, ``xonxoff`` handshake."""

    data_bits: int = 8
    parity: str = "N"
    stop_bits: int = 1
    xonxoff: bool = True
    baud: int = 9600


def _parity_bit(value: int, parity: str) -> int:
    ones = bin(value).count("1")
    return ones % 2 if parity == "E" else 1 - ones % 2


def _frame(byte: int, fmt: SerialFormat) -> list[int]:
    """Line bits after the start bit, LSB first, as the sender's UART puts them out (idle line is 1)."""
    value = byte & ((1 << fmt.data_bits) - 1)
    bits = [value >> i & 1 for i in range(fmt.data_bits)]
    if fmt.parity != "N":
        bits.append(_parity_bit(value, fmt.parity))
    return bits + [1] * fmt.stop_bits


def cross_line(byte: int, sender: SerialFormat, receiver: SerialFormat) -> tuple[int, bool]:
    """What the receiving UART makes of one character sent in another format: (data, error flag).
    The error flag is a parity or framing error."""
    line = _frame(byte, sender) + [1] * 4  # idle after the frame
    value = sum(bit << i for i, bit in enumerate(line[: receiver.data_bits]))
    pos = receiver.data_bits
    error = False
    if receiver.parity != "N":
        error |= line[pos] != _parity_bit(value, receiver.parity)
        pos += 1
    error |= line[pos] != 1  # stop bit
    return value, error


def host_format(fd: int) -> SerialFormat:
    """The format the driver set on the pty slave with termios. Linux ptys keep the speed and IXON but force CS8
    and drop PARENB, so data bits and parity read here are only right for 8N1 hosts (see ``observing_serial``)."""
    iflag, _oflag, cflag, _lflag, ispeed, _ospeed, _cc = termios.tcgetattr(fd)
    data_bits = 7 if cflag & termios.CSIZE == termios.CS7 else 8
    parity = "N" if not cflag & termios.PARENB else ("O" if cflag & termios.PARODD else "E")
    speeds = {getattr(termios, f"B{b}"): b for b in (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)}
    return SerialFormat(data_bits, parity, 2 if cflag & termios.CSTOPB else 1, bool(iflag & termios.IXON),
                        speeds.get(ispeed, 0))


class MtSicsBalance:
    """The balance: a reader thread on the pty master, the MT-SICS command set, a load set by the test."""

    def __init__(self, *, fmt: SerialFormat | None = None, level: int = 1, capacity_g: float = 220.0,
                 resolution_g: float = 0.01, serial_number: str = "B021002593", model: str = "MS204TS",
                 zero_range_fraction: float = 0.02, stable_timeout_s: float = 0.5) -> None:
        self.fmt = fmt or SerialFormat()
        self.level = level
        self.capacity_g = capacity_g
        self.resolution_g = resolution_g
        self.serial_number = serial_number
        self.model = model
        self.zero_range_g = zero_range_fraction * capacity_g
        self.stable_timeout_s = stable_timeout_s
        self.load_g = 0.0  # what lies on the pan (gross, relative to the power-on zero)
        self.stable = True
        self.zero_g = 0.0
        self.tare_g = 0.0
        self.received: list[str] = []
        self.display_text = ""
        self.declared_host: SerialFormat | None = None
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._paused = False  # XOFF received
        self._repeat: str | None = None  # SIR / SR running
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name=f"MT-SICS {self.port}", daemon=True)

    def __enter__(self) -> MtSicsBalance:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)
        for fd in (self._master, self._slave):
            os.close(fd)

    # -- line ------------------------------------------------------------------------------------------------------
    def observing_serial(self) -> type[serial.Serial]:
        """A ``serial.Serial`` subclass to patch into the driver's module: it tells the balance the frame format the
        driver asked for (a pty cannot carry data bits and parity) and tolerates the pty refusing 7-bit/parity
        termios, which a real UART accepts. Everything else is pyserial's own code."""
        balance = self

        class ObservedSerial(serial.Serial):
            def _reconfigure_port(self, force_update: bool = False) -> None:
                try:
                    super()._reconfigure_port(force_update)
                except termios.error:
                    if self.bytesize == 8 and self.parity == serial.PARITY_NONE:
                        raise
                if self.port == balance.port:
                    balance.declared_host = SerialFormat(self.bytesize, self.parity, int(self.stopbits),
                                                         self.xonxoff, self.baudrate)

        return ObservedSerial

    def _host(self) -> SerialFormat:
        return self.declared_host or host_format(self._slave)

    def _send(self, line: str) -> None:
        host = self._host()
        out = bytearray()
        for ch in (line + "\r\n").encode("latin-1"):
            value, error = cross_line(ch, self.fmt, host)
            out.append(0 if error else value)  # a UART hands over NUL for a character in error
        while self._paused and not self._stop.is_set():
            self._poll_input(0.01)
        if host.baud == self.fmt.baud:
            os.write(self._master, bytes(out))

    def _run(self) -> None:
        self._buffer = bytearray()
        self._bad = False
        while not self._stop.is_set():
            self._poll_input(0.05)
            if self._repeat is not None:
                self._send(self._execute(self._repeat))

    def _poll_input(self, wait_s: float) -> None:
        ready, _, _ = select.select([self._master], [], [], wait_s)
        if not ready:
            return
        try:
            data = os.read(self._master, 4096)
        except OSError:
            self._stop.set()
            return
        host = self._host()
        if host.baud != self.fmt.baud:
            return  # at the wrong speed nothing arrives as characters; a real balance stays silent
        for byte in data:
            value, error = cross_line(byte, host, self.fmt)
            if self.fmt.xonxoff and not error and value in (XON, XOFF):
                self._paused = value == XOFF
                continue
            self._bad |= error
            self._buffer.append(value)
            if self._buffer.endswith(b"\r\n"):
                raw, bad = bytes(self._buffer[:-2]), self._bad
                self._buffer.clear()
                self._bad = False
                self._repeat = None  # any command ends SIR / SR
                reply = "ET" if bad else self._execute(raw.decode("latin-1"))
                self.received.append(raw.decode("latin-1"))
                if reply is not None:
                    self._send(reply)

    # -- commands ----------------------------------------------------------------------------------------------------
    def _weight(self, grams: float) -> str:
        decimals = max(0, -int(f"{self.resolution_g:e}".split("e")[1]))
        rounded = round(grams / self.resolution_g) * self.resolution_g
        return f"{rounded:.{decimals}f}".rjust(10) + " g"

    def _gross(self) -> float:
        return self.load_g - self.zero_g

    def _net_status(self) -> str:
        gross = self._gross()
        if self.load_g > self.capacity_g:
            return "+"
        if gross < -self.zero_range_g:
            return "-"
        return "S" if self.stable else "D"

    def _wait_stable(self) -> bool:
        deadline = time.monotonic() + self.stable_timeout_s
        while not self.stable and time.monotonic() < deadline:
            time.sleep(0.01)
        return self.stable

    def _execute(self, line: str) -> str | None:
        name, _, arg = line.partition(" ")
        known = LEVEL0 + (LEVEL1 if self.level >= 1 else ())
        if name not in known:
            return "ES"
        handler = getattr(self, f"_cmd_{name.replace('@', 'at')}")
        return handler(arg)

    def _cmd_at(self, arg: str) -> str:
        self.tare_g = 0.0
        self._repeat = None
        return f'I4 A "{self.serial_number}"'

    def _cmd_I0(self, arg: str) -> str:
        cmds = [(0, c) for c in LEVEL0] + ([(1, c) for c in LEVEL1] if self.level >= 1 else [])
        lines = [f'I0 B {lv} "{c}"' for lv, c in cmds[:-1]] + [f'I0 A {cmds[-1][0]} "{cmds[-1][1]}"']
        return "\r\n".join(lines)

    def _cmd_I1(self, arg: str) -> str:
        levels = "01" if self.level >= 1 else "0"
        return f'I1 A "{levels}" "2.20" "2.20" "" ""'

    def _cmd_I2(self, arg: str) -> str:
        return f'I2 A "{self.model} {self.capacity_g:.2f} g"'

    def _cmd_I3(self, arg: str) -> str:
        return 'I3 A "1.10"'

    def _cmd_I4(self, arg: str) -> str:
        return f'I4 A "{self.serial_number}"'

    def _cmd_I5(self, arg: str) -> str:
        return 'I5 A "11671158C"'

    def _cmd_S(self, arg: str) -> str:
        status = self._net_status()
        if status in "+-":
            return f"S {status}"
        if not self._wait_stable():
            return "S I"
        return "S S" + " " + self._weight(self._gross() - self.tare_g)

    def _cmd_SI(self, arg: str) -> str:
        status = self._net_status()
        if status in "+-":
            return f"S {status}"
        return f"S {status} " + self._weight(self._gross() - self.tare_g)

    def _cmd_SIR(self, arg: str) -> str:
        self._repeat = "SI"
        return self._cmd_SI(arg)

    def _cmd_SR(self, arg: str) -> str:
        self._repeat = "S"
        return self._cmd_S(arg)

    def _zero(self, name: str, wait: bool) -> str:
        gross = self.load_g
        if gross > self.zero_range_g:
            return f"{name} +"
        if gross < -self.zero_range_g:
            return f"{name} -"
        if wait and not self._wait_stable():
            return f"{name} I"
        self.zero_g, self.tare_g = self.load_g, 0.0
        return f"{name} A" if wait else f"{name} {'S' if self.stable else 'D'}"

    def _cmd_Z(self, arg: str) -> str:
        return self._zero("Z", wait=True)

    def _cmd_ZI(self, arg: str) -> str:
        return self._zero("ZI", wait=False)

    def _tare(self, name: str, wait: bool) -> str:
        gross = self._gross()
        if self.load_g > self.capacity_g:
            return f"{name} +"
        if gross < 0:
            return f"{name} -"
        if wait and not self._wait_stable():
            return f"{name} I"
        self.tare_g = gross
        return f"{name} {'S' if self.stable else 'D'} " + self._weight(self.tare_g)

    def _cmd_T(self, arg: str) -> str:
        return self._tare("T", wait=True)

    def _cmd_TI(self, arg: str) -> str:
        return self._tare("TI", wait=False)

    def _cmd_TA(self, arg: str) -> str:
        if arg:
            try:
                value = float(arg.split()[0])
            except ValueError:
                return "TA L"
            self.tare_g = value
        return "TA A " + self._weight(self.tare_g)

    def _cmd_TAC(self, arg: str) -> str:
        self.tare_g = 0.0
        return "TAC A"

    def _cmd_D(self, arg: str) -> str:
        if not (arg.startswith('"') and arg.endswith('"') and len(arg) >= 2):
            return "D L"
        self.display_text = arg[1:-1]
        return "D A"

    def _cmd_DW(self, arg: str) -> str:
        self.display_text = ""
        return "DW A"

    def _cmd_K(self, arg: str) -> str:
        return "K A" if arg.strip() in ("1", "2", "3", "4") else "K L"
