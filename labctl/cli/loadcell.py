"""``labctl loadcell read|tare|zero --port PORT``: talk to an MT-SICS load cell directly, e.g. to check wiring."""

from __future__ import annotations

import argparse

from labctl.cli.common import add_json, emit
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("loadcell", help="an MT-SICS load cell on a serial port: read, tare, zero")
    ss = p.add_subparsers(dest="loadcell_command", metavar="{read,tare,zero}")
    ss.required = True
    for name, help_text in (("read", "print the force (N) and whether it is stable"),
                            ("tare", "tare: later readings are net of the present force"),
                            ("zero", "zero: the present force becomes the zero point")):
        c = ss.add_parser(name, help=help_text)
        c.add_argument("--port", required=True, help="serial port (/dev/ttyUSB0, COM3) or pyserial URL")
        c.add_argument("--baudrate", type=int, default=9600, help="default 9600")
        c.add_argument("--format", dest="serial_format", default="8N1", metavar="8N1",
                       help="data bits, parity, stop bits as the terminal's interface is set (default 8N1; e.g. 7E1)")
        c.add_argument("--handshake", choices=("none", "xonxoff", "rtscts"), default="none",
                       help="flow control as the terminal's interface is set (default none)")
        c.add_argument("--timeout", type=float, default=2.0, metavar="S", help="seconds per command (default 2)")
        c.add_argument("--retries", type=int, default=3, help="busy (S I) answers retried (default 3)")
        if name == "read":
            c.add_argument("--stable", action="store_true", help="wait for a stable reading (S instead of SI)")
        add_json(c)
        c.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.timeout > 0:
        raise InputError(f"--timeout {args.timeout!r}: expected a positive number of seconds")
    if args.retries < 0:
        raise InputError(f"--retries {args.retries}: expected zero or more")
    from drivers.hw import MtSicsLoadCell
    from labctl.hardware import hardware_errors

    try:
        cell = MtSicsLoadCell(args.port, baudrate=args.baudrate, timeout_s=args.timeout, busy_retries=args.retries,
                              stable_timeout_s=max(args.timeout, 10.0), serial_format=args.serial_format,
                              handshake=args.handshake)
    except ValueError as exc:
        raise InputError(f"--format {args.serial_format}: {exc}") from None
    with hardware_errors(), cell:
        if args.loadcell_command == "read":
            reading = cell.read_stable() if args.stable else cell.read()
            result = {"force_n": reading.force_n, "stable": reading.stable, "port": args.port}
        else:
            getattr(cell, args.loadcell_command)()
            result = {"done": args.loadcell_command, "port": args.port}
    emit(result, args.json, _text)
    return 0


def _text(result: dict) -> str:
    if "force_n" in result:
        return f"{result['force_n']:.2f} N ({'stable' if result['stable'] else 'dynamic'})"
    return f"{result['done']} done on {result['port']}"
