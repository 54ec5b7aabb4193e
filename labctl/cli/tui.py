"""``labctl tui``: the terminal UI at the rig — run a protocol with live plots and dialogs, or browse a file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from labctl.cli.common import add_json, emit
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tui", help="terminal UI: run a protocol with live plots and dialogs, browse campaign files")
    p.add_argument("protocol", metavar="PROTOCOL", nargs="?",
                   help="protocol TOML file or shipped name (omit to choose on screen)")
    p.add_argument("--backend", choices=("sim", "hw"), default="sim", help="simulated rig or hardware (default sim)")
    p.add_argument("--out", help="campaign file to write (default <protocol>-<date>-<time>.h5)")
    p.add_argument("--autostart", action="store_true", help="start acquiring at once")
    p.add_argument("--resume", action="store_true", help="continue the interrupted campaign file given by --out")
    p.add_argument("--open", metavar="FILE.h5", help="browse an existing campaign file")
    auto = p.add_mutually_exclusive_group()
    auto.add_argument("--auto-confirm", type=float, metavar="SECONDS",
                      help="simulated rig: prompts take their first choice by themselves after SECONDS "
                      "(default 3 s with --autostart)")
    auto.add_argument("--no-auto-confirm", action="store_true", help="every prompt waits for a key press")
    p.add_argument("--world", help="world scenario TOML for the simulated rig (hidden effects)")
    p.add_argument("--seed", type=int, help="random seed for the simulated rig")
    p.add_argument("--rig", help="rig TOML file (default: the paper's rig)")
    p.add_argument("--devices", help="devices TOML file for --backend hw")
    add_json(p)
    p.set_defaults(func=run)


def settings_from(args: argparse.Namespace):  # noqa: ANN201 - TuiSettings, imported lazily
    """Validate the arguments before the screen opens: every mistake is one line on stderr, exit 2."""
    from labctl.protocol import load_protocol
    from labctl.tui import DEFAULT_AUTO_CONFIRM_S, TuiSettings

    auto = args.auto_confirm
    if auto is not None and not 0 <= auto <= 3600:
        raise InputError(f"--auto-confirm {auto:g}: expected seconds between 0 and 3600")
    if auto is not None and args.backend != "sim":
        raise InputError("--auto-confirm is only for --backend sim: on the real rig a person confirms each step")
    if auto is None and args.autostart and args.backend == "sim" and not args.no_auto_confirm:
        auto = DEFAULT_AUTO_CONFIRM_S
    out = Path(args.out) if args.out else None
    if args.resume and (out is None or not out.is_file()):
        raise InputError(f"--resume needs the existing campaign file as --out (got {args.out or 'none'})")
    if out is not None and not args.resume and out.exists():
        raise InputError(f"{out}: already exists; use --resume to continue it or choose another --out")
    protocol = load_protocol(args.protocol) if args.protocol else None
    devices = args.devices
    if args.backend == "hw":
        from labctl.hardware import find_devices_file

        devices = str(find_devices_file(devices))
    return TuiSettings(protocol=protocol, backend=args.backend, out=out, resume=args.resume,
                       autostart=args.autostart and protocol is not None, auto_confirm_s=auto, world=args.world,
                       seed=args.seed, rig=args.rig, devices=devices, no_auto_confirm=args.no_auto_confirm)


def run(args: argparse.Namespace) -> int:
    from labctl.storage import CampaignReader
    from labctl.tui import LabApp

    settings = settings_from(args)
    open_path = Path(args.open) if args.open else None
    if open_path is not None:
        CampaignReader(open_path).close()  # a missing or foreign file fails here, as one line
    if not (sys.stdin.isatty() and sys.stdout.isatty()):
        raise InputError("needs an interactive terminal; for unattended runs use 'labctl run'")
    app = LabApp(settings, open_path=open_path)
    outcome = app.run()
    if app.error is not None:
        sys.stderr.write(f"labctl tui: error: {app.error}\n")
        return 1
    if outcome is None:
        if args.json:
            emit({"status": None, "path": None, "message": ""}, True, str)
        return 0
    emit({"status": outcome.status, "path": str(outcome.path), "message": outcome.message or ""}, args.json,
         lambda r: f"campaign {r['status']}: {r['path']}" + (f" ({r['message']})" if r["message"] else ""))
    return 0 if outcome.status == "complete" else (130 if outcome.status == "interrupted" else 1)
