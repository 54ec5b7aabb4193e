"""``labctl devices check|example``: probe every instrument of a devices file (``--acquire``: and take one test
record of a light tap, printing what it verified); print the example file."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("devices", help="the real rig's instruments: check them, or print an example devices file")
    ss = p.add_subparsers(dest="devices_command", metavar="{check,example}")
    ss.required = True
    c = ss.add_parser("check", help="open and probe each configured instrument; exit 1 if any fails")
    c.add_argument("--devices", metavar="FILE",
                   help="devices file (default: $LABCTL_DEVICES, ./devices.toml, ~/.config/labctl/devices.toml)")
    c.add_argument("--acquire", action="store_true",
                   help="also take one triggered record of a light hammer tap and read the load cell, and print "
                        "what that verified (actual rate, ranges, coupling, IEPE current, trigger, headroom) and "
                        "what it could not")
    c.add_argument("--rate", type=float, default=20480.0, metavar="HZ", help="--acquire: sample rate asked (20480)")
    c.add_argument("--seconds", type=float, default=3.2, metavar="S", help="--acquire: record length (3.2 s)")
    c.add_argument("--trigger-n", type=float, default=10.0, metavar="N", help="--acquire: force trigger level (10 N)")
    c.add_argument("--timeout", type=float, default=60.0, metavar="S", help="--acquire: wait for the tap (60 s)")
    add_json(c)
    c.set_defaults(func=run_check)
    e = ss.add_parser("example", help="print the annotated example devices file (save it as devices.toml, edit)")
    add_json(e)
    e.set_defaults(func=run_example)


def instrument_overrides() -> dict[str, Any]:
    """Replacements for the system's pyusb backend, nidaqmx module and console operator; none in use (a test
    substitutes emulators here to run the command in-process on an emulated rig)."""
    return {}


def run_check(args: argparse.Namespace) -> int:
    from drivers.hw.verify import TapSettings, as_rows, findings_ok
    from labctl.hardware import check_devices, find_devices_file, tap_check_devices

    settings = None
    if args.acquire:
        for option, value in (("--rate", args.rate), ("--seconds", args.seconds), ("--trigger-n", args.trigger_n),
                              ("--timeout", args.timeout)):
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{option} {value:g}: expected a finite positive number")
        try:
            settings = TapSettings(args.rate, args.seconds, args.trigger_n, timeout_s=args.timeout)
        except ValueError as exc:
            raise InputError(f"--acquire: {exc}") from None
    path = find_devices_file(args.devices)
    over = instrument_overrides()
    backends = {k: over[k] for k in ("usb_backend", "nidaqmx_module") if k in over}
    checks = check_devices(path, **backends)
    result: dict[str, Any] = {"devices_file": str(path), "ok": all(c.ok for c in checks),
                              "devices": [c.to_dict() for c in checks]}
    if settings is not None:
        if result["ok"]:
            operator = over.get("operator")
            if operator is None:
                from drivers.operators import ConsoleOperator

                operator = ConsoleOperator(stdout=sys.stderr)  # prompts stay off stdout (--json)
            rows = tap_check_devices(path, operator, settings, **backends)
            result["verification"] = as_rows(rows)
            result["ok"] = findings_ok(rows)
        else:
            result["verification"] = []
    emit(result, args.json, _text)
    return 0 if result["ok"] else 1


def run_example(args: argparse.Namespace) -> int:
    from labctl.hardware import example_path

    emit({"example": example_path().read_text(encoding="utf-8")}, args.json, lambda r: r["example"])
    return 0


def _text(result: dict) -> str:
    lines = [f"devices file: {result['devices_file']}"]
    for d in result["devices"]:
        mark = "ok    " if d["ok"] else "FAILED"
        lines.append(f"  {mark} {d['role']:<9} {d['type']:<8} {d['address']}: {d['detail']}")
    if "verification" not in result:
        lines.append("all instruments answer" if result["ok"] else "some instruments do not work (see FAILED above)")
        return "\n".join(lines)
    rows = result["verification"]
    if not rows:
        lines.append("no test record: fix the instruments that FAILED above first")
        return "\n".join(lines)
    lines.append("test record of one tap:")
    width = {k: max(len(k), *(len(r[k]) for r in rows)) for k in ("instrument", "item", "value", "status")}
    head = {"instrument": "instrument", "item": "item", "value": "value", "status": "status", "note": "note"}
    for r in [head, *rows]:
        lines.append(("  " + "  ".join(f"{r[k]:<{width[k]}}" for k in width) + f"  {r.get('note', '')}").rstrip())
    failed = sum(r["status"] == "FAILED" for r in rows)
    unverified = sum(r["status"] == "not verified" for r in rows)
    lines.append(f"{failed} FAILED, {unverified} not verified (a tap cannot show them; see the notes)" if failed
                 else f"all checks passed; {unverified} items not verified by a tap (see the notes)")
    return "\n".join(lines)
