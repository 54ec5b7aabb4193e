"""The ``labctl`` command line: one module per command in this package, found automatically.

A command module ``labctl/cli/NAME.py`` (the command ``import`` lives in ``importer.py``, ``import`` being a
Python keyword) follows three rules:

- it defines ``register(subparsers)``, which adds the parser ``NAME`` (with sub-commands if it has them),
  calls ``common.add_json`` on every parser that runs something, and sets ``func`` to a callable taking the
  parsed arguments and returning an exit code;
- its top level and ``register`` import only the standard library, ``labctl.cli.common`` and
  ``labctl.errors``: numpy, scipy, the HDF5 bindings, textual, matplotlib and the labctl packages that pull them in are
  imported inside the function that runs the command, so that start-up stays fast
  (tests/test_cli_foundation.py checks this for every command module);
- errors a user can fix raise ``labctl.errors.InputError`` (or another ``LabctlError``): one line on
  stderr, exit 2; ``--json`` prints exactly one JSON object on stdout.

``main`` imports only the module of the command named on the command line; ``labctl --help`` (or an
unknown command) imports them all to list them.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Iterable, Sequence

from labctl import __version__
from labctl.cli.common import run_command

NOT_COMMANDS = frozenset({"common", "progress"})
MODULE_OF_COMMAND = {"import": "importer"}  # commands whose name cannot be a module name


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2, as for every other user error
        self.exit(2, f"labctl {self.prog.partition(' ')[2] or ''}: error: {message}\n".replace("  ", " "))


def command_modules() -> list[str]:
    """Names of the command modules of this package, without importing them."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__)
                  if not m.name.startswith("_") and m.name not in NOT_COMMANDS)


def build_parser(modules: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """The parser with the commands of ``modules`` (default: every command module)."""
    parser = _Parser(prog="labctl", description="Hammer-impact modal tests of roller-rail contact stiffness.")
    parser.add_argument("--version", action="version", version=f"labctl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in command_modules() if modules is None else modules:
        module = importlib.import_module(f"{__name__}.{name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def _modules_for(argv: Sequence[str]) -> list[str] | None:
    """The command modules needed to parse ``argv``: the named command's, none for --version, else all."""
    command = next((a for a in argv if not a.startswith("-")), None)
    if command is None:
        return [] if "--version" in argv and not {"-h", "--help"} & set(argv) else None
    module = MODULE_OF_COMMAND.get(command, command)
    return [module] if module in command_modules() else None


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(_modules_for(argv)).parse_args(argv)
    return run_command(args)


if __name__ == "__main__":
    sys.exit(main())
