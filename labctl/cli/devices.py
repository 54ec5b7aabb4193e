"""``labctl devices check|example``: probe every instrument of a devices file; print the example file."""

from __future__ import annotations

import argparse

from labctl.cli.common import add_json, emit


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("devices", help="the real rig's instruments: check them, or print an example devices file")
    ss = p.add_subparsers(dest="devices_command", metavar="{check,example}")
    ss.required = True
    c = ss.add_parser("check", help="open and probe each configured instrument; exit 1 if any fails")
    c.add_argument("--devices", metavar="FILE",
                   help="devices file (default: $LABCTL_DEVICES, ./devices.toml, ~/.config/labctl/devices.toml)")
    add_json(c)
    c.set_defaults(func=run_check)
    e = ss.add_parser("example", help="print the annotated example devices file (save it as devices.toml, edit)")
    add_json(e)
    e.set_defaults(func=run_example)


def run_check(args: argparse.Namespace) -> int:
    from labctl.hardware import check_devices, find_devices_file

    path = find_devices_file(args.devices)
    checks = check_devices(path)
    result = {"devices_file": str(path), "ok": all(c.ok for c in checks), "devices": [c.to_dict() for c in checks]}
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
    lines.append("all instruments answer" if result["ok"] else "some instruments do not work (see FAILED above)")
    return "\n".join(lines)
