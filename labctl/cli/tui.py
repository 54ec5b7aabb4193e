"""``labctl tui``: the terminal UI at the rig — run a protocol with live plots and dialogs, or browse a file."""

from __future__ import annotations

import argparse
import os
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
    p.add_argument("--watch", metavar="FILE.h5",
                   help="follow a campaign another process (labctl run / labctl tui) is writing, read-only")
    p.add_argument("--serve", action="store_true",
                   help="show this screen in a web browser (textual-serve) instead of the terminal; each browser "
                        "tab starts its own session, so serve --watch FILE to follow a campaign from elsewhere")
    p.add_argument("--host", default="127.0.0.1",
                   help="with --serve: address to listen on (default 127.0.0.1, this machine only)")
    p.add_argument("--port", type=int, default=8000, help="with --serve: port (default 8000)")
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


def serve_command(argv: list[str]) -> str:
    """The ``labctl tui`` command each browser session runs: these arguments without --serve/--host/--port."""
    import shlex

    out, skip = [], False
    for arg in argv:
        if skip:
            skip = False
            continue
        if arg in ("--host", "--port"):
            skip = True
            continue
        if arg == "--serve" or arg.startswith(("--host=", "--port=")):
            continue
        out.append(arg)
    return shlex.join([sys.executable, "-m", "labctl", *out])


def serve(args: argparse.Namespace, argv: list[str]) -> int:
    """Serve the TUI to web browsers through textual-serve (localhost unless --host says otherwise)."""
    try:
        from textual_serve.server import Server
    except ImportError:
        raise InputError("--serve needs textual-serve: pip install textual-serve") from None
    if not 0 < args.port < 65536:
        raise InputError(f"--port {args.port}: expected 1-65535")
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        sys.stderr.write(f"labctl tui: warning: serving on {args.host}: anyone who reaches this address can see "
                         "the screen" + ("" if args.watch else " and drive the rig") + "\n")
    Server(serve_command(argv), host=args.host, port=args.port, title="labctl").serve()
    return 0


def run(args: argparse.Namespace) -> int:
    from labctl.storage import CampaignReader
    from labctl.tui import LabApp

    settings = settings_from(args)
    open_path = Path(args.open) if args.open else None
    watch_path = Path(args.watch) if args.watch else None
    if open_path is not None and watch_path is not None:
        raise InputError("--open and --watch: give one (--watch follows a campaign still being written)")
    if watch_path is not None and args.protocol:
        raise InputError("--watch FILE only follows a campaign another process runs; it takes no PROTOCOL")
    if open_path is not None:
        CampaignReader(open_path).close()  # a missing or foreign file fails here, as one line
    if args.serve:
        return serve(args, sys.argv[1:])
    served = "web_driver" in os.environ.get("TEXTUAL_DRIVER", "")  # a session of labctl tui --serve
    if not served and not (sys.stdin.isatty() and sys.stdout.isatty()):
        raise InputError("needs an interactive terminal; for unattended runs use 'labctl run'")
    app = LabApp(settings, open_path=open_path, watch_path=watch_path)
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
