"""The ``labctl`` command line: one module per command in this package, each exposing ``register``.

Every command module defines ``register(subparsers)`` which adds its parser and sets ``func`` to a callable
taking the parsed arguments and returning an exit code. Errors a user can fix exit 2 with one line on
stderr; ``--json`` output is exactly one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence

from labctl import __version__
from labctl.cli.common import run_command


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2, as for every other user error
        self.exit(2, f"labctl {self.prog.partition(' ')[2] or ''}: error: {message}\n".replace("  ", " "))


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="labctl", description="Hammer-impact modal tests of roller-rail contact stiffness.")
    parser.add_argument("--version", action="version", version=f"labctl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_") or info.name == "common":
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_command(args)


if __name__ == "__main__":
    sys.exit(main())
